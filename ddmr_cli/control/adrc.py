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
from ddmr_cli.compiled import law
from ddmr_cli.control.base import ESTIMATE, STABILITY_LIMIT, SURFACE, Diagnostic, StepRate, WheelController
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
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """[6g] ``u = (w_c (w_d - z1) + w_d' - z2) / b0`` per wheel (the estimate of ``d`` needs the applied
    voltage: :func:`estimates`)."""
    u_R = (p.bandwidth * (wd_R - st["z1"][0]) + wdd_R - st["z2"][0]) * (1.0 / p.b0)
    u_L = (p.bandwidth * (wd_L - st["z1"][1]) + wdd_L - st["z2"][1]) * (1.0 / p.b0)
    st["diagnostics"][0, 0], st["diagnostics"][0, 1] = wd_R - w_R, wd_L - w_L
    return u_R, u_L


@law
def estimates(p, st, w_R, w_L, u_R, u_L):
    """The ESO's estimate of ``d``: the part of ``z2`` the nominal model does not explain under the applied
    voltage ``u`` (after the driver's limit and PWM, the ``u`` the ESO is fed), ``z2 - (f(w) + (g - b0) u)``."""
    f_R, f_L = total_disturbance(p.nominal, p.b0, w_R, w_L, u_R, u_L)
    st["diagnostics"][1, 0], st["diagnostics"][1, 1] = st["z2"][0] - f_R, st["z2"][1] - f_L


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """One ESO step per wheel with the applied ``u``."""
    st["z1"][0], st["z2"][0] = eso_step(st["z1"][0], st["z2"][0], w_R, u_R, p.b0, p.beta1, p.beta2, p.dt)
    st["z1"][1], st["z2"][1] = eso_step(st["z1"][1], st["z2"][1], w_L, u_L, p.b0, p.beta1, p.beta2, p.dt)


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
