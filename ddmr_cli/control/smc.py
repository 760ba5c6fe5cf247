"""Sliding-mode wheel-speed controller with optional disturbance observers (paper 3.1-3.3; docs/model.md §6).

SMC, SMC-NDO and SMC-NDO-NNO are this one law with zero, one or two observers (:mod:`ddmr_cli.control.ndo`,
:mod:`ddmr_cli.control.rbf`).

Surface ``proportional`` (the paper's (10)): ``s = e = w_d - w`` and
``u = g^-1 (w_d' - f(w) + lambda s + K sw(s/Phi) - d_hat)`` (17), lambda read as the linear term of an
exponential reaching law and Phi as the boundary layer (docs/model.md §6). Surface ``integral``:
``s = e + lambda int e`` and ``u = g^-1 (w_d' - f(w) + lambda e + K sw(s/Phi) - d_hat)``, the equivalent control
of that surface plus the switching term. ``d_hat`` is the sum of the observers' estimates (NDO (21), NN (24)).
"""

from __future__ import annotations

import math
import sys
from typing import NamedTuple


from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.control import ndo, rbf
from ddmr_cli.checks import compact, non_negative, one_of, per_wheel, positive
from ddmr_cli.control.base import (DIAGNOSTICS, ESTIMATE, SURFACE, UC_L, UC_R, U_L, U_R, W_L, W_R, WD_L, WD_R, WDD_L,
                                   WDD_R, Diagnostic, StepRate, WheelController)
from ddmr_cli.model.dynamics import sign, voltage_for
from ddmr_cli.model.robot import NominalModel

SURFACES = ("proportional", "integral")
#: the switching function sw of (15): sgn as printed, or its boundary-layer forms
SWITCHING_FUNCTIONS = ("sign", "sat", "tanh")
SIGN, SAT, TANH = range(3)


class SMCParameters(NamedTuple):
    lam: tuple  # lambda per wheel [1/s]
    switching_gain: tuple  # K per wheel [rad/s^2]
    boundary_layer: float  # Phi [rad/s]
    integral_surface: bool
    switching: int  # SIGN, SAT or TANH
    nominal: NominalModel
    dt: float  # [s]
    has_ndo: bool
    ndo: ndo.NDOParameters
    has_nn: bool
    nn: rbf.RBFParameters


@law
def surface(e, error_integral, lam, integral_surface):
    """The sliding variable and the linear term of (17): ``(e, lambda e)`` for (10)'s ``s = e``, or
    ``(e + lambda int e, lambda e)`` for the integral surface [rad/s, rad/s^2]."""
    if integral_surface:
        return e + lam * error_integral, lam * e
    return e, lam * e


@law
def integrated(p, error_integral, e):
    """The integral surface's ``int e`` one Euler step on [rad]."""
    return error_integral + p.dt * e


@law
def switching(s, boundary_layer, kind):
    """``sw(s / Phi)`` of (15): ``sign(s)``, ``sat(s / Phi)`` or ``tanh(s / Phi)``."""
    if kind == SIGN:
        return sign(s) * 1.0
    x = s * (1.0 / boundary_layer)
    if kind == SAT:
        return min(max(x, -1.0), 1.0)
    return math.tanh(x)


@law
def start(p, st, w0_R, w0_L):
    """Zero error integral and network weights; the NDO starts at ``d_hat(0) = 0``."""
    st["error_integral"][0] = 0.0
    st["error_integral"][1] = 0.0
    st["weights"][:, :] = 0.0
    if p.has_ndo:
        ndo.start(p.ndo, st["z"], w0_R, w0_L)


@law
def sliding_voltage(p, kind, s_R, s_L, linear_R, linear_L, wdd_R, wdd_L, gain_R, gain_L, d_hat_R, d_hat_L, w_R, w_L):
    """(17) given the surface, its linear term and the observers' summed estimate ``d_hat``:
    ``u = g^-1 (w_d' - f(w) + linear + K sw(s/Phi) - d_hat)`` [V] (``kind``: the switching function)."""
    a_R = wdd_R + linear_R + gain_R * switching(s_R, p.boundary_layer, kind) - d_hat_R
    a_L = wdd_L + linear_L + gain_L * switching(s_L, p.boundary_layer, kind) - d_hat_L
    return voltage_for(p.nominal, a_R, a_L, w_R, w_L)


