"""The benchmark's yardstick: the paper's loop hand-fused into one numba kernel, on the engine's own noise streams.

``ddmr bench`` times this kernel in the same process as the engine (:func:`ddmr_cli.engine.simulation.simulate`)
and prints the ratio: how far the general engine is from the fastest loop one can write for the same runs. It is
**not a second engine**: it runs only the paper's scenario-1 loop (below) and computes only a few whole-run
metrics. The laws' equations are necessarily written again here, by hand and fused (the SMC law (17), the NDO
(21)-(22), the RBF network (24)-(25), Kanayama's outer loop, the inverse kinematics, the plant (8) with the
terrain disturbance, explicit Euler); every number they use is read from the same
:class:`~ddmr_cli.engine.simulation.Simulation` object the engine gets (robot, terrain, scenario, controller, outer
loop, trajectory, step), through the same set-up functions where the engine has one (the controller's
``law_parameters``, :class:`~ddmr_cli.model.robot.NominalModel`, ``Robot.plant``,
:func:`~ddmr_cli.model.noise.ou_coefficients`, :func:`~ddmr_cli.model.trajectory.reference_table`), so nothing
numeric is duplicated. ``tests/test_reference.py`` proves it computes the engine's numbers (per seed, to 1e-12
relative).

What it supports, and refuses otherwise (:class:`~ddmr_cli.errors.ConfigError`, a ``ValueError`` naming the key):
controller SMC (``smc_ndo`` or ``smc_ndo_nno``: proportional surface, ``sat`` switching, with the NDO, with or
without the RBF network), ideal sensor and actuator, control at every plant step, explicit Euler, a scenario
without damping uncertainty (``paper_1``), any terrain zones, any trajectory (the engine's reference table).

Noise: the engine's :class:`~ddmr_cli.model.noise.NoiseStreams` (each run's ``numpy.random.default_rng(seed)``
stream: 3 normals for the OU initial state, then 3 per step), drawn here by block in chunks of the engine's budget
(:func:`~ddmr_cli.bit_generators.standard_normals_of`, where the engine draws them one at a time as it steps), so
the kernel reads the very same streams; drawing them is part of the timed work (it is of the engine's too).

Three layouts of the same loop (``layout=``):

``"lanes"`` (the default, and the fastest: ``ddmr bench`` prints it beside the exact layout)
    Runs are the inner, SIMD axis: blocks of :data:`BLOCK` runs step together, the state of a block in one local
    array of rows ``(field, run)`` with a constant row length, so that every stage of a step is a loop over the
    block's runs that LLVM vectorises (AVX-512: 8 runs an instruction; a partial block runs the same code on
    fewer runs). numba has no vector ``sin``, ``cos`` or ``exp`` without Intel's SVML (not installed here), and
    LLVM leaves a loop that calls libm's scalar, so this layout uses the branch-free :func:`sincos` and
    :func:`exp_neg` of :mod:`ddmr_cli.model.elementary` (fdlibm's kernels, at most 1 ulp from glibc's; the
    engine's RBF network uses the same exp) with fused multiply-adds: the trajectories agree with the engine's to
    rounding (about 1e-13 relative in the metrics), not to the bit, and a seed gives the same bits alone or in
    any batch. A neuron whose exponent is below -746 for every run of the block (its phi is exactly 0, as in the
    engine) is skipped.
``"exact"`` (the yardstick at equal work: ``ddmr bench`` holds the engine to it)
    The lanes layout computing the engine's numbers: libm's ``sin`` and ``cos`` called a lane at a time, as the
    engine calls them, and no fast-math flag, so that every operation is the scalar layout's (its metrics equal the
    scalar layout's bit for bit on the reference machine; tests hold them to 1e-15). The lanes layout's fdlibm
    kernels and fused multiply-adds are what the engine cannot take: a last-bit difference in the heading grows
    through the sliding mode's switching to 1e-8 relative in some of its per-seed metrics over 15 s, past the
    regression fixture (docs/model.md §4). Measured (SMC-NDO, 1,000 runs of 1 s, one core, ns per run and step):
    lanes 25.0, lanes without fused multiply-adds 31.3, libm's sine and cosine with them 40.7, exact 44.2; the
    engine without its seed bands 55.5 (SMC-NDO-NNO: 38.2, 56.0, 57.5, 62.2 and 86.9).
``"scalar"``
    One run at a time, its state in registers, libm's ``cos`` and ``sin`` and the network's
    :func:`~ddmr_cli.model.elementary.exp_neg` where the engine calls them, the same operations in the same order
    (on the reference machine: the same trajectory bit for bit; the sums differ in summation order only). Each
    step waits for the one before (a long chain of dependent operations), which the lanes layout overlaps across
    runs.

Measured on the 2-core AVX-512 reference machine (kernel alone, noise drawn beforehand, ns per run and step):
lanes 15 (SMC-NDO) and 29 (SMC-NDO-NNO), scalar 50 and 116; with the noise (31 ns a step at 50 runs, 40 at
1000, measured then with numpy's own generators; ddmr's own draw of the same streams now takes about 8 ns a step),
lanes 52-58 and 66-72. The lanes layout wins by
vectorising (its exp and sincos run about 1.8 ns per lane against 8 ns for libm's exp in a loop) and by
overlapping the runs' dependency chains; its block size matters little (8 runs: 10 % slower, 32 to 64 the same).

Fast math: the lanes layout is compiled with ``fastmath={'contract'}`` alone (LLVM may fuse a multiply and an add
into one FMA: its kernel is 15-25 % faster, its sin, cos and exp stay within 1 ulp, its metrics within 3e-13 of
the engine's over 50 seeds of 15 s); not the flags that assume no NaN or inf (a diverging run is detected by its
NaN deviation) nor reassociation. The exact and scalar layouts use none. The two lanes layouts are one body
(``_lanes_steps``, inlined by numba into each layout's kernel with the layout's flags); ``libm`` is a constant of
each, so LLVM keeps only its branch.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple, Sequence

import numpy as np

from ddmr_cli.compiled import AVAILABLE, plain
from ddmr_cli.control import rbf
from ddmr_cli.control.smc import SMC
from ddmr_cli.model import elementary
from ddmr_cli.model.elementary import EXP_ZERO
from ddmr_cli.model.noise import NoiseStreams, ou_coefficients
# _initial_wheel_speeds: the engine's own rolling start (read, not copied)
from ddmr_cli.engine.simulation import Simulation, _initial_wheel_speeds, chunk_steps
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.robot import NominalModel
from ddmr_cli.model.trajectory import reference_table

if AVAILABLE:
    from numba import njit

    #: the lanes layout's only fast-math flag: fused multiply-adds (module docstring)
    _LANES_FASTMATH = {"contract"}

    def _kernel(fn):
        """The scalar layout's kernel: no fast-math flag (the engine's operations, bit for bit)."""
        return njit(nogil=True, error_model="numpy", cache=True)(fn)

    def _lanes_kernel(fn):
        return njit(nogil=True, error_model="numpy", cache=True, fastmath=_LANES_FASTMATH)(fn)

    def _inline(fn):
        """A piece of the lanes layout, inlined into its caller by numba (so the rows of the block's array keep
        their constant stride in the loops LLVM vectorises)."""
        return njit(nogil=True, error_model="numpy", inline="always", fastmath=_LANES_FASTMATH)(fn)
else:  # pragma: no cover - numba is a dependency; without it the kernels run as (very slow) Python
    def _kernel(fn):
        return fn

    _lanes_kernel = _inline = _kernel

#: the layouts of the kernel (module docstring)
LAYOUTS = ("lanes", "exact", "scalar")
#: runs per block of the lanes layout (the row length of its local state array: 8 is 10 % slower, 64 the same)
BLOCK = 32
#: the metrics :func:`reference_metrics` returns per seed (as :data:`ddmr_cli.engine.catalog.METRICS` defines them)
METRICS = ("deviation_mae", "deviation_rmse", "deviation_max", "e_x_mae", "e_y_mae", "e_theta_mae", "iae", "ise")

# rows of the run state S (N_STATE, n_runs) and of the lanes layout's local array L
X, Y, TH, DIST, W_R, W_L, WDP_R, WDP_L, N_R, N_L, Z_R, Z_L = range(12)
N_STATE = 12
# rows of the sums M (N_SUMS, n_runs); in L at SUMS + row
DEV, DEV2, ABS_EX, ABS_EY, ABS_ETH, DEV_MAX, DIV_STEP = range(7)
N_SUMS = 7
SUMS = N_STATE
# the lanes layout's per-step scratch rows of L
A_R, A_L, S_R, S_L, DN_R, DN_L, NN_R, NN_L, COS, SIN, ROUGH, ROLL = range(SUMS + N_SUMS, SUMS + N_SUMS + 12)
N_LOCAL = ROLL + 1


class Constants(NamedTuple):
    """Every number the kernels use, from the :class:`Simulation` (:func:`constants`)."""

    dt: float
    k_x: float
    k_y: float
    k_theta: float
    half_track: float
    inv_radius: float  # 1 / R
    half_radius: float  # R * 0.5 (forward kinematics, as the engine's)
    radius_over_track: float  # R / (2 L)
    inv_control_dt: float
    lam_R: float
    lam_L: float
    gain_R: float  # K
    gain_L: float
    inv_boundary: float  # 1 / Phi
    ndo_R: float  # L of the NDO
    ndo_L: float
    ndo_step_R: float  # dt L
    ndo_step_L: float
    jk_p: float  # J / K_u
    jk_q: float
    b_over_k: float  # B / K_u
    max_voltage: float
    voltage_gain: float  # K_u
    damping: float  # B
    jinv_p: float  # J^-1
    jinv_q: float
    ou_a_R: float
    ou_b_R: float
    ou_a_L: float
    ou_b_L: float
    n_neurons: int  # 0 without the network
    exponent_scale: float  # -1 / (2 sigma^2)
    learn_R: float  # dt gamma
    learn_L: float
    divergence_bound: float


def check_supported(sim: Simulation) -> None:
    """Refuse a configuration the kernel does not run (module docstring): ConfigError naming the key."""
    ctrl = sim.controller
    if type(ctrl) is not SMC:
        raise ConfigError("controller", getattr(ctrl, "name", type(ctrl).__name__),
                          "the reference kernel runs smc_ndo and smc_ndo_nno only")
    if ctrl.ndo is None:
        raise ConfigError("controller.ndo", None, "the reference kernel needs the NDO (smc_ndo, smc_ndo_nno)")
    if ctrl.surface != "proportional":
        raise ConfigError("controller.surface", ctrl.surface, "the reference kernel runs the proportional surface")
    if ctrl.switching != "sat":
        raise ConfigError("controller.switching", ctrl.switching, "the reference kernel runs sat switching")
    if sim.sensor.kind != "ideal":
        raise ConfigError("sensor.kind", sim.sensor.kind, "the reference kernel runs the ideal sensor")
    act = sim.actuator
    for key, value in (("delay", act.delay), ("lag", act.lag), ("pwm_bits", act.pwm_bits)):
        if value:
            raise ConfigError(f"actuator.{key}", value, "the reference kernel runs the ideal actuator")
    if sim.integrator != "euler":
        raise ConfigError("simulation.integrator", sim.integrator, "the reference kernel runs explicit Euler")
    if sim.control_steps != 1:
        raise ConfigError("control.rate", sim.control_rate, "the reference kernel runs control at every plant step")
    for phase in sim.scenario.phases:
        if phase.uncertainty:
            raise ConfigError(f"scenario.phases.{phase.name}.uncertainty", True,
                              "the reference kernel runs scenarios without damping uncertainty (paper_1)")
    if len({bool(p.roughness) for p in sim.scenario.phases}) > 1:
        raise ConfigError("scenario.phases", [p.name for p in sim.scenario.phases],
                          "the reference kernel needs the roughness on or off in every phase")


def constants(sim: Simulation) -> tuple[Constants, np.ndarray]:
    """The kernel's :class:`Constants` and the network's centres ``c_j`` [rad/s] (one 0 without a network) from the
    simulation, through the engine's own set-up functions."""
    nominal = NominalModel.from_robot(sim.robot)
    plant = sim.robot.plant()
    if (plant.voltage_gain, plant.damping, plant.jinv_p, plant.jinv_q) != (
            nominal.voltage_gain, nominal.damping, nominal.jinv_p, nominal.jinv_q):
        raise ValueError("the reference kernel shares the nominal model's f(w) + g u with the plant's")
    p = sim.controller.law_parameters(nominal, sim.control_dt)
    dt = float(sim.dt)
    (a_R, b_R), (a_L, b_L) = (ou_coefficients(dt, sim.terrain.correlation_time) for _ in range(2))
    nn = p.nn.n_neurons if p.has_nn else 0
    gains = sim.outer_loop
    c = Constants(
        dt=dt, k_x=float(gains.k_x), k_y=float(gains.k_y), k_theta=float(gains.k_theta),
        half_track=plant.half_track, inv_radius=1.0 / plant.wheel_radius, half_radius=plant.wheel_radius * 0.5,
        radius_over_track=plant.wheel_radius / (2.0 * plant.half_track), inv_control_dt=1.0 / sim.control_dt,
        lam_R=p.lam[0], lam_L=p.lam[1], gain_R=p.switching_gain[0], gain_L=p.switching_gain[1],
        inv_boundary=1.0 / p.boundary_layer, ndo_R=p.ndo.gain[0], ndo_L=p.ndo.gain[1],
        ndo_step_R=p.dt * p.ndo.gain[0], ndo_step_L=p.dt * p.ndo.gain[1],
        jk_p=nominal.j_over_ku_p, jk_q=nominal.j_over_ku_q, b_over_k=nominal.damping_over_gain,
        max_voltage=plant.max_voltage, voltage_gain=nominal.voltage_gain, damping=nominal.damping,
        jinv_p=nominal.jinv_p, jinv_q=nominal.jinv_q, ou_a_R=a_R, ou_b_R=b_R, ou_a_L=a_L, ou_b_L=b_L,
        n_neurons=nn, exponent_scale=-0.5 / (p.nn.width * p.nn.width),
        learn_R=p.dt * p.nn.learning_rate[0], learn_L=p.dt * p.nn.learning_rate[1],
        divergence_bound=float(sim.divergence_bound))
    centers = np.array([plain(rbf.center)(p.nn, q) for q in range(nn)] or [0.0])  # the engine's c_j, not linspace's
    return c, centers


