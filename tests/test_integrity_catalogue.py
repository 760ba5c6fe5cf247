"""Issue 26: the catalogue of bad inputs and faults (``tests/integrity_catalogue.py``) through the console
script. The first case of each class runs in the fast tier, the rest are marked slow."""

from __future__ import annotations

import pytest

from integrity_catalogue import CASES

_FIRST = {c.cls: c.name for c in reversed(CASES)}


@pytest.mark.parametrize("case", [pytest.param(c, id=f"{c.cls}-{c.name}",
                                               marks=() if _FIRST[c.cls] == c.name else pytest.mark.slow)
                                  for c in CASES])
def test_catalogue(case, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    case.run(work)
