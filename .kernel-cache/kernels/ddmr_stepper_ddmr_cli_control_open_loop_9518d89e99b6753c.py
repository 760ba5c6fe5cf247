# generated from ddmr_cli.engine.stepper for ddmr_cli.control.open_loop; do not edit
"""The step loop: every run of a batch advanced by a chunk of steps, each run on its own (docs/model.md §4-5).

Per step: measure the pose error (2), run the outer loop (3) and inverse kinematics (4)-(5), difference the
wheel-speed reference, run the wheel controller's ``command`` law, saturate ``u``, form this step's
disturbances (terrain zone and scenario phase by the distance travelled, or the phase by time, the OU processes),
compute the plant's acceleration (8), run the controller's ``update`` law, add the step to the metrics (7) and,
on the band grid, to the seed bands, record it if the run's series is kept, and integrate (explicit Euler or
RK4), ``u`` and the disturbances held over the step.

Runs are independent scalar loops (no BLAS, nothing couples runs), so seed k gives bit-identical numbers alone
or inside any batch, in any chunking and with any thread count. This module is the template of the compiled
loop: :mod:`ddmr_cli.engine.kernels` makes one copy per controller whose only change is the import of the
controller's laws below, and compiles it (cached on disk). Without numba the same copy runs as Python.
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import cached_law as law
from ddmr_cli.control.open_loop import command as controller_command
from ddmr_cli.control.open_loop import start as controller_start
from ddmr_cli.control.open_loop import update as controller_update
from ddmr_cli.control.outer_loop import kanayama
from ddmr_cli.engine.bands import band_row
from ddmr_cli.engine.integrators import euler, rk4
from ddmr_cli.engine.metrics import accumulate
from ddmr_cli.engine.noise import ou_step
from ddmr_cli.engine.results import record
from ddmr_cli.model.kinematics import deviation, inverse, pose_error
from ddmr_cli.model.robot import saturate, wheel_acceleration
from ddmr_cli.model.scenario import damping_scale
from ddmr_cli.model.terrain import zone_of

@law
def run_chunk(k0, n_steps, world, plant, params, runs, controller_state, xi, sums, accumulators, series,
              series_slot, bands, band_first, first_run, end_run):
    """Advance runs ``first_run .. end_run - 1`` by ``n_steps`` steps from global step ``k0``; ``xi[r, j]`` are
    run r's standard normals.

    ``world`` and ``plant`` are :class:`~ddmr_cli.engine.batch.World` and :class:`~ddmr_cli.model.robot.Plant`;
    ``runs``, ``controller_state`` and ``accumulators`` (one record per run) are updated in place; kept runs
    (``series_slot[r] >= 0``) are recorded into ``series[slot, k]``, and every run's band channels on the grid
    into ``bands[r, k // world.band_stride - band_first]`` (when ``world.bands``). Compiled, it releases the GIL,
    so threads can advance disjoint blocks of runs at once.
    """
    for r in range(first_run, end_run):
        run_steps(k0, n_steps, world, plant, params, r, runs[r], controller_state[r], xi, sums, accumulators[r],
                  series, series_slot[r], bands, band_first)


@law
def run_steps(k0, n_steps, world, plant, params, r, run, st, xi, sums, acc, series, slot, bands, band_first):
    """One run's steps ``k0 .. k0 + n_steps - 1`` (the loop the module docstring describes)."""
    if k0 == 0:
        controller_start(params, st, run["w"][0], run["w"][1])
    x, y, theta, dist = run["x"], run["y"], run["theta"], run["distance"]
    w_R, w_L = run["w"][0], run["w"][1]
    wdp_R, wdp_L = run["w_d_prev"][0], run["w_d_prev"][1]
    n_R, n_L, n_u = run["noise"][0], run["noise"][1], run["noise"][2]
    for j in range(n_steps):
        k = k0 + j
        x_r, y_r, th_r, v_r, om_r = (world.reference[k, 0], world.reference[k, 1], world.reference[k, 2],
                                     world.reference[k, 3], world.reference[k, 4])
        # measure (2), outer loop (3), inverse kinematics (4)-(5); w_d' by backward difference (4)
        e_x, e_y, e_th = pose_error(x, y, theta, x_r, y_r, th_r)
        dev = deviation(x, y, x_r, y_r)
        v_d, om_d = kanayama(world.gains, e_x, e_y, e_th, v_r, om_r)
        wd_R, wd_L = inverse(v_d, om_d, plant.wheel_radius, plant.half_track)
        wdd_R = 0.0 if k == 0 else (wd_R - wdp_R) * (1.0 / world.dt)
        wdd_L = 0.0 if k == 0 else (wd_L - wdp_L) * (1.0 / world.dt)
        wdp_R, wdp_L = wd_R, wd_L
        # wheel controller (6) and the driver's voltage limit
        uc_R, uc_L, s_R, s_L, ndo_R, ndo_L, nn_R, nn_L = controller_command(
            params, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L)
        u_R, sat_R = saturate(uc_R, plant.max_voltage)
        u_L, sat_L = saturate(uc_L, plant.max_voltage)
        # this step's disturbances, held over it (5)
        n_R = ou_step(world.ou_a[0], world.ou_b[0], n_R, xi[r, j, 0])
        n_L = ou_step(world.ou_a[1], world.ou_b[1], n_L, xi[r, j, 1])
        n_u = ou_step(world.ou_a[2], world.ou_b[2], n_u, xi[r, j, 2])
        phase = zone_of(world.phase_edges, dist) if world.phase_by_distance else world.phase[k]
        zone = zone_of(world.zone_edges, dist)
        rough = world.roughness[zone] * world.roughness_on[phase]
        roll = world.roll_torque[zone]
        uncertain = world.uncertainty_on[phase]
        b = damping_scale(world.uncertainty, n_u) if uncertain else 1.0
        rough_R, rough_L = -n_R * rough, -n_L * rough
        a_R, a_L, d_R, d_L = wheel_acceleration(plant, w_R, w_L, u_R, u_L, b, uncertain, rough_R, rough_L, roll)
        controller_update(params, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L)
        # metrics (7), divergence, kept series
        t = k * world.dt
        accumulate(sums, r, acc, k, world.settle_steps, world.zone_settle_steps, 1 + zone, world.phase_base + phase, t, dev, e_x, e_y, e_th,
                   sat_R or sat_L,
                   u_R, u_L, w_R, w_L, s_R, s_L, d_R, d_L, ndo_R, ndo_L, nn_R, nn_L,
                   plant.back_emf_constant, plant.armature_resistance, world.hp, world.hp_zi)
        if not dev <= world.divergence_bound and run["divergence_step"] < 0:
            run["divergence_step"] = k
        if world.bands and k % world.band_stride == 0:
            band_row(bands[r, k // world.band_stride - band_first], dev, e_x, e_y, e_th, u_R, u_L, s_R, s_L)
        if slot >= 0:
            record(series[slot, k], t, x, y, theta, x_r, y_r, th_r, e_x, e_y, e_th, dev, dist, w_R, w_L,
                   wd_R, wd_L, u_R, u_L, uc_R, uc_L, s_R, s_L, d_R, d_L, ndo_R, ndo_L, nn_R, nn_L, rough, b, zone)
        # integrate plant and pose (4)
        c, sn = math.cos(theta), math.sin(theta)
        if world.rk4:
            x, y, theta, dist, w_R, w_L = rk4(plant, world.dt, x, y, theta, dist, w_R, w_L, c, sn, a_R, a_L,
                                              u_R, u_L, b, uncertain, rough_R, rough_L, roll)
        else:
            x, y, theta, dist, w_R, w_L = euler(plant, world.dt, x, y, theta, dist, w_R, w_L, c, sn, a_R, a_L)
    run["x"], run["y"], run["theta"], run["distance"] = x, y, theta, dist
    run["w"][0], run["w"][1] = w_R, w_L
    run["w_d_prev"][0], run["w_d_prev"][1] = wdp_R, wdp_L
    run["noise"][0], run["noise"][1], run["noise"][2] = n_R, n_L, n_u
