"""Scenario 2's uncertainty in its two forms (docs/model.md §5): an OU process in time, or one value per run held."""

from __future__ import annotations

import numpy as np
import pytest

import ddmr_cli


def _b_series(form: str, seed: int = 3):
    cfg = ddmr_cli.compose_config(["scenario=paper_2", f"scenario/uncertainty={form}", "controller=smc",
                                   "simulation.duration=12", "simulation.dt=0.002", "run.n_runs=1",
                                   f"run.base_seed={seed}", "run.keep_series=first:1"])
    result = ddmr_cli.run_config(cfg)
    series = next(iter(result.series.values()))
    return series, cfg


def test_the_constant_form_holds_one_value_per_run_drawn_from_the_stationary_law():
    series, cfg = _b_series("constant")
    u = cfg.scenario.uncertainty
    on = series["damping_scale"] != 1.0  # the uncertain phases (b is exactly 1 where the uncertainty is off)
    assert on.sum() > 1000
    b = series["damping_scale"][on]
    assert np.ptp(b) == pytest.approx(0.0, abs=1e-15)  # held: one value for the whole run
    # the value is 1 + clip(std n0) for the run's stationary initial draw n0 (its first normal of channel 2)
    n0 = np.random.default_rng(3).standard_normal(3)[2]
    assert b[0] == pytest.approx(1.0 + min(max(float(u.std) * n0, float(u.low)), float(u.high)), rel=1e-12)


def test_the_ou_form_varies_in_time_from_the_same_initial_value():
    series, _ = _b_series("paper")
    on = series["damping_scale"] != 1.0
    b = series["damping_scale"][on]
    assert np.ptp(b) > 0.1  # an OU process with tau = 0.5 s over several seconds


def test_an_unknown_form_is_refused_naming_the_key():
    cfg = ddmr_cli.compose_config(["scenario=paper_2", "scenario.uncertainty.form=drift"])
    with pytest.raises(ddmr_cli.ConfigError, match="scenario.uncertainty.form"):
        ddmr_cli.run_config(cfg)
