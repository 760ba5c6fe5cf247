"""Shared fixtures: the smoke sweep is run once per session through the installed console script."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

# Property tests gate merges, so by default they are deterministic: ``derandomize`` draws each test's examples
# from a seed fixed by the test itself (the same examples on every run and machine, whatever the order, -n or
# the database), a failure prints the blob that replays it (``@reproduce_failure``), and the one health check
# that times things (``too_slow``: data generation slower than a threshold) is off, since a busy CI machine
# would fail it by load alone. ``pytest --hypothesis-profile=explore`` searches with fresh random examples (a
# nightly hunt; run it with ``--hypothesis-seed=N`` to replay one search).
settings.register_profile("gate", derandomize=True, print_blob=True, database=None, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("explore", derandomize=False, print_blob=True, database=None, deadline=None)
settings.load_profile("gate")


def ddmr_executable() -> str:
    """The installed ``ddmr`` console script next to this interpreter (fails loudly when missing)."""
    candidate = Path(sys.executable).with_name("ddmr")
    found = str(candidate) if candidate.exists() else shutil.which("ddmr")
    if not found:
        raise RuntimeError("the ddmr console script is not installed; pip install the project first")
    return found


def run_ddmr(args, cwd, timeout=600, env=None):
    """Run the installed console script; returns the CompletedProcess (text)."""
    full_env = {**os.environ, "PYTHONHASHSEED": "0", **(env or {})}
    return subprocess.run([ddmr_executable(), *args], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env=full_env)


def catalogue(cases, fast=1, ids=None):
    """Parametrize values for a catalogue of like cases: the first ``fast`` run in the fast suite (``pytest -m "not
    slow"``), the rest are marked slow; the README's test command runs them all. A tuple is one case's arguments."""
    return [pytest.param(*(c if isinstance(c, tuple) else (c,)), id=None if ids is None else ids[i],
                         marks=() if i < fast else pytest.mark.slow) for i, c in enumerate(cases)]


@pytest.fixture
def skeletons(tmp_path, monkeypatch) -> Path:
    """ddmr's cache of compositions, empty, in ``tmp_path`` (DDMR_CACHE_DIR), switched on: its ``skeletons`` dir."""
    from ddmr_cli.config import skeleton_cache

    monkeypatch.setenv("DDMR_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv(skeleton_cache.SWITCH, raising=False)
    return tmp_path / "skeletons"


@pytest.fixture(scope="session")
def smoke_sweep_dir(tmp_path_factory) -> Path:
    """A complete ``+experiment=smoke`` sweep (joblib launcher), run once for the whole session."""
    root = tmp_path_factory.mktemp("smoke")
    sweep_dir = root / "sweep"
    # launcher=local named: a sweep this small would otherwise run in-process (cli/modes.py, small_local_sweep)
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "launcher=local", f"hydra.sweep.dir={sweep_dir}"], cwd=root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return sweep_dir
