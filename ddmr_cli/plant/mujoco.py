"""The rigid-body plant: the paper's robot as a MuJoCo model on a heightfield (issue 30; docs/model.md §13, "Physics
plant (MuJoCo)").

:class:`MujocoPlant` is an external plant the engine steps from Python: a batch of ``n`` runs, each its own MuJoCo
model (its own seeded ground) and data. Each plant step holds the applied motor voltages, runs ``dt / timestep``
MuJoCo steps (the DC-motor law is the actuators' affine form, so back-EMF and damping act at every MuJoCo step),
then reads the true state and the lumped disturbance of the paper's (8). The runs advance in threads, one share
each: the calling thread steps the last share and ``threads - 1`` workers the others (``mujoco.mj_step`` releases
the GIL); a run touches only its own model and data, so its numbers do not depend on the thread count.

Needs the optional extra ``physics`` (``pip install -e ".[physics]"``).
"""

from __future__ import annotations

import copy
import functools
import importlib.util
import math
import time
from concurrent.futures import ThreadPoolExecutor, wait
from typing import Any, Callable, Mapping

import numpy as np

from ddmr_cli.compiled import plain, thread_count
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.dynamics import nominal_acceleration
from ddmr_cli.model.robot import NominalModel, Robot
from ddmr_cli.model.scenario import Scenario
from ddmr_cli.model.terrain import Terrain
from ddmr_cli.plant.mujoco_model import (PhysicsConfig, check_reference, check_robot, elevation_range, field_layout,
                                         heightfield, mjcf, normalised, rough_phases, substeps)

__all__ = ["MujocoPlant", "check", "factory", "import_mujoco", "validate", "EXTRA_HINT", "MIN_RUNS_PER_THREAD"]

#: the fewest runs a thread steps when the thread count is left to the plant (``plant.threads`` and the engine's
#: ``run.threads`` 0): the runs are handed to the threads at every plant step, and with fewer runs a thread the
#: hand-off costs more than the threads save. Two threads against one on 2 cores, the caller stepping a share
#: (:meth:`MujocoPlant.step`), 3 alternating pairs each: 12 runs 0.92-1.04x, 16 runs 0.98-1.09x, 24 runs 1.05-1.40x
#: (9 pairs); before the caller stepped a share: 6 runs 0.84x, 24 runs 0.80-1.07x, 50 runs 1.27-1.42x, 100 runs 1.47x
MIN_RUNS_PER_THREAD = 12

#: the one line a missing extra prints
EXTRA_HINT = 'needs MuJoCo, the optional extra: pip install -e ".[physics]"'


def import_mujoco():
    """The ``mujoco`` module, or a :class:`ConfigError` naming the extra that installs it."""
    try:
        import mujoco
    except ImportError:
        raise ConfigError("plant", "mujoco", EXTRA_HINT) from None
    return mujoco


def validate(robot: Robot, terrain: Terrain, config: PhysicsConfig | Mapping, dt: float,
             reference_xy: np.ndarray | None = None, scenario: Scenario | None = None) -> PhysicsConfig:
    """Every check of the plant without building it (config validation, before a run): the physics extra is
    installed, the plant config's own values (a timestep MuJoCo cannot hold stable among them), the robot fits the
    grid (a heightfield too coarse for the wheel radius), ``dt`` a whole number of MuJoCo steps, the zones inside
    the field, the reference path ``(K, 2)`` [m], when given, on it, and the scenario's roughness phases on the
    distance clock (:func:`~ddmr_cli.plant.mujoco_model.rough_phases`). Raises :class:`ConfigError` naming the
    key; returns the parsed config."""
    if importlib.util.find_spec("mujoco") is None:
        raise ConfigError("plant", "mujoco", EXTRA_HINT)
    if not isinstance(config, PhysicsConfig):
        config = PhysicsConfig.from_mapping(config)
    check_robot(robot, config)
    substeps(config, float(dt))
    field_layout(terrain, config.heightfield)
    if reference_xy is not None:
        check_reference(robot, config.heightfield, np.asarray(reference_xy, dtype=float))
    rough_phases(scenario)
    return config


