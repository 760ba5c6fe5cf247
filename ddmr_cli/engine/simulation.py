"""The simulation engine: a batch of seeded runs advanced together (MODEL.md sections 4-5).

Every state array has a leading run axis, so a 50-seed statistic is one call. Each run draws its noise from
its own generator (:mod:`ddmr_cli.engine.noise`) and nothing couples runs, so seed k gives bit-identical numbers
alone or inside any batch. Per step: measure, run the outer loop and the wheel controller, saturate ``u`` to
``[-U_max, U_max]``, hold ``u`` and the disturbance for the step, advance plant and pose (explicit Euler by
default, RK4 as an option). A run whose deviation exceeds ``divergence_bound`` or turns NaN/inf is marked
diverged with the time it happened; the others carry on unaffected.

Two steppers advance the state chunk by chunk and fill the same buffers: :class:`NumpyStepper` (the
specification: vectorised over runs, any :class:`WheelController`) and :class:`CompiledStepper`
(:mod:`ddmr_cli.engine.kernel`, numba, for the built-in controllers; about 20-50x faster). ``engine='auto'`` takes the
compiled one when the controller has a kernel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ddmr_cli.control.base import WheelController
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.kinematics import wrap_angle
from ddmr_cli.engine.metrics import MetricAccumulator, StepSignals
from ddmr_cli.engine import kernel
from ddmr_cli.engine.noise import OUStreams
from ddmr_cli.control.outer_loop import Kanayama
from ddmr_cli.engine.results import SERIES_CHANNELS, SimulationResult
from ddmr_cli.model.robot import NominalModel, Robot
from ddmr_cli.model.scenario import Scenario
from ddmr_cli.model.terrain import Terrain
from ddmr_cli.model.trajectory import StraightLine, Trajectory

INTEGRATORS = ("euler", "rk4")
ENGINES = ("auto", "compiled", "numpy")
#: bytes of per-step signals buffered per run and step (chunked, so memory stays bounded)
_BYTES_PER_RUN_STEP = 8 * (len(kernel.REC1) + 2 * len(kernel.REC2) + 1 + 3)
CHUNK_BUDGET = 192 * 2**20
MAX_CHUNK_STEPS = 4096
MIN_CHUNK_STEPS = 64
#: column of each recorded signal in the step buffers (layout shared with the compiled kernel)
_REC1_INDEX = {name: i for i, name in enumerate(kernel.REC1)}
_REC2_INDEX = {name: i for i, name in enumerate(kernel.REC2)}


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
    engine : {'auto', 'compiled', 'numpy'}
        ``auto``: the compiled kernel when the controller has one, else numpy.
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
    engine: str = "auto"

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


class _Model:
    """Constants of the true plant (MODEL.md 1), kinematics (2), terrain and scenario (5), per batch."""

    def __init__(self, sim: Simulation, n_runs: int) -> None:
        robot, dt = sim.robot, float(sim.dt)
        self.sim, self.n_runs, self.dt, self.n_steps = sim, n_runs, dt, sim.n_steps
        self.L, self.R = robot.half_track, robot.wheel_radius
        self.inv_inertia = robot.inverse_inertia
        self.damping, self.voltage_gain, self.u_max = robot.damping, robot.voltage_gain, robot.max_voltage
        self.terrain, self.scenario, self.kin = sim.terrain, sim.scenario, sim.outer_loop
        self.roughness_table = sim.terrain.roughness
        self.roll_torque_table = robot.rolling_resistance_torque(sim.terrain.mu)
        self.unc = sim.scenario.uncertainty
        self.phase_of_step = sim.scenario.phase_index(np.arange(self.n_steps) * dt)
        self.rough_on = np.array([float(p.roughness) for p in sim.scenario.phases])
        self.unc_on = np.array([bool(p.uncertainty) for p in sim.scenario.phases])
        self.ref = np.array([sim.trajectory.reference(k * dt) for k in range(self.n_steps)], dtype=float)
        self.rk4 = sim.integrator == "rk4"
        self.w0 = np.tile(_initial_wheel_speeds(sim), (n_runs, 1))
        self.pose0 = np.tile(np.array([*map(float, sim.initial_pose), 0.0]), (n_runs, 1))  # x, y, theta, dist


class NumpyStepper:
    """The step loop vectorised over runs with numpy: the specification, for any WheelController."""

    def __init__(self, model: _Model, controller: WheelController) -> None:
        self.m, self.controller = model, controller
        self.x, self.y, self.th, self.dist = (model.pose0[:, i].copy() for i in range(4))
        self.w = model.w0.copy()
        self.w_d_prev = None
        controller.reset(self.w.copy())
        self.zone0 = np.zeros(model.n_runs, dtype=np.intp)
        self.wheel_sign = np.array([1.0, -1.0])  # w_d = (v_d + [1, -1] L omega_d) / R

    def disturbance(self, w, b_scale, d_ext, roll_torque):
        """The lumped disturbance ``d = w' - f_nom(w) - g_nom u`` (MODEL.md 5) of the true plant (6)-(8):
        ``d = -J^-1 (B_nom (b - 1) w + tau_roll sign(w)) + d_ext``; rolling resistance opposes each wheel's
        rotation and ``d_ext = -roughness n(t)`` is the roughness part."""
        torque = np.sign(w) * roll_torque[:, None]
        if b_scale is not None:
            torque += (self.m.damping * (b_scale - 1.0))[:, None] * w
        return d_ext - self.m.inv_inertia(torque)

    def acceleration(self, w, u, d):
        """The paper's (8): ``w' = J^-1 (K_u u - B_nom w) + d``."""
        return self.m.inv_inertia(self.m.voltage_gain * u - self.m.damping * w) + d

    def body_rates(self, w):
        """Forward kinematics (1): ``(v, omega)``."""
        return self.m.R * 0.5 * (w[:, 0] + w[:, 1]), (self.m.R / (2.0 * self.m.L)) * (w[:, 0] - w[:, 1])

    def advance(self, k0, noise, rec1, rec2, rec_zone) -> None:
        m, controller = self.m, self.controller
        L, R, dt, u_max = m.L, m.R, m.dt, m.u_max
        terrain, kin = m.terrain, m.kin
        single_zone = len(terrain.zones) == 1
        x, y, th, dist, w = self.x, self.y, self.th, self.dist, self.w
        roughness_noise = -noise[:, :, :2]  # (runs, steps, 2)
        damping_scale = 1.0 + np.clip(m.unc.std * noise[:, :, 2], m.unc.low, m.unc.high)
        I, J = _REC1_INDEX, _REC2_INDEX
        for j in range(noise.shape[1]):
            k = k0 + j
            x_r, y_r, th_r, v_r, omega_r = m.ref[k]
            # measure: pose error in the robot frame (MODEL.md 2)
            dx, dy = x_r - x, y_r - y
            c, sn = np.cos(th), np.sin(th)
            e_x = c * dx + sn * dy
            e_y = c * dy - sn * dx
            e_th = wrap_angle(th_r - th)
            # outer loop (MODEL.md 3) and inverse kinematics (4); w_d' by backward difference (MODEL.md 4)
            v_d, omega_d = kin.command(e_x, e_y, e_th, v_r, omega_r)
            w_d = (v_d[:, None] + (L * omega_d)[:, None] * self.wheel_sign) * (1.0 / R)
            w_d_dot = np.zeros_like(w_d) if self.w_d_prev is None else (w_d - self.w_d_prev) * (1.0 / dt)
            self.w_d_prev = w_d
            # wheel controller and saturation (MODEL.md 4)
            u_cmd = controller.command(w, w_d, w_d_dot)
            u = np.minimum(np.maximum(u_cmd, -u_max), u_max)
            # disturbances of this step, held over it (MODEL.md 5)
            p = m.phase_of_step[k]
            zone = self.zone0 if single_zone else terrain.zone_index(dist)
            rough, roll_torque = m.roughness_table[zone], m.roll_torque_table[zone]
            if m.rough_on[p] != 1.0:
                rough = rough * m.rough_on[p]
            d_ext = roughness_noise[:, j] * rough[:, None]
            b_scale = damping_scale[:, j] if m.unc_on[p] else None
            d_true = self.disturbance(w, b_scale, d_ext, roll_torque)
            w_dot = self.acceleration(w, u, d_true)
            controller.update(w, u, u_cmd)
            # record
            r1, r2 = rec1[:, j], rec2[:, j]
            r1[:, I["dev"]] = np.hypot(dx, dy)
            r1[:, I["e_x"]], r1[:, I["e_y"]], r1[:, I["e_theta"]] = e_x, e_y, e_th
            r1[:, I["x"]], r1[:, I["y"]], r1[:, I["theta"]], r1[:, I["distance"]] = x, y, th, dist
            r1[:, I["roughness"]] = rough
            r1[:, I["damping_scale"]] = 1.0 if b_scale is None else b_scale
            r2[:, J["u"]], r2[:, J["u_command"]], r2[:, J["w"]], r2[:, J["w_d"]] = u, u_cmd, w, w_d
            r2[:, J["s"]], r2[:, J["d_true"]] = controller.s, d_true
            r2[:, J["d_hat_ndo"]], r2[:, J["d_hat_nn"]] = controller.d_hat_ndo, controller.d_hat_nn
            rec_zone[:, j] = zone
            # advance plant and pose (MODEL.md 4)
            v, omega = self.body_rates(w)
            if not m.rk4:  # explicit Euler
                x = x + dt * (v * c)
                y = y + dt * (v * sn)
                th = th + dt * omega
                dist = dist + dt * np.abs(v)
                w = w + dt * w_dot
            else:
                x, y, th, dist, w = _rk4_step(
                    x, y, th, dist, w, v, omega, w_dot, dt, self.body_rates,
                    lambda w_: self.acceleration(w_, u, self.disturbance(w_, b_scale, d_ext, roll_torque)))
        self.x, self.y, self.th, self.dist, self.w = x, y, th, dist, w


class CompiledStepper:
    """The same step loop compiled with numba (:func:`ddmr_cli.engine.kernel.run_chunk`), one run at a time."""

    def __init__(self, model: _Model, spec) -> None:
        self.m = model
        self.kind, self.params, self.centers, self.state = spec
        self.pose = model.pose0.copy()
        self.w = model.w0.copy()
        self.w_d_prev = np.zeros_like(self.w)
        jinv = model.inv_inertia
        j_over_ku = NominalModel.from_robot(model.sim.robot).inertia_over_gain
        unc = model.unc
        consts = np.zeros(kernel.N_CONSTS)
        for index, value in ((kernel.C_L, model.L), (kernel.C_R, model.R), (kernel.C_JINV_P, jinv.p),
                             (kernel.C_JINV_Q, jinv.q), (kernel.C_DAMPING, model.damping),
                             (kernel.C_KU, model.voltage_gain), (kernel.C_UMAX, model.u_max),
                             (kernel.C_KX, model.kin.k_x), (kernel.C_KY, model.kin.k_y),
                             (kernel.C_KTH, model.kin.k_theta), (kernel.C_DT, model.dt),
                             (kernel.C_JKU_P, j_over_ku.p), (kernel.C_JKU_Q, j_over_ku.q),
                             (kernel.C_UNC_STD, unc.std), (kernel.C_UNC_LOW, unc.low), (kernel.C_UNC_HIGH, unc.high)):
            consts[index] = value
        self.consts = consts
        self.zone_edges = np.ascontiguousarray(model.terrain.inner_edges)
        self.phase = np.ascontiguousarray(model.phase_of_step.astype(np.int64))

    def advance(self, k0, noise, rec1, rec2, rec_zone) -> None:
        m, n = self.m, noise.shape[1]
        kernel.run_chunk(self.kind, self.params, self.state, self.centers, self.pose, self.w, self.w_d_prev, k0,
                         m.ref[k0:k0 + n], noise, self.phase[k0:k0 + n], m.rough_on, m.unc_on, self.zone_edges,
                         m.roughness_table, m.roll_torque_table, self.consts, m.rk4, rec1, rec2, rec_zone)


def _kernel_applies(controller: WheelController) -> bool:
    """True when the controller's compiled form describes it: the class that defines ``kernel_spec`` also
    defines (or inherits) every step method, so a subclass overriding ``command`` runs on numpy."""
    mro = type(controller).__mro__
    owner = next((cls for cls in mro if "kernel_spec" in vars(cls)), None)
    if owner is None:
        return False
    for name in ("bind", "reset", "command", "update"):
        definer = next(cls for cls in mro if name in vars(cls))
        if not issubclass(owner, definer):
            return False
    return True


def _stepper(sim: Simulation, model: _Model):
    """The stepper for ``sim.engine`` and its name."""
    if sim.engine not in ENGINES:
        raise ConfigError("simulation.engine", sim.engine, f"must be one of {', '.join(ENGINES)}")
    controller = sim.controller.bind(NominalModel.from_robot(sim.robot), model.dt)
    use_kernel = kernel.AVAILABLE and sim.engine != "numpy" and _kernel_applies(controller)
    spec = controller.kernel_spec(model.w0.copy()) if use_kernel else None
    if spec is None and sim.engine == "compiled":
        why = "numba is not installed" if not kernel.AVAILABLE else f"{type(controller).__name__} has no kernel"
        raise ConfigError("simulation.engine", sim.engine, f"not available: {why}")
    if spec is not None:
        return CompiledStepper(model, spec), "compiled"
    return NumpyStepper(model, controller), "numpy"


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
    n_runs, n_steps, dt = len(seeds), sim.n_steps, float(sim.dt)
    keep_idx = [seeds.index(s) for s in dict.fromkeys(int(k) for k in keep_series) if s in seeds]
    model = _Model(sim, n_runs)
    stepper, engine = _stepper(sim, model)
    streams = OUStreams(seeds, dt, [sim.terrain.correlation_time] * 2 + [sim.scenario.uncertainty.correlation_time])
    chunk = int(max(MIN_CHUNK_STEPS, min(MAX_CHUNK_STEPS, CHUNK_BUDGET // (_BYTES_PER_RUN_STEP * n_runs))))
    acc = MetricAccumulator(n_runs, dt, sim.terrain.names, sim.scenario.names, sim.robot.back_emf_constant,
                            sim.robot.armature_resistance)
    diverged = np.zeros(n_runs, dtype=bool)
    divergence_time = np.full(n_runs, np.nan)
    series = {name: np.empty((len(keep_idx), n_steps)) for name in SERIES_CHANNELS} if keep_idx else {}
    I, J = _REC1_INDEX, _REC2_INDEX
    with np.errstate(all="ignore"):
        k0 = 0
        while k0 < n_steps:
            n = min(chunk, n_steps - k0)
            noise = streams.next_chunk(n)  # (runs, n, 3): roughness R, roughness L, uncertainty
            rec1 = np.empty((n_runs, n, len(kernel.REC1)))
            rec2 = np.empty((n_runs, n, len(kernel.REC2), 2))
            rec_zone = np.empty((n_runs, n), dtype=np.intp)
            stepper.advance(k0, noise, rec1, rec2, rec_zone)
            t = (k0 + np.arange(n)) * dt
            dev = rec1[:, :, I["dev"]]
            # divergence: first step of each run whose deviation is over the bound or not finite
            bad = ~(dev <= sim.divergence_bound)
            newly = bad.any(axis=1) & ~diverged
            if newly.any():
                first = np.argmax(bad, axis=1)
                divergence_time[newly] = t[first[newly]]
                diverged |= newly
            acc.consume(StepSignals(t=t, dev=dev, e_x=rec1[:, :, I["e_x"]], e_y=rec1[:, :, I["e_y"]],
                                    e_theta=rec1[:, :, I["e_theta"]], u=rec2[:, :, J["u"]],
                                    u_command=rec2[:, :, J["u_command"]], w=rec2[:, :, J["w"]],
                                    s=rec2[:, :, J["s"]], d_true=rec2[:, :, J["d_true"]],
                                    d_hat_ndo=rec2[:, :, J["d_hat_ndo"]], d_hat_nn=rec2[:, :, J["d_hat_nn"]],
                                    zone=rec_zone, phase=model.phase_of_step[k0:k0 + n]))
            if keep_idx:
                _record_series(series, rec1, rec2, rec_zone, model.ref[k0:k0 + n], t, keep_idx, k0)
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
        dt=dt, duration=n_steps * dt, wall_time=time.perf_counter() - started, engine=engine,
    )


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


def _record_series(series, rec1, rec2, rec_zone, ref, t, keep_idx, k0):
    n = len(t)
    sl = slice(k0, k0 + n)
    series["t"][:, sl] = t
    for name, col in (("x_ref", 0), ("y_ref", 1), ("theta_ref", 2)):
        series[name][:, sl] = ref[:, col]
    for i, name in enumerate(kernel.REC1):
        series["deviation" if name == "dev" else name][:, sl] = rec1[keep_idx, :, i]
    for i, name in enumerate(kernel.REC2):
        if name == "u_command":
            continue
        for wheel, suffix in ((0, "right"), (1, "left")):
            series[f"{name}_{suffix}"][:, sl] = rec2[keep_idx, :, i, wheel]
    series["zone"][:, sl] = rec_zone[keep_idx]