# ---------------------------------------------------------------------------------------------------------------
# The lanes layout's sin, cos and exp: the engine's (:mod:`ddmr_cli.model.elementary`), compiled inline with the
# lanes layout's fast-math flag; the engine's wrap, written again (branch-free for the lanes layout).

#: ``(sin x, cos x)``, :func:`ddmr_cli.model.elementary.sincos` inlined with fused multiply-adds
sincos = _inline(plain(elementary.sincos))
#: ``exp(x)`` for ``x <= 0``, :func:`ddmr_cli.model.elementary.exp_neg` inlined with fused multiply-adds
exp_neg = _inline(plain(elementary.exp_neg))


@_inline
def wrap_fast(angle):
    """The engine's wrap into (-pi, pi] (:func:`ddmr_cli.model.kinematics.wrap_angle`), branch-free: outside
    its fast path a floor-based modulo (an ulp of the angle from Python's ``%``; never taken on the paper's line)."""
    turned = math.pi - angle
    inside = 0.0 <= turned < 2.0 * math.pi
    m = turned if inside else turned - 2.0 * math.pi * math.floor(turned * (1.0 / (2.0 * math.pi)))
    wrapped = math.pi - m
    return wrapped + 2.0 * math.pi if wrapped <= -math.pi else wrapped


