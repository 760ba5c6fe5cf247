"""A sweep's first compositions shared between processes (ddmr_cli/config/compose_parallel.py): only on a cold cache
and with enough sets, every set into the cache once, configs equal to Hydra's own, a set that does not compose
left to validation, and a helper that ends with its parent."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import JobComposer, compose_config, compose_parallel
from ddmr_cli.config.compose_once import compositions_once

CONTROLLERS = ("pid", "smc", "smc_ndo", "smc_ndo_nno", "sta", "sta_ndo", "adrc", "adaptive_smc", "adaptive_smc_ndo")


@pytest.fixture
def cache(skeletons):
    return skeletons


def _shares(monkeypatch) -> list[list]:
    """Record the shares handed to helpers instead of starting them."""
    handed = []
    monkeypatch.setattr(compose_parallel, "_start", lambda name, sets: handed.append(sets))
    return handed


def test_helpers_only_for_a_cold_cache_with_enough_sets(monkeypatch):
    sets = [(f"controller={i}",) for i in range(1 + 3 * compose_parallel.MIN_SETS)]
    here = []

    def compose(cold):
        return lambda groups: here.append(groups) or cold

    handed = _shares(monkeypatch)
    assert compose_parallel.share(sets, compose(False), "config", 4) == 0  # the first set loaded: a warm cache
    assert here == sets[:1] and handed == []
    here.clear()
    few = sets[:compose_parallel.MIN_SETS + 1]
    assert compose_parallel.share(few, compose(True), "config", 4) == 0  # too few to pay a helper's start
    assert here == few[:1] and handed == []
    here.clear()
    compose_parallel.share(sets, compose(True), "config", 4)  # 24 left: 3 processes of 8 (not 4 of 6)
    assert len(handed) == 2 and here[0] == sets[0]
    rest = here[1:] + [s for part in handed for s in part]
    assert sorted(rest) == sorted(sets[1:]) and len(rest) == len(set(rest))  # each set once
    assert here[1:] == sets[1::3] and handed == [sets[2::3], sets[3::3]]  # interleaved shares


def test_a_cold_sweep_is_composed_in_two_processes_into_the_cache_and_equals_hydras(cache):
    jobs = [[f"controller={c}", f"scenario={s}", "run.n_runs=3"] for c in CONTROLLERS for s in ("paper_1", "paper_2")]
    jobs.append(["controller=no_such_controller", "scenario=paper_1"])  # does not compose: left to validation
    composer = JobComposer()
    assert composer.prefetch(jobs, 2) == 1  # one helper beside this process
    kept = len(list(cache.glob("*.pkl")))
    assert kept == len(jobs) - 1, kept  # every set that composes, once
    later = JobComposer()  # another validation: every set loads, none is composed again
    with compositions_once() as memo:
        configs = [later.compose(job) for job in jobs[:-1]]
        assert memo.composed == 0
    assert later.prefetch(jobs, 2) == 0  # warm: no helper
    for job, cfg in zip(jobs[:-1], configs):
        assert OmegaConf.to_container(cfg) == OmegaConf.to_container(
            compose_config(job)), job  # Hydra's own composition of the job
    with pytest.raises(Exception, match="no_such_controller"):
        later.compose(jobs[-1])


def test_a_helper_ends_when_its_parent_closes_its_stdin(cache):
    sets = [(f"controller={c}", f"scenario={s}", f"trajectory={t}") for c in CONTROLLERS
            for s in ("paper_1", "paper_2") for t in ("line", "circle", "figure_eight")]
    helper = compose_parallel._start("config", sets)  # 54 sets: about 15 s of work
    time.sleep(1.0)
    started = time.monotonic()
    helper.stdin.close()
    helper.wait(timeout=30)
    assert time.monotonic() - started < 10 and helper.returncode == 0
    assert len(list(cache.glob("*.pkl"))) < len(sets)  # it stopped before its share was done


def test_the_helper_runs_as_a_module():
    done = subprocess.run([sys.executable, "-m", "ddmr_cli.config"], input=b'["config", []]\n',
                          capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_ddmr_runs_planning_composes_a_cold_sweep_in_parallel_and_plans_every_job(cache, monkeypatch, tmp_path):
    from ddmr_cli import compiled
    from ddmr_cli.cli.args import normalise, split_args
    from ddmr_cli.cli.run import prepare

    started, real = [], compose_parallel._start
    monkeypatch.setattr(compose_parallel, "_start", lambda name, sets: started.append(len(sets)) or real(name, sets))
    monkeypatch.setattr(compiled, "thread_count", lambda n: 2)  # two cores, whatever this machine has
    argv = normalise(["-m", f"controller={','.join(CONTROLLERS)}", "scenario=paper_1,paper_2", "run.n_runs=2",
                      f"hydra.sweep.dir={tmp_path / 'sweep'}"])
    overrides, _ = split_args(argv)
    launch = prepare(argv, overrides, True)
    assert len(launch.plan) == 18 and started == [8]  # 17 sets left after the first: 9 here, 8 in the helper
    assert len(list(cache.glob("*.pkl"))) >= 18  # the jobs' sets (and the primary config's composition)
    assert not (tmp_path / "sweep").exists()  # planning writes nothing but the cache
