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
from .metrics import BLOCK_STEPS, MetricAccumulator, StepSignals
from .noise import OUStreams
from .outer_loop import Kanayama
from .results import SERIES_CHANNELS, SimulationResult
from .robot import NominalModel, Robot, WheelMatrix
from .scenario import Scenario
from .terrain import Terrain
from .trajectory import StraightLine, Trajectory

INTEGRATORS = ("euler", "rk4")
#: bytes of per-step signals buffered per run and step (chunked, so memory stays bounded)
_BYTES_PER_RUN_STEP = 8 * 40
CHUNK_BUDGET = 192 * 2**20
MAX_CHUNK_STEPS = 4096


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

    # constants of the true plant (MODEL.md 1) and the kinematics (MODEL.md 2)
    L, R = robot.half_track, robot.wheel_radius
    inv_inertia = WheelMatrix.of(robot.inverse_inertia)
    damping, voltage_gain = robot.damping, robot.voltage_gain
    u_max = robot.max_voltage
    terrain, scenario, kin = sim.terrain, sim.scenario, sim.outer_loop
    roughness_table = terrain.roughness
    roll_torque_table = robot.rolling_resistance_torque(terrain.mu)
    single_zone = len(terrain.zones) == 1
    unc = scenario.uncertainty
    phase_of_step = scenario.phase_index(np.arange(n_steps) * dt)
    rough_on = [float(p.roughness) for p in scenario.phases]
    unc_on = [bool(p.uncertainty) for p in scenario.phases]
    ref = [tuple(map(float, sim.trajectory.reference(k * dt))) for k in range(n_steps)]
    controller = sim.controller.bind(NominalModel.from_robot(robot), dt)
    rk4 = sim.integrator == "rk4"
    wheel_sign = np.array([1.0, -1.0])  # w_d = (v_d + [1, -1] L omega_d) / R

    # state
    x = np.full(n_runs, float(sim.initial_pose[0]))
    y = np.full(n_runs, float(sim.initial_pose[1]))
    th = np.full(n_runs, float(sim.initial_pose[2]))
    w = np.tile(_initial_wheel_speeds(sim), (n_runs, 1))
    dist = np.zeros(n_runs)
    w_d_prev = None
    controller.reset(w.copy())

    streams = OUStreams(seeds, dt, [terrain.correlation_time] * 2 + [unc.correlation_time])
    chunk = int(min(MAX_CHUNK_STEPS, CHUNK_BUDGET // (_BYTES_PER_RUN_STEP * n_runs)))
    chunk = max(BLOCK_STEPS, chunk // BLOCK_STEPS * BLOCK_STEPS)  # whole blocks: see metrics.BLOCK_STEPS
    acc = MetricAccumulator(n_runs, dt, terrain.names, scenario.names, robot.back_emf_constant,
                            robot.armature_resistance)
    diverged = np.zeros(n_runs, dtype=bool)
    divergence_time = np.full(n_runs, np.nan)
    series = {name: np.empty((len(keep_idx), n_steps)) for name in SERIES_CHANNELS} if keep_idx else {}
    zone0 = np.zeros(n_runs, dtype=np.intp)
    rough0, roll0 = roughness_table[zone0], roll_torque_table[zone0]

    def disturbance(w_, b_scale_, d_ext_, roll_torque_):
        """The lumped disturbance ``d = w' - f_nom(w) - g_nom u`` (MODEL.md 5) of the true plant (6)-(8):
        ``d = -J^-1 (B_nom (b - 1) w + tau_roll) + d_ext``; rolling resistance opposes each wheel's rotation and
        ``d_ext = -roughness n(t)`` is the roughness part."""
        torque = np.sign(w_) * roll_torque_[:, None]
        if b_scale_ is not None:
            torque += (damping * (b_scale_ - 1.0))[:, None] * w_
        return d_ext_ - inv_inertia(torque)

    def wheel_acceleration(w_, u_, d_):
        """The paper's (8): ``w' = J^-1 (K_u u - B_nom w) + d``."""
        return inv_inertia(voltage_gain * u_ - damping * w_) + d_

    def body_rates(w_):
        """Forward kinematics (1): ``(v, omega)``."""
        return R * 0.5 * (w_[:, 0] + w_[:, 1]), (R / (2.0 * L)) * (w_[:, 0] - w_[:, 1])

    with np.errstate(all="ignore"):
        k0 = 0
        while k0 < n_steps:
            n = min(chunk, n_steps - k0)
            noise = streams.next_chunk(n)  # (n, runs, 3): roughness R, roughness L, uncertainty
            roughness_noise = -noise[:, :, :2]
            damping_scale = 1.0 + np.clip(unc.std * noise[:, :, 2], unc.low, unc.high)
            rec = {key: np.empty((n, n_runs)) for key in _RECORD_1}
            rec.update({key: np.empty((n, n_runs, 2)) for key in _RECORD_2})
            if keep_idx:
                rec.update({key: np.empty((n, n_runs)) for key in _SERIES_ONLY_1})
                rec["w_d"] = np.empty((n, n_runs, 2))
            zone_buf = np.empty((n, n_runs), dtype=np.intp)
            for j in range(n):
                k = k0 + j
                x_r, y_r, th_r, v_r, omega_r = ref[k]
                # measure: pose error in the robot frame (MODEL.md 2)
                dx, dy = x_r - x, y_r - y
                c, sn = np.cos(th), np.sin(th)
                e_x = c * dx + sn * dy
                e_y = c * dy - sn * dx
                e_th = wrap_angle(th_r - th)
                # outer loop (MODEL.md 3) and inverse kinematics (4); w_d' by backward difference (MODEL.md 4)
                v_d, omega_d = kin.command(e_x, e_y, e_th, v_r, omega_r)
                w_d = (v_d[:, None] + (L * omega_d)[:, None] * wheel_sign) * (1.0 / R)
                w_d_dot = np.zeros_like(w_d) if w_d_prev is None else (w_d - w_d_prev) * (1.0 / dt)
                w_d_prev = w_d
                # wheel controller and saturation (MODEL.md 4)
                u_cmd = controller.command(w, w_d, w_d_dot)
                u = np.minimum(np.maximum(u_cmd, -u_max), u_max)
                # disturbances of this step, held over it (MODEL.md 5)
                p = phase_of_step[k]
                if single_zone:
                    zone, rough, roll_torque = zone0, rough0, roll0
                else:
                    zone = terrain.zone_index(dist)
                    rough, roll_torque = roughness_table[zone], roll_torque_table[zone]
                if rough_on[p] != 1.0:
                    rough = rough * rough_on[p]
                d_ext = roughness_noise[j] * rough[:, None]
                b_scale = damping_scale[j] if unc_on[p] else None
                d_true = disturbance(w, b_scale, d_ext, roll_torque)
                w_dot = wheel_acceleration(w, u, d_true)
                controller.update(w, u, u_cmd)
                # record
                rec["dev"][j] = np.hypot(dx, dy)
                rec["e_x"][j], rec["e_y"][j], rec["e_theta"][j] = e_x, e_y, e_th
                rec["u"][j], rec["u_command"][j], rec["w"][j] = u, u_cmd, w
                rec["s"][j], rec["d_true"][j] = controller.s, d_true
                rec["d_hat_ndo"][j], rec["d_hat_nn"][j] = controller.d_hat_ndo, controller.d_hat_nn
                zone_buf[j] = zone
                if keep_idx:
                    rec["x"][j], rec["y"][j], rec["theta"][j], rec["distance"][j] = x, y, th, dist
                    rec["roughness"][j], rec["w_d"][j] = rough, w_d
                    rec["damping_scale"][j] = 1.0 if b_scale is None else b_scale
                # advance plant and pose (MODEL.md 4)
                v, omega = body_rates(w)
                if not rk4:  # explicit Euler
                    x = x + dt * (v * c)
                    y = y + dt * (v * sn)
                    th = th + dt * omega
                    dist = dist + dt * np.abs(v)
                    w = w + dt * w_dot
                else:
                    x, y, th, dist, w = _rk4_step(
                        x, y, th, dist, w, v, omega, w_dot, dt, body_rates,
                        lambda w_: wheel_acceleration(w_, u, disturbance(w_, b_scale, d_ext, roll_torque)))
            t = (k0 + np.arange(n)) * dt
            # divergence: first step of each run whose deviation is over the bound or not finite
            bad = ~(rec["dev"] <= sim.divergence_bound)
            newly = bad.any(axis=0) & ~diverged
            if newly.any():
                first = np.argmax(bad, axis=0)
                divergence_time[newly] = t[first[newly]]
                diverged |= newly
            acc.consume(StepSignals(t=t, dev=rec["dev"], e_x=rec["e_x"], e_y=rec["e_y"], e_theta=rec["e_theta"],
                                    u=rec["u"], u_command=rec["u_command"], w=rec["w"], s=rec["s"],
                                    d_true=rec["d_true"], d_hat_ndo=rec["d_hat_ndo"], d_hat_nn=rec["d_hat_nn"],
                                    zone=zone_buf, phase=phase_of_step[k0:k0 + n]))
            if keep_idx:
                _record_series(series, rec, zone_buf, ref[k0:k0 + n], t, keep_idx, k0)
            k0 += n
            if progress is not None:
                progress(k0, n_steps)

    metrics = acc.finalize()
    for arr in metrics.values():
        arr[diverged] = np.nan
    return SimulationResult(
        seeds=seeds, controller=getattr(sim.controller, "name", type(sim.controller).__name__),
        scenario=scenario.name, segments=acc.segments, metrics=metrics, diverged=diverged,
        divergence_time=divergence_time, series={seeds[i]: {k: v[n_i] for k, v in series.items()}
                                                 for n_i, i in enumerate(keep_idx)},
        dt=dt, duration=n_steps * dt, wall_time=time.perf_counter() - started,
    )


_RECORD_1 = ("dev", "e_x", "e_y", "e_theta")
_RECORD_2 = ("u", "u_command", "w", "s", "d_true", "d_hat_ndo", "d_hat_nn")
_SERIES_ONLY_1 = ("x", "y", "theta", "distance", "roughness", "damping_scale")


def _rk4_step(x, y, th, dist, w, v1, om1, a1, dt, body_rates, accel):
    """Classic RK4 over one step for pose, distance and wheel speeds, with ``u`` and disturbances held."""
    h = 0.5 * dt
    th2, w2 = th + h * om1, w + h * a1
    v2, om2 = body_rates(w2)
    a2 = accel(w2)
    th3, w3 = th + h * om2, w + h * a2
    v3, om3 = body_rates(w3)
    a3 = accel(w3)
    th4, w4 = th + dt * om3, w + dt * a3
    v4, om4 = body_rates(w4)
    a4 = accel(w4)
    sixth = dt / 6.0
    x = x + sixth * (v1 * np.cos(th) + 2.0 * v2 * np.cos(th2) + 2.0 * v3 * np.cos(th3) + v4 * np.cos(th4))
    y = y + sixth * (v1 * np.sin(th) + 2.0 * v2 * np.sin(th2) + 2.0 * v3 * np.sin(th3) + v4 * np.sin(th4))
    dist = dist + sixth * (np.abs(v1) + 2.0 * np.abs(v2) + 2.0 * np.abs(v3) + np.abs(v4))
    return x, y, th + sixth * (om1 + 2.0 * om2 + 2.0 * om3 + om4), dist, w + sixth * (a1 + 2.0 * a2 + 2.0 * a3 + a4)


def _record_series(series, rec, zone_buf, ref, t, keep_idx, k0):
    n = len(t)
    sl = slice(k0, k0 + n)
    ref = np.asarray(ref)
    series["t"][:, sl] = t
    for name, col in (("x_ref", 0), ("y_ref", 1), ("theta_ref", 2)):
        series[name][:, sl] = ref[:, col]
    for name in ("x", "y", "theta", "e_x", "e_y", "e_theta", "dev", "distance", "roughness", "damping_scale"):
        series["deviation" if name == "dev" else name][:, sl] = rec[name][:, keep_idx].T
    for name in ("w", "w_d", "u", "s", "d_true", "d_hat_ndo", "d_hat_nn"):
        for wheel, suffix in ((0, "right"), (1, "left")):
            series[f"{name}_{suffix}"][:, sl] = rec[name][:, keep_idx, wheel].T
    series["zone"][:, sl] = zone_buf[:, keep_idx].T
