"""Adaptive-gain SMC: the law (17) of :mod:`ddmr_cli.control.smc` with its switching gain K adapted per wheel
(docs/model.md §6, "Adaptive-gain SMC").

``K' = gamma |s| - sigma K`` while ``|s| >= eps`` and ``K' = 0`` inside the dead zone ``|s| < eps``; K is clipped
to ``[K_min, K_max]`` and starts at the configured ``switching_gain``. One explicit-Euler step per control step:
``K_k+1 = clip(K_k + dt (gamma |s_k| - sigma K_k), K_min, K_max)``. With the NDO (``adaptive_smc_ndo``) the
gain only has to cover what the observer leaves.
"""

from __future__ import annotations

import sys
from typing import NamedTuple

from ddmr_cli.checks import compact, non_negative, per_wheel, positive
from ddmr_cli.compiled import inlined_law, law
from ddmr_cli.control import smc
from ddmr_cli.control.base import DIAGNOSTICS
from ddmr_cli.errors import ConfigError


class AdaptiveSMCParameters(NamedTuple):
    smc: smc.SMCParameters  # the law (17); its switching_gain is K(0)
    adaptation_rate: tuple  # gamma per wheel [1/s^2]
    leakage: float  # sigma [1/s]
    dead_zone: float  # eps [rad/s]
    gain_min: float  # K_min [rad/s^2]
    gain_max: float  # K_max [rad/s^2]


@law
def adapt(gain, s, rate, leakage, dead_zone, gain_min, gain_max, dt):
    """One Euler step of ``K' = gamma |s| - sigma K`` outside the dead zone ``|s| < eps``, clipped to
    ``[K_min, K_max]``; K held inside the dead zone [rad/s^2]."""
    if abs(s) < dead_zone:
        return gain
    return min(max(gain + dt * (rate * abs(s) - leakage * gain), gain_min), gain_max)


@law
def start(p, st, w0_R, w0_L):
    """The law's states as for SMC; ``K(0)`` = the configured switching gain."""
    smc.start(p.smc, st, w0_R, w0_L)
    st["gain"][0] = p.smc.switching_gain[0]
    st["gain"][1] = p.smc.switching_gain[1]


@law
def command(p, st, k, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L):
    """(17) with the adapted gains ``K(t)``."""
    return smc.sliding_command(p.smc, st, w_R, w_L, wd_R, wd_L, wdd_R, wdd_L, st["gain"][0], st["gain"][1])


@law
def update(p, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L):
    """SMC's states (error integral, NDO), then the gains, from this step's sliding variable."""
    smc.update(p.smc, st, w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L, sat_R, sat_L)
    q = p.smc
    st["gain"][0] = adapt(st["gain"][0], st["diagnostics"][0, 0], p.adaptation_rate[0], p.leakage, p.dead_zone, p.gain_min,
                          p.gain_max, q.dt)
    st["gain"][1] = adapt(st["gain"][1], st["diagnostics"][0, 1], p.adaptation_rate[1], p.leakage, p.dead_zone, p.gain_min,
                          p.gain_max, q.dt)


# --- lanes (ddmr_cli.control.base, "Lanes"): the laws above over a block of runs ----------------------------------
#: rows of the controller's array C of a block: SMC's, then the gains K per wheel
GAIN_R = smc.LANE_STATE_ROWS
GAIN_L = GAIN_R + 1
#: rows of C (ddmr_cli.control.base, "Lanes")
LANE_STATE_ROWS = GAIN_R + 2


@law
def lanes_load(p, st, C, l):
    """Run record ``st`` into lane ``l`` of ``C``."""
    smc.lanes_load(p.smc, st, C, l)
    C[GAIN_R, l], C[GAIN_L, l] = st["gain"][0], st["gain"][1]


@law
def lanes_store(p, st, C, l):
    """Lane ``l`` of ``C`` back into run record ``st``."""
    smc.lanes_store(p.smc, st, C, l)
    st["gain"][0], st["gain"][1] = C[GAIN_R, l], C[GAIN_L, l]