@law
def sliding_command(p, st, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L, gain_R, gain_L):
    """(17) with the switching gains ``K`` given per wheel [rad/s^2] (constant here, adapted in
    :mod:`ddmr_cli.control.adaptive_smc`): ``u = g^-1 (w_d' - f(w) + linear + K sw(s/Phi) - d_hat)``."""
    s_R, linear_R = surface(wd_R - w_R, st["error_integral"][0], p.lam[0], p.integral_surface)
    s_L, linear_L = surface(wd_L - w_L, st["error_integral"][1], p.lam[1], p.integral_surface)
    dndo_R = dndo_L = dnn_R = dnn_L = 0.0
    if p.has_ndo:
        dndo_R, dndo_L = ndo.estimate(p.ndo, st["z"], w_R, w_L)
    if p.has_nn:
        dnn_R, dnn_L = rbf.estimate(p.nn, st["weights"], st["phi"], w_R, w_L)
    u_R, u_L = sliding_voltage(p, p.switching, s_R, s_L, linear_R, linear_L, wdd_R, wdd_L, gain_R, gain_L,
                               dndo_R + dnn_R, dndo_L + dnn_L, w_R, w_L)
    diagnostics = st["diagnostics"]  # rows: s, then NDO and NN when present (SMC.diagnostics)
    diagnostics[0, 0], diagnostics[0, 1] = s_R, s_L
    if p.has_ndo:
        diagnostics[1, 0], diagnostics[1, 1] = dndo_R, dndo_L
    if p.has_nn:
        nn_row = 2 if p.has_ndo else 1
        diagnostics[nn_row, 0], diagnostics[nn_row, 1] = dnn_R, dnn_L
    return u_R, u_L


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """(17): ``u = g^-1 (w_d' - f(w) + linear + K sw(s/Phi) - d_hat)`` per wheel, K the configured gains."""
    return sliding_command(p, st, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L, p.switching_gain[0], p.switching_gain[1])


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """Advance the error integral (integral surface), the NDO (22) and the network (25) by one step."""
    if p.integral_surface:
        st["error_integral"][0] = integrated(p, st["error_integral"][0], wd_R - w_R)
        st["error_integral"][1] = integrated(p, st["error_integral"][1], wd_L - w_L)
    diagnostics = st["diagnostics"]
    if p.has_ndo:
        ndo.update(p.ndo, p.nominal, p.dt, st["z"], diagnostics[1, 0], diagnostics[1, 1], w_R, w_L, u_R, u_L)
    if p.has_nn:
        rbf.update(p.nn, p.dt, st["weights"], st["phi"], diagnostics[0, 0], diagnostics[0, 1])


# --- lanes (ddmr_cli.control.base, "Lanes"): the laws above over a block of runs ----------------------------------
#: rows of the controller's array C of a block: the error integral, the NDO's state, the observers' estimates this
#: step, then the network's weights (row NEURONS + 2 j + wheel) and basis (row PHI + j), for up to LANE_NEURONS
EI_R, EI_L, Z_R, Z_L, DNDO_R, DNDO_L, DNN_R, DNN_L = range(8)
NEURONS = 8
#: the most neurons a network runs with in lanes (the sensitivity study's largest is 20)
LANE_NEURONS = 32
PHI = NEURONS + 2 * LANE_NEURONS
#: rows of C (ddmr_cli.control.base, "Lanes")
LANE_STATE_ROWS = PHI + LANE_NEURONS


@law
def lanes_load(p, st, C, l):
    """Run record ``st`` into lane ``l`` of ``C``."""
    C[EI_R, l], C[EI_L, l] = st["error_integral"][0], st["error_integral"][1]
    C[Z_R, l], C[Z_L, l] = st["z"][0], st["z"][1]
    for j in range(p.nn.n_neurons if p.has_nn else 0):
        C[NEURONS + 2 * j, l], C[NEURONS + 2 * j + 1, l] = st["weights"][0, j], st["weights"][1, j]
        C[PHI + j, l] = st["phi"][j]


@law
def lanes_store(p, st, C, l):
    """Lane ``l`` of ``C`` back into run record ``st``."""
    st["error_integral"][0], st["error_integral"][1] = C[EI_R, l], C[EI_L, l]
    st["z"][0], st["z"][1] = C[Z_R, l], C[Z_L, l]
    for j in range(p.nn.n_neurons if p.has_nn else 0):
        st["weights"][0, j], st["weights"][1, j] = C[NEURONS + 2 * j, l], C[NEURONS + 2 * j + 1, l]
        st["phi"][j] = C[PHI + j, l]


