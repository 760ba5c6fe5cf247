"""PID wheel-speed controller, the paper's linear baseline (Table 3; docs/model.md §6).

``u = K_p e + K_i int e + K_d e'`` on the wheel-speed error ``e = w_d - w``, with no feed-forward; ``e'`` is
the backward difference of ``e`` (zero at the first step). Anti-windup by conditional integration: the
integrator holds while a wheel is saturated and its error would drive it further into saturation.
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

import numpy as np

from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.checks import boolean, compact, per_wheel
from ddmr_cli.control.base import (DIAGNOSTICS, SAT_L, SAT_R, SURFACE, UC_L, UC_R, W_L, W_R, WD_L, WD_R, Diagnostic,
                                   WheelController)
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.dynamics import sign
from ddmr_cli.model.robot import NominalModel


class PIDParameters(NamedTuple):
    kp: tuple  # (right, left) [V s/rad]
    ki: tuple  # [V/rad]
    kd: tuple  # [V s^2/rad]
    anti_windup: bool
    dt: float  # [s]


@law
def start(p, st, w0_R, w0_L):
    """The integral and the previous error start at zero."""
    st["integral"][0] = 0.0
    st["integral"][1] = 0.0
    st["e_prev"][0] = 0.0
    st["e_prev"][1] = 0.0


@law
def pid(kp, ki, kd, e, integral, e_dot):
    """``u = K_p e + K_i int e + K_d e'`` [V] (Table 3)."""
    return kp * e + ki * integral + kd * e_dot


@law
def error_rate(k, e, e_prev, dt):
    """``e' = (e_k - e_k-1) / dt`` [rad/s^2], 0 at the first step."""
    return 0.0 if k == 0 else (e - e_prev) * (1.0 / dt)


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """PID per wheel on ``e = w_d - w``."""
    e_R, e_L = wd_R - w_R, wd_L - w_L
    ed_R, ed_L = error_rate(k, e_R, st["e_prev"][0], p.dt), error_rate(k, e_L, st["e_prev"][1], p.dt)
    st["e_prev"][0] = e_R
    st["e_prev"][1] = e_L
    u_R = pid(p.kp[0], p.ki[0], p.kd[0], e_R, st["integral"][0], ed_R)
    u_L = pid(p.kp[1], p.ki[1], p.kd[1], e_L, st["integral"][1], ed_L)
    st["diagnostics"][0, 0] = e_R
    st["diagnostics"][0, 1] = e_L
    return u_R, u_L


@law
def integrand(e, u_command, saturated, anti_windup):
    """What the integrator adds per second: ``e``, or 0 while saturated with ``e`` pushing further in."""
    if anti_windup and saturated and sign(e) == sign(u_command):
        return 0.0
    return e


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """One Euler step of the integral of the error, with conditional integration."""
    st["integral"][0] += p.dt * integrand(wd_R - w_R, uc_R, sat_R, p.anti_windup)
    st["integral"][1] += p.dt * integrand(wd_L - w_L, uc_L, sat_L, p.anti_windup)


# --- lanes (ddmr_cli.control.base, "Lanes"): the laws above over a block of runs ----------------------------------
#: rows of the controller's array C of a block: the error integral and the previous error, per wheel
INTEGRAL_R, INTEGRAL_L, E_PREV_R, E_PREV_L = range(4)
#: rows of C (ddmr_cli.control.base, "Lanes")
LANE_STATE_ROWS = 4


@law
def lanes_load(p, st, C, l):
    """Run record ``st`` into lane ``l`` of ``C``."""
    C[INTEGRAL_R, l], C[INTEGRAL_L, l] = st["integral"][0], st["integral"][1]
    C[E_PREV_R, l], C[E_PREV_L, l] = st["e_prev"][0], st["e_prev"][1]


