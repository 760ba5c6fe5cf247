"""The simulation of a batch of seeded runs (docs/model.md §4-5, §7): :class:`Simulation` and :func:`simulate`.

Every run draws its noise from its own generator (:mod:`ddmr_cli.model.noise`) and nothing couples runs, so seed
k gives bit-identical numbers alone or inside any batch, in any chunking and with any thread count. The step loop
(:mod:`ddmr_cli.engine.stepper`, compiled per controller by :mod:`ddmr_cli.engine.kernels`) accumulates the
metrics as it goes and records time series only for the kept seeds, so memory does not grow with the batch
beyond a few numbers per run. A run whose deviation exceeds ``divergence_bound`` or turns NaN/inf is marked
diverged with the time it happened; the others carry on unaffected.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ddmr_cli import bit_generators
from ddmr_cli.compiled import jit_enabled, plain, thread_count
from ddmr_cli.checks import finite, first_non_finite, non_negative, one_of, per_wheel, positive
from ddmr_cli.control.base import KINDS, LANES, STABILITY_LIMIT, SURFACE, WheelController
from ddmr_cli.control.outer_loop import Kanayama
from ddmr_cli.engine.bands import BAND_CHANNELS, BandAccumulator
from ddmr_cli.engine.batch import HOLD_FIELDS, RUN_FIELDS, World
from ddmr_cli.engine.kernels import (check_single_signature, compiled_copy, compiled_external_step,
                                     compiled_run_chunk, entry_point)
from ddmr_cli.engine.metrics import ACCUMULATOR_FIELDS, MetricAccumulator, estimation_membership
from ddmr_cli.engine.pipeline import run_chunks
from ddmr_cli.model.noise import NoiseStreams, SensorNoise, ou_coefficients
from ddmr_cli.engine.results import SimulationResult
from ddmr_cli.engine.series import series_channels
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.actuator import ACTUATOR_FIELDS, Actuator, delay_lines
from ddmr_cli.model.kinematics import inverse
from ddmr_cli.model.robot import NominalModel, Robot
from ddmr_cli.model.scenario import Scenario
from ddmr_cli.model.sensor import NOISE_CHANNELS, SENSOR_FIELDS, Sensor
from ddmr_cli.model.terrain import Terrain
from ddmr_cli.model.trajectory import StraightLine, Trajectory, reference_table
from ddmr_cli.plant.base import ExternalPlant, check_state

INTEGRATORS = ("euler", "rk4")
#: bytes of a chunk's per-step buffers (band rows; the sensor's normals when it is noisy; the runs draw their
#: disturbance normals as they step, with no buffer): 8 MiB, not 16, took a 10,000-seed run's peak memory 4 MiB lower
#: at the same speed when the disturbance normals were buffered too; a table4 batch of 50 seeds runs 4096 steps a chunk
CHUNK_BUDGET = 8 * 2**20
MAX_CHUNK_STEPS = 4096
#: the most run-steps (steps x runs) of a chunk: progress is reported after every chunk, and this many take 0.3-0.5 s
#: of one core (SMC-NDO-NNO at 4-7 M/s), so a batch of any size is never silent for long; with no per-step buffer
#: (no bands, an ideal sensor) the memory budget alone would let 10,000 seeds run 4096 steps, seconds, unreported
CHUNK_RUN_STEPS = 2**21
#: the fewest steps of a chunk: low enough that the budget holds for huge batches too (a floor of 64 made 10,000
#: seeds' band buffer 41 MiB), high enough that a chunk's Python work stays small beside its steps
MIN_CHUNK_STEPS = 8
#: with several threads, a chunk's runs are cut into up to this many blocks per thread, which the threads take as
#: they come free, so a core slowed by another process no longer holds the others up at the chunk's end (docs/model.md
#: §5, Threads: waiting 15 % -> 5 % of the step loop's time on a shared 2-core machine); each block has at least
#: :data:`MIN_BLOCK_RUNS` runs
BLOCKS_PER_THREAD = 4
MIN_BLOCK_RUNS = 32
#: band buffers that take turns when several threads step a batch (:func:`ddmr_cli.engine.pipeline.run_chunks`: a
#: block steps on into the next chunk while the chunk before is reduced); the chunk budget counts every one, so the
#: memory is that of one buffer at the same budget (chunks of half the steps)
BAND_SLOTS = 2
#: the template of the loop by blocks of runs (ddmr_cli.engine.kernels copies it per controller; never imported here)
LANES_TEMPLATE = "ddmr_cli.engine.lanes"


def chunk_steps(bytes_per_run_step: int, n_runs: int) -> int:
    """Steps per chunk: as many as :data:`CHUNK_BUDGET` bytes of per-step buffers hold for ``n_runs`` runs, at most
    :data:`CHUNK_RUN_STEPS` run-steps, within [:data:`MIN_CHUNK_STEPS`, :data:`MAX_CHUNK_STEPS`]."""
    by_memory = CHUNK_BUDGET // max(1, bytes_per_run_step * n_runs)
    return int(max(MIN_CHUNK_STEPS, min(MAX_CHUNK_STEPS, by_memory, CHUNK_RUN_STEPS // n_runs)))


@dataclass
class Simulation:
    """Everything one batch of runs needs, as plain objects (no Hydra here).

    Every field is required: the values live once, in the packaged config (``conf/``), and
    :func:`ddmr_cli.paper_simulation` builds this object from it (``dataclasses.replace`` changes a part).

    Parameters
    ----------
    controller : WheelController
        The wheel-speed controller (its state is reset by every :func:`simulate` call).
    robot, terrain, scenario, trajectory, outer_loop
        Model pieces (docs/model.md §1-5).
    dt : float
        Step [s] (docs/model.md §4).
    duration : float
        Simulated time [s].
    integrator : {'euler', 'rk4'}
    initial_pose : (x, y, theta)
        [m, m, rad].
    initial_wheel_speeds : 'reference', 'rest' or (w_R, w_L)
        ``reference``: the wheel speeds of the reference's v_r, omega_r at t = 0 (a rolling start);
        ``rest``: zero.
    divergence_bound : float
        A run whose deviation exceeds this [m] (or turns NaN) is marked diverged.
    settle_time : float
        Steady-state metrics (``<metric>_ss``) count the steps from this time [s] on (docs/model.md §7).
    zone_settle_time : float
        ... and per zone (phase) also from this long [s] after the run entered it.
    sensor : Sensor
        What the controller measures (docs/model.md §10; ``ideal``: the truth).
    actuator : Actuator
        PWM, delay and driver lag between the controller and the motor (docs/model.md §10).
    control_rate : float or None
        The controller's rate [Hz], dividing the plant's ``1 / dt``; None: every plant step.
    plant : callable(Simulation, threads) -> ExternalPlant, or None
        None: the paper's wheel plant, inlined in the compiled step loop (docs/model.md §1, §5). Else a factory
        of an external plant (:class:`ddmr_cli.plant.base.ExternalPlant`, e.g. ``plant=mujoco``, docs/model.md
        §13) for this simulation (``threads``: :func:`simulate`'s), stepped from Python between the compiled
        control and accounting halves.
    """

    controller: WheelController
    robot: Robot
    terrain: Terrain
    scenario: Scenario
    trajectory: Trajectory
    outer_loop: Kanayama
    dt: float
    duration: float
    integrator: str
    initial_pose: Sequence[float]
    initial_wheel_speeds: str | Sequence[float]
    divergence_bound: float
    settle_time: float
    zone_settle_time: float
    sensor: Sensor
    actuator: Actuator
    control_rate: float | None
    plant: Callable[..., ExternalPlant] | None

    @property
    def n_steps(self) -> int:
        return int(round(self.duration / self.dt))

    @property
    def control_steps(self) -> int:
        """Plant steps per control period (1 when the controller runs at every plant step); ConfigError on
        ``control.rate`` when it is above the plant rate ``1 / dt`` or does not divide it."""
        if self.control_rate is None:
            return 1
        rate, plant_rate = positive("control.rate", self.control_rate), 1.0 / float(self.dt)
        ratio = plant_rate / rate
        m = int(round(ratio))
        if ratio < 1.0 - 1e-9:
            raise ConfigError("control.rate", self.control_rate,
                              f"must be <= the plant rate 1/simulation.dt = {plant_rate:g} Hz")
        if abs(ratio - m) > 1e-9 * ratio:
            raise ConfigError("control.rate", self.control_rate, f"must divide the plant rate 1/simulation.dt = "
                                                                 f"{plant_rate:g} Hz ({ratio:.6g} plant steps per "
                                                                 f"control period is not a whole number)")
        return m

    @property
    def control_dt(self) -> float:
        """The control period [s]: ``control_steps * dt``."""
        return self.control_steps * float(self.dt)

    def validate(self) -> None:
        """Check what the parts cannot check alone; raise ConfigError naming the key.

        The integrator, a step that resolves the fastest loop (docs/model.md §4): the plant's fastest pole (with
        scenario 2's largest damping) and the controller's own rates and sampled loops.
        """
        one_of("simulation.integrator", self.integrator, INTEGRATORS)
        dt = positive("simulation.dt", self.dt)
        duration = positive("simulation.duration", self.duration)
        if dt > duration:
            raise ConfigError("simulation.dt", self.dt, f"must be <= simulation.duration ({duration:g})")
        non_negative("metrics.settle_time", self.settle_time)  # >= duration: no steady step, NaN _ss metrics
        non_negative("metrics.zone_settle_time", self.zone_settle_time)
        if not self.divergence_bound > 0:  # inf allowed: never diverge
            raise ConfigError("simulation.divergence_bound", self.divergence_bound, "must be > 0")
        if len(self.initial_pose) != 3:
            raise ConfigError("simulation.initial_pose", list(self.initial_pose), "must be [x, y, theta]")
        for i, v in enumerate(self.initial_pose):
            finite(f"simulation.initial_pose[{i}]", v)
        _initial_wheel_speeds(self)
        self.outer_loop.validate()
        limit = STABILITY_LIMIT[self.integrator]
        b_max = 1.0 + (max(0.0, self.scenario.uncertainty.high) if any(p.uncertainty for p in self.scenario.phases)
                       else 0.0)
        pole = self.robot.step_rate(b_max)
        if dt * pole >= limit:
            raise ConfigError("simulation.dt", self.dt, f"must be < {limit / pole:.3g} s for {self.integrator} with "
                                                        f"the plant's fastest pole = {pole:.3g} 1/s")
        m = self.control_steps
        self.actuator.delay_steps(dt)
        try:  # the controller's own loops run at the control period
            self.controller.check_step(NominalModel.from_robot(self.robot), m * dt, self.integrator)
        except ConfigError as exc:
            if m == 1:
                raise
            raise ConfigError("control.rate", self.control_rate,
                              f"the control period {m * dt:g} s {exc.rule}") from None
        self._check_derived_quantities_finite(m * dt)

    def _check_derived_quantities_finite(self, control_dt: float) -> None:
        """Every model quantity the step loop starts from is finite (the class of issue 26: a value that passes
        its own range check but makes a derived quantity inf or NaN before the first step is refused, naming the
        group and the quantity, instead of a run of NaN metrics)."""
        with np.errstate(all="ignore"):  # a quantity that overflows is refused below, not warned about on the way
            nominal = NominalModel.from_robot(self.robot)
            torque = np.asarray(self.robot.rolling_resistance_torque(self.terrain.mu), dtype=float)
            derived = (("robot", "the plant", self.robot.plant()), ("robot", "the nominal model", nominal),
                       ("controller", "the law parameters", self.controller.law_parameters(nominal, control_dt)))
        for zone, mu, value in zip(self.terrain.names, self.terrain.mu, torque.ravel()):
            if not math.isfinite(value):
                raise ConfigError(f"terrain.zones.{zone}.mu", float(mu),
                                  f"the rolling-resistance torque mu m g R / 2 is {value:g} there: too extreme for the "
                                  f"model")
        for key, what, value in derived:
            bad = first_non_finite(value)
            if bad is not None:
                raise ConfigError(key, bad or what, f"{what} is not finite there before the first step: a value "
                                                    f"of {key} is too extreme for the model")


def _initial_wheel_speeds(sim: Simulation) -> np.ndarray:
    spec = sim.initial_wheel_speeds
    if isinstance(spec, str):
        if spec == "rest":
            return np.zeros(2)
        if spec == "reference":
            _, _, _, v_r, omega_r = sim.trajectory.reference(0.0)
            return np.array(plain(inverse)(v_r, omega_r, sim.robot.wheel_radius, sim.robot.half_track), dtype=float)
        raise ConfigError("simulation.initial_wheel_speeds", spec, "must be 'reference', 'rest' or [w_R, w_L]")
    return np.array(per_wheel("simulation.initial_wheel_speeds", list(spec), finite))


def diagnostic_layout(controller: WheelController) -> tuple[int, np.ndarray, np.ndarray]:
    """Where the engine finds a controller's diagnostic channels (:meth:`WheelController.diagnostics`): the row of
    its surface channel (-1: none), the rows recorded after the base series, and the estimation metrics'
    membership (:func:`~ddmr_cli.engine.metrics.estimation_membership`). ConfigError on ``controller`` for a
    channel of an unknown kind, a repeated name or more than one surface."""
    channels = tuple(controller.diagnostics())
    names = [c.name for c in channels]
    for c in channels:
        if c.kind not in KINDS:
            raise ConfigError("controller", getattr(controller, "name", type(controller).__name__),
                              f"diagnostic channel {c.name!r} has kind {c.kind!r}; must be one of {', '.join(KINDS)}")
    surfaces = [i for i, c in enumerate(channels) if c.kind == SURFACE]
    if len(set(names)) != len(names) or len(surfaces) > 1:
        raise ConfigError("controller", getattr(controller, "name", type(controller).__name__),
                          f"diagnostic channels {names} must have distinct names and at most one surface")
    recorded = np.array([i for i, c in enumerate(channels) if c.kind != SURFACE], dtype=np.int64)
    return (surfaces[0] if surfaces else -1), recorded, estimation_membership(channels)


def blocks_of(n_runs: int, n_threads: int, multiple: int = 1) -> list[tuple[int, int]]:
    """The blocks of runs the threads share: ``n_threads`` times 1 to :data:`BLOCKS_PER_THREAD` blocks, as many as
    keep :data:`MIN_BLOCK_RUNS` runs a block (one block without threads), each but the last a whole number of
    ``multiple`` runs (the loop by blocks of runs, :mod:`ddmr_cli.engine.lanes`, steps the runs past the last whole
    vector of a partial block one at a time: 1,000 runs of SMC-NDO-NNO in blocks of 125 runs, not 128, made 2 threads
    1.39x one thread, not 1.62x, 7 alternating pairs)."""
    per_thread = min(BLOCKS_PER_THREAD, max(1, n_runs // (n_threads * MIN_BLOCK_RUNS))) if n_threads > 1 else 1
    units = -(-n_runs // multiple)
    blocks = _split(units, min(units, n_threads * per_thread))
    return [(first * multiple, min(end * multiple, n_runs)) for first, end in blocks]


def _split(n: int, parts: int) -> list[tuple[int, int]]:
    """``range(n)`` in ``parts`` contiguous ``(first, end)`` blocks of sizes differing by at most one."""
    return [(n * i // parts, n * (i + 1) // parts) for i in range(parts)]


def _world(sim: Simulation, n_steps: int, hp: np.ndarray, hp_zi: np.ndarray, phase_base: int,
           bands: BandAccumulator | None) -> World:
    dt = float(sim.dt)
    uncertainty = sim.scenario.uncertainty
    coefficients = [ou_coefficients(dt, sim.terrain.correlation_time)] * 2 + [
        (1.0, 0.0) if uncertainty.constant else ou_coefficients(dt, uncertainty.correlation_time)]  # §5
    phases = sim.scenario.phases
    surface, recorded, estimation = diagnostic_layout(sim.controller)
    return World(
        reference=reference_table(sim.trajectory, n_steps, dt),
        phase=np.ascontiguousarray(sim.scenario.phase_index(np.arange(n_steps) * dt), dtype=np.int64),
        phase_by_distance=sim.scenario.phase_clock == "distance",
        phase_edges=np.ascontiguousarray(sim.scenario.inner_edges, dtype=float),
        roughness_on=np.array([float(p.roughness) for p in phases]),
        uncertainty_on=np.array([bool(p.uncertainty) for p in phases]),
        zone_edges=np.ascontiguousarray(sim.terrain.inner_edges, dtype=float),
        roughness=sim.terrain.roughness, roll_torque=np.asarray(sim.robot.rolling_resistance_torque(sim.terrain.mu), float),
        ou_a=np.array([c[0] for c in coefficients]), ou_b=np.array([c[1] for c in coefficients]),
        uncertainty=sim.scenario.uncertainty, gains=Kanayama(*map(float, sim.outer_loop)), dt=dt,
        rk4=sim.integrator == "rk4", divergence_bound=float(sim.divergence_bound), hp=hp, hp_zi=hp_zi,
        phase_base=phase_base, settle_steps=int(round(sim.settle_time / dt)),
        zone_settle_steps=int(round(sim.zone_settle_time / dt)), bands=bands is not None,
        band_stride=bands.stride if bands is not None else 1, control_steps=sim.control_steps,
        control_dt=sim.control_dt, sensor=sim.sensor.law_parameters(sim.control_dt),
        actuator=sim.actuator.law_parameters(dt, sim.robot.max_voltage), surface=surface, recorded=recorded,
        estimation=estimation)


@dataclass
class _Batch:
    """What the step loops of one batch share (the arrays :func:`simulate` sets up)."""

    world: World
    plant: object  # the wheel plant's parameters (ddmr_cli.model.robot.Plant): its motor constants serve both kinds
    params: object
    runs: np.ndarray
    lines: np.ndarray  # every run's actuator delay line (n_runs, delay_steps + 1, 2)
    controller_state: np.ndarray
    sums: np.ndarray
    accumulators: np.ndarray
    series: np.ndarray
    slot: np.ndarray
    noise: NoiseStreams
    sensor_noise: SensorNoise | None
    xs: np.ndarray
    bands: BandAccumulator | None
    chunk: int
    band_slots: int  # band buffers taking turns (BAND_SLOTS with threads, else 1): the chunk budget counted each

    def plan(self, n_steps: int) -> list[tuple[int, int, int, int]]:
        """The chunks of a run of ``n_steps`` steps, ``(k0, n, first, end)`` each: the first step, the size (every
        chunk :attr:`chunk` steps but the last) and the range of band grid points that fall on its steps."""
        chunks, k0 = [], 0
        while k0 < n_steps:
            n = min(self.chunk, n_steps - k0)
            first, end = self.bands.grid_range(k0, n) if self.bands is not None else (0, 0)
            chunks.append((k0, n, first, end))
            k0 += n
        return chunks

    def buffers(self) -> Callable[[int, int, int, int], tuple[np.ndarray, np.ndarray]]:
        """The chunks' per-step buffers, allocated once for the largest chunk (chunks of the same size do not allocate
        and free megabytes each: the allocator keeps what it was given back, 10,000 seeds peaked 10 MiB higher), the
        band rows in :attr:`band_slots` buffers that take turns. Returns ``views(i, n, first, end)``: chunk ``i``'s
        sensor normals (:meth:`draw` fills them; :attr:`xs`, zeros never read, when the sensor is not noisy) and band
        buffer, views of the front of those allocations (a shorter last chunk's sensor view overlaps the chunk
        before's). The runs draw their disturbance normals as they step: no buffer."""
        n_runs, channels = len(self.runs), len(BAND_CHANNELS)
        widest = self.bands.most_points(self.chunk) if self.bands is not None else 0
        slots = self.band_slots
        band_memory = [np.empty(n_runs * widest * channels) for _ in range(slots)]
        sensor_memory = np.empty(n_runs * self.chunk * len(NOISE_CHANNELS)) if self.sensor_noise is not None else None

        def views(i: int, n: int, first: int, end: int) -> tuple[np.ndarray, np.ndarray]:
            xs = (self.xs if sensor_memory is None else
                  sensor_memory[:n_runs * n * len(NOISE_CHANNELS)].reshape(n_runs, n, len(NOISE_CHANNELS)))
            band = band_memory[i % slots][:n_runs * (end - first) * channels].reshape(n_runs, end - first, channels)
            return xs, band

        return views

    def chunks(self, n_steps: int):
        """The chunks of :meth:`plan` one after the other with their buffers (:meth:`buffers`):
        ``(k0, n, xs, band_buffer, first, end)`` each."""
        views = self.buffers()
        for i, (k0, n, first, end) in enumerate(self.plan(n_steps)):
            yield (k0, n, *views(i, n, first, end), first, end)

    def draw(self, n: int, xs: np.ndarray, block: tuple[int, int]) -> None:
        """A chunk's sensor normals of the runs ``block`` (first, end) into ``xs``, when the sensor is noisy."""
        if self.sensor_noise is not None:
            self.sensor_noise.next_chunk(n, xs, block)


def in_lanes(sim: Simulation) -> bool:
    """Whether the runs step by blocks, the runs as a vectorised inner axis (:mod:`ddmr_cli.engine.lanes`): the
    compiled loop, the wheel plant and a controller with lanes laws (:meth:`WheelController.runs_in_lanes`), whatever
    the sensor, actuator, control rate and integrator."""
    return jit_enabled() and sim.plant is None and sim.controller.runs_in_lanes()


def _run_compiled(b: _Batch, law_module: str, n_steps: int, n_threads: int, progress, compiling,
                  by_blocks: bool = False) -> None:
    """The wheel plant: every run advanced a chunk of steps at a time by the compiled loop, blocks of runs in
    ``n_threads`` threads, each block on to its next chunk as soon as it is free to
    (:mod:`ddmr_cli.engine.pipeline`); ``by_blocks``: :mod:`ddmr_cli.engine.lanes`'s loop, else
    :mod:`ddmr_cli.engine.stepper`'s."""
    n_runs = len(b.runs)
    streams = b.noise.streams()
    blocks = blocks_of(n_runs, n_threads, LANES if by_blocks else 1)
    plan = b.plan(n_steps)
    views = b.buffers()
    args, sensor, bands = [], [], []
    for i, (k0, n, first, end) in enumerate(plan):
        xs, band_buffer = views(i, n, first, end)
        args.append((k0, n, b.world, b.plant, b.params, b.runs, b.lines, b.controller_state, streams, xs, b.sums,
                     b.accumulators, b.series, b.slot, band_buffer, first))
        sensor.append(xs)
        bands.append((band_buffer, first, _split(end - first, min(n_threads, end - first)) if b.bands else []))
    if not plan:
        return
    # one compiled copy per complete call signature (kernels.py), chosen before the first chunk
    if not by_blocks:
        loop = compiled_run_chunk(law_module, args[0] + (0, n_runs), compiling)
    else:
        loop = compiled_copy(LANES_TEMPLATE, law_module, "run_chunk", args[0] + (0, n_runs), compiling)
    # past numba's typing at every call: each chunk's and each block's arguments checked once (they vary apart)
    call = entry_point(loop, [a + blocks[0] for a in args] + [args[0] + block for block in blocks[1:]])

    def step(i: int, block: int) -> None:  # this block's sensor normals of chunk i, then its steps
        b.draw(plan[i][1], sensor[i], blocks[block])
        call(*args[i], *blocks[block])

    def reduce(i: int, part: int) -> None:  # the bands of a range of chunk i's grid points, over every run
        band_buffer, first, parts = bands[i]
        b.bands.add_chunk(band_buffer, first, parts[part])

    def done(i: int) -> None:
        if i == 0:
            check_single_signature(loop)
        if progress is not None:
            progress(plan[i][0] + plan[i][1], n_steps)

    with np.errstate(all="ignore"):
        shorter = [i > 0 and n != b.chunk for i, (_, n, _, _) in enumerate(plan)]  # reuses the sensor's buffer
        run_chunks(len(plan), len(blocks), step, [len(parts) for _, _, parts in bands], reduce, n_threads,
                   slots=b.band_slots, after_all=shorter, done=done)


#: steps between progress reports of an external plant (its steps are slow: a report every chunk would be rare)
_EXTERNAL_PROGRESS_STEPS = 100


def _run_external(b: _Batch, law_module: str, plant: ExternalPlant, seeds: list[int], n_steps: int, progress,
                  compiling) -> None:
    """An external plant: at every step the compiled control half for all runs, the plant's step from Python (its
    own threads), then the compiled accounting half on the plant's new state. The noise is drawn chunk by chunk
    as for the wheel plant, so every stream a run draws is the same on both plants."""
    n_runs = len(b.runs)
    runs = b.runs
    plant.reset(np.asarray(seeds, dtype=np.int64), np.column_stack([runs["x"], runs["y"], runs["theta"]]),
                np.array(runs["w"]))
    _take_state(runs, plant, n_runs)
    step_out = np.zeros((n_runs, 6))
    streams = b.noise.streams()
    control = account = None
    try:
        with np.errstate(all="ignore"):
            for k0, n, xs, band_buffer, first, end in b.chunks(n_steps):
                b.draw(n, xs, (0, n_runs))
                for j in range(n):
                    k = k0 + j
                    control_args = (k, j, b.world, b.plant, b.params, runs, b.lines, b.controller_state, streams, xs,
                                    step_out)
                    if control is None:
                        control, account = compiled_external_step(law_module, control_args,
                                                                  _account_args(b, k, step_out, band_buffer, first,
                                                                                plant.state(), plant.true_disturbance()),
                                                                  compiling)
                    control(*control_args)
                    plant.step(step_out[:, 0:2], step_out[:, 2])
                    state = plant.state()
                    account(*_account_args(b, k, step_out, band_buffer, first, state, plant.true_disturbance()))
                    gone = plant.diverged() & (runs["divergence_step"] < 0)
                    runs["divergence_step"][gone] = k
                    if progress is not None and (k + 1) % _EXTERNAL_PROGRESS_STEPS == 0 and k + 1 < n_steps:
                        progress(k + 1, n_steps)
                if b.bands is not None:
                    b.bands.add_chunk(band_buffer, first, (0, end - first))
                if progress is not None:
                    progress(k0 + n, n_steps)
    finally:
        close = getattr(plant, "close", None)
        if close is not None:
            close()


def _account_args(b: _Batch, k: int, step_out: np.ndarray, band_buffer: np.ndarray, first: int, state, d) -> tuple:
    return (k, b.world, b.plant, b.runs, b.controller_state, step_out, np.ascontiguousarray(d, dtype=float),
            *(np.ascontiguousarray(state[key], dtype=float) for key in ("x", "y", "theta", "distance", "w")),
            b.sums, b.accumulators, b.series, b.slot, band_buffer, first)


def _take_state(runs: np.ndarray, plant: ExternalPlant, n_runs: int) -> None:
    """The external plant's state at its reset into the run records (it settles the robot onto its ground: the
    pose there is the plant's, not exactly the configured one)."""
    state = plant.state()
    check_state(state, n_runs)
    for key in ("x", "y", "theta", "distance"):
        runs[key] = state[key]
    runs["w"] = state["w"]


def simulate(sim: Simulation, seeds: Sequence[int], keep_series: Sequence[int] = (),
             progress: Callable[[int, int], None] | None = None, threads: int = 0, bands: bool = True,
             compiling: Callable[[], None] | None = None, lanes: bool | None = None) -> SimulationResult:
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
    threads : int
        Threads advancing disjoint blocks of runs (0: every core); on an external plant, its worker threads
        (unless its config sets them). The numbers do not depend on it.
    bands : bool
        Also compute the mean and 5-95 % band over the seeds of a few channels at every grid step
        (:mod:`ddmr_cli.engine.bands`; ``SimulationResult.bands``).
    compiling : callable(), optional
        Called just before the step loop is compiled (no compiled copy for this controller and call is cached).
    lanes : bool, optional
        Step the runs by blocks, vectorised (:mod:`ddmr_cli.engine.lanes`), or one at a time
        (:mod:`ddmr_cli.engine.stepper`); by default by blocks wherever :func:`in_lanes`. The same numbers.
        ``True`` where :func:`in_lanes` is false raises ValueError (a controller without lanes laws, the loop run as
        Python, an external plant).

    Returns
    -------
    SimulationResult
    """
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ConfigError("run.n_runs", 0, "must be >= 1")
    sim.validate()
    by_blocks = in_lanes(sim)
    if lanes and not by_blocks:
        raise ValueError("simulate(lanes=True): this configuration does not run by blocks of runs (engine/lanes.py: "
                         "the compiled loop of the wheel plant with a controller's lanes laws only)")
    by_blocks = by_blocks and lanes is not False
    bit_generators.require_compiled_draws()
    started = time.perf_counter()
    n_runs, n_steps, dt = len(seeds), sim.n_steps, float(sim.dt)
    keep_idx = [seeds.index(s) for s in dict.fromkeys(int(k) for k in keep_series) if s in seeds]
    controller = sim.controller
    params = controller.law_parameters(NominalModel.from_robot(sim.robot), sim.control_dt)
    acc = MetricAccumulator(n_runs, dt, sim.terrain.names, sim.scenario.names)
    band_acc = BandAccumulator(n_steps, dt) if bands else None
    world = _world(sim, n_steps, acc.hp, acc.hp_zi, acc.phase_base, band_acc)
    noise = NoiseStreams(seeds)
    sensor_noise = SensorNoise(seeds, len(NOISE_CHANNELS)) if world.sensor.noisy else None
    xs = np.zeros((n_runs, 1, len(NOISE_CHANNELS)))
    runs = np.zeros(n_runs, dtype=np.dtype(RUN_FIELDS + HOLD_FIELDS + SENSOR_FIELDS + ACTUATOR_FIELDS))
    runs["x"], runs["y"], runs["theta"] = (float(v) for v in sim.initial_pose)
    runs["w"] = _initial_wheel_speeds(sim)
    runs["noise"] = noise.initial_state()
    runs["divergence_step"] = -1
    accumulators = np.zeros(n_runs, dtype=np.dtype(ACCUMULATOR_FIELDS))
    MetricAccumulator.initial_state(accumulators)
    controller_state = controller.initial_state(n_runs)
    channels = series_channels(controller.diagnostics())
    series = np.zeros((len(keep_idx), n_steps if keep_idx else 1, len(channels)))
    slot = np.full(n_runs, -1, dtype=np.int64)
    slot[keep_idx] = np.arange(len(keep_idx))
    n_threads = min(thread_count(threads) if jit_enabled() else 1, n_runs) if sim.plant is None else 1
    band_slots = BAND_SLOTS if n_threads > 1 else 1
    bytes_per_run_step = ((band_slots * 8 * len(BAND_CHANNELS) // world.band_stride if bands else 0)
                          + (8 * len(NOISE_CHANNELS) if sensor_noise is not None else 0))
    chunk = chunk_steps(bytes_per_run_step, n_runs)
    plant = sim.robot.plant()
    batch = _Batch(world, plant, params, runs, delay_lines(n_runs, world.actuator.delay_steps), controller_state,
                   acc.sums, accumulators, series, slot, noise, sensor_noise, xs, band_acc, chunk, band_slots)
    if sim.plant is None:
        _run_compiled(batch, controller.laws.__name__, n_steps, n_threads, progress, compiling, by_blocks)
    else:
        _run_external(batch, controller.laws.__name__, sim.plant(sim, threads), seeds, n_steps, progress,
                      compiling)
    # what only the steps needed (the generators, the controllers' states) goes before the
    # metrics are formed, which is when a large batch's memory peaks
    del batch, noise, sensor_noise, controller_state
    diverged = runs["divergence_step"] >= 0
    divergence_time = np.where(diverged, runs["divergence_step"] * dt, np.nan)
    metrics = acc.finalize(accumulators)
    for arr in metrics.values():
        arr[diverged] = np.nan
    return SimulationResult(
        seeds=seeds, controller=getattr(controller, "name", type(controller).__name__),
        scenario=sim.scenario.name, segments=acc.segments, metrics=metrics, diverged=diverged,
        divergence_time=divergence_time,
        series={seeds[i]: {name: series[n_i, :, c].copy() for c, name in enumerate(channels)}
                for n_i, i in enumerate(keep_idx)},
        dt=dt, duration=n_steps * dt, wall_time=time.perf_counter() - started, engine="compiled" if jit_enabled() else "python",
        bands=band_acc.arrays() if band_acc is not None else {},
    )


__all__ = ["Simulation", "simulate", "INTEGRATORS"]
