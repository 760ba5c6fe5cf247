"""The step loop: every run of a batch advanced by a chunk of steps, each run on its own (docs/model.md §4-5, §10).

Per plant step: measure the true pose error (2) for the metrics; at a control instant (every
``world.control_steps`` plant steps, ``control.rate``), read the sensor (truth, encoders or noise: the controller
sees only this), run the outer loop (3) and inverse kinematics (4)-(5) on the measured pose, difference the
wheel-speed reference over the control period, run the wheel controller's ``command`` law on the measured wheel
speeds, saturate and PWM-quantise ``u`` and run its ``update`` law; between control instants all of it is held
(zero-order hold). Then the actuator (delay, driver lag) gives the motor's voltage, this step's disturbances are
formed (terrain zone and scenario phase by the distance travelled, or the phase by time, the OU processes), the
plant's acceleration (8) computed, the step added to the metrics (7) (on the truth) and, on the band grid, to the
seed bands, recorded if the run's series is kept, and integrated (explicit Euler or RK4), ``u`` and the
disturbances held over the step. With the ideal sensor and actuator and control at every step this is the
paper's loop, number for number.

Runs are independent scalar loops (no BLAS, nothing couples runs), so seed k gives bit-identical numbers alone or
inside any batch, in any chunking and with any thread count. A controller with lanes laws steps its runs by blocks
instead (:mod:`ddmr_cli.engine.lanes`, the same stages and laws over a block's runs); this loop runs the others, the
loop as Python, and is what tests/test_lanes.py holds the blocks to. This module is the template of the compiled
loop: its controller laws come from the slot :mod:`ddmr_cli.engine.controller_slot`, and
:mod:`ddmr_cli.engine.kernels` makes one copy per controller whose only change is those four import lines, pointed
at the controller's module, and compiles it (cached on disk). Without numba the same copy runs as Python.
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import law
from ddmr_cli.engine.controller_slot import command as controller_command  # controller laws
from ddmr_cli.engine.controller_slot import estimates as controller_estimates  # controller laws
from ddmr_cli.engine.controller_slot import start as controller_start  # controller laws
from ddmr_cli.engine.controller_slot import update as controller_update  # controller laws
from ddmr_cli.control.outer_loop import kanayama
from ddmr_cli.engine.bands import band_row
from ddmr_cli.model.integrators import euler, rk4
from ddmr_cli.engine.metrics import accumulate, flush
from ddmr_cli.model.noise import ou_step
from ddmr_cli.engine.results import record
from ddmr_cli.model import actuator, sensor
from ddmr_cli.model.kinematics import deviation, inverse, pose_error
from ddmr_cli.model.dynamics import saturate, wheel_acceleration
from ddmr_cli.model.scenario import damping_scale
from ddmr_cli.model.terrain import zone_of
from ddmr_cli.bit_generators import keep, next_normal, stream_of

@law
def run_chunk(k0, n_steps, world, plant, params, runs, lines, controller_state, streams, xs, sums, accumulators,
              series, series_slot, bands, band_first, first_run, end_run):
    """Advance runs ``first_run .. end_run - 1`` by ``n_steps`` steps from global step ``k0``; run r draws its
    standard normals from its own stream as it steps (three a step: ``stream_of(streams, r)``, ``next_normal``,
    ``keep``; :mod:`ddmr_cli.bit_generators`), ``xs[r, j]`` are its sensor normals (``xs`` is a dummy unless the
    sensor is noisy).

    ``world`` and ``plant`` are :class:`~ddmr_cli.engine.batch.World` and :class:`~ddmr_cli.model.robot.Plant`;
    ``runs``, ``controller_state`` and ``accumulators`` (one record per run) and ``lines`` (each run's actuator
    delay line, :func:`~ddmr_cli.model.actuator.delay_lines`) are updated in place; kept runs
    (``series_slot[r] >= 0``) are recorded into ``series[slot, k]``, and every run's band channels on the grid
    into ``bands[r, k // world.band_stride - band_first]`` (when ``world.bands``). Compiled, it releases the GIL,
    so threads can advance disjoint blocks of runs at once.
    """
    for r in range(first_run, end_run):
        run_steps(k0, n_steps, world, plant, params, r, runs[r], lines[r], controller_state[r], streams, xs, sums,
                  accumulators[r], series, series_slot[r], bands, band_first)


@law
def run_steps(k0, n_steps, world, plant, params, r, run, line, st, streams, xs, sums, acc, series, slot, bands,
              band_first):
    """One run's steps ``k0 .. k0 + n_steps - 1`` (the loop the module docstring describes)."""
    sen, act, m = world.sensor, world.actuator, world.control_steps
    if k0 == 0:
        controller_start(params, st, run["w"][0], run["w"][1])
        sensor.start(sen, run, run["w"][0], run["w"][1])
    x, y, theta, dist = run["x"], run["y"], run["theta"], run["distance"]
    w_R, w_L = run["w"][0], run["w"][1]
    wdp_R, wdp_L = run["w_d_prev"][0], run["w_d_prev"][1]
    noise = run["noise"]  # the OU processes' state (5), stepped in place
    # what the zero-order hold keeps between control instants
    uc_R, uc_L, us_R, us_L = run["u_command"][0], run["u_command"][1], run["u_sent"][0], run["u_sent"][1]
    sat_R, sat_L = run["saturated"][0] != 0, run["saturated"][1] != 0
    diagnostics, surface = st["diagnostics"], world.surface  # the controller's channels, held in its record
    wd_R, wd_L = run["w_d"][0], run["w_d"][1]
    # steps to the next control instant and to the next band grid point, and their indices, counted from the chunk's
    # first step: no integer division at each step (a 64-bit division costs tens of cycles)
    to_control, kc = (m - k0 % m) % m, (k0 + m - 1) // m
    stride = world.band_stride
    to_band, band_j = (stride - k0 % stride) % stride, 0  # band_j: the grid point's row in this chunk's buffer
    stream = stream_of(streams, r)  # the run's generator, in registers until keep() below
    for j in range(n_steps):
        k = k0 + j
        x_r, y_r, th_r, v_r, om_r = (world.reference[k, 0], world.reference[k, 1], world.reference[k, 2],
                                     world.reference[k, 3], world.reference[k, 4])
        # the true pose error (2), for the metrics
        e_x, e_y, e_th = pose_error(x, y, theta, x_r, y_r, th_r)
        dev = deviation(x, y, x_r, y_r)
        control_instant = to_control == 0  # k % m == 0
        to_control = m - 1 if control_instant else to_control - 1
        if control_instant:
            # a control instant (control instant kc = k // m): read the sensor (§10); outer loop (3) and inverse
            # kinematics (4)-(5) on the measured pose; w_d' by backward difference over the control period (4)
            mw_R, mw_L, c_ex, c_ey, c_eth = w_R, w_L, e_x, e_y, e_th
            if not sen.ideal:
                mw_R, mw_L, mx, my, mth = sensor.measure(sen, run, x, y, theta, w_R, w_L, xs[r, j if sen.noisy else 0],
                                                         plant.wheel_radius, plant.half_track)
                c_ex, c_ey, c_eth = pose_error(mx, my, mth, x_r, y_r, th_r)
            v_d, om_d = kanayama(world.gains, c_ex, c_ey, c_eth, v_r, om_r)
            wd_R, wd_L = inverse(v_d, om_d, plant.wheel_radius, plant.half_track)
            wdd_R = 0.0 if kc == 0 else (wd_R - wdp_R) * (1.0 / world.control_dt)
            wdd_L = 0.0 if kc == 0 else (wd_L - wdp_L) * (1.0 / world.control_dt)
            wdp_R, wdp_L = wd_R, wd_L
            # wheel controller (6) on the measured speeds, the driver's voltage limit and PWM (§10), the estimates
            # of d reported under the applied voltage
            uc_R, uc_L = controller_command(params, st, kc, mw_R, mw_L, wd_R, wd_L, wdd_R, wdd_L)
            us_R, sat_R = saturate(uc_R, plant.max_voltage)
            us_L, sat_L = saturate(uc_L, plant.max_voltage)
            if act.pwm:
                us_R, us_L = actuator.pwm(us_R, act.pwm_step), actuator.pwm(us_L, act.pwm_step)
            controller_estimates(params, st, mw_R, mw_L, us_R, us_L)
            controller_update(params, st, mw_R, mw_L, wd_R, wd_L, us_R, us_L, uc_R, uc_L, sat_R, sat_L)
            if k == 0:
                actuator.start(act, run, line, us_R, us_L)
            kc += 1
        # the motor's voltage: the held command, delayed and lagged (§10)
        u_R, u_L = actuator.apply(act, run, line, k, us_R, us_L)
        # this step's disturbances, held over it (5): the run's next three normals, in the channels' order
        for c in range(3):  # one call of the draw (numba inlines a draw called three times with scope warnings)
            xi, stream = next_normal(stream)
            noise[c] = ou_step(world.ou_a[c], world.ou_b[c], noise[c], xi)
        n_R, n_L, n_u = noise[0], noise[1], noise[2]
        phase = zone_of(world.phase_edges, dist) if world.phase_by_distance else world.phase[k]
        zone = zone_of(world.zone_edges, dist)
        rough = world.roughness[zone] * world.roughness_on[phase]
        roll = world.roll_torque[zone]
        uncertain = world.uncertainty_on[phase]
        b = damping_scale(world.uncertainty, n_u) if uncertain else 1.0
        rough_R, rough_L = -n_R * rough, -n_L * rough
        a_R, a_L, d_R, d_L = wheel_acceleration(plant, w_R, w_L, u_R, u_L, b, uncertain, rough_R, rough_L, roll)
        # metrics (7) on the truth, divergence, kept series
        t = k * world.dt
        s_R = diagnostics[surface, 0] if surface >= 0 else math.nan
        s_L = diagnostics[surface, 1] if surface >= 0 else math.nan
        accumulate(sums, r, acc, k, world.settle_steps, world.zone_settle_steps, 1 + zone, world.phase_base + phase, t,
                   dev, e_x, e_y, e_th, sat_R or sat_L,
                   u_R, u_L, w_R, w_L, s_R, s_L, d_R, d_L, diagnostics, world.estimation,
                   plant.back_emf_constant, plant.armature_resistance, world.hp, world.hp_zi)
        if not dev <= world.divergence_bound and run["divergence_step"] < 0:
            run["divergence_step"] = k
        band_point = to_band == 0  # k % stride == 0: a grid point of the bands, row k // stride - band_first
        to_band = stride - 1 if band_point else to_band - 1
        if band_point:
            if world.bands:
                band_row(bands[r, band_j], dev, e_x, e_y, e_th, u_R, u_L, s_R, s_L)
            band_j += 1
        if slot >= 0:
            record(series[slot, k], t, x, y, theta, x_r, y_r, th_r, e_x, e_y, e_th, dev, dist, w_R, w_L,
                   wd_R, wd_L, u_R, u_L, uc_R, uc_L, s_R, s_L, d_R, d_L, rough, b, zone, diagnostics, world.recorded)
        # integrate plant and pose (4); the encoders' true wheel angles
        c, sn = math.cos(theta), math.sin(theta)
        w0_R, w0_L = w_R, w_L
        if world.rk4:
            x, y, theta, dist, w_R, w_L = rk4(plant, world.dt, x, y, theta, dist, w_R, w_L, c, sn, a_R, a_L,
                                              u_R, u_L, b, uncertain, rough_R, rough_L, roll)
        else:
            x, y, theta, dist, w_R, w_L = euler(plant, world.dt, x, y, theta, dist, w_R, w_L, c, sn, a_R, a_L)
        if sen.encoder:
            run["wheel_angle"][0] = sensor.wheel_angle(run["wheel_angle"][0], w0_R, w_R, world.dt)
            run["wheel_angle"][1] = sensor.wheel_angle(run["wheel_angle"][1], w0_L, w_L, world.dt)
    keep(streams, r, stream)
    run["x"], run["y"], run["theta"], run["distance"] = x, y, theta, dist
    run["w"][0], run["w"][1] = w_R, w_L
    run["w_d_prev"][0], run["w_d_prev"][1] = wdp_R, wdp_L
    run["u_command"][0], run["u_command"][1], run["u_sent"][0], run["u_sent"][1] = uc_R, uc_L, us_R, us_L
    run["saturated"][0], run["saturated"][1] = 1 if sat_R else 0, 1 if sat_L else 0
    run["w_d"][0], run["w_d"][1] = wd_R, wd_L
    if k0 + n_steps == world.reference.shape[0]:  # the run's last step: add its open block to its segments
        flush(sums, r, acc)


# --- an external plant (ddmr_cli.plant.base) -------------------------------------------------------------------
# The same laws as run_steps in the same order, split where the plant steps (from Python, between the two calls).
# run_steps keeps its body in one function: split into shared helpers it measured 2x slower, when numba still
# counted a reference to every array of ``world`` a helper took (the loop is now compiled without counting:
# compiled.loop_law; not measured again). tests/test_external_plant.py
# holds the two orchestrations to one another: the wheel plant stepped from Python matches run_steps.

@law
def external_control(k, j, world, plant, params, runs, lines, controller_state, streams, xs, step_out):
    """Step ``k`` (the ``j``-th of its chunk) of every run up to the plant's step: the control instant when it is
    one, the motor's voltage and the step's disturbances, from the true state the run record holds (the plant's,
    written by :func:`external_account`). Writes ``step_out[r] = (u_R, u_L, b, rough, zone, phase)`` for the
    plant's step and the accounting after it."""
    sen, m = world.sensor, world.control_steps
    for r in range(runs.shape[0]):
        run, line, st = runs[r], lines[r], controller_state[r]
        x, y, theta, dist, w_R, w_L = run["x"], run["y"], run["theta"], run["distance"], run["w"][0], run["w"][1]
        if k == 0:
            controller_start(params, st, w_R, w_L)
            sensor.start(sen, run, w_R, w_L)
        if k % m == 0:
            external_control_instant(world, plant, params, run, line, st, k, xs, r, j, x, y, theta, w_R, w_L)
        u_R, u_L = actuator.apply(world.actuator, run, line, k, run["u_sent"][0], run["u_sent"][1])
        # this step's disturbances (5): the roughness is the ground's, scenario 2's damping scale acts on the motor
        noise, stream = run["noise"], stream_of(streams, r)
        for c in range(3):  # one call of the draw, as in run_steps
            xi, stream = next_normal(stream)
            noise[c] = ou_step(world.ou_a[c], world.ou_b[c], noise[c], xi)
        keep(streams, r, stream)
        n_u = noise[2]
        phase = zone_of(world.phase_edges, dist) if world.phase_by_distance else world.phase[k]
        zone = zone_of(world.zone_edges, dist)
        rough = world.roughness[zone] * world.roughness_on[phase]
        b = damping_scale(world.uncertainty, n_u) if world.uncertainty_on[phase] else 1.0
        step_out[r, 0], step_out[r, 1], step_out[r, 2], step_out[r, 3] = u_R, u_L, b, rough
        step_out[r, 4], step_out[r, 5] = zone, phase


@law
def external_account(k, world, plant, runs, controller_state, step_out, d, x1, y1, theta1, dist1, w1, sums,
                     accumulators, series, series_slot, bands, band_first):
    """Step ``k`` of every run after the plant stepped, as :func:`run_steps` accounts it: the metrics (7), the
    divergence rule, the seed bands and the kept series on the true state before the step (``d`` ``(n, 2)``: the
    plant's true disturbance over it); then the plant's new state (``x1`` ... ``w1``) into the run records and the
    encoders' true wheel angles one step on."""
    for r in range(runs.shape[0]):
        run, st = runs[r], controller_state[r]
        x, y, theta, dist, w_R, w_L = run["x"], run["y"], run["theta"], run["distance"], run["w"][0], run["w"][1]
        x_r, y_r, th_r = world.reference[k, 0], world.reference[k, 1], world.reference[k, 2]
        e_x, e_y, e_th = pose_error(x, y, theta, x_r, y_r, th_r)
        dev = deviation(x, y, x_r, y_r)
        u_R, u_L, b, rough = step_out[r, 0], step_out[r, 1], step_out[r, 2], step_out[r, 3]
        zone, phase = int(step_out[r, 4]), int(step_out[r, 5])
        d_R, d_L = d[r, 0], d[r, 1]
        diagnostics, surface, t = st["diagnostics"], world.surface, k * world.dt
        s_R = diagnostics[surface, 0] if surface >= 0 else math.nan
        s_L = diagnostics[surface, 1] if surface >= 0 else math.nan
        saturated = run["saturated"][0] != 0 or run["saturated"][1] != 0
        accumulate(sums, r, accumulators[r], k, world.settle_steps, world.zone_settle_steps, 1 + zone,
                   world.phase_base + phase, t, dev, e_x, e_y, e_th, saturated, u_R, u_L, w_R, w_L, s_R, s_L, d_R, d_L,
                   diagnostics, world.estimation, plant.back_emf_constant, plant.armature_resistance, world.hp,
                   world.hp_zi)
        if not dev <= world.divergence_bound and run["divergence_step"] < 0:
            run["divergence_step"] = k
        if world.bands and k % world.band_stride == 0:
            band_row(bands[r, k // world.band_stride - band_first], dev, e_x, e_y, e_th, u_R, u_L, s_R, s_L)
        slot = series_slot[r]
        if slot >= 0:
            wd_R, wd_L, uc_R, uc_L = run["w_d"][0], run["w_d"][1], run["u_command"][0], run["u_command"][1]
            record(series[slot, k], t, x, y, theta, x_r, y_r, th_r, e_x, e_y, e_th, dev, dist, w_R, w_L,
                   wd_R, wd_L, u_R, u_L, uc_R, uc_L, s_R, s_L, d_R, d_L, rough, b, zone, diagnostics, world.recorded)
        run["x"], run["y"], run["theta"], run["distance"] = x1[r], y1[r], theta1[r], dist1[r]
        run["w"][0], run["w"][1] = w1[r, 0], w1[r, 1]
        if world.sensor.encoder:
            run["wheel_angle"][0] = sensor.wheel_angle(run["wheel_angle"][0], w_R, w1[r, 0], world.dt)
            run["wheel_angle"][1] = sensor.wheel_angle(run["wheel_angle"][1], w_L, w1[r, 1], world.dt)
        if k + 1 == world.reference.shape[0]:  # the run's last step: add its open block to its segments
            flush(sums, r, accumulators[r])


@law
def external_control_instant(world, plant, params, run, line, st, k, xs, r, j, x, y, theta, w_R, w_L):
    """The control instant of :func:`run_steps` at plant step ``k`` on a run record: the sensor, the outer loop
    (3), inverse kinematics (4)-(5), the wheel controller (6), the driver's limit and PWM, the estimates and the
    update law, the holds written back to the record."""
    sen, act, m = world.sensor, world.actuator, world.control_steps
    kc = k // m
    x_r, y_r, th_r, v_r, om_r = (world.reference[k, 0], world.reference[k, 1], world.reference[k, 2],
                                 world.reference[k, 3], world.reference[k, 4])
    e_x, e_y, e_th = pose_error(x, y, theta, x_r, y_r, th_r)
    mw_R, mw_L, c_ex, c_ey, c_eth = w_R, w_L, e_x, e_y, e_th
    if not sen.ideal:
        row = j if sen.noisy else 0
        mw_R, mw_L, mx, my, mth = sensor.measure(sen, run, x, y, theta, w_R, w_L, xs[r, row], plant.wheel_radius,
                                                 plant.half_track)
        c_ex, c_ey, c_eth = pose_error(mx, my, mth, x_r, y_r, th_r)
    v_d, om_d = kanayama(world.gains, c_ex, c_ey, c_eth, v_r, om_r)
    wd_R, wd_L = inverse(v_d, om_d, plant.wheel_radius, plant.half_track)
    wdd_R = 0.0 if kc == 0 else (wd_R - run["w_d_prev"][0]) * (1.0 / world.control_dt)
    wdd_L = 0.0 if kc == 0 else (wd_L - run["w_d_prev"][1]) * (1.0 / world.control_dt)
    uc_R, uc_L = controller_command(params, st, kc, mw_R, mw_L, wd_R, wd_L, wdd_R, wdd_L)
    us_R, sat_R = saturate(uc_R, plant.max_voltage)
    us_L, sat_L = saturate(uc_L, plant.max_voltage)
    if act.pwm:
        us_R, us_L = actuator.pwm(us_R, act.pwm_step), actuator.pwm(us_L, act.pwm_step)
    controller_estimates(params, st, mw_R, mw_L, us_R, us_L)
    controller_update(params, st, mw_R, mw_L, wd_R, wd_L, us_R, us_L, uc_R, uc_L, sat_R, sat_L)
    if kc == 0:
        actuator.start(act, run, line, us_R, us_L)
    run["w_d_prev"][0], run["w_d_prev"][1] = wd_R, wd_L
    run["w_d"][0], run["w_d"][1] = wd_R, wd_L
    run["u_command"][0], run["u_command"][1], run["u_sent"][0], run["u_sent"][1] = uc_R, uc_L, us_R, us_L
    run["saturated"][0], run["saturated"][1] = 1 if sat_R else 0, 1 if sat_L else 0