@inlined_law
def lanes_command(p, C, L, nb, k):
    """:func:`command` for lanes ``0 .. nb - 1``: SMC's (17) with each lane's gains."""
    smc.sliding_lanes_command(p.smc, C, L, nb, k, GAIN_R)


@inlined_law
def lanes_update(p, C, L, nb):
    """:func:`update` for lanes ``0 .. nb - 1``: SMC's states, then the gains from this step's sliding variable."""
    smc.lanes_update(p.smc, C, L, nb)
    q = p.smc
    for l in range(nb):
        C[GAIN_R, l] = adapt(C[GAIN_R, l], L[DIAGNOSTICS, l], p.adaptation_rate[0], p.leakage, p.dead_zone,
                             p.gain_min, p.gain_max, q.dt)
        C[GAIN_L, l] = adapt(C[GAIN_L, l], L[DIAGNOSTICS + 1, l], p.adaptation_rate[1], p.leakage, p.dead_zone,
                             p.gain_min, p.gain_max, q.dt)


class AdaptiveSMC(smc.SMC):
    """SMC (17) whose switching gain adapts (docs/model.md §6).

    Parameters
    ----------
    adaptation_rate : float or (float, float)
        gamma per wheel [1/s^2].
    leakage : float
        sigma [1/s] (sigma-modification: K relaxes towards gamma |s| / sigma).
    dead_zone : float
        eps [rad/s]: no adaptation while ``|s| < eps``.
    gain_min, gain_max : float
        K_min, K_max [rad/s^2]; ``switching_gain`` (K(0)) must lie in between.
    **smc_values
        As :class:`~ddmr_cli.control.smc.SMC` (``switching_gain`` is K(0)).
    """

    laws = sys.modules[__name__]
    largest_gain_key = "gain_max"

    def __init__(self, *, adaptation_rate, leakage: float, dead_zone: float, gain_min: float, gain_max: float,
                 **smc_values) -> None:
        super().__init__(**smc_values)
        self.adaptation_rate = per_wheel("controller.adaptation_rate", adaptation_rate, positive)
        self.leakage = non_negative("controller.leakage", leakage)
        self.dead_zone = non_negative("controller.dead_zone", dead_zone)
        self.gain_min = non_negative("controller.gain_min", gain_min)
        self.gain_max = positive("controller.gain_max", gain_max)
        if self.gain_max < self.gain_min:
            raise ConfigError("controller.gain_max", gain_max, f"must be >= controller.gain_min ({self.gain_min:g})")
        for k0 in self.switching_gain:
            if not self.gain_min <= k0 <= self.gain_max:
                raise ConfigError("controller.switching_gain", compact(self.switching_gain),
                                  f"K(0) must lie in [gain_min, gain_max] = [{self.gain_min:g}, {self.gain_max:g}]")

    def law_parameters(self, nominal, dt) -> AdaptiveSMCParameters:
        return AdaptiveSMCParameters(super().law_parameters(nominal, dt), self.adaptation_rate, self.leakage,
                                     self.dead_zone, self.gain_min, self.gain_max)

    def state_fields(self):
        # the gain first: SMC's fields then sit at other offsets, so numba compiles SMC's laws for this record
        # rather than treating it as a subtype of SMC's record
        return [("gain", "f8", 2)] + super().state_fields()

    @property
    def largest_gain(self) -> float:
        """K never exceeds K_max, so the boundary layer's fastest rate is ``lambda + K_max / Phi``."""
        return self.gain_max

    def parameters(self):
        params = super().parameters()
        params["K"] = f"{params['K']} (K(0))"
        params.update({"gamma": compact(self.adaptation_rate), "sigma": self.leakage, "eps": self.dead_zone,
                       "K range": f"[{self.gain_min:g}, {self.gain_max:g}]"})
        return params
