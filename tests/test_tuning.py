"""Gain tuning through ddmr's Optuna sweeper (hydra/sweeper=ddmr_optuna; ddmr_cli/study/tuning.py, docs/model.md §9):
the search spaces name real keys, bad input is one line and exit 2, the objective's penalty rule, a study end to
end (joblib and basic launchers give the same trials), resumption continuing the trial count (also after a
SIGKILL mid-study), the study database opened by ``optuna.load_study``, the report at tuned gains."""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import subprocess
import time
from pathlib import Path

import pandas as pd
import pytest
from conftest import catalogue
import yaml
from omegaconf import OmegaConf

from conftest import ddmr_executable, run_ddmr

pytest.importorskip("optuna", reason="the tune extra is not installed (pip install -e '.[tune]')")

from ddmr_cli.config import compose_config, group_options, key_doc, seeds_of  # noqa: E402
from ddmr_cli.cli.main import main  # noqa: E402
from ddmr_cli.study import tuning as TU  # noqa: E402
from ddmr_cli.report.tuning import pareto_front  # noqa: E402

#: a tiny study: 2 seeds, 0.4 s at a 2 ms step (every controller's loop is stable there), 4 trials
TINY = ["run.n_runs=2", "simulation.duration=0.4", "simulation.dt=0.002", "metrics.settle_time=0.2",
        "metrics.zone_settle_time=0.1", "tuning.held_out.n_runs=6"]


# --- the search spaces ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("option", group_options("tune"))
def test_search_space_names_real_keys_around_the_paper_gains(option):
    cfg = compose_config([f"+tune={option}"], return_hydra_config=True)
    assert cfg.tuning.controller == option and cfg.controller.get("name", "pid") == option
    space = TU.search_space(cfg)
    assert len(space) >= 3
    for dim in space:
        doc = key_doc(cfg, dim.key)  # KeyError when the key is not in the composed config
        assert doc.unit and doc.help, dim.key  # a documented schema field, not a free-form entry
        paper = float(doc.value)
        assert dim.low < paper < dim.high, (dim.key, paper, dim.low, dim.high)
        assert dim.log, f"{dim.key}: the gains span decades; the search is on a log scale"


def test_the_study_settings_are_the_same_for_every_controller():
    studies = [compose_config([f"+tune={o}"], return_hydra_config=True) for o in group_options("tune")]
    for key in ("tuning.n_trials", "tuning.seed", "tuning.batch", "run.n_runs", "run.base_seed",
                "tuning.saturation_limit", "tuning.held_out.base_seed", "tuning.held_out.n_runs",
                "hydra.sweeper.n_trials", "hydra.sweeper.sampler.seed"):
        assert len({str(OmegaConf.select(c, key)) for c in studies}) == 1, key


@pytest.mark.parametrize("objective, sampler, directions", [("deviation", "TPESampler", ["minimize"]),
                                                            ("pareto", "NSGAIISampler", ["minimize", "minimize"])])
def test_every_study_is_ddmrs_optuna_sweeper_on_sqlite(objective, sampler, directions):
    from hydra.utils import instantiate

    cfg = compose_config(["+tune=smc_ndo", f"objective={objective}"], return_hydra_config=True)
    sweeper = instantiate(cfg.hydra.sweeper)  # as Hydra instantiates it (the sampler node with it)
    assert type(sweeper).__name__ == "DdmrOptunaSweeper" and type(sweeper.sampler_config).__name__ == sampler
    assert sweeper.directions == directions and sweeper.storage == f"sqlite:///{cfg.hydra.sweep.dir}/study.db"
    assert sweeper.study_name == f"smc_ndo-{objective}" and sweeper.n_jobs == cfg.tuning.batch


