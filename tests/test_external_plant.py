"""The external-plant path of the engine (ddmr_cli.plant.base; engine/stepper.py's external_control and
external_account, driven by engine/simulation.py): the same laws in the same order as the compiled wheel loop,
split where a plant stepped from Python advances.

The check that holds the two orchestrations to one another: the paper's wheel plant, written as an external plant
from the model's own laws (:class:`WheelPlantFromPython`), gives the compiled loop's metrics and series to 1e-9
(Python rounds every operation, compiled code may fuse a multiply-add, so not bit for bit). Roughness is off in
these runs: its OU torques are drawn inside the engine, which an external plant does not see (a physics plant's
roughness is its ground); rolling resistance per zone and scenario 2's damping scale act.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ddmr_cli import Terrain, TerrainZone, paper_simulation, simulate
from ddmr_cli.compiled import plain
from ddmr_cli.engine.integrators import euler
from ddmr_cli.model.robot import wheel_acceleration
from ddmr_cli.model.terrain import zone_of
from ddmr_cli.plant.base import ExternalPlant, check_state
from test_determinism import SCENARIO

#: zones without roughness, each its own rolling resistance, crossed in a 0.5 s run
SMOOTH = Terrain(zones=(TerrainZone("a", 0.0, 0.0, 0.02), TerrainZone("b", 0.15, 0.0, 0.10),
                        TerrainZone("c", 0.3, 0.0, 0.05)), correlation_time=0.02)
SEEDS = [0, 1, 2, 3]


class WheelPlantFromPython:
    """The paper's wheel plant (8) as an :class:`ExternalPlant`: :func:`wheel_acceleration` and explicit Euler,
    plain Python, rolling resistance by the zone of the distance travelled, the damping scale the engine hands
    it. ``diverge_at``: ``{run: step}`` to flag a run diverged from that step on (a tipped robot)."""

    def __init__(self, sim, threads=0, diverge_at=None):
        self.plant, self.dt = sim.robot.plant(), float(sim.dt)
        self.edges = np.asarray(sim.terrain.inner_edges, dtype=float)
        self.roll = np.asarray(sim.robot.rolling_resistance_torque(sim.terrain.mu), dtype=float)
        self.diverge_at = diverge_at or {}

    def reset(self, seeds, pose0, w0):
        n = len(seeds)
        self.s = {"x": pose0[:, 0].copy(), "y": pose0[:, 1].copy(), "theta": pose0[:, 2].copy(),
                  "distance": np.zeros(n), "w": np.array(w0, dtype=float)}
        self.d, self.k, self.gone = np.zeros((n, 2)), 0, np.zeros(n, dtype=bool)

    def state(self):
        return {key: value.copy() for key, value in self.s.items()}

    def step(self, u, damping_scale):
        s, p = self.s, self.plant
        for r in range(len(s["x"])):
            w_R, w_L = s["w"][r]
            zone = plain(zone_of)(self.edges, s["distance"][r])
            a_R, a_L, d_R, d_L = plain(wheel_acceleration)(p, w_R, w_L, u[r, 0], u[r, 1], damping_scale[r], True,
                                                           0.0, 0.0, self.roll[zone])
            theta = s["theta"][r]
            (s["x"][r], s["y"][r], s["theta"][r], s["distance"][r], s["w"][r, 0], s["w"][r, 1]) = plain(euler)(
                p, self.dt, s["x"][r], s["y"][r], theta, s["distance"][r], w_R, w_L, math.cos(theta),
                math.sin(theta), a_R, a_L)
            self.d[r] = d_R, d_L
        self.k += 1
        for r, k in self.diverge_at.items():
            self.gone[r] |= self.k > k

    def true_disturbance(self):
        return self.d.copy()

    def diverged(self):
        return self.gone.copy()


def _sim(*overrides, plant=None):
    sim = paper_simulation("controller=smc_ndo_nno", "simulation.duration=0.5", *overrides, terrain=SMOOTH,
                           scenario=SCENARIO)
    return sim if plant is None else paper_simulation("controller=smc_ndo_nno", "simulation.duration=0.5",
                                                      *overrides, terrain=SMOOTH, scenario=SCENARIO, plant=plant)


def test_the_python_wheel_plant_keeps_the_contract():
    sim = _sim()
    plant = WheelPlantFromPython(sim)
    assert isinstance(plant, ExternalPlant)
    plant.reset(np.array(SEEDS), np.zeros((4, 3)), np.ones((4, 2)))
    check_state(plant.state(), 4)


@pytest.mark.parametrize("overrides", [(), ("sensor=encoder", "actuator=realistic", "control.rate=250"),
                                       ("sensor=noisy", "actuator=pwm8")],
                         ids=["ideal", "encoder-realistic-250Hz", "noisy-pwm8"])
def test_the_wheel_plant_stepped_from_python_gives_the_compiled_loops_numbers(overrides):
    """Every metric of every seed and the kept series agree to 1e-9 (relative) with the compiled wheel loop, with
    the sensor, actuator and control-rate holds in play."""
    compiled = simulate(_sim(*overrides), SEEDS, keep_series=[1])
    external = simulate(_sim(*overrides, plant=WheelPlantFromPython), SEEDS, keep_series=[1])
    assert compiled.segments == external.segments
    assert not external.diverged.any()
    checked = 0
    for name, values in compiled.metrics.items():
        np.testing.assert_allclose(external.metrics[name], values, rtol=1e-9, atol=1e-12, err_msg=name)
        checked += np.isfinite(values).sum()
    assert checked > 100  # the comparison saw numbers, not only NaN
    for channel, values in compiled.series[1].items():
        np.testing.assert_allclose(external.series[1][channel], values, rtol=1e-9, atol=1e-12, err_msg=channel)
    for name, values in compiled.bands.items():
        np.testing.assert_allclose(external.bands[name], values, rtol=1e-9, atol=1e-12, err_msg=name)


def test_a_run_the_plant_calls_diverged_is_a_diverged_result_at_that_step():
    def plant(sim, threads):
        return WheelPlantFromPython(sim, threads, diverge_at={2: 123})

    result = simulate(_sim(plant=plant), SEEDS)
    assert list(result.diverged) == [False, False, True, False]
    assert result.divergence_time[2] == pytest.approx(123 * 0.001)
    mae = np.asarray(result.metrics["deviation_mae"])
    assert np.isnan(mae[2]).all() and np.isfinite(mae[[0, 1, 3]]).all()
