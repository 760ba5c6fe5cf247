"""ddmr: trajectory-tracking experiments for differential-drive mobile robots.

Python API (model code, no Hydra needed)::

    from ddmr_cli import paper_simulation, paper_controller, simulate
    sim = paper_simulation("controller=smc_ndo", "scenario=paper_2")   # every value from the packaged config
    sim = paper_simulation(controller=paper_controller("smc", "controller.switching_gain=20"), duration=5.0)
    result = simulate(sim, seeds=range(50))
    result.to_pandas()

The model classes (``Simulation``, ``Robot``, ``SMC``, ...) take every value as a required argument; the
defaults live once, in the packaged YAML (``conf/``), which the ``paper_*`` functions read.

Config-driven (the same configs as the CLI)::

    from ddmr_cli import compose_config, run_config
    result = run_config(compose_config(["controller=smc_ndo_nno", "scenario=paper_2"]))

A sweep's results (``ddmr run -m ...``), one row per job and seed, swept keys as columns::

    from ddmr_cli import load_sweep
    table = load_sweep("outputs/run/2026-01-01_12-00-00")
"""

from typing import TYPE_CHECKING

from ddmr_cli.exports import lazy_exports
from ddmr_cli.version import __version__

#: public name -> module that defines it; imported on first use (PEP 562), so ``ddmr --help`` starts fast
_EXPORTS = {
    "PID": "control", "SMC": "control", "AdaptiveSMC": "control", "SuperTwisting": "control", "ADRC": "control",
    "NonlinearDisturbanceObserver": "control",
    "OpenLoop": "control", "RBFNetworkObserver": "control", "WheelController": "control",
    "ConfigError": "errors", "DDMRError": "errors",
    "Kanayama": "control.outer_loop",
    "paper_config": "config.presets", "paper_simulation": "config.presets",
    "paper_controller": "config.presets", "paper_trajectory": "config.presets",
    "paper_robot": "config.presets", "paper_scenario": "config.presets", "paper_terrain": "config.presets",
    "SimulationResult": "engine.results", "NominalModel": "model.robot", "Robot": "model.robot",
    "DampingUncertainty": "model.scenario", "Phase": "model.scenario", "Scenario": "model.scenario",
    "Simulation": "engine.simulation", "simulate": "engine.simulation", "Terrain": "model.terrain", "TerrainZone": "model.terrain",
    "Circle": "model.trajectory", "FigureEight": "model.trajectory", "Sinusoid": "model.trajectory",
    "StraightLine": "model.trajectory",
}


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)


if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

    from ddmr_cli.control import (ADRC, PID, SMC, AdaptiveSMC, NonlinearDisturbanceObserver, OpenLoop,
                                  RBFNetworkObserver, SuperTwisting, WheelController)
    from ddmr_cli.errors import ConfigError, DDMRError
    from ddmr_cli.control.outer_loop import Kanayama
    from ddmr_cli.config.presets import (paper_config, paper_controller, paper_robot, paper_scenario,
                                             paper_simulation, paper_terrain, paper_trajectory)
    from ddmr_cli.engine.results import SimulationResult
    from ddmr_cli.model.robot import NominalModel, Robot
    from ddmr_cli.model.scenario import DampingUncertainty, Phase, Scenario
    from ddmr_cli.engine.simulation import Simulation, simulate
    from ddmr_cli.model.terrain import Terrain, TerrainZone
    from ddmr_cli.model.trajectory import Circle, FigureEight, Sinusoid, StraightLine


def compose_config(overrides=(), config_name: str = "config"):
    """Compose the packaged Hydra config with overrides (see :mod:`ddmr_cli.config`)."""
    from ddmr_cli.config import compose_config as _compose

    return _compose(list(overrides), config_name)


def load_sweep(path, segments: bool = False) -> "pd.DataFrame":
    """The tidy per-seed table of a sweep dir (``ddmr run -m ...``) or a run dir, as a pandas DataFrame.

    One row per job and seed (``segments=True``: per job, seed and terrain zone / scenario phase) of every
    complete job; every key the sweep varies (``controller.switching_gain=4,8,12``) is a typed column, and the
    rows are sorted by those values (numbers as numbers), then by seed. See :mod:`ddmr_cli.storage.sweep`."""
    from ddmr_cli.storage.sweep import load_table

    return load_table(path, segments=segments)


def run_config(cfg, progress=None) -> "SimulationResult":
    """Build the simulation a composed config describes and run its seeds (see :mod:`ddmr_cli.config`)."""
    from ddmr_cli.config import run_config as _run

    return _run(cfg, progress=progress)


__all__ = [
    "Simulation", "simulate", "SimulationResult", "Robot", "NominalModel", "Terrain", "TerrainZone", "Scenario",
    "Phase", "DampingUncertainty", "StraightLine", "Circle", "FigureEight", "Sinusoid", "Kanayama", "WheelController",
    "PID", "SMC", "AdaptiveSMC", "SuperTwisting", "ADRC", "OpenLoop", "NonlinearDisturbanceObserver", "RBFNetworkObserver",
    "paper_terrain", "paper_scenario",
    "paper_config", "paper_simulation", "paper_controller", "paper_trajectory", "paper_robot",
    "compose_config", "run_config", "load_sweep", "ConfigError", "DDMRError",
]
