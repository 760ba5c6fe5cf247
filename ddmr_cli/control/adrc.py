"""Linear active disturbance rejection control with an extended state observer (Gao 2003, bandwidth
parameterisation; docs/model.md §6, "ADRC").

Per wheel the plant is read as ``w' = b0 u + f``, with ``b0`` the nominal model's direct input gain (the diagonal
of ``g = J^-1 K_u``) and ``f`` the total disturbance: the drift ``f(w)``, the other wheel's voltage through the
off-diagonal of ``g``, and ``d``. A second-order ESO estimates ``z1 ~ w`` and ``z2 ~ f``:

``z1' = z2 + b0 u + beta1 (w - z1)``, ``z2' = beta2 (w - z1)``, ``beta1 = 2 w_o``, ``beta2 = w_o^2``

(both observer poles at ``-w_o``), fed with the applied (saturated) ``u`` and advanced by explicit Euler at the
control step; the control law is ``u = (w_c (w_d - z1) + w_d' - z2) / b0`` (controller pole at ``-w_c``).

The ESO starts at the nominal model's equilibrium at ``w(0)``: ``z1(0) = w(0)`` and ``z2(0) = f`` of the nominal
plant under the voltage that holds ``w(0)``, so a rolling start on the reference gets no kick (as the NDO's
``d_hat(0) = 0``).
"""

from __future__ import annotations

import sys
from typing import NamedTuple

from ddmr_cli.checks import positive
from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.control.base import (DIAGNOSTICS, ESTIMATE, STABILITY_LIMIT, SURFACE, U_L, U_R, UC_L, UC_R, W_L, W_R, WD_L,
                                   WD_R, WDD_L, WDD_R, Diagnostic, StepRate, WheelController)
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.dynamics import nominal_acceleration, voltage_for
from ddmr_cli.model.robot import NominalModel


class ADRCParameters(NamedTuple):
    bandwidth: float  # w_c [1/s]
    beta1: float  # 2 w_o [1/s]
    beta2: float  # w_o^2 [1/s^2]
    b0: float  # [rad/(s^2 V)]
    nominal: NominalModel
    dt: float  # [s]


@law
def eso_step(z1, z2, w, u, b0, beta1, beta2, dt):
    """One Euler step of the ESO: ``z1' = z2 + b0 u + beta1 (w - z1)``, ``z2' = beta2 (w - z1)``."""
    e = w - z1
    return z1 + dt * (z2 + b0 * u + beta1 * e), z2 + dt * (beta2 * e)


@law
def total_disturbance(nominal, b0, w_R, w_L, u_R, u_L):
    """What ``f = w' - b0 u`` is in the nominal plant (no ``d``) at ``w``, ``u``: ``f(w) + (g - b0) u`` [rad/s^2]."""
    a_R, a_L = nominal_acceleration(nominal, w_R, w_L, u_R, u_L)
    return a_R - b0 * u_R, a_L - b0 * u_L


@law
def start(p, st, w0_R, w0_L):
    """``z1(0) = w(0)``, ``z2(0)`` the nominal total disturbance under the voltage that holds ``w(0)``."""
    u_R, u_L = voltage_for(p.nominal, 0.0, 0.0, w0_R, w0_L)
    f_R, f_L = total_disturbance(p.nominal, p.b0, w0_R, w0_L, u_R, u_L)
    st["z1"][0], st["z1"][1] = w0_R, w0_L
    st["z2"][0], st["z2"][1] = f_R, f_L


@law
def voltage(p, z1, z2, wd, wdd):
    """[6g] ``u = (w_c (w_d - z1) + w_d' - z2) / b0`` of one wheel [V]."""
    return (p.bandwidth * (wd - z1) + wdd - z2) * (1.0 / p.b0)


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """[6g] per wheel (the estimate of ``d`` needs the applied voltage: :func:`estimates`)."""
    u_R = voltage(p, st["z1"][0], st["z2"][0], wd_R, wdd_R)
    u_L = voltage(p, st["z1"][1], st["z2"][1], wd_L, wdd_L)
    st["diagnostics"][0, 0], st["diagnostics"][0, 1] = wd_R - w_R, wd_L - w_L
    return u_R, u_L


@law
def disturbance_estimate(p, z2_R, z2_L, w_R, w_L, u_R, u_L):
    """The ESO's estimate of ``d``: the part of ``z2`` the nominal model does not explain under the applied
    voltage ``u`` (after the driver's limit and PWM, the ``u`` the ESO is fed), ``z2 - (f(w) + (g - b0) u)``."""
    f_R, f_L = total_disturbance(p.nominal, p.b0, w_R, w_L, u_R, u_L)
    return z2_R - f_R, z2_L - f_L


@law
def estimates(p, st, w_R, w_L, u_R, u_L):
    """:func:`disturbance_estimate` into the second diagnostic channel."""
    st["diagnostics"][1, 0], st["diagnostics"][1, 1] = disturbance_estimate(p, st["z2"][0], st["z2"][1], w_R, w_L,
                                                                            u_R, u_L)


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """One ESO step per wheel with the applied ``u``."""
    st["z1"][0], st["z2"][0] = eso_step(st["z1"][0], st["z2"][0], w_R, u_R, p.b0, p.beta1, p.beta2, p.dt)
    st["z1"][1], st["z2"][1] = eso_step(st["z1"][1], st["z2"][1], w_L, u_L, p.b0, p.beta1, p.beta2, p.dt)


