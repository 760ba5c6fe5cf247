"""The simulation engine: a batch of seeded runs advanced together (MODEL.md sections 4-5).

Every state array has a leading run axis, so a 50-seed statistic is one call. Each run draws its noise from
its own generator (:mod:`ddmr_cli.noise`) and nothing couples runs, so seed k gives bit-identical numbers
alone or inside any batch. Per step: measure, run the outer loop and the wheel controller, saturate ``u`` to
``[-U_max, U_max]``, hold ``u`` and the disturbance for the step, advance plant and pose (explicit Euler by
default, RK4 as an option). A run whose deviation exceeds ``divergence_bound`` or turns NaN/inf is marked
diverged with the time it happened; the others carry on unaffected.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .controllers.base import WheelController
from .errors import ConfigError
from .kinematics import wrap_angle
from .metrics import MetricAccumulator, StepSignals
from .noise import CHANNELS, OUStreams
from .outer_loop import Kanayama
from .results import SERIES_CHANNELS, SimulationResult
from .robot import NominalModel, Robot
from .scenario import Scenario
from .terrain import Terrain
from .trajectory import StraightLine, Trajectory

INTEGRATORS = ("euler", "rk4")
#: bytes of per-step signals buffered per run and step (chunked, so memory stays bounded)
_BYTES_PER_RUN_STEP = 8 * 40
CHUNK_BUDGET = 192 * 2**20


@dataclass
class Simulation:
    """Everything one batch of runs needs, as plain objects (no Hydra here).

    Parameters
    ----------
    controller : WheelController
        The wheel-speed controller (its state is reset by every :func:`simulate` call).
    robot, terrain, scenario, trajectory, outer_loop
        Model pieces; defaults are the paper's robot, no terrain, one phase, the paper's line, Kanayama.
    dt : float
        Step [s] (MODEL.md 4: 1 ms).
    duration : float
        Simulated time [s] (paper: 15).
    integrator : {'euler', 'rk4'}
    initial_pose : (x, y, theta)
        Paper: (0, 0.05, 0.05).
    initial_wheel_speeds : 'reference', 'rest' or (w_R, w_L)
        ``reference``: the wheel speeds of the reference's v_r, omega_r at t = 0 (a rolling start, the default);
        ``rest``: zero.
    divergence_bound : float
        A run whose deviation exceeds this [m] is marked diverged.
    """

    controller: WheelController
    robot: Robot = field(default_factory=Robot)
    terrain: Terrain = field(default_factory=Terrain)
    scenario: Scenario = field(default_factory=Scenario)
    trajectory: Trajectory = field(default_factory=StraightLine)
    outer_loop: Kanayama = field(default_factory=Kanayama)
    dt: float = 1e-3
    duration: float = 15.0
    integrator: str = "euler"
    initial_pose: Sequence[float] = (0.0, 0.05, 0.05)
    initial_wheel_speeds: str | Sequence[float] = "reference"
    divergence_bound: float = 1.0

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.dt))


def _initial_wheel_speeds(sim: Simulation) -> np.ndarray:
    spec = sim.initial_wheel_speeds
    if isinstance(spec, str):
        if spec == "rest":
            return np.zeros(2)
        if spec == "reference":
            _, _, _, v_r, omega_r = sim.trajectory.reference(0.0)
            L, R = sim.robot.half_track, sim.robot.wheel_radius
            return np.array([(v_r + L * omega_r) / R, (v_r - L * omega_r) / R])
        raise ConfigError("simulation.initial_wheel_speeds", spec, "must be 'reference', 'rest' or [w_R, w_L]")
    arr = np.asarray(spec, dtype=float)
    if arr.shape != (2,):
        raise ConfigError("simulation.initial_wheel_speeds", spec, "must be 'reference', 'rest' or [w_R, w_L]")
    return arr


def simulate(sim: Simulation, seeds: Sequence[int], keep_series: Sequence[int] = (),
             progress: Callable[[int, int], None] | None = None) -> SimulationResult:
    """Run one batch: one run per seed, all advanced together.

    Parameters
    ----------
    sim : Simulation
    seeds : sequence of int
        One run per seed; seed k gives the same numbers whatever else is in the batch.
    keep_series : sequence of int
        Seeds whose full time series are kept (the others keep only metrics).
    progress : callable(steps_done, steps_total), optional
        Called after every chunk of steps.

    Returns
    -------
    SimulationResult
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ConfigError("run.n_runs", 0, "must be >= 1")
    if sim.integrator not in INTEGRATORS:
        raise ConfigError("simulation.integrator", sim.integrator, f"must be one of {', '.join(INTEGRATORS)}")
    started = time.perf_counter()
    robot, dt, n_steps, n_runs = sim.robot, float(sim.dt), sim.n_steps, len(seeds)
    keep_idx = [seeds.index(s) for s in dict.fromkeys(int(k) for k in keep_series) if s in seeds]

    # constants of the true plant and the kinematics
    L, R = robot.half_track, robot.wheel_radius
    A = robot.drift_matrix.T  # row-vector form: w @ A == (J^-1 B w)^T
    G = robot.input_matrix.T
    Jinv = robot.inverse_inertia.T
    u_max = robot.max_voltage
    roughness_table, mu_table = sim.terrain.roughness, sim.terrain.mu
    roll_torque_table = robot.rolling_resistance_torque(mu_table)
    unc = sim.scenario.uncertainty
    phase_of_step = sim.scenario.phase_index(np.arange(n_steps) * dt)
    phases = sim.scenario.phases
    rough_on = np.array([p.roughness for p in phases], dtype=float)
    unc_on = np.array([p.uncertainty for p in phases], dtype=bool)
    ref = np.array([sim.trajectory.reference(k * dt) for k in range(n_steps)])  # (n_steps, 5)
    kin = sim.outer_loop

    controller = sim.controller.bind(NominalModel.from_robot(robot), dt)

    # state
    x = np.full(n_runs, float(sim.initial_pose[0]))
    y = np.full(n_runs, float(sim.initial_pose[1]))
    th = np.full(n_runs, float(sim.initial_pose[2]))
    w = np.tile(_initial_wheel_speeds(sim), (n_runs, 1))
    dist = np.zeros(n_runs)
    w_d_prev = None
    controller.reset(w.copy())

    streams = OUStreams(seeds, dt, [sim.terrain.correlation_time] * 2 + [unc.correlation_time])
    chunk = int(max(16, min(4096, CHUNK_BUDGET // (_BYTES_PER_RUN_STEP * n_runs))))
    chunk = min(chunk, max(n_steps, 1))
    acc = MetricAccumulator(n_runs, dt, sim.terrain.names, sim.scenario.names,
                            robot.back_emf_constant, robot.armature_resistance)
    diverged = np.zeros(n_runs, dtype=bool)
    divergence_time = np.full(n_runs, np.nan)
    series = {name: np.empty((len(keep_idx), n_steps)) for name in SERIES_CHANNELS} if keep_idx else {}

    def rates(th_, w_, u_, b_scale_, d_ext_, roll_torque_):
        """Plant (6)-(8) and kinematics (1)-(2): (x', y', th', w', distance')."""
        v_ = R * 0.5 * (w_[:, 0] + w_[:, 1])
        omega_ = (R / (2.0 * L)) * (w_[:, 0] - w_[:, 1])
        drift = (w_ @ A) * b_scale_[:, None]
        roll = (np.sign(w_) * roll_torque_[:, None]) @ Jinv  # J^-1 tau_roll, opposing rotation
        w_dot_ = -drift + u_ @ G - roll + d_ext_
        return v_ * np.cos(th_), v_ * np.sin(th_), omega_, w_dot_, np.abs(v_)

    ones = np.ones(n_runs)
    with np.errstate(all="ignore"):
        k0 = 0
        while k0 < n_steps:
            n = min(chunk, n_steps - k0)
            noise = streams.next_chunk(n)  # (n, runs, 3)
            buf = {key: np.empty((n, n_runs)) for key in ("dev", "e_x", "e_y", "e_theta", "x", "y", "theta",
                                                           "distance", "roughness", "damping_scale")}
            buf.update({key: np.empty((n, n_runs, 2)) for key in ("u", "u_command", "w", "w_d", "s", "d_true",
                                                                   "d_hat_ndo", "d_hat_nn")})
            zone_buf = np.empty((n, n_runs), dtype=np.intp)
            for j in range(n):
                k = k0 + j
                x_r, y_r, th_r, v_r, omega_r = ref[k]
                dx, dy = x_r - x, y_r - y
                c, sn = np.cos(th), np.sin(th)
                e_x = c * dx + sn * dy
                e_y = c * dy - sn * dx
                e_th = wrap_angle(th_r - th)
                # outer loop (MODEL.md 3) and inverse kinematics (4)
                v_d, omega_d = kin.command(e_x, e_y, e_th, v_r, omega_r)
                w_d = np.empty((n_runs, 2))
                w_d[:, 0] = (v_d + L * omega_d) / R
                w_d[:, 1] = (v_d - L * omega_d) / R
                w_d_dot = np.zeros_like(w_d) if w_d_prev is None else (w_d - w_d_prev) / dt
                w_d_prev = w_d
                # wheel controller and saturation (MODEL.md 4)
                u_cmd = controller.command(w, w_d, w_d_dot)
                u = np.clip(u_cmd, -u_max, u_max)
                # disturbances of this step (MODEL.md 5)
                p = phase_of_step[k]
                zone = sim.terrain.zone_index(dist)
                rough = roughness_table[zone] * rough_on[p]
                roll_torque = roll_torque_table[zone]
                d_ext = noise[j, :, :2] * (-rough)[:, None]
                if unc_on[p]:
                    b_scale = 1.0 + np.clip(unc.std * noise[j, :, 2], unc.low, unc.high)
                else:
                    b_scale = ones
                k1 = rates(th, w, u, b_scale, d_ext, roll_torque)
                # the lumped disturbance an observer should estimate: w' - f_nom(w) - g_nom u (MODEL.md 5)
                d_true = k1[3] + w @ A - u @ G
                controller.update(w, u, u_cmd)
                # record
                buf["dev"][j] = np.hypot(dx, dy)
                buf["e_x"][j], buf["e_y"][j], buf["e_theta"][j] = e_x, e_y, e_th
                buf["x"][j], buf["y"][j], buf["theta"][j], buf["distance"][j] = x, y, th, dist
                buf["roughness"][j], buf["damping_scale"][j] = rough, b_scale
                buf["u"][j], buf["u_command"][j], buf["w"][j], buf["w_d"][j] = u, u_cmd, w, w_d
                buf["s"][j], buf["d_true"][j] = controller.s, d_true
                buf["d_hat_ndo"][j], buf["d_hat_nn"][j] = controller.d_hat_ndo, controller.d_hat_nn
                zone_buf[j] = zone
                # advance plant and pose
                if sim.integrator == "euler":
                    xd, yd, thd, wd, sd = k1
                else:
                    h = 0.5 * dt
                    k2 = rates(th + h * k1[2], w + h * k1[3], u, b_scale, d_ext, roll_torque)
                    k3 = rates(th + h * k2[2], w + h * k2[3], u, b_scale, d_ext, roll_torque)
                    k4 = rates(th + dt * k3[2], w + dt * k3[3], u, b_scale, d_ext, roll_torque)
                    xd, yd, thd, wd, sd = ((a + 2.0 * b + 2.0 * cc + e) / 6.0 for a, b, cc, e in zip(k1, k2, k3, k4))
                x, y, th, w, dist = x + dt * xd, y + dt * yd, th + dt * thd, w + dt * wd, dist + dt * sd
            t = (k0 + np.arange(n)) * dt
            # divergence: first step of each run whose deviation is over the bound or not finite
            bad = ~(buf["dev"] <= sim.divergence_bound)
            newly = bad.any(axis=0) & ~diverged
            if newly.any():
                first = np.argmax(bad, axis=0)
                divergence_time[newly] = t[first[newly]]
                diverged |= newly
            acc.consume(StepSignals(t=t, dev=buf["dev"], e_x=buf["e_x"], e_y=buf["e_y"], e_theta=buf["e_theta"],
                                    u=buf["u"], u_command=buf["u_command"], w=buf["w"], s=buf["s"],
                                    d_true=buf["d_true"], d_hat_ndo=buf["d_hat_ndo"], d_hat_nn=buf["d_hat_nn"],
                                    zone=zone_buf, phase=phase_of_step[k0:k0 + n]))
            if keep_idx:
                _record_series(series, buf, zone_buf, ref[k0:k0 + n], t, keep_idx, k0)
            k0 += n
            if progress is not None:
                progress(k0, n_steps)

    metrics = acc.finalize()
    for arr in metrics.values():
        arr[diverged] = np.nan
    return SimulationResult(
        seeds=seeds, controller=getattr(sim.controller, "name", type(sim.controller).__name__),
        scenario=sim.scenario.name, segments=acc.segments, metrics=metrics, diverged=diverged,
        divergence_time=divergence_time, series={seeds[i]: {k: v[n_i] for k, v in series.items()}
                                                 for n_i, i in enumerate(keep_idx)},
        dt=dt, duration=n_steps * dt, wall_time=time.perf_counter() - started,
    )


def _record_series(series, buf, zone_buf, ref, t, keep_idx, k0):
    n = len(t)
    sl = slice(k0, k0 + n)
    series["t"][:, sl] = t
    for name, col in (("x_ref", 0), ("y_ref", 1), ("theta_ref", 2)):
        series[name][:, sl] = ref[:, col]
    for name in ("x", "y", "theta", "e_x", "e_y", "e_theta", "dev", "distance", "roughness", "damping_scale"):
        series["deviation" if name == "dev" else name][:, sl] = buf[name][:, keep_idx].T
    for name in ("w", "w_d", "u", "s", "d_true", "d_hat_ndo", "d_hat_nn"):
        for wheel, suffix in ((0, "right"), (1, "left")):
            series[f"{name}_{suffix}"][:, sl] = buf[name][:, keep_idx, wheel].T
    series["zone"][:, sl] = zone_buf[:, keep_idx].T
