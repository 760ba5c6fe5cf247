"""Scenarios: which disturbances act when (docs/model.md §5; paper Fig. 10).

A scenario is a list of phases along the distance the robot has travelled (``phase_clock: distance``, the
default, on the same axis as the terrain zones) or along time (``phase_clock: time``). In each phase the terrain
roughness and the parametric uncertainty (the true damping ``B(t) = B_nom (1 + delta(t))``) are on or off;
rolling resistance always acts. Why distance: docs/model.md §5 ("One clock for zones and phases").
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple, Sequence

import numpy as np

from ddmr_cli.checks import finite, non_negative, one_of, positive, starts_increasing_from_zero
from ddmr_cli.compiled import law
from ddmr_cli.errors import ConfigError


#: What a phase's ``start`` is measured along: the distance travelled [m] or time [s].
PHASE_CLOCKS = ("distance", "time")
#: The form of scenario 2's uncertainty delta (docs/model.md §5): ``ou``, a stationary OU process in time (our
#: reading); ``constant``, one value per run drawn from the same stationary law and held (a fixed unknown
#: parameter, the classic reading of "parametric uncertainty"; the OU process with an infinite correlation time)
UNCERTAINTY_FORMS = ("ou", "constant")


@dataclass(frozen=True)
class Phase:
    """From ``start`` [m travelled or s, by the scenario's ``phase_clock``] to the next phase's start."""

    name: str
    start: float
    roughness: bool
    uncertainty: bool


class DampingUncertainty(NamedTuple):
    """The true damping's relative deviation delta(t): an OU process, clipped (docs/model.md §5, scenario 2).

    Parameters
    ----------
    correlation_time : float
        [s].
    std : float
        Stationary standard deviation.
    low, high : float
        Clip bounds of delta (the paper's reading: -0.5, 1.0, so ``B_true`` stays in ``[0.5, 2] B_nom``).
    constant : bool
        The ``constant`` form (:data:`UNCERTAINTY_FORMS`): delta drawn once per run and held; ``correlation_time``
        is then unused.
    """

    correlation_time: float
    std: float
    low: float
    high: float
    constant: bool


@dataclass(frozen=True)
class Scenario:
    """A named sequence of phases plus the uncertainty process.

    Paper scenario 1: one phase, terrain only. Scenario 2: ``[0, 5)`` terrain only, ``[5, 10)`` uncertainty only
    (roughness off, mu kept), ``[10, 15]`` both, in m travelled (``phase_clock='distance'``; the paper's Fig. 10
    gives seconds at the reference speed of 1 m/s) or in s (``phase_clock='time'``).
    """

    name: str
    phases: Sequence[Phase]
    uncertainty: DampingUncertainty
    phase_clock: str

    def __post_init__(self):
        object.__setattr__(self, "phases", tuple(self.phases))
        one_of("scenario.phase_clock", self.phase_clock, PHASE_CLOCKS)
        starts_increasing_from_zero("scenario.phases", [(p.name, p.start) for p in self.phases], "phase")
        u = self.uncertainty
        positive("scenario.uncertainty.correlation_time", u.correlation_time)
        non_negative("scenario.uncertainty.std", u.std)
        low, high = finite("scenario.uncertainty.low", u.low), finite("scenario.uncertainty.high", u.high)
        if low <= -1.0:
            raise ConfigError("scenario.uncertainty.low", u.low, "must be > -1 (the true damping must stay positive)")
        if high <= low:
            raise ConfigError("scenario.uncertainty.high", u.high, f"must be > scenario.uncertainty.low ({low:g})")

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.phases]

    @property
    def inner_edges(self) -> np.ndarray:
        """The starts of every phase but the first (in the unit of :attr:`phase_clock`)."""
        return np.array([p.start for p in self.phases[1:]], dtype=float)

    def phase_index(self, t: np.ndarray) -> np.ndarray:
        """Index of the phase each time lies in (``phase_clock='time'``)."""
        return np.searchsorted(self.inner_edges, t, side="right")


@law
def damping_scale(uncertainty, n):
    """The true damping's ratio ``b = B_true / B_nom = 1 + clip(std n(t), low, high)`` for the unit OU process
    ``n(t)`` (docs/model.md §5, scenario 2)."""
    return 1.0 + min(max(uncertainty.std * n, uncertainty.low), uncertainty.high)
