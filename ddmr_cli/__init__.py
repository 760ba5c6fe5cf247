"""ddmr: trajectory-tracking experiments for differential-drive mobile robots.

Python API (model code, no Hydra needed)::

    from ddmr_cli import Simulation, simulate, SMC, NonlinearDisturbanceObserver, paper_terrain, paper_scenario
    sim = Simulation(controller=SMC(ndo=NonlinearDisturbanceObserver(50.0)),
                     terrain=paper_terrain(), scenario=paper_scenario(1))
    result = simulate(sim, seeds=range(50))
    result.to_pandas()

Config-driven (the same configs as the CLI)::

    from ddmr_cli import compose_config, run_config
    result = run_config(compose_config(["controller=smc_ndo_nno", "scenario=paper_2"]))
"""

from importlib import import_module
from typing import TYPE_CHECKING

__version__ = "0.1.0"

#: public name -> module that defines it; imported on first use (PEP 562), so ``ddmr --help`` starts fast
_EXPORTS = {
    "PID": "controllers", "SMC": "controllers", "NonlinearDisturbanceObserver": "controllers",
    "OpenLoop": "controllers", "RBFNetworkObserver": "controllers", "WheelController": "controllers",
    "ConfigError": "errors", "DDMRError": "errors", "SimulationError": "errors",
    "Kanayama": "outer_loop", "paper_scenario": "presets", "paper_terrain": "presets",
    "SimulationResult": "results", "NominalModel": "robot", "Robot": "robot",
    "DampingUncertainty": "scenario", "Phase": "scenario", "Scenario": "scenario",
    "Simulation": "simulation", "simulate": "simulation", "Terrain": "terrain", "TerrainZone": "terrain",
    "Circle": "trajectory", "FigureEight": "trajectory", "StraightLine": "trajectory",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'ddmr_cli' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_EXPORTS))


if TYPE_CHECKING:  # pragma: no cover
    from .controllers import (PID, SMC, NonlinearDisturbanceObserver, OpenLoop, RBFNetworkObserver,
                              WheelController)
    from .errors import ConfigError, DDMRError, SimulationError
    from .outer_loop import Kanayama
    from .presets import paper_scenario, paper_terrain
    from .results import SimulationResult
    from .robot import NominalModel, Robot
    from .scenario import DampingUncertainty, Phase, Scenario
    from .simulation import Simulation, simulate
    from .terrain import Terrain, TerrainZone
    from .trajectory import Circle, FigureEight, StraightLine


def compose_config(overrides=(), config_name: str = "config"):
    """Compose the packaged Hydra config with overrides (see :mod:`ddmr_cli.config`)."""
    from .config import compose_config as _compose

    return _compose(list(overrides), config_name)


def run_config(cfg, progress=None) -> "SimulationResult":
    """Build the simulation a composed config describes and run its seeds (see :mod:`ddmr_cli.config`)."""
    from .config import run_config as _run

    return _run(cfg, progress=progress)


__all__ = [
    "Simulation", "simulate", "SimulationResult", "Robot", "NominalModel", "Terrain", "TerrainZone", "Scenario",
    "Phase", "DampingUncertainty", "StraightLine", "Circle", "FigureEight", "Kanayama", "WheelController", "PID",
    "SMC", "OpenLoop", "NonlinearDisturbanceObserver", "RBFNetworkObserver", "paper_terrain", "paper_scenario",
    "compose_config", "run_config", "ConfigError", "DDMRError", "SimulationError",
]
