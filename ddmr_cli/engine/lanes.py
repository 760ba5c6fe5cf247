"""The step loop by blocks of runs: the runs of a block step together, each stage of a step a loop over them (lanes).

:mod:`ddmr_cli.engine.stepper` advances one run at a time: each step waits for the one before (a long chain of
dependent operations) and the CPU's vector units stay idle. Here a block of up to :data:`LANES` runs keeps its state
in rows ``(row, lane)`` of a local array, and every stage of a step is a loop over the block's lanes that LLVM
vectorises (AVX-512: 8 runs an instruction), overlapping the runs' dependency chains. The stages are
:func:`ddmr_cli.engine.stepper.run_steps`'s in its order, and the laws the same definitions it calls (kinematics,
Kanayama's outer loop, the controller's laws in their lanes form, :mod:`ddmr_cli.control.base`, "Lanes", the
driver's limit and PWM, the OU noise, the plant (8), the metric terms, Euler or RK4), compiled without fast-math
flags, so a lane computes exactly the operations of one run alone: a run's numbers are the same in any block, in any
batch, chunk or thread (tests/test_lanes.py holds them to the run-at-a-time loop's).

What cannot be a vectorised loop runs beside the lanes, one lane at a time: the noise draws (numpy's ziggurat,
compiled, into a buffer of :data:`DRAW_STEPS` steps per block), libm's sine and cosine, the wrap of the heading
error (a modulo outside its fast path), the addition of a run's block of sums to its segments when a segment
changes, the seed bands' rows on their grid, the kept series, and the laws whose state is the run record's: a
sensor's reading other than the ideal one (its encoder angles, filter and odometry) and the actuator's delay line
and lag.

Used for every run of the wheel plant whose controller has lanes laws (:func:`ddmr_cli.engine.simulation.in_lanes`),
whatever its sensor, actuator, control rate and integrator; the control instants are the same steps in every lane,
so each is one branch for the block. Otherwise (a controller without lanes laws, the loop run as Python) the
run-at-a-time loop runs. Like the step loop, this module is a template: :mod:`ddmr_cli.engine.kernels` makes one copy
per controller, its controller-law imports pointed at the controller's module.
"""

from __future__ import annotations

import math

from ddmr_cli import compiled
from ddmr_cli.compiled import inlined_law
from ddmr_cli.compiled import law
from ddmr_cli.engine.controller_slot import LANE_STATE_ROWS as controller_LANE_STATE_ROWS  # controller laws
from ddmr_cli.engine.controller_slot import lanes_command as controller_lanes_command  # controller laws
from ddmr_cli.engine.controller_slot import lanes_load as controller_lanes_load  # controller laws
from ddmr_cli.engine.controller_slot import lanes_store as controller_lanes_store  # controller laws
from ddmr_cli.engine.controller_slot import lanes_update as controller_lanes_update  # controller laws
from ddmr_cli.engine.controller_slot import start as controller_start  # controller laws
from ddmr_cli.bit_generators import standard_normals_of
from ddmr_cli.control.base import (DIAGNOSTICS, LANES, LANE_ROWS, SAT_L, SAT_R, UC_L, UC_R, U_L, U_R, W_L, W_R, WD_L,
                                   WD_R, WDD_L, WDD_R)
from ddmr_cli.control.outer_loop import kanayama_of
from ddmr_cli.engine.bands import band_row
from ddmr_cli.engine.metrics import N_SUMS, add_block, add_terms, flush, highpass, segment_key, step_terms
from ddmr_cli.engine.results import record
from ddmr_cli.model import actuator, sensor
from ddmr_cli.model.dynamics import saturate, wheel_acceleration
from ddmr_cli.model.integrators import euler, rk4
from ddmr_cli.model.kinematics import deviation, frame_error, inverse, pose_error, wrap_angle, wrap_in_range
from ddmr_cli.model.noise import ou_step
from ddmr_cli.model.scenario import damping_scale

#: steps of noise drawn per block at a time (the buffer: LANES x DRAW_STEPS x 3 normals, 48 KiB)
DRAW_STEPS = 64
DRAW_VALUES = DRAW_STEPS * 3

