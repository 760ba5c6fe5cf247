"""A test controller in a module of its own (the way a user adds one): constant 11 V, except that each run
gets a NaN command from its own step ``k_bad`` on, a numerically broken run."""

from __future__ import annotations

import math
import sys
from typing import NamedTuple

import numpy as np

from ddmr_cli.compiled import law
from ddmr_cli.control.base import WheelController


class NaNAfterParameters(NamedTuple):
    voltage: float


@law
def start(p, st, w0_R, w0_L):
    """``k_bad`` is set per run by :meth:`NaNAfter.initial_state`."""


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    u_R = math.nan if k >= st["k_bad"] else p.voltage
    return u_R, p.voltage  # no diagnostic channels: the engine records s as NaN


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    pass


class NaNAfter(WheelController):
    """Run 0 turns NaN at step ``k_bad``; the other runs never do."""

    name = "nan_after"
    laws = sys.modules[__name__]

    def __init__(self, k_bad: int) -> None:
        self.k_bad = int(k_bad)

    def law_parameters(self, nominal, dt):
        return NaNAfterParameters(11.0)

    def state_fields(self):
        return [("k_bad", "i8")]

    def initial_state(self, n_runs):
        state = super().initial_state(n_runs)
        state["k_bad"] = 2**62
        state["k_bad"][0] = self.k_bad
        return state
