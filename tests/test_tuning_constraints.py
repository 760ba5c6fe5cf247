"""Known values of a tuning trial's constraints (issue 27, "tests that cannot fail"; docs/model.md §9 [9c]).

A trial is infeasible when a run diverged or the mean saturation fraction exceeds ``tuning.saturation_limit``,
and then scores ``bound (1 + v)`` with the violation ``v = diverged / runs + max(0, saturation - limit)``. The
fast tier checked a saturation limit of 0 only (so a law that ignored the limit passed) and no diverging run (so
any penalty for divergence passed). Here each part of ``v`` is set to a value known before the trial runs: the
diverged runs by a divergence bound placed between the seeds' own largest deviations (measured first with no
bound), the excess saturation by limits below, at and above the measured fraction.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("optuna", reason="the tune extra is not installed (pip install -e '.[tune]')")

from ddmr_cli import simulate  # noqa: E402
from ddmr_cli.study import tuning as TU  # noqa: E402
from ddmr_cli.config import compose_config, seeds_of, validate_config  # noqa: E402

#: a PID study of 4 seeds, 0.4 s at 2 ms (both scenarios are in their terrain-only phase for the whole run)
STUDY = ["+tune=pid", "run.n_runs=4", "simulation.duration=0.4", "simulation.dt=0.002", "metrics.settle_time=0.2"]
#: gains too weak to follow the reference: the robot falls behind, the deviation grows all run long
WEAK = ["controller.kp=0.5", "controller.ki=0.0", "controller.kd=0.0"]


def _study(*extra):
    return compose_config([*STUDY, *extra])


def _per_run(cfg, metric):
    """``metric`` of every run of the study's scenarios, simulated directly (scenario-major, then seed)."""
    out = []
    for name in cfg.tuning.scenarios:
        result = simulate(validate_config(TU.scenario_config(cfg, name)), seeds_of(cfg), keep_series=[])
        assert not result.diverged.any()
        out.extend(result.metric(metric))
    return np.array(out)


def _bound_between(peaks, below: int) -> float:
    """A divergence bound above the ``below`` smallest distinct peaks and under the others (``below=0``: under
    every peak, above the start's deviation, 0.05 m: every run diverges on the way)."""
    ranked = np.unique(peaks)
    assert len(ranked) >= 3 and np.all(np.diff(ranked) > 1e-7)  # seeds apart: a bound between them is clear
    low = ranked[below - 1] if below else 0.05
    return float(0.5 * (low + ranked[below]))


@pytest.mark.parametrize("objective, below", [("deviation", 2), ("pareto", 1), ("deviation", 0)],
                         ids=["some-diverge", "some-diverge-pareto", "all-diverge"])
def test_a_diverging_gain_is_penalised_by_the_share_of_runs_that_diverged(objective, below):
    peaks = _per_run(_study(*WEAK, "simulation.divergence_bound=1e9"), "deviation_max")
    bound = _bound_between(peaks, below)
    diverged, runs = int(np.sum(peaks > bound)), len(peaks)
    assert 0 < diverged <= runs and (diverged < runs) == (below > 0)
    cfg = _study(*WEAK, f"simulation.divergence_bound={bound!r}", "tuning.saturation_limit=1.0",
                 f"objective={objective}")
    outcome = TU.evaluate_gains(cfg)
    assert (outcome.runs, outcome.diverged) == (runs, diverged)
    assert not outcome.feasible and f"{diverged}/{runs} runs diverged" in outcome.reason
    assert math.isclose(outcome.violation, diverged / runs, rel_tol=0, abs_tol=1e-15)
    u_max, dt = float(cfg.robot.max_voltage), float(cfg.simulation.dt)
    expected = [bound * (1.0 + diverged / runs), 2.0 * u_max / dt * (1.0 + diverged / runs)]
    assert len(outcome.values) == (2 if objective == "pareto" else 1)
    np.testing.assert_allclose(outcome.values, expected[:len(outcome.values)], rtol=1e-12)
    if diverged < runs:  # above every feasible trial: the runs that did not diverge stayed under the bound
        assert outcome.values[0] > bound > outcome.deviation
    else:
        assert math.isnan(outcome.deviation) and outcome.values[0] == 2.0 * bound


@pytest.mark.parametrize("limit, excess", [(0.01, 0.02), (0.025, 0.005), (0.03, 0.0), (0.05, 0.0)])
def test_the_saturation_limit_sets_the_violation(limit, excess):
    """PID from the offset pose saturates on 3 % of the steps in both scenarios (measured here, then the limit
    placed below, at and above it): the violation is the excess over the limit, nothing at or under it."""
    saturation = float(np.mean(_per_run(_study(), TU.SATURATION_METRIC)))
    assert math.isclose(saturation, 0.03, rel_tol=1e-12)
    cfg = _study(f"tuning.saturation_limit={limit}")
    outcome = TU.evaluate_gains(cfg)
    assert math.isclose(outcome.saturation, saturation, rel_tol=1e-12) and outcome.diverged == 0
    assert math.isclose(outcome.violation, excess, rel_tol=0, abs_tol=1e-15)
    if excess:
        assert not outcome.feasible and f"saturation 0.0300 > limit {limit:g}" in outcome.reason
        bound = float(cfg.simulation.divergence_bound)
        assert math.isclose(outcome.values[0], bound * (1.0 + excess), rel_tol=1e-12)
    else:
        assert outcome.feasible and outcome.reason == ""
        assert outcome.values == (outcome.deviation,)