@_inline
def wrap(angle):
    """The engine's wrap into (-pi, pi] (:func:`ddmr_cli.model.kinematics.wrap_angle`), written again."""
    turned = math.pi - angle
    wrapped = math.pi - (turned if 0.0 <= turned < 2.0 * math.pi else turned % (2.0 * math.pi))
    return wrapped + 2.0 * math.pi if wrapped <= -math.pi else wrapped


# ---------------------------------------------------------------------------------------------------------------
# The lanes layout: one loop over a block's runs per stage of a step (module docstring).

@_inline
def _lanes_control(L, nb, k, x_r, y_r, th_r, v_r, om_r, wdd_scale, c, libm):
    """Pose error (2), metrics (7), Kanayama (3), inverse kinematics (4)-(5), w_d', the surface and (17) less the
    network's estimate, the NDO's estimate (21); sine and cosine libm's when ``libm`` (a constant of the layout:
    LLVM drops the other branch), else fdlibm's vectorised :func:`sincos`."""
    for l in range(nb):
        x, y, th, w_R, w_L = L[X, l], L[Y, l], L[TH, l], L[W_R, l], L[W_L, l]
        dx = x_r - x
        dy = y_r - y
        if libm:
            sn, cs = math.sin(th), math.cos(th)
        else:
            sn, cs = sincos(th)
        e_x = cs * dx + sn * dy
        e_y = cs * dy - sn * dx
        e_th = wrap_fast(th_r - th)
        dev = math.sqrt(dx * dx + dy * dy)
        if libm:
            se, ce = math.sin(e_th), math.cos(e_th)
        else:
            se, ce = sincos(e_th)
        v_d = v_r * ce + c.k_x * e_x
        om_d = om_r + v_r * (c.k_y * e_y + c.k_theta * se)
        wd_R = (v_d + c.half_track * om_d) * c.inv_radius
        wd_L = (v_d - c.half_track * om_d) * c.inv_radius
        wdd_R = (wd_R - L[WDP_R, l]) * wdd_scale
        wdd_L = (wd_L - L[WDP_L, l]) * wdd_scale
        L[WDP_R, l] = wd_R
        L[WDP_L, l] = wd_L
        s_R = wd_R - w_R
        s_L = wd_L - w_L
        L[DN_R, l] = L[Z_R, l] + c.ndo_R * w_R
        L[DN_L, l] = L[Z_L, l] + c.ndo_L * w_L
        L[A_R, l] = wdd_R + c.lam_R * s_R + c.gain_R * min(max(s_R * c.inv_boundary, -1.0), 1.0)
        L[A_L, l] = wdd_L + c.lam_L * s_L + c.gain_L * min(max(s_L * c.inv_boundary, -1.0), 1.0)
        L[S_R, l] = s_R
        L[S_L, l] = s_L
        L[COS, l] = cs
        L[SIN, l] = sn
        L[NN_R, l] = 0.0
        L[NN_L, l] = 0.0
        L[SUMS + DEV, l] += dev
        L[SUMS + DEV2, l] += dev * dev
        L[SUMS + ABS_EX, l] += abs(e_x)
        L[SUMS + ABS_EY, l] += abs(e_y)
        L[SUMS + ABS_ETH, l] += abs(e_th)
        L[SUMS + DEV_MAX, l] = dev if dev > L[SUMS + DEV_MAX, l] else L[SUMS + DEV_MAX, l]
        diverging = not dev <= c.divergence_bound and L[SUMS + DIV_STEP, l] < 0.0
        L[SUMS + DIV_STEP, l] = k if diverging else L[SUMS + DIV_STEP, l]


