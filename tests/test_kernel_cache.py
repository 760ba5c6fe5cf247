"""A warm kernel cache runs exactly the code a cold one compiles (issue 31; ddmr_cli/engine/kernels.py).

The mechanism: the compiled step loop's on-disk copy was named after the controller's law module and state layout
only, so every other argument type (the run record, whose delay line's length depends on ``actuator.delay``; the
sensor's state; the World) shared one copy, and numba's index beside it collected one entry per signature (16
after ordinary use). A warm cache then handed a call an entry compiled for another layout (``TypeError: can't
unbox array``), and where the types happen to agree it would run another layout's code. The copy's name now holds
the call's complete argument types, so each copy's index holds one signature: that is what these tests pin, and
that warm numbers equal cold ones bit for bit, across processes, in mixed orders and in a reused joblib worker.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest

from ddmr_cli.compiled import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="the disk cache is numba's")

#: runs each job given as controller:scenario:realism (``-`` for none) and prints {job: per-seed metrics}
_SCRIPT = textwrap.dedent("""
    import json, sys
    from ddmr_cli import paper_simulation, simulate

    def job(spec):
        controller, scenario, realism = spec.split(":")
        overrides = [f"controller={controller}", f"scenario={scenario}", "simulation.duration=0.06"]
        if realism != "-":
            overrides.append(f"+realism={realism}")
        r = simulate(paper_simulation(*overrides), [3, 4])
        return [float(v).hex() for name in ("deviation_mae", "e_x_mae", "chattering", "d_est_mae")
                for v in r.metric(name)]

    def jobs(specs):
        return {spec: job(spec) for spec in specs}

    if __name__ == "__main__":
        if sys.argv[1] == "joblib":  # one reused loky worker runs every batch, one after another
            from joblib import Parallel, delayed
            batches = [sys.argv[2:][i::2] for i in range(2)] * 2
            out = {}
            for part in Parallel(n_jobs=1, backend="loky")(delayed(jobs)(b) for b in batches):
                for spec, values in part.items():
                    assert out.setdefault(spec, values) == values, spec
        else:
            out = jobs(sys.argv[1:])
        print(json.dumps(out))
""")


def _run(cache: Path, *args: str) -> dict:
    script = cache.parent / "cache_job.py"
    script.write_text(_SCRIPT)
    env = {**os.environ, "DDMR_CACHE_DIR": str(cache)}
    p = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, env=env, timeout=1200)
    assert p.returncode == 0, p.stderr[-3000:]
    return json.loads(p.stdout.strip().splitlines()[-1])


def _entries_per_copy(cache: Path) -> Counter:
    """How many compiled signatures numba's index holds for each generated copy's run_chunk (one .nbc each)."""
    pattern = re.compile(r"^(ddmr_stepper_\w+?)\.run_chunk-\d+\.py\d+\.\d+\.nbc$")
    found = (pattern.match(p.name) for p in (cache / "kernels" / "__pycache__").glob("*.nbc"))
    return Counter(m.group(1) for m in found if m)


def _check(tmp_path: Path, jobs: list[str]) -> None:
    cold = {}
    for i, spec in enumerate(jobs):  # every job alone in a fresh cache: what a cold cache computes
        cold.update(_run(tmp_path / f"cold{i}", spec))
    warm = tmp_path / "warm"
    filled = {**_run(warm, *jobs[::2]), **_run(warm, *jobs[1::2][::-1])}  # two processes fill one cache
    mixed = _run(warm, *jobs[::-1])  # a third loads every copy, in another order
    reused = _run(warm, "joblib", *jobs)  # one reused joblib worker runs them all, twice
    for spec in jobs:
        assert filled[spec] == cold[spec], spec
        assert mixed[spec] == cold[spec], spec
        assert reused[spec] == cold[spec], spec
    entries = _entries_per_copy(warm)
    assert entries and max(entries.values()) == 1, entries  # one signature per copy: nothing to confuse


def test_a_warm_cache_gives_each_actuator_delay_its_own_compiled_loop(tmp_path):
    """Two delays of one controller (two run-record layouts) in one cache: each its own copy, cold numbers."""
    _check(tmp_path, ["pid:paper_2:delay_2ms", "pid:paper_2:delay_5ms", "pid:paper_1:-"])


@pytest.mark.slow
def test_a_warm_cache_filled_by_every_realism_kind_runs_cold_numbers(tmp_path):
    """The SMC family (one law module, several state layouts) x delay, rate, encoder and noise points x both
    scenarios (12 jobs; about 20 compilations, 3-5 min on 2 cores)."""
    jobs = [f"{c}:{s}:{r}" for c in ("smc_ndo", "smc_ndo_nno") for s in ("paper_1", "paper_2")
            for r in ("delay_5ms", "rate_250hz", "realistic")]
    _check(tmp_path, jobs)


def test_the_identity_spells_nested_shapes_and_tuple_classes():
    import numpy as np

    from ddmr_cli.engine.kernels import call_identity

    one = np.zeros(2, dtype=[("delay_line", "f8", (3, 2))])
    other = np.zeros(2, dtype=[("delay_line", "f8", (6, 2))])
    assert call_identity((one,)) != call_identity((other,))
    assert "(3, 2)" in call_identity((one,)) and "(6, 2)" in call_identity((other,))
