"""Hydra at the edge: config schemas, composition, validation and building the model from a config."""

from __future__ import annotations

from typing import Callable, Sequence

from ddmr_cli.cli.config import schema  # noqa: F401  (registers the schemas in Hydra's ConfigStore)
from ddmr_cli.cli.config.build import build_simulation, config_hash, seeds_of
from ddmr_cli.cli.config.validate import validate_config

CONFIG_MODULE = "ddmr_cli.conf"


def compose_config(overrides: Sequence[str] = (), config_name: str = "config", return_hydra_config: bool = False):
    """Compose the packaged config with Hydra's compose API (no output directory is made)."""
    from hydra import compose, initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return compose(config_name=config_name, overrides=list(overrides), return_hydra_config=return_hydra_config)


def group_options(group: str) -> list[str]:
    """The options of a config group (``controller`` -> ``pid, smc, ...``), schemas left out."""
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        options = GlobalHydra.instance().config_loader().get_group_options(group)
    return sorted(options)


def run_config(cfg, progress: Callable[[int, int], None] | None = None):
    """Validate a composed config, build its simulation and run its seeds. Returns a SimulationResult."""
    from ddmr_cli.engine.simulation import simulate

    sim = validate_config(cfg)
    return simulate(sim, seeds_of(cfg), keep_series=list(cfg.run.keep_series), progress=progress)


__all__ = ["compose_config", "group_options", "run_config", "build_simulation", "validate_config", "config_hash", "seeds_of"]