@_inline
def _lanes_live(L, nb, center, scale):
    """Whether neuron ``center``'s exponent reaches :data:`EXP_ZERO` for some run of the block."""
    live = False
    for l in range(nb):
        live |= ((L[W_R, l] - center) ** 2 + (L[W_L, l] - center) ** 2) * scale >= EXP_ZERO
    return live


@_inline
def _lanes_neuron(L, nb, q, center, scale, PHI, WN):
    """Neuron ``q`` of the network (27), and its term of the estimate (24)."""
    for l in range(nb):
        phi = exp_neg(((L[W_R, l] - center) ** 2 + (L[W_L, l] - center) ** 2) * scale)
        PHI[q, l] = phi
        L[NN_R, l] += WN[q, 0, l] * phi
        L[NN_L, l] += WN[q, 1, l] * phi


@_inline
def _lanes_zone(L, nb, edge, rough, roll):
    """The terrain zone starting at ``edge`` for the runs past it."""
    for l in range(nb):
        past = L[DIST, l] >= edge
        L[ROUGH, l] = rough if past else L[ROUGH, l]
        L[ROLL, l] = roll if past else L[ROLL, l]


@_inline
def _lanes_plant(L, nb, xi, b0, j, c):
    """The voltage (17), saturated; the NDO's update (22); the OU noise; the plant (8) with the terrain; Euler."""
    for l in range(nb):
        i = b0 + l
        w_R, w_L = L[W_R, l], L[W_L, l]
        dn_R, dn_L = L[DN_R, l], L[DN_L, l]
        a_R = L[A_R, l] - (dn_R + L[NN_R, l])
        a_L = L[A_L, l] - (dn_L + L[NN_L, l])
        u_R = c.jk_p * a_R + c.jk_q * a_L + c.b_over_k * w_R
        u_L = c.jk_q * a_R + c.jk_p * a_L + c.b_over_k * w_L
        u_R = min(max(u_R, -c.max_voltage), c.max_voltage)
        u_L = min(max(u_L, -c.max_voltage), c.max_voltage)
        m_R = c.voltage_gain * u_R - c.damping * w_R
        m_L = c.voltage_gain * u_L - c.damping * w_L
        f_R = c.jinv_p * m_R + c.jinv_q * m_L
        f_L = c.jinv_q * m_R + c.jinv_p * m_L
        L[Z_R, l] -= c.ndo_step_R * (dn_R + f_R)
        L[Z_L, l] -= c.ndo_step_L * (dn_L + f_L)
        n_R = c.ou_b_R * xi[i, j, 0] + c.ou_a_R * L[N_R, l]
        n_L = c.ou_b_L * xi[i, j, 1] + c.ou_a_L * L[N_L, l]
        L[N_R, l] = n_R
        L[N_L, l] = n_L
        rough, roll = L[ROUGH, l], L[ROLL, l]
        t_R = (1.0 if w_R > 0.0 else (-1.0 if w_R < 0.0 else 0.0)) * roll
        t_L = (1.0 if w_L > 0.0 else (-1.0 if w_L < 0.0 else 0.0)) * roll
        d_R = -n_R * rough - (c.jinv_p * t_R + c.jinv_q * t_L)
        d_L = -n_L * rough - (c.jinv_q * t_R + c.jinv_p * t_L)
        v = c.half_radius * (w_R + w_L)
        om = c.radius_over_track * (w_R - w_L)
        L[X, l] += c.dt * (v * L[COS, l])
        L[Y, l] += c.dt * (v * L[SIN, l])
        L[TH, l] += c.dt * om
        L[DIST, l] += c.dt * abs(v)
        L[W_R, l] = w_R + c.dt * (f_R + d_R)
        L[W_L, l] = w_L + c.dt * (f_L + d_L)


