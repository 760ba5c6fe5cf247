"""The configs of ``hydra/sweeper=ddmr_optuna`` and its samplers (``hydra/sweeper/sampler=tpe|nsgaii|...``).

The keys are those of Hydra's ``hydra-optuna-sweeper`` (``sampler``, ``direction``, ``storage``, ``study_name``,
``n_trials``, ``n_jobs``, ``max_failure_rate``, ``params``, ``custom_search_space``), so a config written for that
plugin runs here with ``hydra/sweeper: ddmr_optuna``. Nothing here imports Optuna: the sampler nodes name their
class (``_target_``) and are instantiated when the sweeper starts.

The samplers live in Hydra's group ``hydra/sweeper/sampler`` under the names users know (``tpe``, ``nsgaii``,
``random``, ``cmaes``, ``gp``, ``qmc``, ``grid``); each field is an argument of the Optuna >= 4 sampler of the same
name, left to Optuna's default when ``None``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING

#: The directions an objective may have (Optuna's ``StudyDirection`` names).
DIRECTIONS = ("minimize", "maximize")


@dataclass
class SamplerConfig:
    _target_: str = MISSING


@dataclass
class TPESamplerConfig(SamplerConfig):
    """``optuna.samplers.TPESampler`` (one or several objectives)."""

    _target_: str = "optuna.samplers.TPESampler"
    seed: Optional[int] = None
    consider_magic_clip: Optional[bool] = None
    consider_endpoints: Optional[bool] = None
    n_startup_trials: int = 10
    n_ei_candidates: int = 24
    multivariate: Optional[bool] = None
    group: bool = False
    warn_independent_sampling: Optional[bool] = None
    constant_liar: bool = True


@dataclass
class RandomSamplerConfig(SamplerConfig):
    """``optuna.samplers.RandomSampler``."""

    _target_: str = "optuna.samplers.RandomSampler"
    seed: Optional[int] = None


@dataclass
class CmaEsSamplerConfig(SamplerConfig):
    """``optuna.samplers.CmaEsSampler`` (needs the ``cmaes`` package)."""

    _target_: str = "optuna.samplers.CmaEsSampler"
    seed: Optional[int] = None
    x0: Optional[Dict[str, Any]] = None
    sigma0: Optional[float] = None
    n_startup_trials: int = 1
    warn_independent_sampling: bool = True
    consider_pruned_trials: bool = False
    restart_strategy: Optional[str] = None
    use_separable_cma: bool = False


@dataclass
class NSGAIISamplerConfig(SamplerConfig):
    """``optuna.samplers.NSGAIISampler`` (several objectives: a Pareto front)."""

    _target_: str = "optuna.samplers.NSGAIISampler"
    seed: Optional[int] = None
    population_size: int = 50
    mutation_prob: Optional[float] = None
    crossover_prob: float = 0.9
    swapping_prob: float = 0.5


@dataclass
class GPSamplerConfig(SamplerConfig):
    """``optuna.samplers.GPSampler`` (needs torch)."""

    _target_: str = "optuna.samplers.GPSampler"
    seed: Optional[int] = None
    n_startup_trials: int = 10
    deterministic_objective: bool = False
    warn_independent_sampling: bool = True


@dataclass
class QMCSamplerConfig(SamplerConfig):
    """``optuna.samplers.QMCSampler``."""

    _target_: str = "optuna.samplers.QMCSampler"
    seed: Optional[int] = None
    qmc_type: str = "sobol"
    scramble: bool = False
    warn_asynchronous_seeding: bool = True
    warn_independent_sampling: bool = True


@dataclass
class GridSamplerConfig(SamplerConfig):
    """``optuna.samplers.GridSampler``: its grid is the search space (choice and range sweeps only), built when
    the sweep starts."""

    _target_: str = "optuna.samplers.GridSampler"
    _partial_: bool = True
    seed: Optional[int] = None


SAMPLERS = {"tpe": TPESamplerConfig, "random": RandomSamplerConfig, "cmaes": CmaEsSamplerConfig,
            "nsgaii": NSGAIISamplerConfig, "gp": GPSamplerConfig, "qmc": QMCSamplerConfig, "grid": GridSamplerConfig}


@dataclass
class DdmrOptunaSweeperConf:
    """``hydra/sweeper=ddmr_optuna``: an Optuna study whose trials are Hydra jobs."""

    _target_: str = "hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper.DdmrOptunaSweeper"
    defaults: List[Any] = field(default_factory=lambda: [{"sampler": "tpe"}])
    sampler: SamplerConfig = MISSING
    # "minimize" | "maximize", or a list of them (one per objective the task returns)
    direction: Any = "minimize"
    # an Optuna storage URL (sqlite:///path/study.db); None: in memory, gone when the sweep ends
    storage: Optional[Any] = None
    study_name: Optional[str] = None
    n_trials: int = 20
    # trials asked of the sampler at once and launched as one batch
    n_jobs: int = 2
    # the largest fraction of a batch's trials that may fail before the sweep stops
    max_failure_rate: float = 0.0
    # key -> sweep: interval(a, b), tag(log, interval(a, b)), choice(...), range(...); or a fixed value
    params: Optional[Dict[str, str]] = None
    # a dotted path to f(config: DictConfig, trial: optuna.Trial) -> None suggesting more parameters
    custom_search_space: Optional[str] = None


def register() -> None:
    """Store the sweeper and its samplers in Hydra's ConfigStore (idempotent)."""
    cs = ConfigStore.instance()
    cs.store(group="hydra/sweeper", name="ddmr_optuna", node=DdmrOptunaSweeperConf, provider="ddmr")
    for name, node in SAMPLERS.items():
        cs.store(group="hydra/sweeper/sampler", name=name, node=node, provider="ddmr")


register()

__all__ = ["DdmrOptunaSweeperConf", "SAMPLERS", "DIRECTIONS", "register"]
