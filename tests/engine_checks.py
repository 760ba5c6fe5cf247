"""Engine-level checks every wheel controller owes (docs/model.md §4, §6), shared by the controllers' test files:
zero disturbance and zero initial error keep every error at zero; seed k alone equals seed k in a batch."""

from __future__ import annotations

import numpy as np

from paper import make_simulation, make_terrain
from ddmr_cli import TerrainZone, simulate
from test_determinism import SCENARIO, TERRAIN

QUIET = make_terrain(TerrainZone("quiet", 0.0, 0.0, 0.0))


def zero_error_run(controller, duration: float = 1.0):
    """On the reference line from (0, 0, 0) at the reference wheel speeds with no disturbance: the kept series."""
    sim = make_simulation(controller=controller, terrain=QUIET, duration=duration, initial_pose=(0.0, 0.0, 0.0))
    return sim.robot, simulate(sim, [0], keep_series=[0]).series[0]


def assert_zero_error_stays_zero(controller, duration: float = 1.0) -> None:
    """With no disturbance and no initial error every error (pose, sliding variable, wheel speed) and every
    disturbance estimate stays at rounding level, and u is the voltage that holds the speed, B w / K_u."""
    robot, s = zero_error_run(controller, duration)
    for ch in ("e_x", "e_y", "e_theta", "deviation"):
        assert np.max(np.abs(s[ch])) < 1e-12, ch
    w_ref = 1.0 / robot.wheel_radius
    for wheel in ("right", "left"):
        assert np.max(np.abs(s[f"s_{wheel}"])) < 1e-12 * w_ref
        assert np.max(np.abs(s[f"w_{wheel}"] - w_ref)) < 1e-12 * w_ref
        for channel in (k for k in s if k.startswith("d_hat_") and k.endswith(wheel)):  # each estimate of d
            assert np.max(np.abs(s[channel])) < 1e-9, channel
        np.testing.assert_allclose(s[f"u_{wheel}"], robot.damping * w_ref / robot.voltage_gain, rtol=1e-12)


def assert_seed_alone_equals_seed_in_batch(controller, seed: int = 5) -> None:
    """Short zones and phases (every zone, phase and noise channel in 0.5 s): seed k alone and inside a batch give
    bit-identical metrics and series."""
    sim = make_simulation(controller=controller, terrain=TERRAIN, scenario=SCENARIO, dt=1e-3, duration=0.5)
    batch = simulate(sim, seeds=list(range(8)), keep_series=[seed])
    alone = simulate(sim, seeds=[seed], keep_series=[seed])
    for name in batch.metrics:
        assert np.array_equal(batch.metrics[name][seed], alone.metrics[name][0], equal_nan=True), name
    for ch in batch.series[seed]:
        assert np.array_equal(batch.series[seed][ch], alone.series[seed][ch], equal_nan=True), ch
    assert np.ptp(batch.metrics["deviation_mae"][:, 0]) > 0  # the seeds do differ