@_inline
def _lanes_learn(L, nb, q, c, PHI, WN):
    """The network's update (25) for neuron ``q``."""
    for l in range(nb):
        WN[q, 0, l] -= (c.learn_R * L[S_R, l]) * PHI[q, l]
        WN[q, 1, l] -= (c.learn_L * L[S_L, l]) * PHI[q, l]


@_inline
def _lanes_steps(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi, libm):
    """Advance every run by steps ``k0 .. k0 + n - 1``, a block of runs at a time (the lanes layouts), ``xi[r, j]``
    run r's normals of step k0 + j; libm's sine and cosine when ``libm`` (:func:`_lanes_control`)."""
    n_runs, nn = S.shape[1], c.n_neurons
    L = np.zeros((N_LOCAL, BLOCK))  # the block's state and scratch, rows (field, run): BLOCK is a constant stride
    PHI = np.zeros((max(nn, 1), BLOCK))
    WN = np.zeros((max(nn, 1), 2, BLOCK))
    live = np.zeros(max(nn, 1), dtype=np.bool_)
    for b0 in range(0, n_runs, BLOCK):
        nb = min(BLOCK, n_runs - b0)
        for l in range(nb):
            for f in range(N_STATE):
                L[f, l] = S[f, b0 + l]
            for f in range(N_SUMS):
                L[SUMS + f, l] = M[f, b0 + l]
            for q in range(nn):
                WN[q, 0, l] = W[q, 0, b0 + l]
                WN[q, 1, l] = W[q, 1, b0 + l]
        for j in range(n):
            k = k0 + j
            _lanes_control(L, nb, k, reference[k, 0], reference[k, 1], reference[k, 2], reference[k, 3],
                           reference[k, 4], c.inv_control_dt if k > 0 else 0.0, c, libm)
            for q in range(nn):
                live[q] = _lanes_live(L, nb, centers[q], c.exponent_scale)
                if live[q]:
                    _lanes_neuron(L, nb, q, centers[q], c.exponent_scale, PHI, WN)
            for l in range(nb):
                L[ROUGH, l] = rough[0]
                L[ROLL, l] = roll[0]
            for e in range(edges.shape[0]):
                _lanes_zone(L, nb, edges[e], rough[e + 1], roll[e + 1])
            _lanes_plant(L, nb, xi, b0, j, c)
            for q in range(nn):
                if live[q]:
                    _lanes_learn(L, nb, q, c, PHI, WN)
        for l in range(nb):
            for f in range(N_STATE):
                S[f, b0 + l] = L[f, l]
            for f in range(N_SUMS):
                M[f, b0 + l] = L[SUMS + f, l]
            for q in range(nn):
                W[q, 0, b0 + l] = WN[q, 0, l]
                W[q, 1, b0 + l] = WN[q, 1, l]