# --- lanes (ddmr_cli.control.base, "Lanes"): the laws above over a block of runs ----------------------------------
#: rows of the controller's array C of a block: the ESO's state per wheel
Z1_R, Z1_L, Z2_R, Z2_L = range(4)
#: rows of C (ddmr_cli.control.base, "Lanes")
LANE_STATE_ROWS = 4


@law
def lanes_load(p, st, C, l):
    """Run record ``st`` into lane ``l`` of ``C``."""
    C[Z1_R, l], C[Z1_L, l], C[Z2_R, l], C[Z2_L, l] = st["z1"][0], st["z1"][1], st["z2"][0], st["z2"][1]


@law
def lanes_store(p, st, C, l):
    """Lane ``l`` of ``C`` back into run record ``st``."""
    st["z1"][0], st["z1"][1], st["z2"][0], st["z2"][1] = C[Z1_R, l], C[Z1_L, l], C[Z2_R, l], C[Z2_L, l]


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``."""
    for l in range(nb):
        L[UC_R, l] = voltage(p, C[Z1_R, l], C[Z2_R, l], L[WD_R, l], L[WDD_R, l])
        L[UC_L, l] = voltage(p, C[Z1_L, l], C[Z2_L, l], L[WD_L, l], L[WDD_L, l])
        L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l] = L[WD_R, l] - L[W_R, l], L[WD_L, l] - L[W_L, l]


@inlined_law
def lanes_update(p, C, L, nb):
    """:func:`estimates`, then :func:`update`, for lanes ``0 .. nb - 1``."""
    for l in range(nb):
        L[DIAGNOSTICS + 2, l], L[DIAGNOSTICS + 3, l] = disturbance_estimate(p, C[Z2_R, l], C[Z2_L, l], L[W_R, l],
                                                                            L[W_L, l], L[U_R, l], L[U_L, l])
        C[Z1_R, l], C[Z2_R, l] = eso_step(C[Z1_R, l], C[Z2_R, l], L[W_R, l], L[U_R, l], p.b0, p.beta1, p.beta2, p.dt)
        C[Z1_L, l], C[Z2_L, l] = eso_step(C[Z1_L, l], C[Z2_L, l], L[W_L, l], L[U_L, l], p.b0, p.beta1, p.beta2, p.dt)


class ADRC(WheelController):
    """Linear ADRC per wheel (docs/model.md §6).

    Parameters
    ----------
    bandwidth : float
        Controller bandwidth w_c [1/s] (closed-loop pole at -w_c).
    observer_bandwidth : float
        ESO bandwidth w_o [1/s] (double observer pole at -w_o).
    name : str
        Label in tables and plots.
    """

    laws = sys.modules[__name__]

    def __init__(self, *, bandwidth: float, observer_bandwidth: float, name: str = "adrc") -> None:
        self.bandwidth = positive("controller.bandwidth", bandwidth)
        self.observer_bandwidth = positive("controller.observer_bandwidth", observer_bandwidth)
        self.name = str(name)

    @staticmethod
    def input_gain(nominal: NominalModel) -> float:
        """b0: the diagonal of the nominal ``g = J^-1 K_u`` [rad/(s^2 V)]."""
        return nominal.jinv_p * nominal.voltage_gain

    def law_parameters(self, nominal: NominalModel, dt: float) -> ADRCParameters:
        w_o = self.observer_bandwidth
        return ADRCParameters(self.bandwidth, 2.0 * w_o, w_o * w_o, self.input_gain(nominal), nominal, float(dt))

    def state_fields(self):
        return [("z1", "f8", 2), ("z2", "f8", 2)]

    def step_rates(self, nominal: NominalModel) -> list[StepRate]:
        """The control pole ``-w_c`` under the plant's integrator (the observer is checked in :meth:`check_step`)."""
        return [StepRate("controller.bandwidth", self.bandwidth)]

    def check_step(self, nominal: NominalModel, dt: float, integrator: str) -> None:
        """Also: the Euler ESO's error obeys ``e_k+1 = M e_k`` with a double eigenvalue ``1 - w_o dt`` (docs/model.md
        §6), stable only while ``w_o dt < 2``, whatever the plant's integrator."""
        super().check_step(nominal, dt, integrator)
        limit = STABILITY_LIMIT["euler"]
        if dt * self.observer_bandwidth >= limit:
            raise ConfigError("simulation.dt", dt, f"must be < {limit / self.observer_bandwidth:.3g} s for the "
                                                   f"Euler ESO with controller.observer_bandwidth = "
                                                   f"{self.observer_bandwidth:.3g} 1/s")

    def diagnostics(self):
        """The speed error (ADRC has no surface), then the ESO's estimate of d (:func:`estimates`)."""
        return (Diagnostic("s", SURFACE, "the speed error w_d - w [rad/s] (no sliding surface)"),
                Diagnostic("ESO", ESTIMATE, "the ESO's estimate of d, z2 - (f(w) + (g - b0) u) [rad/s^2]"))

    def parameters(self):
        return {"w_c": self.bandwidth, "w_o": self.observer_bandwidth, "b0": "diag(g) of the nominal model"}
