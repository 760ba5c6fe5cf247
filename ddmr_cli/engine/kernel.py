"""The compiled step loop (numba): the numpy engine's model, one run at a time, for the built-in controllers.

The numpy modules are the specification: every function below names the law, and the equation, of the module
it mirrors (``kinematics``, ``outer_loop``, ``controllers.*``, the plant in ``simulation``).
``tests/test_engines.py`` checks that both engines give the same numbers. Runs are independent scalar loops,
so a run gives bit-identical numbers alone or inside any batch. Compiled once per machine and cached on disk
(numba ``cache=True``); without numba, or for a controller without a kernel, the numpy engine runs instead.

Buffers: ``rec1[r, j, c]`` holds the scalar signals in the order of :data:`REC1`, ``rec2[r, j, c, wheel]``
the wheel signals in the order of :data:`REC2`, ``rec_zone[j, r]`` the terrain zone.
"""

from __future__ import annotations

import math

import numpy as np

try:
    from numba import njit, prange
except ImportError:  # pragma: no cover - exercised only where numba is missing
    njit, prange = None, range

AVAILABLE = njit is not None

REC1 = ("dev", "e_x", "e_y", "e_theta", "x", "y", "theta", "distance", "roughness", "damping_scale")
REC2 = ("u", "u_command", "w", "s", "d_true", "d_hat_ndo", "d_hat_nn", "w_d")

# controller kinds and the layout of their parameter vectors (see each controller's ``kernel_spec``)
OPEN_LOOP, PID_KIND, SMC_KIND = 0, 1, 2
SWITCH_SIGN, SWITCH_SAT, SWITCH_TANH = 0, 1, 2
# consts vector
(C_L, C_R, C_JINV_P, C_JINV_Q, C_DAMPING, C_KU, C_UMAX, C_KX, C_KY, C_KTH, C_DT, C_JKU_P, C_JKU_Q,
 C_UNC_STD, C_UNC_LOW, C_UNC_HIGH) = range(16)
N_CONSTS = 16


def set_threads(n: int) -> int:
    """Use ``n`` threads in the compiled step loop (0: every core this process may use); returns the count."""
    if not AVAILABLE:
        return 1
    import os

    import numba

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    count = max(1, min(int(n) if n else cores, numba.config.NUMBA_NUM_THREADS))
    numba.set_num_threads(count)
    return count


def _jit(fn):
    """Compiled, cached on disk, and releasing the GIL (other Python threads go on meanwhile)."""
    return njit(cache=True, nogil=True)(fn) if AVAILABLE else fn


def _jit_parallel(fn):
    """Compiled with the runs spread over threads (``prange``); each run stays on one thread, in order."""
    return njit(cache=True, nogil=True, parallel=True)(fn) if AVAILABLE else fn


@_jit
def _sign(v):
    return (v > 0.0) - (v < 0.0)


@_jit
def _wrap(a):
    """kinematics.wrap_angle: into (-pi, pi]."""
    out = math.pi - ((math.pi - a) % (2.0 * math.pi))
    return out + 2.0 * math.pi if out <= -math.pi else out


@_jit
def _accel(wR, wL, uR, uL, b, dextR, dextL, roll, consts, has_unc):
    """simulation.disturbance + wheel_acceleration, the paper's (6)-(8) with MODEL.md 5's disturbances.

    Returns (w'_R, w'_L, d_R, d_L) with ``d = -J^-1 (B (b - 1) w + tau_roll sign(w)) + d_ext`` and
    ``w' = J^-1 (K_u u - B w) + d``.
    """
    jp, jq, B, ku = consts[C_JINV_P], consts[C_JINV_Q], consts[C_DAMPING], consts[C_KU]
    tR = _sign(wR) * roll
    tL = _sign(wL) * roll
    if has_unc:
        tR += (B * (b - 1.0)) * wR
        tL += (B * (b - 1.0)) * wL
    dR = dextR - (jp * tR + jq * tL)
    dL = dextL - (jq * tR + jp * tL)
    mR = ku * uR - B * wR
    mL = ku * uL - B * wL
    return jp * mR + jq * mL + dR, jq * mR + jp * mL + dL, dR, dL