@_lanes_kernel
def lanes_chunk(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi):
    """Advance every run by steps ``k0 .. k0 + n - 1`` (lanes layout: fdlibm's vectorised sine and cosine, fused
    multiply-adds), ``xi[r, j]`` run r's normals of step k0 + j."""
    _lanes_steps(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi, False)


@_kernel
def exact_chunk(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi):
    """Advance every run by steps ``k0 .. k0 + n - 1`` (exact layout: the lanes layout with libm's sine and cosine
    a lane at a time and no fast-math flag); arguments as :func:`lanes_chunk`."""
    _lanes_steps(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi, True)


# ---------------------------------------------------------------------------------------------------------------
# The scalar layout: one run at a time, the engine's libm calls in the engine's order.

@_kernel
def scalar_chunk(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi):
    """Advance every run by steps ``k0 .. k0 + n - 1`` (scalar layout); arguments as :func:`lanes_chunk`."""
    nn = c.n_neurons
    phi = np.zeros(max(nn, 1))
    for r in range(S.shape[1]):
        x, y, th, dist = S[X, r], S[Y, r], S[TH, r], S[DIST, r]
        w_R, w_L, wdp_R, wdp_L = S[W_R, r], S[W_L, r], S[WDP_R, r], S[WDP_L, r]
        n_R, n_L, z_R, z_L = S[N_R, r], S[N_L, r], S[Z_R, r], S[Z_L, r]
        dev_sum, dev2_sum, ex_sum, ey_sum = M[DEV, r], M[DEV2, r], M[ABS_EX, r], M[ABS_EY, r]
        eth_sum, dev_max, div_step = M[ABS_ETH, r], M[DEV_MAX, r], M[DIV_STEP, r]
        for j in range(n):
            k = k0 + j
            x_r, y_r, th_r, v_r, om_r = (reference[k, 0], reference[k, 1], reference[k, 2], reference[k, 3],
                                         reference[k, 4])
            dx = x_r - x
            dy = y_r - y
            cs, sn = math.cos(th), math.sin(th)
            e_x = cs * dx + sn * dy
            e_y = cs * dy - sn * dx
            e_th = wrap(th_r - th)
            dev = math.sqrt(dx * dx + dy * dy)
            v_d = v_r * math.cos(e_th) + c.k_x * e_x
            om_d = om_r + v_r * (c.k_y * e_y + c.k_theta * math.sin(e_th))
            wd_R = (v_d + c.half_track * om_d) * c.inv_radius
            wd_L = (v_d - c.half_track * om_d) * c.inv_radius
            wdd_R = 0.0 if k == 0 else (wd_R - wdp_R) * c.inv_control_dt
            wdd_L = 0.0 if k == 0 else (wd_L - wdp_L) * c.inv_control_dt
            wdp_R, wdp_L = wd_R, wd_L
            s_R, s_L = wd_R - w_R, wd_L - w_L
            dn_R = z_R + c.ndo_R * w_R
            dn_L = z_L + c.ndo_L * w_L
            nn_R = nn_L = 0.0
            for q in range(nn):  # the basis first, then the sums (the engine's order: its exp loop vectorises)
                phi[q] = elementary.exp_neg(((w_R - centers[q]) ** 2 + (w_L - centers[q]) ** 2) * c.exponent_scale)
            for q in range(nn):
                nn_R += W[q, 0, r] * phi[q]
                nn_L += W[q, 1, r] * phi[q]
            a_R = wdd_R + c.lam_R * s_R + c.gain_R * min(max(s_R * c.inv_boundary, -1.0), 1.0) - (dn_R + nn_R)
            a_L = wdd_L + c.lam_L * s_L + c.gain_L * min(max(s_L * c.inv_boundary, -1.0), 1.0) - (dn_L + nn_L)
            u_R = c.jk_p * a_R + c.jk_q * a_L + c.b_over_k * w_R
            u_L = c.jk_q * a_R + c.jk_p * a_L + c.b_over_k * w_L
            u_R = min(max(u_R, -c.max_voltage), c.max_voltage)
            u_L = min(max(u_L, -c.max_voltage), c.max_voltage)
            m_R = c.voltage_gain * u_R - c.damping * w_R
            m_L = c.voltage_gain * u_L - c.damping * w_L
            f_R = c.jinv_p * m_R + c.jinv_q * m_L
            f_L = c.jinv_q * m_R + c.jinv_p * m_L
            z_R -= c.ndo_step_R * (dn_R + f_R)
            z_L -= c.ndo_step_L * (dn_L + f_L)
            for q in range(nn):
                W[q, 0, r] -= (c.learn_R * s_R) * phi[q]
                W[q, 1, r] -= (c.learn_L * s_L) * phi[q]
            n_R = c.ou_b_R * xi[r, j, 0] + c.ou_a_R * n_R
            n_L = c.ou_b_L * xi[r, j, 1] + c.ou_a_L * n_L
            zone = 0
            while zone < edges.shape[0] and dist >= edges[zone]:
                zone += 1
            t_R = (1.0 if w_R > 0.0 else (-1.0 if w_R < 0.0 else 0.0)) * roll[zone]
            t_L = (1.0 if w_L > 0.0 else (-1.0 if w_L < 0.0 else 0.0)) * roll[zone]
            d_R = -n_R * rough[zone] - (c.jinv_p * t_R + c.jinv_q * t_L)
            d_L = -n_L * rough[zone] - (c.jinv_q * t_R + c.jinv_p * t_L)
            dev_sum += dev
            dev2_sum += dev * dev
            ex_sum += abs(e_x)
            ey_sum += abs(e_y)
            eth_sum += abs(e_th)
            if dev > dev_max:
                dev_max = dev
            if not dev <= c.divergence_bound and div_step < 0.0:
                div_step = k
            v = c.half_radius * (w_R + w_L)
            om = c.radius_over_track * (w_R - w_L)
            x += c.dt * (v * cs)
            y += c.dt * (v * sn)
            th += c.dt * om
            dist += c.dt * abs(v)
            w_R += c.dt * (f_R + d_R)
            w_L += c.dt * (f_L + d_L)
        S[X, r], S[Y, r], S[TH, r], S[DIST, r] = x, y, th, dist
        S[W_R, r], S[W_L, r], S[WDP_R, r], S[WDP_L, r] = w_R, w_L, wdp_R, wdp_L
        S[N_R, r], S[N_L, r], S[Z_R, r], S[Z_L, r] = n_R, n_L, z_R, z_L
        M[DEV, r], M[DEV2, r], M[ABS_EX, r], M[ABS_EY, r] = dev_sum, dev2_sum, ex_sum, ey_sum
        M[ABS_ETH, r], M[DEV_MAX, r], M[DIV_STEP, r] = eth_sum, dev_max, div_step


