"""The paper's terrain and scenarios as plain objects, for the Python API without Hydra.

The YAML files in ``conf/terrain`` and ``conf/scenario`` hold the same values for the CLI
(a test checks that both agree).
"""

from __future__ import annotations

from ddmr_cli.model.scenario import DampingUncertainty, Phase, Scenario
from ddmr_cli.model.terrain import Terrain, TerrainZone


def paper_terrain() -> Terrain:
    """Paper Fig. 3 (docs/model.md §5): flat [0, 5) m, very rough [5, 10) m, slightly rough from 10 m."""
    return Terrain(zones=(TerrainZone("flat", 0.0, 0.1, 0.02), TerrainZone("very_rough", 5.0, 100.0, 0.10),
                          TerrainZone("slightly_rough", 10.0, 5.0, 0.05)), correlation_time=0.02)


def paper_scenario(number: int) -> Scenario:
    """Paper scenario 1 (terrain only) or 2 (terrain, then uncertainty, then both; Fig. 10)."""
    if number == 1:
        return Scenario("paper_1", (Phase("terrain", 0.0, roughness=True, uncertainty=False),))
    if number == 2:
        return Scenario("paper_2", (Phase("terrain", 0.0, True, False), Phase("uncertainty", 5.0, False, True),
                                    Phase("both", 10.0, True, True)), DampingUncertainty(0.5, 0.4, -0.5, 1.0))
    raise ValueError(f"paper scenario must be 1 or 2, got {number!r}")
