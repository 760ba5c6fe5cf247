"""Mirror symmetry of the whole closed loop (issue 27, "tests that cannot fail": per-wheel asymmetry).

Reflect a run across the x axis: the reference ``(x, y, theta, v, omega) -> (x, -y, -theta, v, -omega)``, the
initial pose ``(x, y, theta) -> (x, -y, -theta)``, and give the right wheel what the left one had (every per-wheel
gain swapped). The robot is left-right symmetric (J = [[p, q], [q, p]], one damping, one rolling resistance), so the
mirrored run is the same run seen in a mirror: ``e_y -> -e_y``, ``e_theta -> -e_theta``, ``u_R <-> u_L``,
``w_R <-> w_L``, ``s_R <-> s_L``, every estimate of ``d`` swapped, every scalar metric equal and every per-wheel
metric swapped.

A law that reads the wrong wheel's value (``p.lam[1]`` where ``p.lam[0]`` belongs, ``st["v"][0]`` in the left
wheel's line, ``w_R`` in the plant's left row) breaks this, while the paper's straight line with equal gains on
both wheels cannot see it (both wheels do almost the same there). The gains below differ per wheel by a third or
more so that such a swap moves the numbers far above the tolerance.

Noise: the terrain's roughness draws one stream per wheel from the run's generator (``model/noise.py``: right,
left, uncertainty), which a mirror would have to swap; the runs here have no roughness (``terrain=flat`` with its
roughness 0) but keep the rolling resistance (it opposes each wheel's rotation) and scenario 2's damping
uncertainty (one stream shared by both wheels, so the mirrored run draws the same), switched on after 0.8 m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from ddmr_cli import paper_simulation, paper_trajectory, simulate

#: flat ground without roughness, rolling resistance kept; the damping uncertainty on from 0.8 m; 2 s of a lane
#: change (the sinusoid turns left first, its mirror right first)
SETTING = ("terrain=flat", "terrain.zones.flat.roughness=0.0", "scenario=paper_2",
           "scenario.phases.uncertainty.start=0.8", "scenario.phases.both.start=100.0", "simulation.duration=2.0",
           "metrics.settle_time=0.5", "metrics.zone_settle_time=0.2")
SEEDS = [3, 4]
POSE = (0.0, 0.05, 0.05)

#: per controller: its per-wheel gains (right, left), deliberately unequal
ASYMMETRIC = {
    "smc_ndo_nno": {"controller.lam": (20.0, 30.0), "controller.switching_gain": (9.0, 15.0),
                    "controller.ndo.gain": (40.0, 60.0), "controller.nn.learning_rate": (30.0, 70.0)},
    "pid": {"controller.kp": (4.0, 6.0), "controller.ki": (0.5, 2.0), "controller.kd": (0.005, 0.015)},
    "smc": {"controller.lam": (18.0, 30.0), "controller.switching_gain": (10.0, 14.0)},
    "sta_ndo": {"controller.k1": (80.0, 120.0), "controller.k2": (4000.0, 6500.0),
                "controller.ndo.gain": (40.0, 60.0)},
    "adaptive_smc_ndo": {"controller.lam": (20.0, 30.0), "controller.switching_gain": (9.0, 15.0),
                         "controller.adaptation_rate": (1500.0, 2500.0), "controller.ndo.gain": (40.0, 60.0)},
    "adrc": {},  # no per-wheel gains: the mirror still checks every wheel-indexed state of its ESO
}
#: further overrides per controller (the integral surface has wheel-indexed state of its own)
EXTRA = {"smc": ("controller.surface=integral", "controller.switching=tanh")}

#: series channels that change sign in the mirror; right/left channels swap; the others stay
NEGATED = {"y", "theta", "y_ref", "theta_ref", "e_y", "e_theta"}


@dataclass(frozen=True)
class Mirrored:
    """A trajectory reflected across the x axis: ``(x, -y, -theta, v, -omega)`` (the Trajectory protocol)."""

    trajectory: object

    def reference(self, t: float):
        x, y, theta, v, omega = self.trajectory.reference(t)
        return x, -y, -theta, v, -omega


def _overrides(gains: dict, swap: bool) -> list[str]:
    return [f"{key}=[{b!r},{a!r}]" if swap else f"{key}=[{a!r},{b!r}]" for key, (a, b) in gains.items()]


def _run(controller: str, gains: dict, swap_gains: bool, mirror: bool, *extra: str, trajectory: str = "sinusoid"):
    x, y, theta = POSE
    pose = (x, -y, -theta) if mirror else POSE
    overrides = [*SETTING, f"controller={controller}", *EXTRA.get(controller, ()), *_overrides(gains, swap_gains),
                 f"trajectory={trajectory}", f"simulation.initial_pose=[{pose[0]!r},{pose[1]!r},{pose[2]!r}]", *extra]
    reference = paper_trajectory(trajectory)
    sim = paper_simulation(*overrides, trajectory=Mirrored(reference) if mirror else reference)
    return simulate(sim, seeds=SEEDS, keep_series=SEEDS)


def _swapped(name: str) -> str:
    """The other wheel's name of a channel or metric (``u_right`` <-> ``u_left``), else the name."""
    for a, b in (("right", "left"), ("left", "right")):
        if a in name.split("_"):
            return "_".join(b if part == a else part for part in name.split("_"))
    return name


