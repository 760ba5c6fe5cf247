"""Terrain zones along the distance travelled, and the roughness process (MODEL.md section 5).

A zone has a ``roughness`` [rad/s^2, the units of the paper's d(t)] scaling a unit-variance
Ornstein-Uhlenbeck process per wheel, and a rolling-resistance coefficient ``mu``. The terrain torque is
``tau_d = mu m g R / 2 [1, 1] + J n(t) roughness``, hence ``d = -J^-1 mu m g R / 2 [1, 1] - roughness n(t)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np


@dataclass(frozen=True)
class TerrainZone:
    """One stretch of terrain, from ``start`` [m of distance travelled] to the next zone's start."""

    name: str
    start: float
    roughness: float
    mu: float


@dataclass(frozen=True)
class Terrain:
    """Zones along the distance travelled, plus the correlation time of the roughness process.

    Parameters
    ----------
    zones : sequence of TerrainZone
        Ordered by ``start``; the first starts at 0, the last extends to infinity.
        Paper (Fig. 3): flat [0, 5) m, very rough [5, 10) m, slightly rough [10, inf) m.
    correlation_time : float
        tau_c of the unit-variance OU process n(t) per wheel [s] (MODEL.md: 0.02).
    """

    zones: Sequence[TerrainZone] = field(default_factory=lambda: (TerrainZone("flat", 0.0, 0.0, 0.0),))
    correlation_time: float = 0.02

    def __post_init__(self):
        object.__setattr__(self, "zones", tuple(self.zones))

    @property
    def names(self) -> list[str]:
        return [z.name for z in self.zones]

    @property
    def roughness(self) -> np.ndarray:
        return np.array([z.roughness for z in self.zones], dtype=float)

    @property
    def mu(self) -> np.ndarray:
        return np.array([z.mu for z in self.zones], dtype=float)

    @property
    def inner_edges(self) -> np.ndarray:
        """Zone starts after the first one, for :meth:`zone_index`."""
        return np.array([z.start for z in self.zones[1:]], dtype=float)

    def zone_index(self, distance: np.ndarray) -> np.ndarray:
        """Index of the zone each distance [m] lies in (edges belong to the zone they start)."""
        return np.searchsorted(self.inner_edges, distance, side="right")


def ou_coefficients(dt: float, correlation_time: float) -> tuple[float, float]:
    """Exact discretisation of a unit-variance OU process: ``n_k+1 = a n_k + b xi_k``, ``b = sqrt(1 - a^2)``."""
    a = float(np.exp(-dt / correlation_time))
    return a, float(np.sqrt(1.0 - a * a))
