"""ddmr's Optuna sweeper plugin (hydra/sweeper=ddmr_optuna, hydra_plugins/ddmr_optuna_sweeper) on its own, with a
toy Hydra app: hydra-optuna-sweeper's search-space grammar, SQLite storage and resume, several objectives, the
grid sampler, failed trials. The ddmr studies on top of it: tests/test_tuning.py, tests/test_study_search.py."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

optuna = pytest.importorskip("optuna", reason="the tune extra is not installed (pip install -e '.[tune]')")

from hydra.core.override_parser.overrides_parser import OverridesParser  # noqa: E402
from hydra_plugins.ddmr_optuna_sweeper._space import (  # noqa: E402
    dimension, directions, objective_values, search_space)

APP = '''
import hydra
from hydra.core.plugins import Plugins
from hydra_plugins.ddmr_optuna_sweeper import config  # noqa: F401 (hydra/sweeper=ddmr_optuna)
from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import DdmrOptunaSweeper

Plugins.instance().register(DdmrOptunaSweeper)


@hydra.main(version_base="1.3", config_path=".", config_name="config")
def main(cfg):
    if cfg.c == "boom":
        raise RuntimeError("boom trial")
    value = (cfg.x - 0.3) ** 2 + cfg.y
    return [value, -cfg.x] if cfg.two else value


main()
'''

CONFIG = '''
defaults:
  - override hydra/sweeper: ddmr_optuna
  - _self_
x: 0.0
y: 1
c: a
two: false
hydra:
  sweep:
    dir: sweep
    subdir: ${hydra.job.num}
  sweeper:
    storage: sqlite:///study.db
    study_name: toy
    n_trials: 6
    n_jobs: 2
    sampler:
      seed: 0
    params:
      x: interval(-1.0, 1.0)
      y: range(1, 4)
      c: choice(a, b)
'''


def _parse(text: str):
    return dimension(OverridesParser.create().parse_override(text))


def test_the_grammar_of_hydra_optuna_sweeper():
    x = _parse("x=interval(-1, 1.5)")
    assert (x.kind, x.low, x.high, x.log) == ("float", -1.0, 1.5, False)
    assert _parse("n=interval(1, 8)").kind == "float"  # Hydra's grammar reads an interval's ends as floats
    g = _parse("g=tag(log, interval(0.01, 10))")
    assert (g.kind, g.low, g.high, g.log) == ("float", 0.01, 10.0, True)
    c = _parse("c=choice(a, 2, 0.5, true)")
    assert c.kind == "categorical" and c.choices == ("a", 2, 0.5, True)
    r = _parse("r=range(1, 10, 3)")  # Hydra's range: 1, 4, 7 (stop excluded, as the basic sweeper runs it)
    assert (r.kind, r.low, r.high, r.step) == ("int", 1, 7, 3) and r.grid() == [1, 4, 7]
    assert _parse("r=range(5, 0, -2)").grid() == [1, 3, 5]
    f = _parse("f=range(0.0, 1.0, 0.25)")
    assert (f.kind, f.low, f.high, f.step) == ("float", 0.0, 0.75, 0.25)
    assert _parse("s=shuffle(range(1, 4))").kind == "categorical"
    assert _parse("k=3") is None  # a plain override: passed to every trial
    dims, fixed = search_space(["x=interval(0, 1)", "+tune=pid", "x=choice(0.5, 0.7)", "k=interval(1, 2)", "k=3"])
    assert list(dims) == ["x"] and dims["x"].kind == "categorical"  # a later override of a key replaces it
    assert fixed == ["+tune=pid", "k=3"]
    with pytest.raises(ValueError, match="grid sampler needs choice"):
        x.grid()


def test_directions_and_returned_values_are_checked():
    assert directions("minimize") == ["minimize"] and directions(["minimize", "maximize"]) == ["minimize", "maximize"]
    with pytest.raises(ValueError, match=r"hydra.sweeper.direction='min': each direction must be one of"):
        directions("min")
    assert objective_values(1, 1) == [1.0] and objective_values((1, 2.5), 2) == [1.0, 2.5]
    with pytest.raises(ValueError, match="returned 1 values for 2 objectives"):
        objective_values([1.0], 2)


def _toy(tmp_path: Path, *overrides: str) -> subprocess.CompletedProcess:
    (tmp_path / "app.py").write_text(textwrap.dedent(APP))
    (tmp_path / "config.yaml").write_text(textwrap.dedent(CONFIG))
    return subprocess.run([sys.executable, "app.py", "-m", *overrides], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)


def _load(tmp_path: Path):
    return optuna.load_study(study_name="toy", storage=f"sqlite:///{tmp_path / 'study.db'}")


def test_a_study_in_sqlite_and_the_same_command_resuming_it(tmp_path):
    proc = _toy(tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    trials = _load(tmp_path).trials
    assert [t.state.name for t in trials] == ["COMPLETE"] * 6
    for t in trials:
        assert -1.0 <= t.params["x"] <= 1.0 and t.params["y"] in (1, 2, 3) and t.params["c"] in ("a", "b")
        assert t.value == pytest.approx((t.params["x"] - 0.3) ** 2 + t.params["y"], rel=1e-12)
    # each trial is one Hydra job numbered as its trial, launched with the sampled values
    job = yaml.safe_load((tmp_path / "sweep" / "5" / ".hydra" / "overrides.yaml").read_text())
    assert job == [f"{k}={v}" for k, v in trials[5].params.items()]
    best = yaml.safe_load((tmp_path / "sweep" / "optimization_results.yaml").read_text())
    assert best["best_value"] == pytest.approx(min(t.value for t in trials), rel=1e-12)
    # the same command again: the stored study continues
    again = _toy(tmp_path, "hydra.sweeper.n_trials=3")
    assert again.returncode == 0, again.stderr[-3000:]
    resumed = _load(tmp_path).trials
    assert [t.number for t in resumed] == list(range(9)) and [t.params for t in resumed[:6]] == \
        [t.params for t in trials]


@pytest.mark.slow
def test_command_line_sweeps_extend_the_space_and_several_objectives_give_a_front(tmp_path):
    proc = _toy(tmp_path, "x=tag(log, interval(0.01, 10))", "two=true", "hydra.sweeper.direction=[minimize,minimize]",
                "hydra/sweeper/sampler=nsgaii", "hydra.sweeper.sampler.population_size=4", "hydra.sweeper.n_trials=8")
    assert proc.returncode == 0, proc.stderr[-3000:]
    study = _load(tmp_path)
    assert len(study.directions) == 2 and len(study.trials) == 8
    assert type(study.trials[0].distributions["x"]).__name__ == "FloatDistribution"
    assert study.trials[0].distributions["x"].log and all(0.01 <= t.params["x"] <= 10 for t in study.trials)
    front = yaml.safe_load((tmp_path / "sweep" / "optimization_results.yaml").read_text())["solutions"]
    values = [tuple(s["values"]) for s in front]
    assert values and all(not any(b[0] <= a[0] and b[1] <= a[1] and b != a for b in values) for a in values)


@pytest.mark.slow
def test_the_grid_sampler_and_failed_trials(tmp_path):
    grid = _toy(tmp_path, "hydra/sweeper/sampler=grid", "x=choice(0.0, 0.5)", "hydra.sweeper.n_trials=50")
    assert grid.returncode == 0, grid.stderr[-3000:]
    points = {(t.params["x"], t.params["y"], t.params["c"]) for t in _load(tmp_path).trials}
    assert len(_load(tmp_path).trials) == 12 and len(points) == 12  # 2 x 3 x 2, each once
    # a trial whose job raises is FAIL; within max_failure_rate the sweep goes on, beyond it stops with the error
    failing = tmp_path / "failing"
    failing.mkdir()
    ok = _toy(failing, "c=choice(a, boom)", "hydra.sweeper.max_failure_rate=1.0", "hydra.sweeper.n_trials=6")
    assert ok.returncode == 0, ok.stderr[-3000:]
    states = {t.params["c"]: set() for t in _load(failing).trials}
    for t in _load(failing).trials:
        states[t.params["c"]].add(t.state.name)
    assert states.get("boom", {"FAIL"}) == {"FAIL"} and states.get("a", {"COMPLETE"}) == {"COMPLETE"}
    stop = _toy(failing, "c=boom", "hydra.sweeper.n_trials=2")
    assert stop.returncode != 0 and "boom trial" in stop.stderr


def test_trials_compose_once_and_run_alike_through_the_joblib_launcher(tmp_path):
    """The trials differ in values only: each batch is validated (composed) before it is launched, so the one
    composition they share is made in the sweeping process and travels to the launcher's workers (a worker
    composing it itself could not pickle the launcher's structured config, a class its plugin scan re-made).
    The seeded search is the same through the joblib launcher as through the basic one."""
    basic = tmp_path / "basic"
    pooled = tmp_path / "joblib"
    basic.mkdir(), pooled.mkdir()
    assert _toy(basic).returncode == 0
    proc = _toy(pooled, "hydra/launcher=joblib", "hydra.launcher.n_jobs=2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    ours, theirs = _load(pooled).trials, _load(basic).trials
    assert [t.params for t in ours] == [t.params for t in theirs]
    assert [t.value for t in ours] == pytest.approx([t.value for t in theirs], rel=1e-12)


def _seeded_steps(study, storage_trials=None, n=6):
    """Ask, suggest and tell ``n`` trials of a toy objective two at a time (as the sweeper's batches), recording
    them through ``storage_trials`` (a StoredTrials) when given; returns the told parameters."""
    told = []
    for _ in range(n // 2):
        trials = [study.ask() for _ in range(2)]
        for t in trials:
            t.suggest_float("x", -1.0, 1.0)
            t.suggest_categorical("c", ["a", "b"])
        if storage_trials is not None:
            storage_trials.launched(trials)
        for t in trials:
            study.tell(t, (t.params["x"] - 0.3) ** 2 + (t.params["c"] == "b"))
            if storage_trials is not None:
                storage_trials.ended(t)
            told.append(t.params)
    return told


def _stored(url):
    return [(t.number, t.state.name, t.params, t.values, t.system_attrs)
            for t in optuna.load_study(study_name="s", storage=url).trials]


def test_stored_trials_record_what_optuna_would_have_stored(tmp_path):
    """A study worked on in memory and recorded trial by trial (StoredTrials) leaves the storage as Optuna working
    on the storage itself leaves it: the same trials, numbers, parameters, values and enqueued trials, resumed
    alike from a study with complete, enqueued and stale RUNNING trials; while a batch runs, the storage holds its
    trials RUNNING with their parameters."""
    from optuna.samplers import TPESampler

    from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import StoredTrials

    optuna.logging.set_verbosity(optuna.logging.WARNING)

    def start(url):  # two complete trials, one left RUNNING by a killed session, one enqueued
        study = optuna.create_study(study_name="s", storage=url, sampler=TPESampler(seed=1))
        _seeded_steps(study, n=2)
        study.ask().suggest_float("x", -1.0, 1.0)
        study.enqueue_trial({"x": 0.25, "c": "b"})

    direct, recorded = f"sqlite:///{tmp_path / 'direct.db'}", f"sqlite:///{tmp_path / 'recorded.db'}"
    start(direct)
    start(recorded)
    a = _seeded_steps(optuna.load_study(study_name="s", storage=direct, sampler=TPESampler(seed=7)))
    stored = StoredTrials(recorded, "s", TPESampler(seed=7), ["minimize"])
    b = _seeded_steps(stored.study, stored)
    assert a == b and a[0] == {"x": 0.25, "c": "b"}
    assert _stored(direct) == _stored(recorded)
    assert [s for _, s, *_ in _stored(recorded)] == ["COMPLETE"] * 2 + ["RUNNING"] + ["COMPLETE"] * 6
    # a batch launched and not yet ended is in the storage, RUNNING, with its parameters
    trial = stored.study.ask()
    trial.suggest_float("x", -1.0, 1.0)
    stored.launched([trial])
    last = optuna.load_study(study_name="s", storage=recorded).trials[-1]
    assert (last.number, last.state.name, last.params) == (trial.number, "RUNNING", trial.params)


def test_stored_trials_refuse_a_study_another_process_writes_into(tmp_path):
    from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import StoredTrials

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    url = f"sqlite:///{tmp_path / 'study.db'}"
    stored = StoredTrials(url, "s", optuna.samplers.RandomSampler(seed=0), ["minimize"])
    optuna.load_study(study_name="s", storage=url).ask()  # another process's trial 0
    trial = stored.study.ask()
    trial.suggest_float("x", 0.0, 1.0)
    with pytest.raises(RuntimeError, match="another process"):
        stored.launched([trial])


def _sweeper(launch):
    from types import SimpleNamespace

    from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import DdmrOptunaSweeper

    sweeper = DdmrOptunaSweeper(sampler=None, direction="minimize", storage=None, study_name=None, n_trials=4,
                                n_jobs=2)
    sweeper.launcher = SimpleNamespace(launch=launch)
    return sweeper


def test_the_form_of_a_trials_overrides_keeps_names_number_types_and_texts():
    from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import override_form

    one = override_form({"x": 0.1, "n": 3, "c": "a", "flag": True})
    assert one == override_form({"x": -7e-5, "n": 9, "c": "a", "flag": True})  # other numbers: the same form
    for other in ({"x": 0.1, "n": 3.0, "c": "a", "flag": True}, {"x": 0.1, "n": 3, "c": "b", "flag": True},
                  {"x": 0.1, "n": 3, "c": "a", "flag": False}, {"x": 0.1, "n": 3, "c": "a"},
                  {"y": 0.1, "n": 3, "c": "a", "flag": True}):
        assert override_form(other) != one, other


def test_a_batch_composes_only_the_trials_of_a_form_not_composed_before(monkeypatch):
    """Hydra's validate_batch_is_legal gets the first trial of each new form: a later batch of the same forms
    composes nothing, a new text (a config group's option) composes that trial alone."""
    from types import SimpleNamespace

    sweeper, composed = _sweeper(None), []
    monkeypatch.setattr(sweeper, "validate_batch_is_legal", lambda batch: composed.append(batch))
    validated = set()

    def batch(*params):
        trials = [SimpleNamespace(params=p) for p in params]
        sweeper._validate(trials, [[f"{k}={v}" for k, v in p.items()] for p in params], validated)

    batch({"x": 0.1, "c": "a"}, {"x": 0.5, "c": "a"})
    assert composed == [[["x=0.1", "c=a"]]]
    batch({"x": 0.9, "c": "a"}, {"x": 0.2, "c": "a"})
    assert len(composed) == 1
    batch({"x": 0.3, "c": "a"}, {"x": 0.4, "c": "b"})
    assert composed[1:] == [[["x=0.4", "c=b"]]]


def test_a_batchs_running_records_are_written_while_it_launches_and_complete_before_it_is_told():
    """StoredTrials.launched runs in the recorder's thread during the launch; _launch returns (or raises) only
    once the records are written, and a recording error (another process writing into the study) is raised after
    the batch, as is the launcher's own error, which wins."""
    import threading
    import time
    from concurrent.futures import ThreadPoolExecutor
    from types import SimpleNamespace

    events = []

    def launched(trials, fail=False):
        events.append(("recording", threading.current_thread() is threading.main_thread()))
        time.sleep(0.2)
        events.append("recorded")
        if fail:
            raise RuntimeError("another process is writing into the same study")

    def launch(overrides, initial_job_idx):
        events.append("launched")
        return ["returns"]

    trials = [SimpleNamespace(number=0)]
    with ThreadPoolExecutor(1) as recorder:
        sweeper = _sweeper(launch)
        assert sweeper._launch(trials, [["x=1"]], SimpleNamespace(launched=launched), recorder) == ["returns"]
        assert events[-1] == "recorded" and ("recording", False) in events and "launched" in events
        events.clear()
        with pytest.raises(RuntimeError, match="another process"):
            sweeper._launch(trials, [["x=1"]], SimpleNamespace(launched=lambda t: launched(t, fail=True)), recorder)
        assert events[-1] == "recorded" and "launched" in events
        events.clear()

        def interrupted(overrides, initial_job_idx):
            raise KeyboardInterrupt

        with pytest.raises(KeyboardInterrupt):
            _sweeper(interrupted)._launch(trials, [["x=1"]], SimpleNamespace(launched=launched), recorder)
        assert events[-1] == "recorded"
        assert _sweeper(launch)._launch(trials, [["x=1"]], None, None) == ["returns"]  # no storage: no recorder