def mirror_mismatch(a, b) -> list[str]:
    """What of run ``b`` is not run ``a`` mirrored (empty when it is, to the tolerance)."""
    bad = []

    def close(what, x, y):
        x, y = np.asarray(x, float), np.asarray(y, float)
        scale = max(1.0, float(np.nanmax(np.abs(x))) if x.size else 1.0)
        if x.shape != y.shape or not np.allclose(x, y, rtol=1e-9, atol=1e-11 * scale, equal_nan=True):
            worst = float(np.nanmax(np.abs(x - y))) if x.shape == y.shape else float("nan")
            bad.append(f"{what}: differs by up to {worst:.3g} (scale {scale:.3g})")

    assert not a.diverged.any() and not b.diverged.any()
    for seed in SEEDS:
        sa, sb = a.series[seed], b.series[seed]
        for name, values in sa.items():
            partner = sb[_swapped(name)]
            close(f"seed {seed} series {name}", -values if name in NEGATED else values, partner)
    for name, values in a.metrics.items():
        close(f"metric {name}", values, b.metrics[_swapped(name)])  # per segment
    return bad


@pytest.mark.parametrize("controller", list(ASYMMETRIC))
def test_the_mirrored_run_with_swapped_wheels_is_the_run_in_a_mirror(controller):
    gains = ASYMMETRIC[controller]
    run = _run(controller, gains, swap_gains=False, mirror=False)
    mirrored = _run(controller, gains, swap_gains=True, mirror=True)
    assert mirror_mismatch(run, mirrored) == []
    # not vacuous: the run turns (both wheels differ by volts) and, for a controller with per-wheel gains, the
    # mirror without swapping the gains is a different run (the gains' asymmetry is visible at this tolerance)
    series = run.series[SEEDS[0]]
    assert np.max(np.abs(series["u_right"] - series["u_left"])) > 1.0
    assert np.max(np.abs(series["e_y"])) > 0.01 and np.max(series["damping_scale"]) > 1.05
    if gains:
        unswapped = _run(controller, gains, swap_gains=False, mirror=True)
        assert len(mirror_mismatch(run, unswapped)) > 5


@pytest.mark.parametrize("controller", ["smc_ndo_nno", "pid"])
def test_a_circle_turning_left_mirrors_the_circle_turning_right(controller):
    """The same property on the circle (constant turning: one wheel faster all the time), from a rest start."""
    gains = ASYMMETRIC[controller]
    extra = ("simulation.initial_wheel_speeds=rest", "trajectory.radius=1.5")
    run = _run(controller, gains, False, False, *extra, trajectory="circle")
    assert mirror_mismatch(run, _run(controller, gains, True, True, *extra, trajectory="circle")) == []
