"""Nonlinear disturbance observer, the paper's (21)-(22) with ``Gamma = L I`` (docs/model.md §6).

``d_hat = z + Gamma w``, ``z' = -Gamma (d_hat + f(w) + g u)``, fed with the applied (saturated) ``u``, and
``z(0) = -Gamma w(0)`` so that ``d_hat(0) = 0``. For a constant disturbance the estimation error obeys
``d_tilde' = -Gamma d_tilde`` (the paper's (20)): it converges at rate ``L``. Discretised by explicit Euler at
the control step.
"""

from __future__ import annotations

from typing import NamedTuple

from ddmr_cli.compiled import law
from ddmr_cli.checks import compact, per_wheel, positive
from ddmr_cli.control.base import StepRate
from ddmr_cli.model.dynamics import nominal_acceleration


class NDOParameters(NamedTuple):
    gain: tuple  # L per wheel (right, left) [1/s]


@law
def start(p, z, w0_R, w0_L):
    """``z(0) = -Gamma w(0)``, so that ``d_hat(0) = 0``."""
    z[0] = -p.gain[0] * w0_R
    z[1] = -p.gain[1] * w0_L


@law
def estimate_of(p, z_R, z_L, w_R, w_L):
    """(21): ``d_hat = z + Gamma w`` [rad/s^2], the state given by value."""
    return z_R + p.gain[0] * w_R, z_L + p.gain[1] * w_L


@law
def estimate(p, z, w_R, w_L):
    """(21) on the state array ``z``: :func:`estimate_of`."""
    return estimate_of(p, z[0], z[1], w_R, w_L)


@law
def next_state(p, nominal, dt, z_R, z_L, d_hat_R, d_hat_L, w_R, w_L, u_R, u_L):
    """(22), one Euler step, by value: ``z - dt Gamma (d_hat + f(w) + g u)``."""
    a_R, a_L = nominal_acceleration(nominal, w_R, w_L, u_R, u_L)
    return z_R - (dt * p.gain[0]) * (d_hat_R + a_R), z_L - (dt * p.gain[1]) * (d_hat_L + a_L)


@law
def update(p, nominal, dt, z, d_hat_R, d_hat_L, w_R, w_L, u_R, u_L):
    """(22) on the state array ``z``: :func:`next_state`."""
    z[0], z[1] = next_state(p, nominal, dt, z[0], z[1], d_hat_R, d_hat_L, w_R, w_L, u_R, u_L)


class NonlinearDisturbanceObserver:
    """The NDO of the paper's section 3.2 (docs/model.md §6).

    Parameters
    ----------
    gain : float or (float, float)
        Observer gain L per wheel [1/s] (Table 3: 50).
    """

    def __init__(self, gain) -> None:
        self.gain = per_wheel("controller.ndo.gain", gain, positive)

    def law_parameters(self) -> NDOParameters:
        return NDOParameters(self.gain)

    def step_rates(self) -> list[StepRate]:
        """The error decays at rate L: explicit Euler needs ``dt L`` below its limit."""
        return [StepRate("controller.ndo.gain", max(self.gain))]

    def parameters(self) -> dict[str, object]:
        return {"L": compact(self.gain)}