# the engine's rows of the block array L, after the contract's (ddmr_cli.control.base, whose W_R, W_L are the speeds
# the controller measures): the run's state (WT_R, WT_L: the true wheel speeds) ...
X, Y, TH, DIST, WT_R, WT_L, WDP_R, WDP_L, N_R, N_L, N_U, DIV = range(LANE_ROWS, LANE_ROWS + 12)
# ... the metric accumulator's (ddmr_cli.engine.metrics.ACCUMULATOR_FIELDS) ...
(UP_R, UP_L, HP_R0, HP_R1, HP_L0, HP_L1, STARTED, DEV_MAX, DEV_MAX_SS, DEV_FINAL, ZONE_SEG, ZONE_ENTRY, PHASE_SEG,
 PHASE_ENTRY, KEY) = range(DIV + 1, DIV + 16)
BLOCK = KEY + 1  # the block of sums, N_SUMS rows
# ... and this step's values
# (CE_*: the pose error the controller sees, MU_*: the motor's voltage, W0_*: the true speeds before the step)
(ZONE, PHASE, ROUGH_ZONE, ROUGH_ON, UNCERTAIN, ROLL, NEW_KEY, COS, SIN, E_X, E_Y, E_TH, DEV, A_R, A_L, D_R, D_L,
 DAMPING, DT0_R, DT0_L, DT1_R, DT1_L, PREV_R, PREV_L, HP_Y_R, HP_Y_L, CE_X, CE_Y, CE_TH, COS_E, SIN_E, MU_R, MU_L,
 W0_R, W0_L) = range(BLOCK + N_SUMS, BLOCK + N_SUMS + 35)
#: rows of the block array L
ROWS = W0_L + 1


@law
def run_chunk(k0, n_steps, world, plant, params, runs, lines, controller_state, streams, xs, sums, accumulators,
              series, series_slot, bands, band_first, first_run, end_run):
    """Advance runs ``first_run .. end_run - 1`` by ``n_steps`` steps from global step ``k0``, a block of
    :data:`LANES` runs at a time (arguments as :func:`ddmr_cli.engine.stepper.run_chunk`'s). The block's rows ``L``
    (:data:`ROWS`, LANES), the controller's ``C`` (its ``LANE_STATE_ROWS``, LANES) and the noise buffer live on
    the stack (``compiled.stack_matrix``): LLVM then knows that nothing else overlaps them, which it
    must to vectorise a loop that writes them."""
    L = compiled.stack_matrix(ROWS, LANES)
    C = compiled.stack_matrix(controller_LANE_STATE_ROWS, LANES)
    XI = compiled.stack_matrix(LANES, DRAW_VALUES).reshape((LANES, DRAW_STEPS, 3))
    for first in range(first_run, end_run, LANES):
        nb = min(LANES, end_run - first)
        if k0 == 0:
            for l in range(nb):
                run = runs[first + l]
                controller_start(params, controller_state[first + l], run["w"][0], run["w"][1])
                sensor.start(world.sensor, run, run["w"][0], run["w"][1])
        load(params, runs, controller_state, accumulators, L, C, first, nb)
        kept = False
        for l in range(nb):
            kept |= series_slot[first + l] >= 0
        j0 = 0
        while j0 < n_steps:
            m = min(DRAW_STEPS, n_steps - j0)
            standard_normals_of(streams[first:first + nb], XI[:nb, :m], 0, nb)
            for j in range(m):
                step(k0 + j0 + j, j, j0 + j, world, plant, params, runs, lines, controller_state, xs, sums, series,
                     series_slot, bands, band_first, L, C, XI, first, nb, kept)
            j0 += m
        store(params, runs, controller_state, accumulators, L, C, first, nb)
        if k0 + n_steps == world.reference.shape[0]:  # the runs' last step: add their open blocks to their segments
            for l in range(nb):
                flush(sums, first + l, accumulators[first + l])


