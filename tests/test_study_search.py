"""The sensitivity study's calibration search through ddmr's Optuna sweeper (docs/model.md §11): the search
space is the box, the same seed gives the same trials, the objective is the Table 4 distance (capped, never NaN),
a trial's reading is checked against the box, the warm start picks the uniform sample's best readings, bad
settings are one line and exit 2, and the global analyses take clipped statistics."""

from __future__ import annotations

import json
import math

import numpy as np
import optuna
import pandas as pd
import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import compose_config
from ddmr_cli.cli.main import main
from ddmr_cli.errors import ConfigError
from ddmr_cli.study import analysis, claims, design, search
from ddmr_cli.study.space import Box
from ddmr_cli.study.setup import study_setup


@pytest.fixture(scope="module")
def cfg():
    return compose_config(["+experiment=sensitivity_calibration"])


@pytest.fixture(scope="module")
def quick():
    return compose_config(["+experiment=sensitivity_calibration", "study=quick"])


def _ask(cfg, seed: int, trials: int, batch: int) -> list[dict]:
    """Trials as ddmr's Optuna sweeper asks them: ``batch`` at a time from a seeded TPE sampler, the reading drawn
    by the sweeper's custom_search_space, told a value that depends on the reading."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(sampler=optuna.samplers.TPESampler(seed=seed), direction="minimize")
    out = []
    while len(out) < trials:
        asked = [study.ask() for _ in range(batch)]
        for t in asked:
            search.suggest_reading(cfg, t)
        for t in asked:
            value = sum(math.log(v) if isinstance(v, float) and v > 0 else 0.0 for v in t.params.values())
            study.tell(t, value ** 2)
            out.append(dict(t.params))
    return out


def test_the_search_space_is_the_box(cfg, quick):
    box = Box.from_config(cfg.study)
    params = _ask(cfg, 0, 3, 3)
    for p in params:
        assert sorted(p) == sorted(search.PREFIX + n for n in box.global_names())
        for key, value in p.items():
            par = box[key.removeprefix(search.PREFIX)]
            assert value in par.options if par.is_choice else par.low <= value <= par.high, (key, value)
    # study.vary restricts the search as it restricts every global design
    assert sorted(_ask(quick, 0, 1, 1)[0]) == sorted(search.PREFIX + str(n) for n in quick.study.vary)
    # a log axis is searched log-uniformly: the distribution Optuna records says so
    study = optuna.create_study()
    trial = study.ask()
    search.suggest_reading(cfg, trial)
    log_axis = trial.distributions[search.PREFIX + "nn_learning_rate"]
    assert getattr(log_axis, "log", type(log_axis).__name__ == "LogUniformDistribution")
    linear = trial.distributions[search.PREFIX + "nn_center_range"]
    assert not getattr(linear, "log", type(linear).__name__ == "LogUniformDistribution")


def test_the_search_runs_on_ddmrs_optuna_sweeper_with_the_box_as_its_space():
    from hydra.utils import instantiate

    cfg = compose_config(["+experiment=sensitivity_calibration"], return_hydra_config=True)
    sweeper = instantiate(cfg.hydra.sweeper)
    assert type(sweeper).__name__ == "DdmrOptunaSweeper" and sweeper.extend is search.suggest_reading
    assert type(sweeper.sampler_config).__name__ == "TPESampler" and sweeper.directions == ["minimize"]
    assert sweeper.storage.startswith("sqlite:///") and sweeper.storage.endswith("/study.db")
    assert sweeper.n_jobs == cfg.study.calibration.batch and not sweeper.params


def test_the_same_seed_gives_the_same_trials(cfg):
    a, b = _ask(cfg, 3, 14, 4), _ask(cfg, 3, 14, 4)  # past TPE's 10 random start-up trials
    assert a == b
    assert _ask(cfg, 4, 2, 2) != a[:2]


def _with_reading(cfg, reading: dict):
    study = OmegaConf.create(OmegaConf.to_container(cfg.study))
    study.reading = reading
    return study


def test_a_trial_is_a_sample_at_its_reading(cfg):
    box, _, faithful, _ = study_setup(cfg)
    d = design.build(_with_reading(cfg, {"nn_width": 7.5, "integrator": "rk4"}), box, faithful)
    assert d.samples == [{**faithful, "nn_width": 7.5, "integrator": "rk4"}] and d.labels == ["trial"]
    for bad, named in (({"nn_width": 1000.0}, "study.reading.nn_width"), ({"integrator": "rk45"}, "integrator"),
                       ({"nn_widht": 3.0}, "nn_widht")):
        with pytest.raises(ConfigError, match=named):
            design.build(_with_reading(cfg, bad), box, faithful)


def test_the_objective_fits_the_means_and_reports_the_sds():
    paper = claims.paper_table4()
    assert search.objective(paper) == pytest.approx(0.0, abs=1e-15)
    scaled = {k: v * math.exp(0.3) for k, v in paper.items()}
    assert search.objective(scaled) == pytest.approx(0.3, rel=1e-12)  # every mean off by e^0.3
    # the SDs, which no reading reaches, are reported but do not steer the search (SD_WEIGHT = 0)
    sds_off = {k: v * (100.0 if k.endswith(":deviation_sd") else 1.0) for k, v in paper.items()}
    assert search.objective(sds_off) == pytest.approx(0.0, abs=1e-15)
    assert search.objective_terms(sds_off)["sds"] == pytest.approx(math.log(100.0), rel=1e-12)
    # one mean 10^4 off counts as 100x; a missing one (a failed sample) at the cap too: never NaN
    far = {**paper, "t4:pid:e_x_mae": paper["t4:pid:e_x_mae"] * 1e4}
    assert search.objective(far) == pytest.approx(math.sqrt(search.LOG_CAP ** 2 / 16), rel=1e-12)
    missing = {**paper, "t4:pid:e_x_mae": math.nan}
    assert search.objective(missing) == pytest.approx(search.objective(far), rel=1e-12)
    assert search.objective({}) == pytest.approx(search.LOG_CAP, rel=1e-12)
    assert search.objective_of({"status": "failed"}) == search.LOG_CAP
    assert search.objective_of({"objective": 0.7}) == 0.7


def test_the_warm_start_is_the_uniform_samples_best():
    paper = claims.paper_table4()
    rows = pd.DataFrame({"sample": [0, 1, 2, 3], "a": [1.0, 2.0, 3.0, 4.0], "b": ["x", "y", "x", "y"]})
    for k, v in paper.items():
        rows[k] = [v * math.exp(0.5), v * math.exp(0.1), np.nan, v * math.exp(-0.2)]
    rows["distance"] = [0.5, 0.1, np.nan, 0.2]
    assert search.warm_readings(rows, ["a", "b"], 2) == [{"a": 2.0, "b": "y"}, {"a": 4.0, "b": "y"}]
    assert search.warm_readings(rows, ["a"], 0) == []


def test_the_global_analyses_take_bounded_statistics_and_impute_nothing():
    rows = pd.DataFrame({"vs_smc_ndo": [30.0, -1.0e4, np.nan, 250.0, -50.0, -np.inf]})
    y, undefined, clipped = analysis.outputs(rows, "vs_smc_ndo")
    assert undefined == 1 and clipped == 3
    # -inf (the candidate diverged) and NaN (no defined statistic) are a claim that cannot hold: -100 %, not a
    # median of the others (which was -10 here and made a diverged sample look like an ordinary one)
    assert list(y) == pytest.approx([30.0, -100.0, -100.0, 100.0, -50.0, -100.0], rel=1e-12)


def test_divergence_shares_and_sobol_power():
    rows = pd.DataFrame({"diverged:pid": [0.0, 0.0, 0.0, 0.0], "diverged:smc": [0.0, 0.5, 0.0, 0.25],
                         "diverged:smc_ndo": [0.0] * 4, "diverged:smc_ndo_nno": [1.0, 1.0, 1.0, 1.0]})
    div = analysis.divergence(rows).set_index("controller")
    assert div.loc["smc", "diverging_samples"] == 2 and div.loc["smc", "share"] == pytest.approx(0.5)
    assert div.loc["smc", "runs_diverged"] == pytest.approx(0.1875)
    assert div.loc["smc_ndo_nno", "share"] == 1.0 and div.loc["pid", "share"] == 0.0
    low, high = analysis.wilson(2, 4)
    assert div.loc["smc", "share_low"] == pytest.approx(low) and 0.0 < low < 0.5 < high < 1.0
    table = pd.DataFrame({"ST": [0.5, 0.05, 0.3], "ST_conf": [0.08, 0.4, 0.12]})
    power = analysis.sobol_power(table)  # the 0.4 half-width belongs to an index below 0.1: not counted
    assert power["relevant"] == 2 and power["widest_half_width"] == pytest.approx(0.12) and not power["met"]
    assert analysis.sobol_power(table.assign(ST_conf=[0.08, 0.4, 0.1]))["met"]


@pytest.mark.parametrize("args, named", [
    (["study.calibration.trials=0"], "study.calibration.trials=0"),
    (["study.calibration.batch=-1"], "study.calibration.batch=-1"),
    (["study.chunks=2"], "study.chunks=2"),
    (["+study.reading.dt=0.5"], "study.reading.dt=0.5"),
    (["study.calibration.warm_start_from=/nonexistent/study.csv"], "study.calibration.warm_start_from"),
])
def test_bad_search_input_is_one_line_and_exit_2(tmp_path, capsys, args, named):
    out = tmp_path / "calibration"
    assert main(["run", "-m", "+experiment=sensitivity_calibration", *args, f"hydra.sweep.dir={out}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ddmr: error: ") and named in err[0], err
    assert not out.exists()


def test_a_dir_holding_another_search_is_refused(tmp_path, capsys):
    out = tmp_path / "calibration"
    out.mkdir()
    (out / search.SEARCH_FILE).write_text(json.dumps({"study_name": "calibration", "hash": "0" * 16}))
    assert main(["run", "-m", "+experiment=sensitivity_calibration", f"hydra.sweep.dir={out}"]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds a calibration search of another config" in err and "\n" not in err


def test_the_search_hash_ignores_the_budget_and_the_other_stages():
    """A search resumes with a larger budget, another batch or seed, or other sizes of the other stages; any
    setting that changes a trial's numbers is another search."""
    base = search.search_hash(compose_config(["+experiment=sensitivity_calibration"]))
    same = compose_config(["+experiment=sensitivity_calibration", "study.calibration.trials=7",
                           "study.calibration.batch=1", "study.lhs.samples=3", "study.sobol.base=8"])
    assert search.search_hash(same) == base
    for other in (["run.n_runs=5"], ["study.parameters.dt.high=0.0005"], ["study.vary=[dt]"]):
        assert search.search_hash(compose_config(["+experiment=sensitivity_calibration", *other])) != base, other
