"""Super-twisting sliding-mode wheel-speed controller (Levant 1993), with the optional NDO (docs/model.md §6,
"Super-twisting").

In the sign convention of the paper's (17), on ``s = e = w_d - w`` (10):
``u = g^-1 (w_d' - f(w) + k1 |s|^(1/2) sign(s) + v - d_hat)``, ``v' = k2 sign(s)``, ``v(0) = 0``, so that
``s' = -k1 |s|^(1/2) sign(s) - v - (d - d_hat)``: with ``z = -(v + d - d_hat)`` the standard super-twisting form
``s' = -k1 |s|^(1/2) sign(s) + z``, ``z' = -k2 sign(s) - (d - d_hat)'``. ``v`` is advanced by explicit Euler;
``u`` is continuous in time (the discontinuity is integrated), unlike sign-SMC's. ``v`` is an integrator: with
``anti_windup`` it is held while the wheel is saturated and ``sign(s)`` would drive it further in (the PID's
conditional integration, :func:`ddmr_cli.control.pid.integrand`).
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

from ddmr_cli.checks import boolean, compact, per_wheel, positive
from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.control import ndo
from ddmr_cli.control.pid import integrand
from ddmr_cli.control.base import (DIAGNOSTICS, ESTIMATE, SAT_L, SAT_R, SURFACE, U_L, U_R, UC_L, UC_R, W_L, W_R, WD_L,
                                   WD_R, WDD_L, WDD_R, Diagnostic, StepRate, WheelController)
from ddmr_cli.model.dynamics import sign, voltage_for
from ddmr_cli.model.robot import NominalModel


class STAParameters(NamedTuple):
    k1: tuple  # per wheel [(rad/s)^(1/2) / s]
    k2: tuple  # per wheel [rad/s^3]
    anti_windup: bool
    nominal: NominalModel
    dt: float  # [s]
    has_ndo: bool
    ndo: ndo.NDOParameters


@law
def super_twisting(s, k1, v):
    """The super-twisting term ``k1 |s|^(1/2) sign(s) + v`` [rad/s^2]."""
    return k1 * math.sqrt(abs(s)) * sign(s) + v


@law
def start(p, st, w0_R, w0_L):
    """``v(0) = 0``; the NDO starts at ``d_hat(0) = 0``."""
    st["v"][0] = 0.0
    st["v"][1] = 0.0
    if p.has_ndo:
        ndo.start(p.ndo, st["z"], w0_R, w0_L)


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """``u = g^-1 (w_d' - f(w) + k1 |s|^(1/2) sign(s) + v - d_hat)`` per wheel, ``s = w_d - w``."""
    s_R, s_L = wd_R - w_R, wd_L - w_L
    dndo_R = dndo_L = 0.0
    diagnostics = st["diagnostics"]  # rows: s, then NDO when present (SuperTwisting.diagnostics)
    if p.has_ndo:
        dndo_R, dndo_L = ndo.estimate(p.ndo, st["z"], w_R, w_L)
        diagnostics[1, 0], diagnostics[1, 1] = dndo_R, dndo_L
    diagnostics[0, 0], diagnostics[0, 1] = s_R, s_L
    a_R = wdd_R + super_twisting(s_R, p.k1[0], st["v"][0]) - dndo_R
    a_L = wdd_L + super_twisting(s_L, p.k1[1], st["v"][1]) - dndo_L
    u_R, u_L = voltage_for(p.nominal, a_R, a_L, w_R, w_L)
    return u_R, u_L


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """One Euler step of ``v' = k2 sign(s)`` (held while saturated further in, with anti-windup) and of the NDO."""
    st["v"][0] += (p.dt * p.k2[0]) * integrand(sign(wd_R - w_R) * 1.0, uc_R, sat_R, p.anti_windup)
    st["v"][1] += (p.dt * p.k2[1]) * integrand(sign(wd_L - w_L) * 1.0, uc_L, sat_L, p.anti_windup)
    if p.has_ndo:
        ndo.update(p.ndo, p.nominal, p.dt, st["z"], st["diagnostics"][1, 0], st["diagnostics"][1, 1], w_R, w_L, u_R,
                   u_L)


# --- lanes (ddmr_cli.control.base, "Lanes"): the laws above over a block of runs ----------------------------------
#: rows of the controller's array C of a block: the integral v, the NDO's state, the NDO's estimate this step
V_R, V_L, Z_R, Z_L, DNDO_R, DNDO_L = range(6)
#: rows of C (ddmr_cli.control.base, "Lanes")
LANE_STATE_ROWS = 6


@law
def lanes_load(p, st, C, l):
    """Run record ``st`` into lane ``l`` of ``C``."""
    C[V_R, l], C[V_L, l] = st["v"][0], st["v"][1]
    C[Z_R, l], C[Z_L, l] = st["z"][0], st["z"][1]


@law
def lanes_store(p, st, C, l):
    """Lane ``l`` of ``C`` back into run record ``st``."""
    st["v"][0], st["v"][1] = C[V_R, l], C[V_L, l]
    st["z"][0], st["z"][1] = C[Z_R, l], C[Z_L, l]


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``: the NDO's estimate (21), then the super-twisting voltage."""
    for l in range(nb):
        w_R, w_L = L[W_R, l], L[W_L, l]
        s_R, s_L = L[WD_R, l] - w_R, L[WD_L, l] - w_L
        dndo_R, dndo_L = ndo.estimate_of(p.ndo, C[Z_R, l], C[Z_L, l], w_R, w_L) if p.has_ndo else (0.0, 0.0)
        C[DNDO_R, l], C[DNDO_L, l] = dndo_R, dndo_L
        a_R = L[WDD_R, l] + super_twisting(s_R, p.k1[0], C[V_R, l]) - dndo_R
        a_L = L[WDD_L, l] + super_twisting(s_L, p.k1[1], C[V_L, l]) - dndo_L
        L[UC_R, l], L[UC_L, l] = voltage_for(p.nominal, a_R, a_L, w_R, w_L)
        L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l] = s_R, s_L
    if p.has_ndo:  # the channel after s
        for l in range(nb):
            L[DIAGNOSTICS + 2, l], L[DIAGNOSTICS + 3, l] = C[DNDO_R, l], C[DNDO_L, l]


