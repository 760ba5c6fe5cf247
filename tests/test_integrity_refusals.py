"""Issue 12: every refusal is one line naming the key (or the path), with exit 2 for bad input and exit 1 for a
file-system fault or a held lock, before Hydra starts, leaving nothing behind. The cases are data
(``tests/integrity_cases.py``), shared with ``benchmarks/integrity_table.py``; here they run in-process (about
0.1 s each: nothing runs past validation)."""

from __future__ import annotations

import contextlib
import logging

import pytest

from integrity_cases import CASES, left_behind, prepare

from ddmr_cli.storage import jobdir

from ddmr_cli.cli import main

#: one case per kind of refusal runs in the fast suite (``pytest -m "not slow"``): a typo, a value a model part
#: refuses, a keep-series form, a file in the way, a held lock; the whole catalogue (each case composes a config,
#: about 0.15 s; "huge network" builds 10^8 neurons' centres, 3-4 s) runs in the full suite
FAST = {"typo added", "mass overflows J", "keep bad form", "sweep dir is a file", "dir locked"}


@pytest.mark.parametrize("case", [pytest.param(c, id=c.name, marks=() if c.name in FAST else pytest.mark.slow)
                                  for c in CASES])
def test_refused_with_one_line_and_nothing_left(case, tmp_path, monkeypatch, capfd, caplog):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    args = prepare(case, work)
    with contextlib.ExitStack() as stack:
        if case.setup == "lock":
            stack.enter_context(jobdir.DirLock(work / "locked"))
        code = main.main(["run", *args])
    err = capfd.readouterr().err  # file-descriptor level: log handlers' lines count too
    lines = err.strip().splitlines()
    assert code == case.exit, err
    assert len(lines) == 1 and lines[0].startswith("ddmr: error: ") and case.message in lines[0], lines
    assert "Traceback" not in err
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []  # no extra log lines
    assert left_behind(work, case) == []


def test_the_lock_message_names_the_holder(tmp_path, monkeypatch, capsys):
    import os
    import socket

    monkeypatch.chdir(tmp_path)
    with jobdir.DirLock(tmp_path / "locked"):
        assert main.main(["run", f"hydra.run.dir={tmp_path / 'locked'}"]) == 1
    line = capsys.readouterr().err.strip()
    assert f"in use by pid {os.getpid()} on {socket.gethostname()} since " in line
    assert "(ddmr" in line and "choose another output dir" in line  # the holder's command (its argv may be empty)