@law
def lanes_store(p, st, C, l):
    """Lane ``l`` of ``C`` back into run record ``st``."""
    st["integral"][0], st["integral"][1] = C[INTEGRAL_R, l], C[INTEGRAL_L, l]
    st["e_prev"][0], st["e_prev"][1] = C[E_PREV_R, l], C[E_PREV_L, l]


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``."""
    for l in range(nb):
        e_R, e_L = L[WD_R, l] - L[W_R, l], L[WD_L, l] - L[W_L, l]
        ed_R, ed_L = error_rate(k, e_R, C[E_PREV_R, l], p.dt), error_rate(k, e_L, C[E_PREV_L, l], p.dt)
        C[E_PREV_R, l], C[E_PREV_L, l] = e_R, e_L
        L[UC_R, l] = pid(p.kp[0], p.ki[0], p.kd[0], e_R, C[INTEGRAL_R, l], ed_R)
        L[UC_L, l] = pid(p.kp[1], p.ki[1], p.kd[1], e_L, C[INTEGRAL_L, l], ed_L)
        L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l] = e_R, e_L


@inlined_law
def lanes_update(p, C, L, nb):
    """:func:`update` for lanes ``0 .. nb - 1``."""
    for l in range(nb):
        C[INTEGRAL_R, l] += p.dt * integrand(L[WD_R, l] - L[W_R, l], L[UC_R, l], L[SAT_R, l] != 0.0, p.anti_windup)
        C[INTEGRAL_L, l] += p.dt * integrand(L[WD_L, l] - L[W_L, l], L[UC_L, l], L[SAT_L, l] != 0.0, p.anti_windup)


def _pd_spectral_radius(dt_g_kp: float, g_kd: float) -> float:
    """Largest |root| of the sampled wheel-speed loop under PD with a backward-difference derivative,
    ``e_k+1 = (1 - dt g K_p - g K_d) e_k + g K_d e_k-1`` (the integral term is slow and left out).

    The roots of ``z^2 - a z - b`` in closed form (no LAPACK, so the verdict is the same on every CPU):
    real ``(a +- sqrt(a^2 + 4 b)) / 2``, or a complex pair of modulus ``sqrt(-b)``."""
    a, b = float(1.0 - dt_g_kp - g_kd), float(g_kd)  # Python floats: an extreme gain overflows to inf, unwarned
    disc = a * a + 4.0 * b
    if disc >= 0.0:
        root = math.sqrt(disc)
        return max(abs(0.5 * (a + root)), abs(0.5 * (a - root)))
    return math.sqrt(-b)


class PID(WheelController):
    """PID on the wheel-speed error (docs/model.md §6).

    Parameters
    ----------
    kp, ki, kd : float or (float, float)
        Gains per wheel [V s/rad, V/rad, V s^2/rad] (Table 3: 5, 0.1, 0.01).
    anti_windup : bool
        Hold the integrator while saturated.
    """

    name = "pid"
    laws = sys.modules[__name__]

    def __init__(self, *, kp, ki, kd, anti_windup: bool) -> None:
        self.kp = per_wheel("controller.kp", kp)
        self.ki = per_wheel("controller.ki", ki)
        self.kd = per_wheel("controller.kd", kd)
        self.anti_windup = boolean("controller.anti_windup", anti_windup)

    def law_parameters(self, nominal: NominalModel, dt: float) -> PIDParameters:
        return PIDParameters(self.kp, self.ki, self.kd, self.anti_windup, float(dt))

    def state_fields(self):
        return [("integral", "f8", 2), ("e_prev", "f8", 2)]

    def diagnostics(self):
        return (Diagnostic("s", SURFACE, "the speed error w_d - w [rad/s] (no sliding surface)"),)

    def check_step(self, nominal: NominalModel, dt: float, integrator: str) -> None:
        """The sampled PD loop ``e_k+1 = (1 - dt g K_p - g K_d) e_k + g K_d e_k-1`` must be stable (docs/model.md
        §4): its spectral radius below 1 with ``g`` the nominal input gain's largest eigenvalue."""
        g = max(nominal.jinv_p + nominal.jinv_q, nominal.jinv_p - nominal.jinv_q) * nominal.voltage_gain
        kp, kd = max(self.kp), max(self.kd)
        if _pd_spectral_radius(dt * g * kp, g * kd) >= 1.0:
            stable = [h for h in np.geomspace(dt, dt * 1e-3, 61) if _pd_spectral_radius(h * g * kp, g * kd) < 1]
            bound = f"must be < {stable[0]:.3g} s" if stable else "has no stable value"
            raise ConfigError("simulation.dt", dt, f"{bound}: the sampled PD loop (controller.kp={kp:g}, "
                                                   f"controller.kd={kd:g}) is unstable at this step")

    def parameters(self):
        return {"K_p": compact(self.kp), "K_i": compact(self.ki), "K_d": compact(self.kd),
                "anti_windup": self.anti_windup}