_CHUNK_KERNELS = {"lanes": lanes_chunk, "exact": exact_chunk, "scalar": scalar_chunk}


def reference_metrics(sim: Simulation, seeds: Sequence[int], layout: str = "lanes") -> dict[str, np.ndarray]:
    """Run the paper's loop for every seed with the hand-fused kernel and return its per-seed metrics.

    Parameters
    ----------
    sim : Simulation
        A configuration the kernel supports (:func:`check_supported`); validated as :func:`simulate` does.
    seeds : sequence of int
        One run per seed, on the engine's noise stream of that seed.
    layout : {'lanes', 'exact', 'scalar'}
        The kernel's layout (module docstring); the same numbers to rounding.

    Returns
    -------
    dict of str -> ndarray
        :data:`METRICS` (float, shape ``(len(seeds),)``, NaN for a diverged run, as the engine's whole-run
        metrics), ``diverged`` (bool) and ``divergence_time`` [s] (NaN where not diverged).

    Raises
    ------
    ConfigError
        On a configuration the kernel does not run (naming the key) or an invalid one.
    """
    if layout not in LAYOUTS:
        raise ValueError(f"layout must be one of {LAYOUTS}, not {layout!r}")
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ConfigError("run.n_runs", 0, "must be >= 1")
    sim.validate()
    check_supported(sim)
    c, centers = constants(sim)
    n_runs, n_steps, nn = len(seeds), sim.n_steps, c.n_neurons
    reference = reference_table(sim.trajectory, n_steps, c.dt)
    edges = np.ascontiguousarray(sim.terrain.inner_edges, dtype=float)
    roughness_on = float(bool(sim.scenario.phases[0].roughness))
    rough = np.ascontiguousarray(sim.terrain.roughness * roughness_on, dtype=float)
    roll = np.ascontiguousarray(sim.robot.rolling_resistance_torque(sim.terrain.mu), dtype=float)
    noise = NoiseStreams(seeds)
    S = np.zeros((N_STATE, n_runs))
    S[X], S[Y], S[TH] = (float(v) for v in sim.initial_pose)
    S[W_R], S[W_L] = w0 = _initial_wheel_speeds(sim)
    S[[N_R, N_L]] = noise.initial_state()[:, :2].T
    S[Z_R], S[Z_L] = -c.ndo_R * w0[0], -c.ndo_L * w0[1]  # d_hat(0) = 0 (ndo.start)
    M = np.zeros((N_SUMS, n_runs))
    M[DEV_MAX], M[DIV_STEP] = -np.inf, -1.0
    W = np.zeros((max(nn, 1), 2, n_runs))
    kernel = _CHUNK_KERNELS[layout]
    chunk = chunk_steps(8 * NoiseStreams.channels, n_runs)
    xi = None
    with np.errstate(all="ignore"):
        k0 = 0
        while k0 < n_steps:
            n = min(chunk, n_steps - k0)
            if xi is None or xi.shape[1] != n:
                xi = np.empty((n_runs, n, NoiseStreams.channels))
            noise.next_chunk(n, xi)
            kernel(k0, n, c, reference, centers, edges, rough, roll, S, W, M, xi)
            k0 += n
        count = float(n_steps)
        out = {"deviation_mae": M[DEV] / count, "deviation_rmse": np.sqrt(M[DEV2] / count),
               "deviation_max": np.where(np.isfinite(M[DEV_MAX]), M[DEV_MAX], np.nan),
               "e_x_mae": M[ABS_EX] / count, "e_y_mae": M[ABS_EY] / count, "e_theta_mae": M[ABS_ETH] / count,
               "iae": M[DEV] * c.dt, "ise": M[DEV2] * c.dt}
    diverged = M[DIV_STEP] >= 0
    for values in out.values():
        values[diverged] = np.nan
    out["diverged"] = diverged
    out["divergence_time"] = np.where(diverged, M[DIV_STEP] * c.dt, np.nan)
    return out


def reference_throughput(sim: Simulation, n_runs: int, layout: str = "lanes") -> float:
    """Simulated steps per second (runs x steps / wall time) of one :func:`reference_metrics` call on seeds
    ``0 .. n_runs - 1``: set-up, noise and kernel, as the bench times :func:`simulate` (warm it up first: the
    first call in a process compiles, or loads the kernels from numba's cache)."""
    started = time.perf_counter()
    reference_metrics(sim, range(n_runs), layout)
    return n_runs * sim.n_steps / (time.perf_counter() - started)


__all__ = ["BLOCK", "LAYOUTS", "METRICS", "Constants", "check_supported", "constants", "exp_neg",
           "reference_metrics", "reference_throughput", "sincos"]
