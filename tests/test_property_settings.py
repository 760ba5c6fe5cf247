"""The property tests that gate merges are deterministic (issue 27: one failed once in about 60 runs and never
reproduced): tests/conftest.py loads the ``gate`` profile (``derandomize``), so a property test draws the same
examples on every run, and ``--hypothesis-profile=explore`` is the way to search with fresh ones."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import test_properties

GATE = settings.get_profile("gate")


def _drawn():
    seen = []

    @settings(max_examples=25)
    @given(x=st.floats(-1e6, 1e6), n=st.integers(0, 10**9))
    def probe(x, n):
        seen.append((x, n))

    probe()
    return seen


@pytest.mark.skipif(not settings.default.derandomize, reason="a search profile (--hypothesis-profile=explore)")
def test_property_tests_draw_the_same_examples_every_run():
    first, second = _drawn(), _drawn()
    assert first == second and len(set(first)) > 10


@pytest.mark.skipif(not settings.default.derandomize, reason="a search profile (--hypothesis-profile=explore)")
def test_the_property_modules_settings_inherit_the_gate_profile():
    assert GATE.derandomize and GATE.print_blob and GATE.database is None
    for name in ("FAST", "SLOW"):
        chosen = getattr(test_properties, name)
        assert chosen.derandomize and chosen.print_blob, name