def check(config: Mapping, sim) -> None:
    """The checks of ``plant=mujoco`` for a simulation, before it runs (config validation): :func:`validate` on its
    robot, terrain, step and scenario, with the reference path every 10 ms over the run (the field's check needs the
    path, not every step)."""
    from ddmr_cli.model.trajectory import reference_table

    stride = max(1, int(round(0.01 / float(sim.dt))))
    table = reference_table(sim.trajectory, sim.n_steps // stride + 1, float(sim.dt) * stride)
    validate(sim.robot, sim.terrain, config, float(sim.dt), table[:, :2], sim.scenario)


def factory(config: Mapping) -> Callable[..., "MujocoPlant"]:
    """The plant of a simulation for ``plant=mujoco`` (conf/plant/mujoco.yaml's values): a picklable callable
    ``(sim, threads)`` that builds a :class:`MujocoPlant` from the simulation's robot, terrain, step and scenario
    (:attr:`ddmr_cli.engine.simulation.Simulation.plant`); ``threads`` is the engine's (``run.threads``: 1 per job
    in a sweep), used where ``plant.threads`` is 0. Parses the config; MuJoCo is imported when the plant is built."""
    return functools.partial(_for_simulation, PhysicsConfig.from_mapping(config))


def _for_simulation(config: PhysicsConfig, sim, threads: int = 0) -> "MujocoPlant":
    return MujocoPlant(sim.robot, sim.terrain, config, float(sim.dt), sim.scenario, threads=threads)


class MujocoPlant:
    """A batch of runs of the robot on its own seeded ground, stepped by the engine (the external plant contract).

    Parameters
    ----------
    robot : Robot
        The robot (conf/robot): mass, inertias, wheel radius, track, motor constants.
    terrain : Terrain
        The zones (conf/terrain): their starts are distances along x from ``plant.heightfield.origin``; roughness
        sets each zone's height SD, ``mu`` its rolling friction.
    config : PhysicsConfig or mapping
        The plant's own parameters (conf/plant/mujoco.yaml).
    dt : float
        The plant step [s] (``simulation.dt``): a whole multiple of ``plant.timestep``.
    scenario : Scenario, optional
        Its phases that turn the roughness off (scenario 2's [5, 10) m) are flat ground (the zone's rolling
        friction kept); None: the zones' roughness everywhere.
    threads : int
        Threads stepping the runs, the calling one included, when ``config.threads`` is 0 (0 here too: one per
        :data:`MIN_RUNS_PER_THREAD` runs of the batch, at most one per core of this process).

    Attributes
    ----------
    dt : float
        The plant step [s].
    xml : str
        The generated MJCF (the heightfields' data are set per run at :meth:`reset`).

    Notes
    -----
    Call :meth:`reset` before the first :meth:`step`; after each :meth:`step`, :meth:`state`,
    :meth:`true_disturbance` and :meth:`diverged` describe that step. A diverged run is no longer stepped: its
    state stays where it was when it diverged and its disturbance is NaN.
    """

    def __init__(self, robot: Robot, terrain: Terrain, config: PhysicsConfig | Mapping, dt: float,
                 scenario: Scenario | None = None, threads: int = 0) -> None:
        self._mj = mj = import_mujoco()
        config = validate(robot, terrain, config, dt, scenario=scenario)
        self._rough = rough_phases(scenario)
        self.robot, self.terrain, self.config = robot, terrain, config
        self.dt = float(dt)
        self._substeps = substeps(config, self.dt)
        self._layout = field_layout(terrain, config.heightfield)
        self._span = elevation_range(robot, terrain, config.heightfield)
        self.xml = mjcf(robot, terrain, config, self._layout)
        self._model = mj.MjModel.from_xml_string(self.xml)
        m = self._model
        self._hfields = [(int(m.hfield_adr[i]), int(m.hfield_ncol[i])) for i in range(m.nhfield)]
        joints = [mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, f"wheel_{s}") for s in ("R", "L")]
        self._wheel_dof = np.array([m.jnt_dofadr[j] for j in joints])
        self._caster_qpos = np.array([m.jnt_qposadr[mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, f"caster_{s}")]
                                      for s in ("front", "rear")])
        self._spec = int(mj.mjtState.mjSTATE_QPOS | mj.mjtState.mjSTATE_QVEL)
        self._nq = m.nq
        self._nominal = NominalModel.from_robot(robot)
        self._chosen = config.threads or threads  # 0: chosen from the batch's size at reset
        self._threads = self._chosen or thread_count(0)
        self._settle_steps = int(round(config.settle_time / config.timestep))
        self._airborne_steps = max(1, int(math.ceil(config.divergence.airborne_time / self.dt - 1e-9)))
        self._bad_qacc = int(mj.mjtWarning.mjWARN_BADQACC)
        self._n = 0

    # -- the batch -------------------------------------------------------------------------------------------

    def heights(self, seed: int) -> np.ndarray:
        """The ground of ``seed`` [m], shape ``(nrow, ncol)``, rows along y and columns along x
        (:func:`ddmr_cli.plant.mujoco_model.heightfield`)."""
        return heightfield(seed, self.robot, self.terrain, self.config.heightfield, self._layout, self._rough)

    def field_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """The heightfield's sample coordinates ``(x, y)`` [m]."""
        return self._layout.x, self._layout.y

    def _model_for(self, seed: int):
        """The model with the ground of ``seed``, and that ground's heights as MuJoCo holds them [m]."""
        model = copy.deepcopy(self._model)
        data = normalised(self.heights(seed), self._span).astype(np.float32)
        for i, (adr, ncol) in enumerate(self._hfields):
            c0 = self._layout.columns[i]
            model.hfield_data[adr:adr + data.shape[0] * ncol] = data[:, c0:c0 + ncol].ravel()
        return model, (data.astype(float) - 0.5) * self._span

    def reset(self, seeds: np.ndarray, pose0: np.ndarray, w0: np.ndarray) -> None:
        """Start a batch: each run's ground from its seed, the robot settled onto it at ``pose0`` and rolling
        without slip at wheel speeds ``w0``.

        Parameters
        ----------
        seeds : int array (n,)
        pose0 : array (n, 3)
            x [m], y [m], theta [rad] of the axle midpoint.
        w0 : array (n, 2)
            Wheel speeds (right, left) [rad/s].
        """
        mj = self._mj
        seeds = np.asarray(seeds).reshape(-1)
        n = len(seeds)
        pose0 = np.broadcast_to(np.asarray(pose0, dtype=float), (n, 3))
        w0 = np.broadcast_to(np.asarray(w0, dtype=float), (n, 2))
        self._n = n
        if not self._chosen:
            self._threads = max(1, min(thread_count(0), n // MIN_RUNS_PER_THREAD))
            self.close()  # a pool sized for another batch
        self._models, grounds = map(list, zip(*[self._model_for(int(s)) for s in seeds]))
        self._datas = [mj.MjData(m) for m in self._models]
        R, L = self.robot.wheel_radius, self.robot.half_track
        for m, d, ground, (x, y, th), (wr, wl) in zip(self._models, self._datas, grounds, pose0, w0):
            d.ctrl[:] = (0.0, 0.0, 1.0, 1.0)
            # dropped from 1 mm above the highest ground under its footprint: no wheel or caster starts inside it
            d.qpos[0:3] = (x, y, R + self._highest(ground, x, y) + 1e-3)
            d.qpos[3:7] = (math.cos(th / 2), 0.0, 0.0, math.sin(th / 2))
            mj.mj_forward(m, d)
            held = np.r_[0, 1, 5, self._wheel_dof]  # x, y, yaw rate, wheels held still: z, roll, pitch settle
            for settled in range(2):
                for _ in range(self._settle_steps):
                    mj.mj_step(m, d)
                    d.qvel[held] = 0.0
                # the caster springs carry no load at rest: their reference is where the first settling left them
                m.qpos_spring[self._caster_qpos] = d.qpos[self._caster_qpos]
            v, om = R * (wr + wl) / 2, R * (wr - wl) / (2 * L)
            yaw = _yaw(d.qpos[3:7])
            d.qvel[:] = 0.0
            d.qvel[0:2] = v * math.cos(yaw), v * math.sin(yaw)
            d.qvel[5] = om
            d.qvel[self._wheel_dof] = wr, wl
            d.time = 0.0
            mj.mj_forward(m, d)
        self._state = np.array([np.r_[d.qpos, d.qvel] for d in self._datas])
        self._qpos, self._qvel = self._state[:, :self._nq], self._state[:, self._nq:]
        self._touch = np.ones((n, 2))
        self._theta = np.array([_yaw(q[3:7]) for q in self._qpos])
        self._distance = np.zeros(n)
        self._d = np.zeros((n, 2))
        self._diverged = np.zeros(n, dtype=bool)
        self._airborne = np.zeros(n, dtype=np.int64)
        self._seconds = {"mujoco": 0.0, "step": 0.0}
        self._check_divergence()

    def _highest(self, ground: np.ndarray, x: float, y: float) -> float:
        """The highest ground [m] of ``ground`` (rows along y, columns along x) within the robot's reach of
        ``(x, y)``: a square of half side the farthest of a wheel's rim (``L + R``), a caster's and the chassis's
        corner from the axle midpoint, whatever the heading."""
        lay, cfg = self._layout, self.config
        reach = max(self.robot.half_track + self.robot.wheel_radius, cfg.caster.offset + cfg.caster.radius,
                    math.hypot(cfg.chassis.length / 2, cfg.chassis.width / 2))
        c0, c1 = (int(np.clip(round((v - lay.x_min) / lay.dx), 0, lay.ncol - 1)) for v in (x - reach, x + reach))
        r0, r1 = (int(np.clip(round((v + lay.half_width) / lay.dy), 0, lay.nrow - 1)) for v in (y - reach, y + reach))
        return float(ground[r0:r1 + 1, c0:c1 + 1].max())

    # -- a step --------------------------------------------------------------------------------------------

    def _advance(self, runs: np.ndarray, ctrl: np.ndarray) -> None:
        """Step ``runs`` (one worker's share): hold ``ctrl``, ``dt / timestep`` MuJoCo steps, read the state."""
        mj, nsub, spec, state, touch, bad = self._mj, self._substeps, self._spec, self._state, self._touch, self._bad_qacc
        for i in runs:
            m, d = self._models[i], self._datas[i]
            d.ctrl[:] = ctrl[i]
            before = d.warning[bad].number
            mj.mj_step(m, d, nsub)
            mj.mj_getState(m, d, state[i], spec)
            touch[i] = d.sensordata
            if d.warning[bad].number != before:  # MuJoCo found the simulation unstable and reset it
                state[i] = np.nan

    def step(self, u: np.ndarray, damping_scale: np.ndarray) -> None:
        """Advance every run by one plant step ``dt``.

        Parameters
        ----------
        u : array (n, 2)
            The applied motor voltages (right, left) [V], held over the step (after the driver's limit).
        damping_scale : array (n,)
            ``b = B_true / B_nom`` (scenario 2's uncertainty; 1.0 when none), held over the step.
        """
        u = np.broadcast_to(np.asarray(u, dtype=float), (self._n, 2))
        b = np.broadcast_to(np.asarray(damping_scale, dtype=float), (self._n,))
        ctrl = np.column_stack([u, b, b])  # the motors' voltages and the dampers' scale (motor_gains)
        self._diverged |= ~np.isfinite(ctrl).all(axis=1)  # a non-finite voltage or damping: diverged, not stepped
        w_before = self._qvel[:, self._wheel_dof].copy()
        xy_before = self._qpos[:, 0:2].copy()
        started = time.perf_counter()
        live = np.flatnonzero(~self._diverged)
        shares = [s for s in np.array_split(live, min(self._threads, max(len(live), 1))) if len(s)]
        if len(shares) <= 1:
            for s in shares:
                self._advance(s, ctrl)
        else:  # the calling thread steps the last share itself
            futures = [self._pool().submit(self._advance, s, ctrl) for s in shares[:-1]]
            try:
                self._advance(shares[-1], ctrl)
            finally:  # no worker is left stepping when this returns or raises
                wait(futures)
            for f in futures:
                f.result()
        stepped = time.perf_counter()
        w = self._qvel[:, self._wheel_dof]
        a_R, a_L = plain(nominal_acceleration)(self._nominal, w_before[:, 0], w_before[:, 1], u[:, 0], u[:, 1])
        d = (w - w_before) / self.dt - np.stack([a_R, a_L], axis=1)
        d[self._diverged] = np.nan
        self._d = d
        live_mask = ~self._diverged
        self._distance[live_mask] += np.hypot(*(self._qpos[live_mask, 0:2] - xy_before[live_mask]).T)
        yaw = np.array([_yaw(q[3:7]) for q in self._qpos])
        step = np.where(live_mask, np.angle(np.exp(1j * (yaw - self._theta))), 0.0)
        self._theta = self._theta + np.nan_to_num(step, nan=0.0)
        self._airborne = np.where((self._touch > 0).any(axis=1), 0, self._airborne + 1)
        self._check_divergence()
        self._seconds["mujoco"] += stepped - started
        self._seconds["step"] += time.perf_counter() - started

    def _pool(self) -> ThreadPoolExecutor:
        """The ``threads - 1`` workers that step the shares the calling thread does not: its own share saves a
        hand-off a step (24 runs on 2 cores, 4 alternating pairs of processes: 1.08-1.18x the steps a second)."""
        if getattr(self, "_executor", None) is None:
            self._executor = ThreadPoolExecutor(self._threads - 1, thread_name_prefix="mujoco")
        return self._executor

    def close(self) -> None:
        """Stop the worker threads (also done when the plant is garbage-collected)."""
        executor, self._executor = getattr(self, "_executor", None), None
        if executor is not None:
            executor.shutdown()

    def __del__(self) -> None:
        self.close()

    def _check_divergence(self) -> None:
        q = self._qpos
        finite = np.isfinite(q).all(axis=1) & np.isfinite(self._qvel).all(axis=1)
        # tilt: the angle between the chassis's z axis and the world's, cos = 1 - 2 (q_x^2 + q_y^2)
        cos_tilt = 1.0 - 2.0 * (q[:, 4] ** 2 + q[:, 5] ** 2)
        tipped = ~(cos_tilt >= math.cos(self.config.divergence.tip_angle))
        airborne = self._airborne >= self._airborne_steps
        self._diverged |= ~finite | tipped | airborne

    # -- what the engine reads --------------------------------------------------------------------------------

    def state(self) -> dict[str, np.ndarray]:
        """The true state after the last step: ``x``, ``y`` [m] and ``theta`` [rad, continuous, not wrapped] of the
        axle midpoint, ``distance`` [m] travelled in the plane since :meth:`reset`, each ``(n,)``, and ``w``
        ``(n, 2)``, the wheel speeds (right, left) [rad/s] relative to the chassis."""
        return {"x": self._qpos[:, 0].copy(), "y": self._qpos[:, 1].copy(), "theta": self._theta.copy(),
                "distance": self._distance.copy(), "w": self._qvel[:, self._wheel_dof].copy()}

    def true_disturbance(self) -> np.ndarray:
        """The lumped disturbance d of the paper's (8) over the last step [rad/s^2], ``(n, 2)``, docs/model.md
        [13g]: the measured wheel acceleration ``(w_{k+1} - w_k) / dt`` less what the nominal model explains,
        ``f(w_k) + g u_k`` (:func:`ddmr_cli.model.dynamics.nominal_acceleration`); NaN for a diverged run."""
        return self._d.copy()

    def energy(self) -> np.ndarray:
        """``(n, 2)`` each run's gravitational potential and kinetic energy [J] (MuJoCo's ``mj_energyPos`` and
        ``mj_energyVel``; contact deformation not included): a diagnostic for the energy checks."""
        mj = self._mj
        out = np.empty((self._n, 2))
        for i, (m, d) in enumerate(zip(self._models, self._datas)):
            # the position-dependent quantities at the current state (what the next step recomputes anyway)
            mj.mj_kinematics(m, d)
            mj.mj_comPos(m, d)
            mj.mj_crb(m, d)
            mj.mj_energyPos(m, d)
            mj.mj_energyVel(m, d)
            out[i] = d.energy
        return out

    @property
    def threads(self) -> int:
        """The threads stepping the runs, the calling one included (``plant.threads``; 0 resolved at
        :meth:`reset`: one per :data:`MIN_RUNS_PER_THREAD` runs, at most one per core of this process)."""
        return self._threads

    def timing(self) -> dict[str, float]:
        """Wall seconds since :meth:`reset`: ``mujoco``, in the MuJoCo steps of the runs (the worker threads'
        section, reading the state included), and ``step``, in the whole of :meth:`step` (the true d, the
        divergence checks and the rest of the plant's own bookkeeping added): ``ddmr bench``'s share."""
        return dict(self._seconds)

    def diverged(self) -> np.ndarray:
        """``(n,)`` bool: the run has tipped over (tilt > ``plant.divergence.tip_angle``), left the ground (neither
        wheel touching for ``plant.divergence.airborne_time``) or turned non-finite (or MuJoCo found it unstable)."""
        return self._diverged.copy()


def _yaw(quat: np.ndarray) -> float:
    """The heading [rad] of a unit quaternion (w, x, y, z): the angle of its x axis in the ground plane."""
    w, x, y, z = quat
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