@inlined_law
def load(params, runs, controller_state, accumulators, L, C, first, nb):
    """Runs ``first .. first + nb - 1`` from their records into the block's lanes."""
    for l in range(nb):
        run, acc, st = runs[first + l], accumulators[first + l], controller_state[first + l]
        L[X, l], L[Y, l], L[TH, l], L[DIST, l] = run["x"], run["y"], run["theta"], run["distance"]
        L[WT_R, l], L[WT_L, l] = run["w"][0], run["w"][1]
        L[WDP_R, l], L[WDP_L, l] = run["w_d_prev"][0], run["w_d_prev"][1]
        # what the zero-order hold keeps between control instants
        L[UC_R, l], L[UC_L, l], L[U_R, l], L[U_L, l] = (run["u_command"][0], run["u_command"][1], run["u_sent"][0],
                                                        run["u_sent"][1])
        L[SAT_R, l], L[SAT_L, l] = 1.0 if run["saturated"][0] != 0 else 0.0, 1.0 if run["saturated"][1] != 0 else 0.0
        L[WD_R, l], L[WD_L, l] = run["w_d"][0], run["w_d"][1]
        L[N_R, l], L[N_L, l], L[N_U, l] = run["noise"][0], run["noise"][1], run["noise"][2]
        L[DIV, l] = run["divergence_step"]
        L[UP_R, l], L[UP_L, l] = acc["u_prev"][0], acc["u_prev"][1]
        L[HP_R0, l], L[HP_R1, l], L[HP_L0, l], L[HP_L1, l] = (acc["hp_state"][0, 0], acc["hp_state"][0, 1],
                                                              acc["hp_state"][1, 0], acc["hp_state"][1, 1])
        L[STARTED, l] = 1.0 if acc["started"] else 0.0
        L[DEV_MAX, l], L[DEV_MAX_SS, l], L[DEV_FINAL, l] = acc["dev_max"], acc["dev_max_ss"], acc["dev_final"]
        L[ZONE_SEG, l], L[ZONE_ENTRY, l] = acc["zone_segment"], acc["zone_entry"]
        L[PHASE_SEG, l], L[PHASE_ENTRY, l], L[KEY, l] = acc["phase_segment"], acc["phase_entry"], acc["block_key"]
        for c in range(N_SUMS):
            L[BLOCK + c, l] = acc["block"][c]
        diagnostics = st["diagnostics"]
        for c in range(diagnostics.shape[0]):
            L[DIAGNOSTICS + 2 * c, l], L[DIAGNOSTICS + 2 * c + 1, l] = diagnostics[c, 0], diagnostics[c, 1]
        controller_lanes_load(params, st, C, l)


@inlined_law
def store(params, runs, controller_state, accumulators, L, C, first, nb):
    """The block's lanes back into the runs' records (the zero-order hold's fields as this step left them)."""
    for l in range(nb):
        run, acc, st = runs[first + l], accumulators[first + l], controller_state[first + l]
        run["x"], run["y"], run["theta"], run["distance"] = L[X, l], L[Y, l], L[TH, l], L[DIST, l]
        run["w"][0], run["w"][1] = L[WT_R, l], L[WT_L, l]
        run["w_d_prev"][0], run["w_d_prev"][1] = L[WDP_R, l], L[WDP_L, l]
        run["noise"][0], run["noise"][1], run["noise"][2] = L[N_R, l], L[N_L, l], L[N_U, l]
        run["divergence_step"] = int(L[DIV, l])
        run["u_command"][0], run["u_command"][1] = L[UC_R, l], L[UC_L, l]
        run["u_sent"][0], run["u_sent"][1] = L[U_R, l], L[U_L, l]
        run["saturated"][0], run["saturated"][1] = int(L[SAT_R, l]), int(L[SAT_L, l])
        run["w_d"][0], run["w_d"][1] = L[WD_R, l], L[WD_L, l]
        acc["u_prev"][0], acc["u_prev"][1] = L[UP_R, l], L[UP_L, l]
        acc["hp_state"][0, 0], acc["hp_state"][0, 1] = L[HP_R0, l], L[HP_R1, l]
        acc["hp_state"][1, 0], acc["hp_state"][1, 1] = L[HP_L0, l], L[HP_L1, l]
        acc["started"] = L[STARTED, l] != 0.0
        acc["dev_max"], acc["dev_max_ss"], acc["dev_final"] = L[DEV_MAX, l], L[DEV_MAX_SS, l], L[DEV_FINAL, l]
        acc["zone_segment"], acc["zone_entry"] = int(L[ZONE_SEG, l]), int(L[ZONE_ENTRY, l])
        acc["phase_segment"], acc["phase_entry"] = int(L[PHASE_SEG, l]), int(L[PHASE_ENTRY, l])
        acc["block_key"] = int(L[KEY, l])
        for c in range(N_SUMS):
            acc["block"][c] = L[BLOCK + c, l]
        diagnostics = st["diagnostics"]
        for c in range(diagnostics.shape[0]):
            diagnostics[c, 0], diagnostics[c, 1] = L[DIAGNOSTICS + 2 * c, l], L[DIAGNOSTICS + 2 * c + 1, l]
        controller_lanes_store(params, st, C, l)


