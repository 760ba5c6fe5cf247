"""The paper's wheel plant stepped from Python (``plant=wheel_python``): the reference implementation of the external
plant contract (:mod:`ddmr_cli.plant.base`), and the check of the engine's external-plant path.

It is the wheel plant of :mod:`ddmr_cli.plant.wheel` written as an :class:`~ddmr_cli.plant.base.ExternalPlant`
from the model's own laws, run as plain Python: per run and step the terrain's OU roughness torques (drawn from
the run's own seed exactly as the engine draws them, :class:`~ddmr_cli.model.noise.NoiseStreams`, so the same
seed gives the same terrain), the rolling resistance of the zone, the acceleration (8) with the true d
(:func:`~ddmr_cli.model.dynamics.wheel_acceleration`) under the applied voltages and the damping scale the engine
hands it, and explicit Euler (:func:`~ddmr_cli.model.integrators.euler`). So ``plant=wheel_python`` gives
``plant=wheel``'s numbers to rounding (tests/test_external_plant.py: 1e-9 relative; Python rounds every
operation where compiled code may fuse a multiply-add), several hundred times slower (about 160 us a run-step
against the compiled loop's 0.25). Explicit Euler only (``simulation.integrator=euler``).

Adding a plant took this module (the class and ``factory``), ``conf/plant/wheel_python.yaml`` (3 lines) and its
test; the engine, metrics, report and determinism rules came with the contract.
"""

from __future__ import annotations

import functools
import math
from typing import Any, Callable, Mapping

import numpy as np

from ddmr_cli.compiled import plain
from ddmr_cli.model.integrators import euler
from ddmr_cli.model.noise import NoiseStreams, ou_coefficients, ou_step
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.dynamics import wheel_acceleration
from ddmr_cli.model.terrain import zone_of

__all__ = ["PythonWheelPlant", "check", "factory"]

#: the name of this plant (``plant.name`` of conf/plant/wheel_python.yaml)
NAME = "wheel_python"


def check(config: Mapping, sim: Any) -> None:
    """Before a run (config validation): explicit Euler is the integrator this plant steps with."""
    if sim.integrator != "euler":
        raise ConfigError("simulation.integrator", sim.integrator, "plant=wheel_python integrates with euler only")


def factory(config: Mapping) -> Callable[..., "PythonWheelPlant"]:
    """The plant of a simulation for ``plant=wheel_python`` (no parameters of its own but ``name``)."""
    unknown = sorted(set(config) - {"name"})
    if unknown:
        raise ConfigError(f"plant.{unknown[0]}", config[unknown[0]], "unknown key (plant=wheel_python has none)")
    return functools.partial(PythonWheelPlant)


class PythonWheelPlant:
    """The wheel plant of ``sim`` (a :class:`~ddmr_cli.engine.simulation.Simulation`) as an external plant.

    Parameters
    ----------
    sim : Simulation
        Its robot, terrain, scenario and step.
    threads : int
        Ignored (one thread: the runs are stepped in turn).
    """

    def __init__(self, sim: Any, threads: int = 0) -> None:
        check({}, sim)
        self.dt = float(sim.dt)
        self._plant = sim.robot.plant()
        self._zone_edges = np.asarray(sim.terrain.inner_edges, dtype=float)
        self._roughness = np.asarray(sim.terrain.roughness, dtype=float)
        self._roll = np.asarray(sim.robot.rolling_resistance_torque(sim.terrain.mu), dtype=float)
        self._ou = ou_coefficients(self.dt, sim.terrain.correlation_time)
        scenario = sim.scenario
        self._phase_by_distance = scenario.phase_clock == "distance"
        self._phase_edges = np.asarray(scenario.inner_edges, dtype=float)
        self._rough_on = np.array([float(p.roughness) for p in scenario.phases])
        self._scenario = scenario

    def reset(self, seeds: np.ndarray, pose0: np.ndarray, w0: np.ndarray) -> None:
        n = len(seeds)
        self._noise = NoiseStreams([int(s) for s in seeds])
        self._n = self._noise.initial_state()[:, 0:2].copy()  # the roughness processes (the third is the engine's b)
        self._s = {"x": np.array(pose0[:, 0], dtype=float), "y": np.array(pose0[:, 1], dtype=float),
                   "theta": np.array(pose0[:, 2], dtype=float), "distance": np.zeros(n),
                   "w": np.array(w0, dtype=float).reshape(n, 2)}
        self._d, self._k = np.zeros((n, 2)), 0

    def state(self) -> dict[str, np.ndarray]:
        return {key: value.copy() for key, value in self._s.items()}

    def step(self, u: np.ndarray, damping_scale: np.ndarray) -> None:
        s, p, (a, b), k = self._s, self._plant, self._ou, self._k
        xi = self._noise.next_chunk(1)[:, 0, :]
        for r in range(len(s["x"])):
            n_R = plain(ou_step)(a, b, self._n[r, 0], xi[r, 0])
            n_L = plain(ou_step)(a, b, self._n[r, 1], xi[r, 1])
            self._n[r] = n_R, n_L
            dist = s["distance"][r]
            phase = (plain(zone_of)(self._phase_edges, dist) if self._phase_by_distance
                     else int(self._scenario.phase_index(np.array([k * self.dt]))[0]))
            zone = plain(zone_of)(self._zone_edges, dist)
            rough = self._roughness[zone] * self._rough_on[phase]
            w_R, w_L = s["w"][r]
            a_R, a_L, d_R, d_L = plain(wheel_acceleration)(p, w_R, w_L, u[r, 0], u[r, 1], damping_scale[r], True,
                                                           -n_R * rough, -n_L * rough, self._roll[zone])
            theta = s["theta"][r]
            (s["x"][r], s["y"][r], s["theta"][r], s["distance"][r], s["w"][r, 0], s["w"][r, 1]) = plain(euler)(
                p, self.dt, s["x"][r], s["y"][r], theta, dist, w_R, w_L, math.cos(theta), math.sin(theta), a_R, a_L)
            self._d[r] = d_R, d_L
        self._k += 1

    def true_disturbance(self) -> np.ndarray:
        return self._d.copy()

    def diverged(self) -> np.ndarray:
        return ~np.isfinite(np.column_stack([self._s["x"], self._s["y"], self._s["w"]])).all(axis=1)