@inlined_law
def _lanes_sliding(p, C, L, nb, kind, gain_row):
    """:func:`sliding_command` for every lane, the switching function ``kind`` a constant of the loop; the gains K
    the configured ones (``gain_row`` -1) or each lane's, in rows ``gain_row`` (right) and ``gain_row + 1``."""
    for l in range(nb):
        w_R, w_L = L[W_R, l], L[W_L, l]
        s_R, linear_R = surface(L[WD_R, l] - w_R, C[EI_R, l], p.lam[0], p.integral_surface)
        s_L, linear_L = surface(L[WD_L, l] - w_L, C[EI_L, l], p.lam[1], p.integral_surface)
        gain_R = p.switching_gain[0] if gain_row < 0 else C[gain_row, l]
        gain_L = p.switching_gain[1] if gain_row < 0 else C[gain_row + 1, l]
        L[UC_R, l], L[UC_L, l] = sliding_voltage(p, kind, s_R, s_L, linear_R, linear_L, L[WDD_R, l], L[WDD_L, l],
                                                 gain_R, gain_L, C[DNDO_R, l] + C[DNN_R, l],
                                                 C[DNDO_L, l] + C[DNN_L, l], w_R, w_L)
        L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l] = s_R, s_L


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``: :func:`sliding_lanes_command` with the configured gains."""
    sliding_lanes_command(p, C, L, nb, k, -1)


@inlined_law
def sliding_lanes_command(p, C, L, nb, k, gain_row):
    """:func:`sliding_command` for lanes ``0 .. nb - 1``: the NDO's estimate (21), the network's (24) a neuron at a
    time over the lanes, then (17) with the gains :func:`_lanes_sliding` reads (``gain_row``)."""
    for l in range(nb):
        C[DNDO_R, l], C[DNDO_L, l], C[DNN_R, l], C[DNN_L, l] = 0.0, 0.0, 0.0, 0.0
    if p.has_ndo:
        for l in range(nb):
            C[DNDO_R, l], C[DNDO_L, l] = ndo.estimate_of(p.ndo, C[Z_R, l], C[Z_L, l], L[W_R, l], L[W_L, l])
    if p.has_nn:
        for j in range(p.nn.n_neurons):
            for l in range(nb):
                phi = rbf.activation(p.nn, j, L[W_R, l], L[W_L, l])
                C[PHI + j, l] = phi
                C[DNN_R, l] += C[NEURONS + 2 * j, l] * phi
                C[DNN_L, l] += C[NEURONS + 2 * j + 1, l] * phi
    if p.switching == SAT:
        _lanes_sliding(p, C, L, nb, SAT, gain_row)
    elif p.switching == SIGN:
        _lanes_sliding(p, C, L, nb, SIGN, gain_row)
    else:
        _lanes_sliding(p, C, L, nb, TANH, gain_row)
    if p.has_ndo:  # the channels after s: the NDO's, then the network's
        for l in range(nb):
            L[DIAGNOSTICS + 2, l], L[DIAGNOSTICS + 3, l] = C[DNDO_R, l], C[DNDO_L, l]
    if p.has_nn:
        row = DIAGNOSTICS + (4 if p.has_ndo else 2)
        for l in range(nb):
            L[row, l], L[row + 1, l] = C[DNN_R, l], C[DNN_L, l]


@inlined_law
def lanes_update(p, C, L, nb):
    """:func:`update` for lanes ``0 .. nb - 1``: the error integral, the NDO (22), the network (25)."""
    if p.integral_surface:
        for l in range(nb):
            C[EI_R, l] = integrated(p, C[EI_R, l], L[WD_R, l] - L[W_R, l])
            C[EI_L, l] = integrated(p, C[EI_L, l], L[WD_L, l] - L[W_L, l])
    if p.has_ndo:
        for l in range(nb):
            C[Z_R, l], C[Z_L, l] = ndo.next_state(p.ndo, p.nominal, p.dt, C[Z_R, l], C[Z_L, l], C[DNDO_R, l],
                                                  C[DNDO_L, l], L[W_R, l], L[W_L, l], L[U_R, l], L[U_L, l])
    if p.has_nn:
        for j in range(p.nn.n_neurons):
            for l in range(nb):
                step_R, step_L = rbf.learning_steps(p.nn, p.dt, L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l])
                C[NEURONS + 2 * j, l] = rbf.learned(C[NEURONS + 2 * j, l], step_R, C[PHI + j, l])
                C[NEURONS + 2 * j + 1, l] = rbf.learned(C[NEURONS + 2 * j + 1, l], step_L, C[PHI + j, l])


class SMC(WheelController):
    """Sliding-mode control law (17) with the observers' estimate subtracted (docs/model.md §6).

    Parameters
    ----------
    lam : float or (float, float)
        lambda per wheel [1/s] (Table 3: 25).
    switching_gain : float or (float, float)
        K per wheel [rad/s^2] (Table 3: 12).
    boundary_layer : float
        Phi [rad/s] (Table 3: 0.1); unused by ``switching='sign'``.
    surface : {'proportional', 'integral'}
    switching : {'sign', 'sat', 'tanh'}
    ndo : NonlinearDisturbanceObserver, optional
        The NDO of 3.2 (SMC-NDO); None for none.
    nn : RBFNetworkObserver, optional
        The RBF network observer of 3.3 (SMC-NDO-NNO with ``ndo``); None for none.
    name : str
        Label in tables and plots.
    """

    laws = sys.modules[__name__]

    def __init__(self, *, lam, switching_gain, boundary_layer: float, surface: str, switching: str,
                 ndo: "ndo.NonlinearDisturbanceObserver | None" = None, nn: "rbf.RBFNetworkObserver | None" = None,
                 name: str = "smc") -> None:
        self.lam = per_wheel("controller.lam", lam, positive)
        self.switching_gain = per_wheel("controller.switching_gain", switching_gain, non_negative)
        self.boundary_layer = positive("controller.boundary_layer", boundary_layer)
        self.surface = one_of("controller.surface", surface, SURFACES)
        self.switching = one_of("controller.switching", switching, SWITCHING_FUNCTIONS)
        self.ndo, self.nn = ndo, nn
        self.name = str(name)

    def law_parameters(self, nominal: NominalModel, dt: float) -> SMCParameters:
        ndo_params = self.ndo.law_parameters() if self.ndo is not None else ndo.NDOParameters((0.0, 0.0))
        nn_params = (self.nn.law_parameters() if self.nn is not None
                     else rbf.RBFParameters(1, 0.0, 0.0, 0.0, 1.0, (0.0, 0.0)))
        return SMCParameters(self.lam, self.switching_gain, self.boundary_layer, self.surface == "integral",
                             SWITCHING_FUNCTIONS.index(self.switching), nominal, float(dt),
                             self.ndo is not None, ndo_params, self.nn is not None, nn_params)

    def state_fields(self):
        """The error integral, the NDO's state and the network's weights and basis, held in blocks of
        :data:`~ddmr_cli.control.rbf.NEURON_BLOCK` neurons (one record layout, one compiled loop, for the sizes
        1 to 16)."""
        n = rbf.capacity(self.nn.n_neurons) if self.nn is not None else 1
        return [("error_integral", "f8", 2), ("z", "f8", 2), ("weights", "f8", (2, n)), ("phi", "f8", n)]

    def runs_in_lanes(self) -> bool:
        """As every controller with lanes laws, for a network of at most :data:`LANE_NEURONS` neurons."""
        return super().runs_in_lanes() and (self.nn is None or self.nn.n_neurons <= LANE_NEURONS)

    def diagnostics(self):
        """The sliding variable, then the NDO's and the network's estimates of d when present (the rows
        :func:`sliding_command` writes)."""
        return ((Diagnostic("s", SURFACE, "the sliding variable s (10) [rad/s]"),)
                + ((Diagnostic("NDO", ESTIMATE, "the NDO's estimate of d (21) [rad/s^2]"),) if self.ndo is not None else ())
                + ((Diagnostic("NN", ESTIMATE, "the RBF network's estimate of d (24) [rad/s^2]"),)
                   if self.nn is not None else ()))

    @property
    def largest_gain(self) -> float:
        """The largest switching gain K the law can apply [rad/s^2] (the configured one here)."""
        return max(self.switching_gain)

    #: the config key of :attr:`largest_gain`, for the step-bound message
    largest_gain_key = "switching_gain"

    def step_rates(self, nominal: NominalModel) -> list[StepRate]:
        """The sliding variable's fastest closed-loop rate is ``lambda + K / Phi`` (inside the boundary layer),
        and the NDO's error decays at ``L``."""
        rates = [StepRate(f"controller.lam + {self.largest_gain_key}/boundary_layer",
                          max(self.lam) + self.largest_gain / self.boundary_layer)]
        return rates + (self.ndo.step_rates() if self.ndo is not None else [])

    def parameters(self):
        params = {"lambda": compact(self.lam), "K": compact(self.switching_gain),
                  "Phi": self.boundary_layer, "surface": self.surface, "switching": self.switching}
        for obs in (self.ndo, self.nn):
            if obs is not None:
                params.update(obs.parameters())
        return params