@_jit_parallel
def run_chunk(kind, cp, cstate, centers, pose, w, w_d_prev, k0, ref, noise, phase, rough_on, unc_on,
              zone_edges, roughness_table, roll_table, consts, rk4, rec1, rec2, rec_zone):
    """Advance every run by ``noise.shape[1]`` steps from global step ``k0``, recording every step.

    ``pose[r] = (x, y, theta, distance)``; ``w``, ``w_d_prev`` and ``cstate`` (controller state) are updated
    in place. See the module docstring for the buffers.
    """
    n_runs, n_steps = noise.shape[0], noise.shape[1]
    L, R, dt, u_max = consts[C_L], consts[C_R], consts[C_DT], consts[C_UMAX]
    kx, ky, kth = consts[C_KX], consts[C_KY], consts[C_KTH]
    jku_p, jku_q, b_over_ku = consts[C_JKU_P], consts[C_JKU_Q], consts[C_DAMPING] / consts[C_KU]
    unc_std, unc_low, unc_high = consts[C_UNC_STD], consts[C_UNC_LOW], consts[C_UNC_HIGH]
    n_edges, n_nn = zone_edges.shape[0], centers.shape[0]
    for r in prange(n_runs):
        phi = np.empty(n_nn)
        x, y, th, dist = pose[r, 0], pose[r, 1], pose[r, 2], pose[r, 3]
        wR, wL = w[r, 0], w[r, 1]
        wdpR, wdpL = w_d_prev[r, 0], w_d_prev[r, 1]
        for j in range(n_steps):
            k = k0 + j
            # measure: pose error in the robot frame (kinematics.pose_error, MODEL.md 2)
            dx, dy = ref[j, 0] - x, ref[j, 1] - y
            c, sn = math.cos(th), math.sin(th)
            e_x = c * dx + sn * dy
            e_y = c * dy - sn * dx
            e_th = _wrap(ref[j, 2] - th)
            v_r, om_r = ref[j, 3], ref[j, 4]
            # outer_loop.Kanayama (MODEL.md 3) and inverse kinematics (4); w_d' backward difference (MODEL.md 4)
            v_d = v_r * math.cos(e_th) + kx * e_x
            om_d = om_r + v_r * (ky * e_y + kth * math.sin(e_th))
            wdR = (v_d + L * om_d) * (1.0 / R)
            wdL = (v_d - L * om_d) * (1.0 / R)
            wddR = 0.0 if k == 0 else (wdR - wdpR) * (1.0 / dt)
            wddL = 0.0 if k == 0 else (wdL - wdpL) * (1.0 / dt)
            wdpR, wdpL = wdR, wdL
            eR, eL = wdR - wR, wdL - wL
            sR, sL = eR, eL
            ndoR = ndoL = nnR = nnL = 0.0
            # wheel controller (MODEL.md 6)
            if kind == OPEN_LOOP:
                ucR, ucL = cp[0], cp[1]
            elif kind == PID_KIND:  # controllers.pid.PID
                edR = 0.0 if k == 0 else (eR - cstate[r, 2]) * (1.0 / dt)
                edL = 0.0 if k == 0 else (eL - cstate[r, 3]) * (1.0 / dt)
                cstate[r, 2], cstate[r, 3] = eR, eL
                ucR = cp[0] * eR + cp[2] * cstate[r, 0] + cp[4] * edR
                ucL = cp[1] * eL + cp[3] * cstate[r, 1] + cp[5] * edL
            else:  # controllers.smc.SMC, (17), with the NDO (21) and the RBF network (24)-(27)
                if cp[5] > 0.5:  # integral surface
                    sR = eR + cp[0] * cstate[r, 0]
                    sL = eL + cp[1] * cstate[r, 1]
                    aR, aL = cp[0] * eR, cp[1] * eL
                else:
                    aR, aL = cp[0] * sR, cp[1] * sL
                switching = int(cp[6])
                if switching == SWITCH_SIGN:
                    swR, swL = _sign(sR) * 1.0, _sign(sL) * 1.0
                else:
                    xR, xL = sR * (1.0 / cp[4]), sL * (1.0 / cp[4])
                    if switching == SWITCH_SAT:
                        swR, swL = min(max(xR, -1.0), 1.0), min(max(xL, -1.0), 1.0)
                    else:
                        swR, swL = math.tanh(xR), math.tanh(xL)
                aR = wddR + aR + cp[2] * swR
                aL = wddL + aL + cp[3] * swL
                if cp[7] > 0.5:
                    ndoR = cstate[r, 2] + cp[8] * wR
                    ndoL = cstate[r, 3] + cp[9] * wL
                if cp[10] > 0.5:
                    scale = -0.5 / (cp[12] * cp[12])
                    for q in range(n_nn):
                        phi[q] = math.exp(((wR - centers[q]) ** 2 + (wL - centers[q]) ** 2) * scale)
                        nnR += cstate[r, 4 + q] * phi[q]
                        nnL += cstate[r, 4 + n_nn + q] * phi[q]
                aR -= ndoR + nnR
                aL -= ndoL + nnL
                ucR = jku_p * aR + jku_q * aL + b_over_ku * wR
                ucL = jku_q * aR + jku_p * aL + b_over_ku * wL
            uR, uL = min(max(ucR, -u_max), u_max), min(max(ucL, -u_max), u_max)
            # disturbances of this step, held over it (MODEL.md 5)
            p = phase[j]
            zone = 0
            while zone < n_edges and dist >= zone_edges[zone]:
                zone += 1
            rough = roughness_table[zone] * rough_on[p]
            roll = roll_table[zone]
            has_unc = unc_on[p]
            b = 1.0
            if has_unc:
                b = 1.0 + min(max(unc_std * noise[r, j, 2], unc_low), unc_high)
            dextR, dextL = -noise[r, j, 0] * rough, -noise[r, j, 1] * rough
            awR, awL, dR, dL = _accel(wR, wL, uR, uL, b, dextR, dextL, roll, consts, has_unc)
            # observers and integrators advance (controllers.*.update)
            if kind == PID_KIND:
                iR, iL = eR, eL
                if cp[6] > 0.5:  # anti-windup: hold while saturated and the error pushes further
                    if uR != ucR and _sign(eR) == _sign(ucR):
                        iR = 0.0
                    if uL != ucL and _sign(eL) == _sign(ucL):
                        iL = 0.0
                cstate[r, 0] += dt * iR
                cstate[r, 1] += dt * iL
            elif kind == SMC_KIND:
                if cp[5] > 0.5:
                    cstate[r, 0] += dt * eR
                    cstate[r, 1] += dt * eL
                if cp[7] > 0.5:  # (22): z' = -Gamma (d_hat + f(w) + g u)
                    jp, jq, B, ku = consts[C_JINV_P], consts[C_JINV_Q], consts[C_DAMPING], consts[C_KU]
                    mR, mL = ku * uR - B * wR, ku * uL - B * wL
                    cstate[r, 2] -= (dt * cp[8]) * (ndoR + (jp * mR + jq * mL))
                    cstate[r, 3] -= (dt * cp[9]) * (ndoL + (jq * mR + jp * mL))
                if cp[10] > 0.5:  # (25): W' = -gamma Phi(x) s^T
                    stR, stL = (dt * cp[13]) * sR, (dt * cp[14]) * sL
                    for q in range(n_nn):
                        cstate[r, 4 + q] -= stR * phi[q]
                        cstate[r, 4 + n_nn + q] -= stL * phi[q]
            # record
            rec1[r, j, 0] = math.hypot(dx, dy)
            rec1[r, j, 1], rec1[r, j, 2], rec1[r, j, 3] = e_x, e_y, e_th
            rec1[r, j, 4], rec1[r, j, 5], rec1[r, j, 6], rec1[r, j, 7] = x, y, th, dist
            rec1[r, j, 8], rec1[r, j, 9] = rough, b
            rec2[r, j, 0, 0], rec2[r, j, 0, 1] = uR, uL
            rec2[r, j, 1, 0], rec2[r, j, 1, 1] = ucR, ucL
            rec2[r, j, 2, 0], rec2[r, j, 2, 1] = wR, wL
            rec2[r, j, 3, 0], rec2[r, j, 3, 1] = sR, sL
            rec2[r, j, 4, 0], rec2[r, j, 4, 1] = dR, dL
            rec2[r, j, 5, 0], rec2[r, j, 5, 1] = ndoR, ndoL
            rec2[r, j, 6, 0], rec2[r, j, 6, 1] = nnR, nnL
            rec2[r, j, 7, 0], rec2[r, j, 7, 1] = wdR, wdL
            rec_zone[r, j] = zone
            # advance plant and pose (MODEL.md 4): forward kinematics (1)-(2)
            v = R * 0.5 * (wR + wL)
            om = (R / (2.0 * L)) * (wR - wL)
            if not rk4:
                x += dt * (v * c)
                y += dt * (v * sn)
                th += dt * om
                dist += dt * abs(v)
                wR += dt * awR
                wL += dt * awL
            else:
                h = 0.5 * dt
                th2, w2R, w2L = th + h * om, wR + h * awR, wL + h * awL
                v2, om2 = R * 0.5 * (w2R + w2L), (R / (2.0 * L)) * (w2R - w2L)
                a2R, a2L, _, _ = _accel(w2R, w2L, uR, uL, b, dextR, dextL, roll, consts, has_unc)
                th3, w3R, w3L = th + h * om2, wR + h * a2R, wL + h * a2L
                v3, om3 = R * 0.5 * (w3R + w3L), (R / (2.0 * L)) * (w3R - w3L)
                a3R, a3L, _, _ = _accel(w3R, w3L, uR, uL, b, dextR, dextL, roll, consts, has_unc)
                th4, w4R, w4L = th + dt * om3, wR + dt * a3R, wL + dt * a3L
                v4, om4 = R * 0.5 * (w4R + w4L), (R / (2.0 * L)) * (w4R - w4L)
                a4R, a4L, _, _ = _accel(w4R, w4L, uR, uL, b, dextR, dextL, roll, consts, has_unc)
                sixth = dt / 6.0
                x += sixth * (v * c + 2.0 * v2 * math.cos(th2) + 2.0 * v3 * math.cos(th3) + v4 * math.cos(th4))
                y += sixth * (v * sn + 2.0 * v2 * math.sin(th2) + 2.0 * v3 * math.sin(th3) + v4 * math.sin(th4))
                dist += sixth * (abs(v) + 2.0 * abs(v2) + 2.0 * abs(v3) + abs(v4))
                th += sixth * (om + 2.0 * om2 + 2.0 * om3 + om4)
                wR += sixth * (awR + 2.0 * a2R + 2.0 * a3R + a4R)
                wL += sixth * (awL + 2.0 * a2L + 2.0 * a3L + a4L)
        pose[r, 0], pose[r, 1], pose[r, 2], pose[r, 3] = x, y, th, dist
        w[r, 0], w[r, 1] = wR, wL
        w_d_prev[r, 0], w_d_prev[r, 1] = wdpR, wdpL
