"""Open-loop constant voltage: no feedback. Used to check the plant against closed-form solutions."""

from __future__ import annotations

import sys
from typing import NamedTuple

from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.checks import compact, finite, per_wheel
from ddmr_cli.control.base import DIAGNOSTICS, SURFACE, UC_L, UC_R, W_L, W_R, WD_L, WD_R, Diagnostic, WheelController
from ddmr_cli.model.robot import NominalModel


class OpenLoopParameters(NamedTuple):
    voltage: tuple  # (u_R, u_L) [V]


@law
def start(p, st, w0_R, w0_L):
    """No state."""


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """``u = (u_R, u_L)`` whatever the wheel speeds; the surface channel reports the speed error."""
    st["diagnostics"][0, 0] = wd_R - w_R
    st["diagnostics"][0, 1] = wd_L - w_L
    return p.voltage[0], p.voltage[1]


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """No state."""


@law
def estimates(p, st, w_R, w_L, u_R, u_L):
    """The estimate channels given the applied voltage ``u`` (after the driver's limit and PWM): by default
    nothing changes (what ``command`` wrote stays). A controller whose estimate depends on the applied voltage
    (ADRC's) defines its own; the step loop uses this one for every controller that does not
    (:mod:`ddmr_cli.engine.kernels`)."""


#: rows of the controller's array of a block of runs (ddmr_cli.control.base, "Lanes"): none used
LANE_STATE_ROWS = 1


@law
def lanes_load(p, st, C, l):
    """No state (ddmr_cli.control.base, "Lanes")."""


@law
def lanes_store(p, st, C, l):
    """No state."""


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``."""
    for l in range(nb):
        L[UC_R, l], L[UC_L, l] = p.voltage[0], p.voltage[1]
        L[DIAGNOSTICS, l], L[DIAGNOSTICS + 1, l] = L[WD_R, l] - L[W_R, l], L[WD_L, l] - L[W_L, l]


@law
def lanes_update(p, C, L, nb):
    """No state."""


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

    def diagnostics(self):
        return (Diagnostic("s", SURFACE, "the speed error w_d - w [rad/s] (no sliding surface)"),)

    def parameters(self):
        return {"voltage": compact(self.voltage)}
