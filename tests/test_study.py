"""The sensitivity study (docs/model.md §11): the box maps onto real config keys, samples <-> overrides round-trip,
designs split into chunks without loss, the claim statistics and the Table 4 distance on constructed data, the
Sobol analysis on a function with known indices, and the quick study end to end through the console script."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import compose_config
from ddmr_cli.errors import ConfigError
from ddmr_cli.study import analysis, claims, design, search
from ddmr_cli.study.space import Box, Parameter
from ddmr_cli.study.setup import study_configs

from conftest import run_ddmr


@pytest.fixture(scope="module")
def study_cfg():
    return compose_config(["+experiment=sensitivity_oat"])


@pytest.fixture(scope="module")
def box(study_cfg):
    return Box.from_config(study_cfg.study)


@pytest.fixture(scope="module")
def configs(study_cfg):
    return study_configs(study_cfg)


# --- the box -------------------------------------------------------------------------------------------------


def test_every_parameter_key_is_a_real_config_key(box, configs):
    """Each key a parameter sets exists, as a leaf, in the composed config of a controller of the study (the NN
    keys in SMC-NDO-NNO's, every other key in all of them)."""
    assert len(box.parameters) >= 20
    for p in box.parameters:
        for key in p.keys:
            present = [c for c, cfg in configs.items() if OmegaConf.select(cfg, key, default=None) is not None]
            assert present, f"{p.name}: {key} is not a key of any study config"
            if not key.startswith("controller."):
                assert len(present) == len(configs), f"{p.name}: {key} missing from some configs"
            value = OmegaConf.select(configs[present[0]], key)
            assert not OmegaConf.is_dict(value), f"{p.name}: {key} is a node, not a value"


def test_box_contains_the_faithful_reading_and_both_nn_readings(box, configs):
    faithful = box.faithful(configs[("smc_ndo_nno", "paper_1")])
    for p in box.parameters:
        value = faithful[p.name]
        if p.is_choice:
            assert value in p.options, p.name
        else:
            assert p.low <= value <= p.high, (p.name, value)
    for lr, width in ((50.0, 2.0), (2.0, 50.0)):  # table / text reading (docs/model.md §6)
        assert box["nn_learning_rate"].low <= lr <= box["nn_learning_rate"].high
        assert box["nn_width"].low <= width <= box["nn_width"].high


def test_sample_to_overrides_round_trips(box, configs):
    """Random samples of the box -> Hydra overrides -> read back from a config with them applied: the same
    sample, and the applied config holds exactly the override values."""
    cfg = configs[("smc_ndo_nno", "paper_2")]
    rng = np.random.default_rng(7)
    for _ in range(5):
        sample = {p.name: p.from_unit(u) for p, u in zip(box.parameters, rng.random(len(box.parameters)))}
        overrides = box.overrides(sample, cfg)
        back = box.sample_of_overrides(overrides, cfg, box.names)
        for name, value in sample.items():
            if isinstance(value, str) or box[name].is_choice:
                assert back[name] == value, name
            else:
                assert math.isclose(back[name], value, rel_tol=1e-12), (name, back[name], value)
        applied = box.apply(sample, cfg)
        for ov in overrides:
            key, _, text = ov.partition("=")
            assert str(OmegaConf.select(applied, key)).replace(" ", "") == text or \
                math.isclose(float(OmegaConf.select(applied, key)), float(text), rel_tol=1e-12), ov
        assert OmegaConf.select(cfg, "robot.max_voltage") == 24.0  # the base config is left unchanged


def test_scale_and_coefficient_parameters(box, configs):
    cfg = configs[("smc_ndo_nno", "paper_1")]
    values = box.key_values({"roughness_scale": 2.0, "nn_center_range": 30.0, "pose_offset_scale": 0.5}, cfg)
    assert values["terrain.zones.very_rough.roughness"] == pytest.approx(200.0, rel=1e-12)
    assert values["terrain.zones.flat.roughness"] == pytest.approx(0.2, rel=1e-12)
    assert values["controller.nn.center_min"] == pytest.approx(-30.0, rel=1e-12)
    assert values["controller.nn.center_max"] == pytest.approx(30.0, rel=1e-12)
    assert values["simulation.initial_pose"] == pytest.approx([0.0, 0.025, 0.025], rel=1e-12)
    # a controller without the NN: its keys are left out, not invented
    assert "controller.nn.width" not in box.key_values({"nn_width": 3.0}, configs[("smc", "paper_1")])


def test_unit_interval_maps_onto_the_box():
    p = Parameter("x", {"a": 1.0}, low=0.5, high=200.0, scale="log")
    assert p.from_unit(0.0) == pytest.approx(0.5, rel=1e-12)
    assert p.from_unit(1.0) == pytest.approx(200.0, rel=1e-12)
    assert p.from_unit(0.5) == pytest.approx(10.0, rel=1e-12)  # geometric mean
    for u in (0.1, 0.37, 0.9):
        assert p.to_unit(p.from_unit(u)) == pytest.approx(u, abs=1e-12)
    c = Parameter("c", {"a": 1.0}, options=("euler", "rk4"))
    assert [c.from_unit(u) for u in (0.0, 0.49, 0.5, 1.0)] == ["euler", "euler", "rk4", "rk4"]


@pytest.mark.parametrize("spec", [{"low": 2.0, "high": 1.0}, {"low": 0.0, "high": 1.0, "scale": "log"},
                                  {"low": 0.0, "high": 1.0, "mode": "double"}])
def test_bad_parameter_is_a_config_error(spec):
    with pytest.raises(ConfigError):
        Box.from_config({"parameters": {"x": {"keys": {"robot.mass": 1}, **spec}}})


# --- designs -------------------------------------------------------------------------------------------------


def test_designs_are_deterministic_and_chunks_partition_them(study_cfg, box, configs):
    faithful = box.faithful(configs[("smc_ndo_nno", "paper_1")])
    k = len(box.global_names())
    m1 = design.morris(box, faithful, trajectories=3, levels=4, seed=0)
    m2 = design.morris(box, faithful, trajectories=3, levels=4, seed=0)
    assert len(m1.samples) == 3 * (k + 1)
    assert np.array_equal(m1.unit, m2.unit)
    s = design.sobol(box, faithful, ["nn_width", "dt", "k_y"], base=8, seed=0)
    assert len(s.samples) == 8 * (3 + 2)
    for chunks in (1, 3, 7):
        parts = [design.chunk_of(len(s.samples), c, chunks) for c in range(chunks)]
        flat = sorted(i for part in parts for i in part)
        assert flat == list(range(len(s.samples)))
    with pytest.raises(ConfigError):
        design.chunk_of(10, 3, 3)
    oat = design.build(study_cfg.study, box, faithful)
    assert oat.labels[:2] == ["faithful", "text_reading"]
    assert oat.samples[0] == faithful
    assert oat.samples[1]["nn_learning_rate"] == 2.0 and oat.samples[1]["nn_width"] == 50.0


# --- claim statistics ----------------------------------------------------------------------------------------


def _runs(dev: dict, scenarios=("paper_1", "paper_2"), chattering=None, d_est=None, seeds=4):
    """Constructed per-seed metrics: ``dev[controller]`` a level (or per-scenario pair) times (1, 2, 3, 4)."""
    base = np.arange(1.0, seeds + 1.0)
    out = {}
    for c in claims.CONTROLLERS:
        for i, s in enumerate(scenarios):
            level = dev[c][i] if isinstance(dev[c], tuple) else dev[c]
            m = {metric: base * 0.001 for metric in claims.METRICS}
            m[claims.DEVIATION] = base * level
            m["hf_fraction"] = base * (chattering or {}).get(c, 10.0)   # the switching measure, as the report
            m["chattering"] = base * 10.0                            # total variation: not what the claim rests on
            m["d_est_mae"] = base * (d_est or {}).get(c, 5.0)
            out[(c, s)] = m
    return out


def test_reduction_pairs_seeds_and_counts_divergence_as_an_outcome():
    assert claims.reduction([1, 2, 3], [0.5, 1, 1.5]) == pytest.approx(50.0, rel=1e-12)
    # seeds both diverged on (NaN in both) are the same outcome: left out of both sums
    assert claims.reduction([1, 2, np.nan, 4], [0.5, 1, np.nan, 2]) == pytest.approx(50.0, rel=1e-12)
    # the candidate diverged where the reference did not: unboundedly worse, whatever the other seeds say
    assert claims.reduction([1, 2, 3, 4], [0.5, 1, 1.5, np.nan]) == -math.inf
    # only the reference diverged: the candidate is the better, at the bound
    assert claims.reduction([1, 2, np.nan], [1.5, 2.5, 3.0]) == 100.0
    assert math.isnan(claims.reduction([np.nan], [np.nan]))


def test_a_diverging_candidate_makes_the_claim_false_and_is_counted():
    runs = _runs({"pid": 4.0, "smc": 2.0, "smc_ndo": 1.0, "smc_ndo_nno": 0.6})
    runs[("smc_ndo_nno", "paper_2")][claims.DEVIATION][0] = np.nan  # one diverged seed of four
    st = claims.statistics(runs, ["paper_1", "paper_2"])
    assert st["vs_smc@paper_2"] == -math.inf and st["vs_smc_holds"] == 0.0
    assert st["diverged:smc_ndo_nno"] == pytest.approx(1 / (2 * len(runs[("pid", "paper_1")][claims.DEVIATION])))
    assert st["diverged:smc"] == 0.0


def test_claim_statistics_on_constructed_runs():
    runs = _runs({"pid": 4.0, "smc": 2.0, "smc_ndo": 1.0, "smc_ndo_nno": 0.6},
                 chattering={"smc_ndo": 10.0, "smc_ndo_nno": 0.5}, d_est={"smc_ndo": 48.3152, "smc_ndo_nno": 15.9876})
    st = claims.statistics(runs, ["paper_1", "paper_2"])
    assert st["vs_smc_ndo"] == pytest.approx(40.0, rel=1e-12) and st["vs_smc_ndo_holds"] == 1.0
    assert st["vs_smc"] == pytest.approx(70.0, rel=1e-12) and st["vs_smc_holds"] == 1.0
    assert st["ranking"] == pytest.approx(40.0, rel=1e-12) and st["ranking_holds"] == 1.0  # min of 50, 50, 40
    assert st["chattering"] == pytest.approx(95.0, rel=1e-12) and st["chattering_holds"] == 1.0
    assert st["estimation"] == pytest.approx(100 * (1 - 15.9876 / 48.3152), rel=1e-12)
    assert st["estimation_holds"] == 1.0
    # SMC-NDO-NNO ties SMC-NDO in scenario 2: the mean is 20 %, and the claim fails (it must hold in both)
    tie = claims.statistics(_runs({"pid": 4.0, "smc": 2.0, "smc_ndo": 1.0, "smc_ndo_nno": (0.6, 1.0)}),
                            ["paper_1", "paper_2"])
    assert tie["vs_smc_ndo@paper_2"] == pytest.approx(0.0, abs=1e-12)
    assert tie["vs_smc_ndo"] == pytest.approx(20.0, rel=1e-12) and tie["vs_smc_ndo_holds"] == 0.0
    assert tie["ranking"] == pytest.approx(0.0, abs=1e-12) and tie["ranking_holds"] == 0.0
    # SMC worse than PID: the ranking's statistic is the reversed pair's (negative) reduction
    rev = claims.statistics(_runs({"pid": 1.0, "smc": 2.0, "smc_ndo": 1.0, "smc_ndo_nno": 0.6}), ["paper_1"])
    assert rev["ranking"] == pytest.approx(-100.0, rel=1e-12) and rev["ranking_holds"] == 0.0


def test_table4_distance_closed_form():
    paper = claims.paper_table4()
    assert len(paper) == 20
    assert claims.distance(paper) == pytest.approx(0.0, abs=1e-15)
    scaled = {k: v * math.exp(0.3) for k, v in paper.items()}
    assert claims.distance(scaled) == pytest.approx(0.3, rel=1e-12)
    half = {k: v * (math.exp(0.2) if i % 2 else math.exp(-0.4)) for i, (k, v) in enumerate(paper.items())}
    assert claims.distance(half) == pytest.approx(math.sqrt((0.04 + 0.16) / 2), rel=1e-12)
    # our Table 4 from per-seed runs: mean and sample SD of deviation_mae, means of the pose errors
    runs = _runs({c: 1.0 for c in claims.CONTROLLERS})
    t4 = claims.table4(runs)
    assert t4["t4:pid:deviation_mean"] == pytest.approx(0.0025, rel=1e-12)
    assert t4["t4:pid:deviation_sd"] == pytest.approx(0.001 * np.std([1, 2, 3, 4], ddof=1), rel=1e-12)


# --- analyses ------------------------------------------------------------------------------------------------


def test_sobol_analysis_recovers_known_indices(box, configs):
    """y = 10 u_a + u_b^2 on the unit cube (additive): S_a = 100/12 / (100/12 + 4/45), S_c = 0; rows shuffled
    (the analysis must put them back in design order)."""
    faithful = box.faithful(configs[("smc_ndo_nno", "paper_1")])
    d = design.sobol(box, faithful, ["nn_width", "dt", "k_y"], base=256, seed=1)
    u = d.unit
    y = 10 * u[:, 0] + u[:, 1] ** 2
    rows = pd.DataFrame({"sample": np.arange(len(y)), **{c: y for c in claims.CLAIM_IDS}}).sample(frac=1, random_state=0)
    table = analysis.sobol(rows, d, resamples=50, seed=0)
    part = table[table["claim"] == "vs_smc_ndo"].set_index("parameter")
    var_a, var_b = 100 / 12, 4 / 45
    assert part.loc["nn_width", "ST"] == pytest.approx(var_a / (var_a + var_b), abs=0.05)
    assert part.loc["dt", "ST"] == pytest.approx(var_b / (var_a + var_b), abs=0.03)
    assert abs(part.loc["k_y", "ST"]) < 0.01
    # the bootstrap intervals are a function of the config too (SALib skips seeding on seed 0: we never pass it)
    again = analysis.sobol(rows, d, resamples=50, seed=0)
    assert again[["S1_conf", "ST_conf"]].equals(table[["S1_conf", "ST_conf"]])
    assert not analysis.sobol(rows, d, resamples=50, seed=1)[["ST_conf"]].equals(table[["ST_conf"]])


def test_share_of_box_and_calibration_pick():
    rows = pd.DataFrame({"sample": [0, 1, 2, 3], "distance": [0.9, 0.4, np.nan, 0.7], "x": [1.0, 2.0, 3.0, 4.0]})
    for c in claims.CLAIM_IDS:
        rows[c] = [10.0, 45.0, np.nan, 35.0]
        rows[f"{c}_holds"] = [0.0, 1.0, np.nan, 1.0]
    paper = claims.paper_table4()
    for k, v in paper.items():
        rows[k] = [v, v * math.exp(0.4), v, v]
    h = analysis.holds(rows).set_index("claim")
    assert h.loc["vs_smc_ndo", "holds"] == 2 and h.loc["vs_smc_ndo", "samples"] == 4
    assert h.loc["vs_smc_ndo", "share_low"] < 0.5 < h.loc["vs_smc_ndo", "share_high"]
    best = analysis.calibration(rows, ["x"])
    assert best["sample"] == 1 and best["reading"] == {"x": 2.0}
    assert all(n["log_ratio"] == pytest.approx(0.4, rel=1e-12) for n in best["numbers"])


# --- end to end ----------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_quick_study_end_to_end(tmp_path):
    """``ddmr sensitivity study=quick``: every stage runs as a sweep (the calibration search through Hydra's Optuna
    sweeper, warm-started from the lhs stage), the analyses and the report are written; the search is the same
    through another launcher, and resumes."""
    out = tmp_path / "study"
    proc = run_ddmr(["sensitivity", "--out", str(out), "study=quick", "launcher=basic"], cwd=tmp_path,
                    env={"DDMR_PROGRESS_DELAY": "0"})  # every bar drawn, however fast the machine
    assert proc.returncode == 0, proc.stderr[-3000:]
    for stage in ("oat", "morris", "sobol", "map", "lhs", "calibration", "points"):
        assert (out / stage / "study.csv").is_file(), stage
    # progress in a log: each stage's bar over its jobs, the search's over its trials, the report's status line
    assert proc.stderr.count("sweep: 1/1 jobs (100 %)") == 6 and "trials: 4/4 trials (100 %)" in proc.stderr
    assert "ddmr sensitivity: writing the report" in proc.stderr
    morris = pd.read_csv(out / "morris" / "morris.csv")
    assert set(morris["claim"]) == set(claims.CLAIM_IDS) and (morris["mu_star"] >= 0).all()
    sobol = pd.read_csv(out / "sobol" / "sobol.csv")
    assert {"S1", "S1_conf", "ST", "ST_conf"} <= set(sobol.columns)
    cal = json.loads((out / "calibration" / "calibration.json").read_text())
    assert len(cal["numbers"]) == 20 and cal["distance"] > 0
    # the search: Optuna's trials, one study row each, numbered; the first is the lhs stage's best reading
    trials = pd.read_csv(out / "calibration" / "study.csv")
    assert list(trials["sample"]) == [0, 1, 2, 3] and list(trials["warm_start"]) == [1, 0, 0, 0]
    assert (trials["runs"] == 4 * 2 * 10).all()
    # what the sweeper was told: the objective, the RMS log ratio over Table 4's means (the SDs reported, not fitted)
    for row in trials.to_dict("records"):
        assert row["objective"] == pytest.approx(search.objective(row), rel=1e-12)
        assert row["objective"] == pytest.approx(search.objective_terms(row)["means"], rel=1e-12)
    best = trials.loc[trials["objective"].idxmin()]
    assert cal["sample"] == best["sample"] and cal["distance"] == pytest.approx(best["distance"], rel=1e-12)
    assert [h["trial"] for h in cal["history"]] == [0, 1, 2, 3] and cal["warm_start"][0]["trial"] == 0
    lhs = pd.read_csv(out / "lhs" / "study.csv")
    best_lhs = lhs.iloc[int(np.argmin([search.objective(r) for r in lhs.to_dict("records")]))]
    for name in ("nn_learning_rate", "nn_width", "roughness_scale", "dt"):
        assert trials.loc[0, name] == pytest.approx(best_lhs[name], rel=1e-12), name
    assert (out / "lhs" / "holds.csv").is_file() and not (out / "calibration" / "holds.csv").exists()
    points = pd.read_csv(out / "points" / "study.csv")
    assert list(points["label"]) == ["faithful", "text_reading", "calibrated"]
    assert (points["runs"] == 4 * 2 * 50).all()
    report = (out / "report.md").read_text()
    assert "# Robustness of the paper's claims" in report and "Share of the box" in report
    assert "ddmr's Optuna sweeper" in report and "**Conclusion: Table 4 is" in report
    for png in ("oat", "morris", "sobol", "nn_map", "calibration"):
        assert (out / "figures" / f"{png}.png").stat().st_size > 1000, png
    # while another `ddmr sensitivity` holds the study, a second is refused and writes nothing
    from ddmr_cli.cli.sensitivity import STUDY_LOCK, SUMMARY
    from ddmr_cli.storage.jobdir import DirLock

    summary = (out / SUMMARY).read_bytes()
    with DirLock(out, name=STUDY_LOCK):
        busy = run_ddmr(["sensitivity", "--out", str(out), "--stages", "oat", "study=quick", "launcher=basic"],
                        cwd=tmp_path)
    assert busy.returncode == 1 and "in use by pid" in busy.stderr, busy.stderr[-2000:]
    assert (out / SUMMARY).read_bytes() == summary
    # resume: the same command again skips every job (complete, same config) and rewrites the report
    again = run_ddmr(["sensitivity", "--out", str(out), "--stages", "morris", "study=quick", "launcher=basic"],
                     cwd=tmp_path)
    assert again.returncode == 0 and "skipped" in again.stdout + again.stderr
    # the search again, into another dir through the joblib launcher: the same trials and the same distances
    other = tmp_path / "again"
    proc = run_ddmr(["run", "-m", "+experiment=sensitivity_calibration", "study=quick", f"hydra.sweep.dir={other}",
                     f"study.calibration.warm_start_from={out / 'lhs' / 'study.csv'}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    same = pd.read_csv(other / "study.csv")
    columns = ["nn_learning_rate", "nn_width", "roughness_scale", "dt", "distance", "objective", "warm_start"]
    pd.testing.assert_frame_equal(same[columns], trials[columns], rtol=1e-12)
    # and resumed: the same command with a larger budget runs only the new trials
    proc = run_ddmr(["run", "-m", "+experiment=sensitivity_calibration", "study=quick", f"hydra.sweep.dir={other}",
                     f"study.calibration.warm_start_from={out / 'lhs' / 'study.csv'}", "study.calibration.trials=5"],
                    cwd=tmp_path)
    assert proc.returncode == 0 and "resuming study calibration: 4/5 trials done" in proc.stdout + proc.stderr
    assert list(pd.read_csv(other / "study.csv")["sample"]) == [0, 1, 2, 3, 4]


def test_ctrl_c_in_a_stage_stops_the_study_and_another_study_on_the_dir_is_refused(tmp_path, monkeypatch, capsys):
    """A stage interrupted (its `ddmr run` returns 130) ends the study with 130 and runs no later stage or report;
    the summary records the stage. A second study on a dir whose lock is held exits 1 and starts no stage."""
    from ddmr_cli.cli import run as run_module
    from ddmr_cli.cli import sensitivity
    from ddmr_cli.storage.jobdir import DirLock

    started = []

    def fake_run(argv):
        started.append(next(a for a in argv if a.startswith("+experiment=")))
        return 130 if len(started) == 2 else 0

    monkeypatch.setattr(run_module, "cmd_run", fake_run)
    monkeypatch.setattr("ddmr_cli.report.sensitivity.write_report", lambda out: pytest.fail("no report"))
    out = tmp_path / "study"
    assert sensitivity.main(["--out", str(out), "--stages", "oat,morris,sobol"]) == 130
    assert started == ["+experiment=sensitivity_oat", "+experiment=sensitivity_morris"]
    assert "study interrupted in stage morris" in capsys.readouterr().err
    assert json.loads((out / sensitivity.SUMMARY).read_text())["stages"]["morris"]["exit"] == 130
    started.clear()
    with DirLock(out, name=sensitivity.STUDY_LOCK):
        assert sensitivity.main(["--out", str(out), "--stages", "oat"]) == 1
    assert started == [] and "in use by pid" in capsys.readouterr().err


def test_a_full_disk_at_the_study_summary_keeps_the_last_summary_whole(tmp_path, monkeypatch, capsys):
    """The study's summary is replaced, not rewritten in place: a write that fails (here: no space left, on any
    file of the summary's name opened for writing, through ``open`` or ``Path.write_text``) leaves the last one
    readable, and the study ends with one error line naming the file, exit 1."""
    import builtins
    import errno
    import io as std_io

    from ddmr_cli.cli import run as run_module
    from ddmr_cli.cli import sensitivity

    monkeypatch.setattr(run_module, "cmd_run", lambda argv: 0)
    monkeypatch.setattr("ddmr_cli.report.sensitivity.write_report", lambda out: out / "report.md")
    out = tmp_path / "study"
    assert sensitivity.main(["--out", str(out), "--stages", "oat"]) == 0
    before = (out / sensitivity.SUMMARY).read_text()
    assert set(json.loads(before)["stages"]) == {"oat"}

    real_open = builtins.open

    class Full:
        def __init__(self, fh):
            self.fh = fh

        def write(self, _text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def __getattr__(self, name):
            return getattr(self.fh, name)

    def full_disk(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        return Full(fh) if "w" in mode and sensitivity.SUMMARY in str(file) else fh

    monkeypatch.setattr(builtins, "open", full_disk)
    monkeypatch.setattr(std_io, "open", full_disk)
    assert sensitivity.main(["--out", str(out), "--stages", "morris"]) == 1
    monkeypatch.undo()
    assert (out / sensitivity.SUMMARY).read_text() == before
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("ddmr: error: ") and "No space left on device" in err[-1] and sensitivity.SUMMARY in err[-1]
