"""Validation of a composed config before anything is run or written.

The model parts and controllers check their own values when they are built (their constructors raise
:class:`~ddmr_cli.errors.ConfigError` naming the key) and :meth:`~ddmr_cli.engine.simulation.Simulation.validate`
checks the step against every part's stability bound; this module adds only what belongs to the CLI: which
classes a config may instantiate, and the ``run`` section. The CLI prints a ConfigError as one line, exit 2.
"""

from __future__ import annotations

from omegaconf import DictConfig

from ddmr_cli.checks import integer
from ddmr_cli.cli.config.build import build_simulation, check_targets


def validate_run(run: DictConfig) -> None:
    """The ``run`` section: seeds, kept series, threads."""
    integer("run.n_runs", run.n_runs, 1)
    integer("run.base_seed", run.base_seed, 0)
    integer("run.threads", run.threads, 0)
    for i, seed in enumerate(run.keep_series):
        integer(f"run.keep_series[{i}]", seed, 0)


def validate_config(cfg: DictConfig):
    """Check every value of a composed config; raise ConfigError on the first bad one. Returns the built
    :class:`~ddmr_cli.engine.simulation.Simulation`."""
    check_targets(cfg.get("controller"), "controller")
    check_targets(cfg.get("trajectory"), "trajectory")
    sim = build_simulation(cfg)
    sim.validate()
    validate_run(cfg.run)
    return sim
