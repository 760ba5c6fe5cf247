"""A sweep's plan and outcome travel through Hydra's config and the sweep dir, not through module state; the
exit status comes from exactly this sweep's planned jobs as they are on disk."""

from __future__ import annotations

import json
import types

import pandas as pd
import pytest
from omegaconf import OmegaConf, open_dict

from conftest import run_ddmr

from ddmr_cli import job as app

from ddmr_cli.storage import io, sweep
from ddmr_cli.cli import callbacks
from ddmr_cli.config import plan as sweep_plan

from ddmr_cli.cli import main, run
from ddmr_cli.config import compose_config


@pytest.mark.parametrize("module", [sweep, main, app, io])
def test_cli_modules_hold_no_mutable_state(module):
    """No module-level variable that could carry state between calls (None placeholders, lists, dicts, sets)."""
    state = {name: value for name, value in vars(module).items()
             if not name.startswith("__") and not isinstance(value, (types.ModuleType, types.FunctionType, type))
             and (value is None or isinstance(value, (list, dict, set)))}
    assert state == {}


def test_the_callback_plans_the_jobs_from_the_config_hydra_carries(tmp_path):
    cfg = compose_config(["+experiment=smoke"], return_hydra_config=True)
    task = ["+experiment=smoke", "controller=pid,smc", "run.n_runs=3"]
    with open_dict(cfg):
        cfg.hydra.overrides.task = task
        cfg.hydra.sweep.dir = str(tmp_path / "sweep")
    callbacks.SweepAggregator().on_multirun_start(cfg)
    plan = json.loads((tmp_path / "sweep" / sweep.PLAN).read_text())["jobs"]
    # smoke's sweeper params give the scenarios, the command line the controllers (overriding smoke's five)
    assert [job["dir"] for job in plan] == [f"controller={c},run.n_runs=3,scenario={s}"
                                            for c in ("pid", "smc") for s in ("paper_1", "paper_2")]
    assert all("hydra.sweep.dir" not in " ".join(job["overrides"]) for job in plan)
    assert plan == sweep_plan.plan_jobs(task, cfg.hydra)


def test_read_state_with_a_plan_covers_exactly_the_planned_jobs(tmp_path):
    for name, status in (("a", "complete"), ("old", "failed")):
        (tmp_path / name).mkdir()
        io.write_json(tmp_path / name / io.SUMMARY, {"status": status, "overrides": []})
    plan = [{"dir": "a", "overrides": []}, {"dir": "b", "overrides": []}]
    state = sweep.read_state(tmp_path, plan=plan)
    assert [d.name for d, _ in state.complete] == ["a"] and state.failed == [] and state.unplanned == ["old"]
    assert [job["dir"] for job in state.missing] == ["b"] and not state.ok
    every = sweep.read_state(tmp_path, plan=plan, every_dir=True)
    assert [d.name for d, _ in every.failed] == ["old"] and [j["dir"] for j in every.missing] == ["b"]


def test_the_output_dir_is_resolved_once_and_pinned_for_hydra(tmp_path, monkeypatch):
    from hydra.core.override_parser.overrides_parser import OverridesParser

    monkeypatch.chdir(tmp_path)
    args = ["-m", "experiment_name=\"it's, odd\"", "run.n_runs=1"]
    launch = run.prepare(args, args[1:], multirun=True)
    assert launch.out_dir.parent == tmp_path.joinpath("outputs", "it's, odd").relative_to(tmp_path)
    pinned = launch.argv[-2]  # then this small sweep's launcher (in this process: cli/modes.py small_local_sweep)
    assert pinned.startswith("hydra.sweep.dir=") and launch.argv == (*args, pinned, "launcher=basic")
    (parsed,) = OverridesParser.create().parse_overrides([pinned])
    assert not parsed.is_sweep_override() and parsed.value() == str(launch.out_dir)
    assert [job["overrides"] for job in launch.plan] == [args[1:]] and list(tmp_path.iterdir()) == []
    again = run.prepare([*args, "hydra.sweep.dir=elsewhere"], [*args[1:], "hydra.sweep.dir=elsewhere"], True)
    assert again.argv[-2] == "hydra.sweep.dir=elsewhere" and again.argv.count("hydra.sweep.dir=elsewhere") == 1


@pytest.mark.slow
def test_exit_status_ignores_job_dirs_of_an_earlier_sweep(tmp_path):
    sweep_dir = tmp_path / "sweep"
    old = sweep_dir / "controller=pid,scenario=paper_2"  # an earlier sweep's failed job in the same dir
    old.mkdir(parents=True)
    io.write_json(old / io.SUMMARY, {"status": "failed", "error": "RuntimeError: earlier", "overrides": []})
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "controller=pid", "scenario=paper_1", "launcher=basic",
                     "run.plots=false", f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "1 complete, 0 failed, 0 missing" in proc.stdout and "earlier sweep" in proc.stdout
    jobs = pd.read_csv(sweep_dir / sweep.JOBS_CSV)
    assert list(jobs.job) == ["controller=pid,scenario=paper_1"] and list(jobs.status) == ["complete"]
    # the same dir, a sweep whose planned job fails (its files cannot be written): exit 1 from the on-disk state
    import errno

    from faults import fault_env

    env = fault_env(tmp_path / "site", errno.ENOSPC, "/.controller=smc,scenario=paper_1.")
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "controller=smc", "scenario=paper_1", "launcher=basic",
                     "run.plots=false", f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path, env=env)
    assert proc.returncode == 1 and "0 complete, 1 failed, 0 missing" in proc.stdout
    assert OmegaConf.load(sweep_dir / "multirun.yaml").hydra.sweep.dir == str(sweep_dir)
