"""Shared fixtures: the smoke sweep is run once per session through the installed console script."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest


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


@pytest.fixture(scope="session")
def smoke_sweep_dir(tmp_path_factory) -> Path:
    """A complete ``+experiment=smoke`` sweep (joblib launcher), run once for the whole session."""
    root = tmp_path_factory.mktemp("smoke")
    sweep_dir = root / "sweep"
    proc = run_ddmr(["run", "-m", "+experiment=smoke", f"hydra.sweep.dir={sweep_dir}"], cwd=root)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return sweep_dir