@inlined_law
def lanes_update(p, C, L, nb):
    """:func:`update` for lanes ``0 .. nb - 1``: v, then the NDO (22)."""
    for l in range(nb):
        C[V_R, l] += (p.dt * p.k2[0]) * integrand(sign(L[WD_R, l] - L[W_R, l]) * 1.0, L[UC_R, l], L[SAT_R, l] != 0.0,
                                                 p.anti_windup)
        C[V_L, l] += (p.dt * p.k2[1]) * integrand(sign(L[WD_L, l] - L[W_L, l]) * 1.0, L[UC_L, l], L[SAT_L, l] != 0.0,
                                                 p.anti_windup)
    if p.has_ndo:
        for l in range(nb):
            C[Z_R, l], C[Z_L, l] = ndo.next_state(p.ndo, p.nominal, p.dt, C[Z_R, l], C[Z_L, l], C[DNDO_R, l],
                                                  C[DNDO_L, l], L[W_R, l], L[W_L, l], L[U_R, l], L[U_L, l])


class SuperTwisting(WheelController):
    """Super-twisting SMC on ``s = w_d - w`` (docs/model.md §6).

    Parameters
    ----------
    k1 : float or (float, float)
        Gain of ``|s|^(1/2) sign(s)`` per wheel [(rad/s)^(1/2)/s].
    k2 : float or (float, float)
        Gain of the integrated ``sign(s)`` per wheel [rad/s^3].
    anti_windup : bool
        Hold ``v`` while the wheel is saturated and ``sign(s)`` pushes further into saturation.
    ndo : NonlinearDisturbanceObserver, optional
        The NDO of the paper's 3.2 (``sta_ndo``); None for none.
    name : str
        Label in tables and plots.
    """

    laws = sys.modules[__name__]

    def __init__(self, *, k1, k2, anti_windup: bool, ndo: "ndo.NonlinearDisturbanceObserver | None" = None,
                 name: str = "sta") -> None:
        self.k1 = per_wheel("controller.k1", k1, positive)
        self.k2 = per_wheel("controller.k2", k2, positive)
        self.anti_windup = boolean("controller.anti_windup", anti_windup)
        self.ndo = ndo
        self.name = str(name)

    def law_parameters(self, nominal: NominalModel, dt: float) -> STAParameters:
        ndo_params = self.ndo.law_parameters() if self.ndo is not None else ndo.NDOParameters((0.0, 0.0))
        return STAParameters(self.k1, self.k2, self.anti_windup, nominal, float(dt), self.ndo is not None, ndo_params)

    def state_fields(self):
        return [("v", "f8", 2), ("z", "f8", 2)]

    def diagnostics(self):
        """The sliding variable ``s = w_d - w``, then the NDO's estimate of d when present."""
        return ((Diagnostic("s", SURFACE, "the sliding variable s = w_d - w [rad/s]"),)
                + ((Diagnostic("NDO", ESTIMATE, "the NDO's estimate of d (21) [rad/s^2]"),) if self.ndo is not None else ()))

    def step_rates(self, nominal: NominalModel) -> list[StepRate]:
        """Only the NDO's rate L: the super-twisting loop is homogeneous, with no linear rate for ``dt`` to resolve
        (sampled, it keeps ``|s| = O(dt^2)`` instead of converging exactly; docs/model.md §6)."""
        return self.ndo.step_rates() if self.ndo is not None else []

    def parameters(self):
        params = {"k1": compact(self.k1), "k2": compact(self.k2), "anti_windup": self.anti_windup}
        if self.ndo is not None:
            params.update(self.ndo.parameters())
        return params