@inlined_law
def step(k, j, jc, world, plant, params, runs, lines, controller_state, xs, sums, series, series_slot, bands,
         band_first, L, C, XI, first, nb, kept):
    """Step ``k`` of the block's lanes (the ``jc``-th of its chunk; ``XI[l, j]``: lane l's normals of this step): the
    stages of :func:`ddmr_cli.engine.stepper.run_steps`, each over the lanes."""
    x_r, y_r, th_r = world.reference[k, 0], world.reference[k, 1], world.reference[k, 2]
    terrain_and_phase(k, world, L, nb)
    # the step's segments (docs/model.md §7); a run whose segments changed adds its block to them (rarely)
    zone_base, phase_base = 1, world.phase_base
    changed = False
    for l in range(nb):
        key, L[ZONE_ENTRY, l], L[PHASE_ENTRY, l] = segment_key(
            k, zone_base + int(L[ZONE, l]), phase_base + int(L[PHASE, l]), int(L[ZONE_SEG, l]),
            int(L[ZONE_ENTRY, l]), int(L[PHASE_SEG, l]), int(L[PHASE_ENTRY, l]), world.settle_steps,
            world.zone_settle_steps)
        L[ZONE_SEG, l], L[PHASE_SEG, l] = zone_base + L[ZONE, l], phase_base + L[PHASE, l]
        L[NEW_KEY, l] = key
        changed |= key != L[KEY, l]
    if changed:
        for l in range(nb):
            if L[NEW_KEY, l] != L[KEY, l]:
                if L[KEY, l] >= 0.0:
                    add_block(sums, first + l, int(L[KEY, l]), L[BLOCK:BLOCK + N_SUMS, l])
                L[KEY, l] = L[NEW_KEY, l]
    # the true pose error (2) and deviation, for the metrics; a heading error outside wrap_angle's fast path wrapped
    # one lane at a time after (its modulo is a call: rare on a path, never on the paper's)
    for l in range(nb):  # libm's, as the run-at-a-time loop's (one call a lane: the same numbers to the bit)
        L[COS, l], L[SIN, l] = math.cos(L[TH, l]), math.sin(L[TH, l])
    outside = False
    for l in range(nb):
        x, y = L[X, l], L[Y, l]
        L[E_X, l], L[E_Y, l] = frame_error(x, y, L[COS, l], L[SIN, l], x_r, y_r)
        L[E_TH, l], inside = wrap_in_range(th_r - L[TH, l])
        outside |= not inside
        L[DEV, l] = deviation(x, y, x_r, y_r)
    if outside:
        for l in range(nb):
            L[E_TH, l] = wrap_angle(th_r - L[TH, l])
    m = world.control_steps
    if k % m == 0:  # a control instant (the same steps in every lane); between them all of it is held
        control_instant(k, k // m, jc, world, plant, params, runs, lines, xs, L, C, first, nb)
    motor_voltage(k, world.actuator, runs, lines, L, first, nb)
    # this step's disturbances (5) and the plant's acceleration (8)
    for l in range(nb):
        n_R = ou_step(world.ou_a[0], world.ou_b[0], L[N_R, l], XI[l, j, 0])
        n_L = ou_step(world.ou_a[1], world.ou_b[1], L[N_L, l], XI[l, j, 1])
        n_u = ou_step(world.ou_a[2], world.ou_b[2], L[N_U, l], XI[l, j, 2])
        L[N_R, l], L[N_L, l], L[N_U, l] = n_R, n_L, n_u
        uncertain = L[UNCERTAIN, l] != 0.0
        b = damping_scale(world.uncertainty, n_u) if uncertain else 1.0
        rough = L[ROUGH_ZONE, l] * L[ROUGH_ON, l]
        L[A_R, l], L[A_L, l], L[D_R, l], L[D_L, l] = wheel_acceleration(
            plant, L[WT_R, l], L[WT_L, l], L[MU_R, l], L[MU_L, l], b, uncertain, -n_R * rough, -n_L * rough,
            L[ROLL, l])
        L[DAMPING, l] = b
    estimation_errors(world.estimation, L, nb)
    metrics(k, world, plant, L, nb)
    grid = world.band_stride
    if world.bands and k % grid == 0:
        for l in range(nb):
            s_R, s_L = surface_of(world.surface, L, l)
            band_row(bands[first + l, k // grid - band_first], L[DEV, l], L[E_X, l], L[E_Y, l], L[E_TH, l],
                     L[MU_R, l], L[MU_L, l], s_R, s_L)
    if kept:
        for l in range(nb):
            slot = series_slot[first + l]
            if slot >= 0:
                keep_step(k, world, controller_state[first + l], series[slot, k], L, l, x_r, y_r, th_r)
    integrate(world, plant, runs, L, first, nb)


@inlined_law
def control_instant(k, kc, jc, world, plant, params, runs, lines, xs, L, C, first, nb):
    """The control instant ``kc`` at plant step ``k`` (the ``jc``-th of the chunk), as
    :func:`ddmr_cli.engine.stepper.run_steps` takes it: the sensor's reading (the controller's speeds into the
    contract's ``W_R``, ``W_L``, its pose error into ``CE_*``); the outer loop (3), inverse kinematics (4)-(5) and
    ``w_d'`` by backward difference over the control period (4); the wheel controller (6), the driver's limit and
    PWM, the controller's estimates and update; at the first, the actuator's start."""
    sen, act = world.sensor, world.actuator
    if sen.ideal:
        for l in range(nb):
            L[W_R, l], L[W_L, l] = L[WT_R, l], L[WT_L, l]
            L[CE_X, l], L[CE_Y, l], L[CE_TH, l] = L[E_X, l], L[E_Y, l], L[E_TH, l]
    else:
        readings(sen, jc, world.reference[k, 0], world.reference[k, 1], world.reference[k, 2], plant.wheel_radius,
                 plant.half_track, runs, xs, L, first, nb)
    v_r, om_r = world.reference[k, 3], world.reference[k, 4]
    inv_dt = 1.0 / world.control_dt
    for l in range(nb):
        L[COS_E, l], L[SIN_E, l] = math.cos(L[CE_TH, l]), math.sin(L[CE_TH, l])
    for l in range(nb):
        v_d, om_d = kanayama_of(world.gains, L[CE_X, l], L[CE_Y, l], L[COS_E, l], L[SIN_E, l], v_r, om_r)
        wd_R, wd_L = inverse(v_d, om_d, plant.wheel_radius, plant.half_track)
        L[WDD_R, l] = 0.0 if kc == 0 else (wd_R - L[WDP_R, l]) * inv_dt
        L[WDD_L, l] = 0.0 if kc == 0 else (wd_L - L[WDP_L, l]) * inv_dt
        L[WD_R, l], L[WD_L, l], L[WDP_R, l], L[WDP_L, l] = wd_R, wd_L, wd_R, wd_L
    controller_lanes_command(params, C, L, nb, kc)
    for l in range(nb):
        u_R, sat_R = saturate(L[UC_R, l], plant.max_voltage)
        u_L, sat_L = saturate(L[UC_L, l], plant.max_voltage)
        L[U_R, l], L[U_L, l] = u_R, u_L
        L[SAT_R, l], L[SAT_L, l] = 1.0 if sat_R else 0.0, 1.0 if sat_L else 0.0
    if act.pwm:
        for l in range(nb):
            L[U_R, l], L[U_L, l] = actuator.pwm(L[U_R, l], act.pwm_step), actuator.pwm(L[U_L, l], act.pwm_step)
    controller_lanes_update(params, C, L, nb)
    if k == 0:
        for l in range(nb):
            actuator.start(act, runs[first + l], lines[first + l], L[U_R, l], L[U_L, l])


@inlined_law
def motor_voltage(k, act, runs, lines, L, first, nb):
    """The motor's voltage ``MU_*``: the held command ``U_*``, delayed and lagged
    (:func:`ddmr_cli.model.actuator.apply`, one lane at a time: the delay line and the driver's output are the run's),
    or the command itself."""
    if act.delay_steps > 0 or act.lagged:
        applied(k, act, runs, lines, L, first, nb)
    else:
        for l in range(nb):
            L[MU_R, l], L[MU_L, l] = L[U_R, l], L[U_L, l]


@inlined_law
def integrate(world, plant, runs, L, first, nb):
    """The plant and the pose one step on (4), by explicit Euler or RK4 (the inputs held over the step); the
    encoders' true wheel angles (one lane at a time: they are the run records')."""
    encoder = world.sensor.encoder
    if encoder:
        for l in range(nb):
            L[W0_R, l], L[W0_L, l] = L[WT_R, l], L[WT_L, l]
    if world.rk4:
        rk4_lanes(plant, world.dt, L, nb)
    else:
        for l in range(nb):
            L[X, l], L[Y, l], L[TH, l], L[DIST, l], L[WT_R, l], L[WT_L, l] = euler(
                plant, world.dt, L[X, l], L[Y, l], L[TH, l], L[DIST, l], L[WT_R, l], L[WT_L, l], L[COS, l],
                L[SIN, l], L[A_R, l], L[A_L, l])
    if encoder:
        wheel_angles(world.dt, runs, L, first, nb)


# --- beyond the paper's loop: compiled apart, called once a step where a configuration needs them. Inlined, they took
# 2 s more of every copy's compile (21.4 against 19.4 s, SMC-NDO) and the paper's loop 5 % longer (54.7 against 52.0
# ns a run-step); called, their own configurations ran as fast or faster (docs/model.md §4)

@law
def readings(sen, jc, x_r, y_r, th_r, wheel_radius, half_track, runs, xs, L, first, nb):
    """A sensor's reading other than the ideal one (docs/model.md §10, :func:`ddmr_cli.model.sensor.measure`), one
    lane at a time (its state is the run record's): the controller's speeds into ``W_R``, ``W_L``, its pose error (2)
    into ``CE_*``."""
    for l in range(nb):
        r = first + l
        L[W_R, l], L[W_L, l], m_x, m_y, m_th = sensor.measure(
            sen, runs[r], L[X, l], L[Y, l], L[TH, l], L[WT_R, l], L[WT_L, l], xs[r, jc if sen.noisy else 0],
            wheel_radius, half_track)
        L[CE_X, l], L[CE_Y, l], L[CE_TH, l] = pose_error(m_x, m_y, m_th, x_r, y_r, th_r)


@law
def applied(k, act, runs, lines, L, first, nb):
    """The motor's voltage through the run's delay line and driver lag (docs/model.md §10,
    :func:`ddmr_cli.model.actuator.apply`), one lane at a time."""
    for l in range(nb):
        L[MU_R, l], L[MU_L, l] = actuator.apply(act, runs[first + l], lines[first + l], k, L[U_R, l], L[U_L, l])


@law
def rk4_lanes(plant, dt, L, nb):
    """The plant and the pose one step on by RK4 (docs/model.md §4 [4b], :func:`ddmr_cli.model.integrators.rk4`),
    the inputs held over the step."""
    for l in range(nb):
        rough = L[ROUGH_ZONE, l] * L[ROUGH_ON, l]
        L[X, l], L[Y, l], L[TH, l], L[DIST, l], L[WT_R, l], L[WT_L, l] = rk4(
            plant, dt, L[X, l], L[Y, l], L[TH, l], L[DIST, l], L[WT_R, l], L[WT_L, l], L[COS, l], L[SIN, l],
            L[A_R, l], L[A_L, l], L[MU_R, l], L[MU_L, l], L[DAMPING, l], L[UNCERTAIN, l] != 0.0,
            -L[N_R, l] * rough, -L[N_L, l] * rough, L[ROLL, l])


@law
def wheel_angles(dt, runs, L, first, nb):
    """The encoders' true wheel angles one step on (docs/model.md §10, :func:`ddmr_cli.model.sensor.wheel_angle`),
    one lane at a time (they are the run records')."""
    for l in range(nb):
        angle = runs[first + l]["wheel_angle"]
        angle[0] = sensor.wheel_angle(angle[0], L[W0_R, l], L[WT_R, l], dt)
        angle[1] = sensor.wheel_angle(angle[1], L[W0_L, l], L[WT_L, l], dt)


@inlined_law
def terrain_and_phase(k, world, L, nb):
    """The lanes' terrain zone (roughness, rolling torque) and scenario phase (roughness on, damping uncertain) by
    the distance travelled, or the phase by time: :func:`ddmr_cli.model.terrain.zone_of` as a select per zone
    edge (the edges ascend)."""
    for l in range(nb):
        L[ZONE, l], L[ROUGH_ZONE, l], L[ROLL, l] = 0.0, world.roughness[0], world.roll_torque[0]
    for e in range(world.zone_edges.shape[0]):
        edge, rough, roll = world.zone_edges[e], world.roughness[e + 1], world.roll_torque[e + 1]
        for l in range(nb):
            past = L[DIST, l] >= edge
            L[ZONE, l] = e + 1.0 if past else L[ZONE, l]
            L[ROUGH_ZONE, l] = rough if past else L[ROUGH_ZONE, l]
            L[ROLL, l] = roll if past else L[ROLL, l]
    if world.phase_by_distance:
        on0, unc0 = world.roughness_on[0], 1.0 if world.uncertainty_on[0] else 0.0
        for l in range(nb):
            L[PHASE, l], L[ROUGH_ON, l], L[UNCERTAIN, l] = 0.0, on0, unc0
        for e in range(world.phase_edges.shape[0]):
            edge, on, unc = world.phase_edges[e], world.roughness_on[e + 1], 1.0 if world.uncertainty_on[e + 1] else 0.0
            for l in range(nb):
                past = L[DIST, l] >= edge
                L[PHASE, l] = e + 1.0 if past else L[PHASE, l]
                L[ROUGH_ON, l] = on if past else L[ROUGH_ON, l]
                L[UNCERTAIN, l] = unc if past else L[UNCERTAIN, l]
    else:
        phase = world.phase[k]
        on, unc = world.roughness_on[phase], 1.0 if world.uncertainty_on[phase] else 0.0
        for l in range(nb):
            L[PHASE, l], L[ROUGH_ON, l], L[UNCERTAIN, l] = phase, on, unc


@inlined_law
def estimation_errors(estimation, L, nb):
    """``d`` less the estimates that count in each estimation metric
    (:func:`ddmr_cli.engine.metrics.estimation_error`, channel by channel over the lanes)."""
    for l in range(nb):
        L[DT0_R, l], L[DT0_L, l], L[DT1_R, l], L[DT1_L, l] = L[D_R, l], L[D_L, l], L[D_R, l], L[D_L, l]
    for i in range(2):
        row = DT0_R + 2 * i
        for m in range(estimation.shape[1]):
            c = estimation[i, m]
            if c < 0:
                break
            for l in range(nb):
                L[row, l] -= L[DIAGNOSTICS + 2 * c, l]
                L[row + 1, l] -= L[DIAGNOSTICS + 2 * c + 1, l]


@inlined_law
def surface_of(surface, L, l):
    """The sliding variable of lane ``l`` (the controller's SURFACE channel, row ``surface``; NaN without one,
    ``surface`` -1), branch-free."""
    row = DIAGNOSTICS + 2 * max(surface, 0)
    has = surface >= 0
    return L[row, l] if has else math.nan, L[row + 1, l] if has else math.nan


@inlined_law
def metrics(k, world, plant, L, nb):
    """Step ``k`` added to the lanes' blocks of sums (:func:`ddmr_cli.engine.metrics.accumulate`), the largest and
    last deviations, the divergence rule."""
    t, hp, hp_zi, settled = k * world.dt, world.hp, world.hp_zi, k >= world.settle_steps
    for l in range(nb):  # the voltage's last value and high-pass, the run's first step starting both at u
        u_R, u_L = L[MU_R, l], L[MU_L, l]
        first_step = L[STARTED, l] == 0.0
        L[PREV_R, l] = u_R if first_step else L[UP_R, l]
        L[PREV_L, l] = u_L if first_step else L[UP_L, l]
        h_R0 = hp_zi[0] * u_R if first_step else L[HP_R0, l]
        h_R1 = hp_zi[1] * u_R if first_step else L[HP_R1, l]
        h_L0 = hp_zi[0] * u_L if first_step else L[HP_L0, l]
        h_L1 = hp_zi[1] * u_L if first_step else L[HP_L1, l]
        L[HP_Y_R, l], L[HP_R0, l], L[HP_R1, l] = highpass(hp, h_R0, h_R1, u_R)
        L[HP_Y_L, l], L[HP_L0, l], L[HP_L1, l] = highpass(hp, h_L0, h_L1, u_L)
        L[UP_R, l], L[UP_L, l], L[STARTED, l] = u_R, u_L, 1.0
    for l in range(nb):  # the step's terms of the sums
        s_R, s_L = surface_of(world.surface, L, l)
        add_terms(L[BLOCK:BLOCK + N_SUMS, l], step_terms(t, L[DEV, l], L[E_X, l], L[E_Y, l], L[E_TH, l],
                                   L[SAT_R, l] + L[SAT_L, l] != 0.0, L[MU_R, l], L[MU_L, l], L[PREV_R, l], L[PREV_L, l],
                                   L[WT_R, l], L[WT_L, l], L[DT0_R, l], L[DT0_L, l], L[DT1_R, l], L[DT1_L, l], s_R, s_L,
                                   L[HP_Y_R, l], L[HP_Y_L, l], plant.back_emf_constant, plant.armature_resistance))
    for l in range(nb):  # the largest and last deviations, the divergence rule
        dev = L[DEV, l]
        L[DEV_MAX, l] = dev if dev > L[DEV_MAX, l] else L[DEV_MAX, l]
        L[DEV_MAX_SS, l] = dev if settled and dev > L[DEV_MAX_SS, l] else L[DEV_MAX_SS, l]
        L[DEV_FINAL, l] = dev
        L[DIV, l] = k if not dev <= world.divergence_bound and L[DIV, l] < 0.0 else L[DIV, l]


@inlined_law
def keep_step(k, world, st, row, L, l, x_r, y_r, th_r):
    """Lane ``l``'s step ``k`` into its kept series ``row`` (:func:`ddmr_cli.engine.results.record`), its
    diagnostic channels through its state record's."""
    diagnostics = st["diagnostics"]
    for c in range(diagnostics.shape[0]):
        diagnostics[c, 0], diagnostics[c, 1] = L[DIAGNOSTICS + 2 * c, l], L[DIAGNOSTICS + 2 * c + 1, l]
    s_R, s_L = surface_of(world.surface, L, l)
    record(row, k * world.dt, L[X, l], L[Y, l], L[TH, l], x_r, y_r, th_r, L[E_X, l], L[E_Y, l], L[E_TH, l],
           L[DEV, l], L[DIST, l], L[WT_R, l], L[WT_L, l], L[WD_R, l], L[WD_L, l], L[MU_R, l], L[MU_L, l], L[UC_R, l],
           L[UC_L, l], s_R, s_L, L[D_R, l], L[D_L, l], L[ROUGH_ZONE, l] * L[ROUGH_ON, l], L[DAMPING, l],
           int(L[ZONE, l]), diagnostics, world.recorded)


__all__ = ["DRAW_STEPS", "ROWS", "run_chunk"]