# --- bad input ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("args, named", catalogue([
    (["+tune=nocontroller"], "tune=nocontroller: unknown tune"),
    (["+tune=pid", "tuning.n_trials=0"], "tuning.n_trials=0"),
    (["+tune=pid", "controller.kp=tag(log,interval(5,1))"], "empty or inverted range"),
    (["+tune=smc", "controller.lam=interval(3,3)"], "empty or inverted range"),
    (["+tune=pid", "controller.kd=tag(log,interval(0,1))"], "log-scale range needs low > 0"),
    (["+tune=pid", "controller.gain_kx=interval(1,2)"], "controller.gain_kx is not a key"),
    (["+tune=pid", "tuning.held_out.base_seed=5"], "overlap the tuning seeds"),
    (["+tune=smc", "objective=best"], "objective=best: unknown objective"),
    (["+tune=smc", "simulation.duration=2", "metrics.settle_time=2"], "metrics.settle_time=2.0: must be <"),
], fast=2))
def test_bad_study_input_is_one_line_and_exit_2(tmp_path, capsys, args, named):
    out = tmp_path / "study"
    assert main(["run", "-m", *args, f"hydra.sweep.dir={out}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ddmr: error: ") and named in err[0], err
    assert not out.exists()


# --- the objective --------------------------------------------------------------------------------------------


def _study_cfg(*extra):
    return compose_config(["+tune=pid", "run.n_runs=3", "simulation.duration=0.4", "simulation.dt=0.002",
                           "metrics.settle_time=0.2", *extra])


def test_a_feasible_trial_scores_the_mean_deviation_over_scenarios_and_runs():
    from ddmr_cli.config import validate_config
    from ddmr_cli.engine.simulation import simulate

    cfg = _study_cfg("tuning.saturation_limit=0.9")
    outcome = TU.evaluate_gains(cfg)
    assert outcome.feasible and outcome.violation == 0.0 and len(outcome.values) == 1
    means = []
    for name in cfg.tuning.scenarios:
        result = simulate(validate_config(TU.scenario_config(cfg, name)), seeds_of(cfg), keep_series=[])
        assert not result.diverged.any()
        means.append(float(result.metric(TU.OBJECTIVE_METRIC).mean()))
    assert math.isclose(outcome.values[0], sum(means) / len(means), rel_tol=1e-12)
    assert set(outcome.per_scenario) == {"paper_1", "paper_2"}


def test_saturation_beyond_the_limit_is_penalised_above_every_feasible_value():
    cfg = _study_cfg("tuning.saturation_limit=0.0")
    outcome = TU.evaluate_gains(cfg)
    assert outcome.saturation > 0.0  # PID's start from the offset pose saturates a little
    assert not outcome.feasible and "saturation" in outcome.reason
    bound = float(cfg.simulation.divergence_bound)
    # closed form: bound * (1 + violation), violation = the saturation fraction beyond the limit (0)
    assert math.isclose(outcome.values[0], bound * (1.0 + outcome.saturation), rel_tol=1e-12)
    assert outcome.values[0] > bound > outcome.deviation and math.isfinite(outcome.values[0])


def test_gains_unstable_at_the_step_are_an_infeasible_trial_not_a_failure():
    cfg = _study_cfg("controller.kd=5.0")  # the sampled PD loop is unstable at 2 ms
    outcome = TU.evaluate_gains(cfg)
    assert not outcome.feasible and outcome.reason.startswith("unstable") and outcome.violation == 1.0
    assert math.isclose(outcome.values[0], 2.0 * float(cfg.simulation.divergence_bound), rel_tol=1e-12)
    pareto = TU.evaluate_gains(_study_cfg("controller.kd=5.0", "objective=pareto"))
    u_max, dt = float(cfg.robot.max_voltage), float(cfg.simulation.dt)
    assert len(pareto.values) == 2 and math.isclose(pareto.values[1], 2.0 * (2.0 * u_max / dt), rel_tol=1e-12)


def test_pareto_front_keeps_the_non_dominated_points():
    points = [(1.0, 5.0), (2.0, 3.0), (2.5, 4.0), (3.0, 1.0), (4.0, 1.0), (0.5, 9.0)]
    assert [points[i] for i in pareto_front(points)] == [(0.5, 9.0), (1.0, 5.0), (2.0, 3.0), (3.0, 1.0)]


# --- end to end -----------------------------------------------------------------------------------------------


def _study(tmp_path: Path, name: str, *extra: str, budget: int = 4) -> Path:
    out = tmp_path / name
    proc = run_ddmr(["run", "-m", *extra, *TINY, f"tuning.n_trials={budget}", f"hydra.sweep.dir={out}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def _trials(study: Path) -> pd.DataFrame:
    return pd.read_csv(study / TU.TRIALS_CSV).sort_values("number").reset_index(drop=True)


@pytest.mark.slow
def test_a_study_end_to_end_and_its_report(tmp_path):
    study = _study(tmp_path, "smc", "+tune=smc")
    trials = _trials(study)
    assert list(trials["state"]) == ["COMPLETE"] * 4 and list(trials["number"]) == [0, 1, 2, 3]
    for _, row in trials.iterrows():  # each trial's own record is what the sweeper was told
        record = json.loads((study / row["dir"] / TU.TRIAL_FILE).read_text())
        assert math.isclose(record["values"][0], row["value_0"], rel_tol=1e-12)
    best = yaml.safe_load((study / TU.BEST_FILE).read_text())["best"]
    assert len(best) == 1 and math.isclose(best[0]["values"][0], trials["value_0"].min(), rel_tol=1e-12)
    # the best trial's value is reproduced by evaluating its gains again
    cfg = compose_config(["+tune=smc", *TINY, *(f"{k}={v!r}" for k, v in best[0]["params"].items())])
    assert TU.OBJECTIVE_METRIC == "deviation_mae_ss" and trials[TU.OBJECTIVE_METRIC].notna().all()
    assert math.isclose(TU.evaluate_gains(cfg).values[0], best[0]["values"][0], rel_tol=1e-12)
    # the same study through the basic launcher: the same trials (the batch, not the launcher, sets the sampling)
    basic = _trials(_study(tmp_path, "basic", "+tune=smc", "launcher=basic"))
    params = [c for c in trials.columns if c.startswith("controller.")]
    pd.testing.assert_frame_equal(trials[params + ["value_0"]], basic[params + ["value_0"]], rtol=1e-12)
    # the report: held-out runs at paper and tuned gains, the comparison, the figures
    proc = run_ddmr(["report", str(study)], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = (study / "report" / "report.md").read_text()
    for section in ("## Studies", "## Paper gains vs tuned gains", "## Held-out evaluation", "## Figures"):
        assert section in report
    gains = pd.read_csv(study / "report" / "tables" / "gains.csv")
    for _, row in gains.iterrows():
        assert math.isclose(row["tuned"], best[0]["params"][row["key"]], rel_tol=1e-12)
    held = pd.read_csv(study / "report" / "tables" / "heldout.csv")
    assert set(held["gains"]) == {"paper", "tuned"} and set(held["runs"]) == {6}
    summary = json.loads((study / "heldout" / "tuned" / "smc-paper_1" / "summary.json").read_text())
    assert summary["seeds"] == [1000, 1005]
    assert summary["parameters"]["lambda"] == pytest.approx(best[0]["params"]["controller.lam"], rel=1e-12)
    for figure in ("history.png", "pareto.png"):
        assert (study / "report" / "figures" / figure).stat().st_size > 1000
    assert (study / "report" / "heldout_tuned" / "report.md").is_file()


@pytest.mark.slow
def test_a_killed_study_resumes_and_the_trial_count_continues(tmp_path):
    import optuna

    study = _study(tmp_path, "pid", "+tune=pid", budget=2)
    info = json.loads((study / TU.STUDY_FILE).read_text())
    # what a kill leaves: a trial asked of the sampler and never told its value (RUNNING)
    stored = optuna.load_study(study_name=info["study_name"], storage=TU.storage_url(study))
    stored.ask()
    command = ["run", "-m", "+tune=pid", *TINY, "tuning.n_trials=4", f"hydra.sweep.dir={study}"]
    # while another session holds the dir (its trial RUNNING), the command is refused and changes nothing
    from ddmr_cli.storage.jobdir import DirLock

    with DirLock(study, kind="sweep"):
        busy = run_ddmr(command, cwd=tmp_path)
    # (the refusal names the holder, this test's process, by its command line: any word may be in it)
    assert busy.returncode == 1 and "in use by pid" in busy.stderr
    assert "ddmr: resuming study" not in busy.stdout + busy.stderr
    again_stored = optuna.load_study(study_name=info["study_name"], storage=TU.storage_url(study))
    assert [t.state.name for t in again_stored.trials] == ["COMPLETE", "COMPLETE", "RUNNING"]
    proc = run_ddmr(command, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "resuming study pid-deviation: 2/4 trials done (1 left running by a killed session marked failed)" \
        in proc.stderr + proc.stdout
    trials = _trials(study)
    assert list(trials["number"]) == [0, 1, 2, 3, 4]
    assert list(trials["state"]) == ["COMPLETE", "COMPLETE", "FAIL", "COMPLETE", "COMPLETE"]
    assert list(trials["killed"]) == [False, False, True, False, False]
    sessions = json.loads((study / TU.STUDY_FILE).read_text())["sessions"]
    assert [s["n_trials"] for s in sessions] == [2, 2] and [s["sampler_seed"] for s in sessions] == [0, 2]
    # the same command once the budget is spent runs nothing and succeeds
    again = run_ddmr(command, cwd=tmp_path)
    assert again.returncode == 0 and len(_trials(study)) == 5
    # another config into the same study dir is refused before anything runs
    other = run_ddmr([*command, "run.n_runs=3"], cwd=tmp_path)
    assert other.returncode == 2 and "holds a study of another config" in other.stderr
    assert len(_trials(study)) == 5


@pytest.mark.slow
def test_the_pareto_mode_returns_a_front_of_non_dominated_trials(tmp_path):
    study = _study(tmp_path, "pareto", "+tune=smc_ndo", "objective=pareto")
    best = yaml.safe_load((study / TU.BEST_FILE).read_text())["best"]
    values = [tuple(b["values"]) for b in best]
    assert values and all(len(v) == 2 for v in values)
    for a in values:
        assert not any(b[0] <= a[0] and b[1] <= a[1] and b != a for b in values)
    trials = _trials(study)
    assert {"value_0", "value_1"} <= set(trials.columns) and (trials["state"] == "COMPLETE").all()


def _states_in_db(db: Path) -> dict[str, int]:
    """Trials per state in a study database, read with plain sqlite3 while the sweeper writes it."""
    if not db.is_file():
        return {}
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1.0) as con:
            return dict(con.execute("SELECT state, count(*) FROM trials GROUP BY state").fetchall())
    except sqlite3.Error:  # the schema not created yet, or the file locked for a moment
        return {}


@pytest.mark.slow
def test_a_study_killed_by_sigkill_mid_study_resumes_without_losing_or_repeating_trials(tmp_path):
    import optuna

    out = tmp_path / "smc_ndo"
    budget = 12
    command = ["run", "-m", "+tune=smc_ndo", "launcher=basic", *TINY, f"tuning.n_trials={budget}",
               f"hydra.sweep.dir={out}"]
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    proc = subprocess.Popen([ddmr_executable(), *command], cwd=tmp_path, env=env, start_new_session=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    try:
        # mid-study: two trials told their values, the next batch asked and running
        while not ((n := _states_in_db(out / TU.STORAGE_FILE)).get("COMPLETE", 0) >= 2 and n.get("RUNNING", 0)):
            assert proc.poll() is None, "the study ended before it could be killed"
            assert time.monotonic() < deadline, "no trial completed in 300 s"
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the session and anything it started, mid-study
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    name = json.loads((out / TU.STUDY_FILE).read_text())["study_name"]
    killed = optuna.load_study(study_name=name, storage=f"sqlite:///{out / TU.STORAGE_FILE}")
    before = {t.number: t for t in killed.get_trials(deepcopy=False)}
    done = [n for n, t in before.items() if t.state == optuna.trial.TrialState.COMPLETE]
    running = [n for n, t in before.items() if t.state == optuna.trial.TrialState.RUNNING]
    assert 2 <= len(done) < budget and running, {n: t.state.name for n, t in before.items()}

    again = run_ddmr(command, cwd=tmp_path)  # the same command
    assert again.returncode == 0, again.stderr[-3000:]
    assert (f"resuming study {name}: {len(done)}/{budget} trials done ({len(running)} left running by a killed "
            f"session marked failed)") in again.stdout + again.stderr
    study = optuna.load_study(study_name=name, storage=f"sqlite:///{out / TU.STORAGE_FILE}")
    trials = study.get_trials(deepcopy=False)
    states = {t.number: t.state.name for t in trials}
    assert sorted(states) == list(range(len(trials)))  # numbered on from the killed session, no gap
    complete = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    assert len(complete) == budget  # none lost, none run beyond the budget
    for n in done:  # the killed session's complete trials are kept as they were
        assert states[n] == "COMPLETE" and study.trials[n].values == before[n].values
    for n in running:  # what it left running is failed and marked, not counted
        assert states[n] == "FAIL" and study.trials[n].user_attrs == {"killed": True}
    params = [tuple(sorted(t.params.items())) for t in complete]
    assert len(set(params)) == budget  # no trial repeated
    table = _trials(out)
    assert list(table["killed"]) == [n in running for n in sorted(states)]
    rows = table[table["state"] == "COMPLETE"]
    assert rows["dir"].notna().all() and rows["dir"].is_unique  # each complete trial has its own job dir
    for _, row in rows.iterrows():
        record = json.loads((out / row["dir"] / TU.TRIAL_FILE).read_text())
        assert math.isclose(record["values"][0], row["value_0"], rel_tol=1e-12)
    assert math.isclose(study.best_value, min(t.values[0] for t in complete), rel_tol=1e-12)


def test_a_session_is_planned_read_only_and_started_under_the_lock(tmp_path):
    """plan_session writes nothing (a RUNNING trial stays RUNNING); Session.start marks it failed, and refuses a
    study whose complete trials changed between planning and the lock."""
    import optuna

    from ddmr_cli.storage.jobdir import FaultError

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name="s", storage=TU.storage_url(tmp_path))
    study.tell(study.ask(), 1.0)
    study.ask()  # left RUNNING by a killed session
    session = TU.plan_session(tmp_path, "s", budget=5, seed=10)
    assert session.overrides == ["hydra.sweeper.n_trials=4", "hydra.sweeper.sampler.seed=11"]
    assert [t.state.name for t in study.get_trials()] == ["COMPLETE", "RUNNING"]
    session.start()
    assert [t.state.name for t in optuna.load_study(study_name="s", storage=TU.storage_url(tmp_path)).trials] \
        == ["COMPLETE", "FAIL"]
    planned = TU.plan_session(tmp_path, "s", budget=5, seed=10)
    study.tell(study.ask(), 2.0)  # another session completed a trial meanwhile
    with pytest.raises(FaultError, match="changed while this session was planned"):
        planned.start()
    fresh = TU.plan_session(tmp_path / "none", "s", budget=3, seed=0)
    assert fresh.overrides == ["hydra.sweeper.n_trials=3", "hydra.sweeper.sampler.seed=0"]
    fresh.start()  # no storage yet: nothing to do
