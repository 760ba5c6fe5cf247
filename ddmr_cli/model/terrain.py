"""Terrain zones along the distance travelled, and the roughness process (docs/model.md §5).

A zone has a ``roughness`` [rad/s^2, the units of the paper's d(t)] scaling a unit-variance
Ornstein-Uhlenbeck process per wheel, and a rolling-resistance coefficient ``mu``. The terrain torque is
``tau_d = mu m g R / 2 sign(w) + J n(t) roughness`` (rolling resistance opposes each wheel's rotation), hence
``d = -J^-1 mu m g R / 2 sign(w) - roughness n(t)`` (docs/model.md §5, where the original spec's ``[1, 1]``
holds for forward motion only).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ddmr_cli.checks import non_negative, positive, starts_increasing_from_zero
from ddmr_cli.compiled import law


@dataclass(frozen=True)
class TerrainZone:
    """One stretch of terrain, from ``start`` [m of distance travelled] to the next zone's start."""

    name: str
    start: float
    roughness: float
    mu: float

    def __post_init__(self) -> None:
        non_negative(f"terrain.zones.{self.name}.start", self.start)
        non_negative(f"terrain.zones.{self.name}.roughness", self.roughness)
        non_negative(f"terrain.zones.{self.name}.mu", self.mu)


@dataclass(frozen=True)
class Terrain:
    """Zones along the distance travelled, plus the correlation time of the roughness process.

    Parameters
    ----------
    zones : sequence of TerrainZone
        Ordered by ``start``; the first starts at 0, the last extends to infinity.
        Paper (Fig. 3): flat [0, 5) m, very rough [5, 10) m, slightly rough [10, inf) m.
    correlation_time : float
        tau_c of the unit-variance OU process n(t) per wheel [s].
    """

    zones: Sequence[TerrainZone]
    correlation_time: float

    def __post_init__(self):
        object.__setattr__(self, "zones", tuple(self.zones))
        positive("terrain.correlation_time", self.correlation_time)
        starts_increasing_from_zero("terrain.zones", [(z.name, z.start) for z in self.zones], "zone")

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
        """Index of the zone each distance [m] lies in (:func:`zone_of`, elementwise)."""
        edges = self.inner_edges
        return np.array([zone_of(edges, float(d)) for d in np.ravel(distance)], dtype=np.intp).reshape(np.shape(distance))


@law
def zone_of(inner_edges, distance):
    """Index of the zone that ``distance`` [m] lies in, given the starts of every zone but the first (an edge
    belongs to the zone it starts; docs/model.md §5)."""
    zone = 0
    while zone < inner_edges.shape[0] and distance >= inner_edges[zone]:
        zone += 1
    return zone
