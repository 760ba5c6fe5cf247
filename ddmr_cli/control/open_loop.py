"""Open-loop constant voltage: no feedback. Used to check the plant against closed-form solutions."""

from __future__ import annotations

import sys
from typing import NamedTuple

from ddmr_cli.compiled import law
from ddmr_cli.checks import compact, finite, per_wheel
from ddmr_cli.control.base import WheelController
from ddmr_cli.model.robot import NominalModel


class OpenLoopParameters(NamedTuple):
    voltage: tuple  # (u_R, u_L) [V]


@law
def start(p, st, w0_R, w0_L):
    """No state."""


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """``u = (u_R, u_L)`` whatever the wheel speeds; ``s`` reports the speed error."""
    return p.voltage[0], p.voltage[1], wd_R - w_R, wd_L - w_L, 0.0, 0.0, 0.0, 0.0


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """No state."""


@law
def estimates(p, st, w_R, w_L, u_R, u_L, ndo_R, ndo_L, nn_R, nn_L):
    """The disturbance estimates reported at a control instant, given the applied voltage ``u`` (after the
    driver's limit and PWM): by default what ``command`` returned. A controller whose estimate depends on the
    applied voltage (ADRC's) defines its own; the step loop uses this one for every controller that does not
    (:mod:`ddmr_cli.engine.kernels`)."""
    return ndo_R, ndo_L, nn_R, nn_L


class OpenLoop(WheelController):
    """Apply a constant voltage ``(u_R, u_L)``.

    Parameters
    ----------
    voltage : float or (float, float)
        Voltage per wheel [V].
    """

    name = "open_loop"
    laws = sys.modules[__name__]

    def __init__(self, voltage) -> None:
        self.voltage = per_wheel("controller.voltage", voltage, finite)

    def law_parameters(self, nominal: NominalModel, dt: float) -> OpenLoopParameters:
        return OpenLoopParameters(self.voltage)

    def parameters(self):
        return {"voltage": compact(self.voltage)}
