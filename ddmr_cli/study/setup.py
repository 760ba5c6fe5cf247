"""What every stage of the sensitivity study shares: its files' names and, from a study config, the box, the
per controller and scenario configs, the faithful reading and the stage's design."""

from __future__ import annotations

import copy
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omegaconf import DictConfig, OmegaConf

from ddmr_cli.keyed import Keyed
from ddmr_cli.study.design import Design, build
from ddmr_cli.study.space import Box

if TYPE_CHECKING:
    from ddmr_cli.config.variants import Variants

#: one row per sample of a study job (in its job dir)
STUDY_ROWS = "study_rows.csv"
#: the stage's table: every sample of every job (in the stage's sweep dir)
STUDY_CSV = "study.csv"


def study_configs(cfg: DictConfig) -> dict[tuple[str, str], DictConfig]:
    """(controller, scenario) -> the job's config with that controller and scenario (no ``study`` node)."""
    from omegaconf import open_dict

    base = copy.deepcopy(cfg)
    study = base.study
    base.study = None
    with open_dict(base):
        base.pop("hydra", None)
    out = {}
    for c, c_cfg in study.configs.controller.items():
        for s, s_cfg in study.configs.scenario.items():
            one = copy.deepcopy(base)
            one.controller = c_cfg
            one.scenario = s_cfg
            out[(str(c), str(s))] = one
    return out


#: study settings a job's models do not depend on: its share of the design, a calibration trial's reading
JOB_SETTINGS = ("chunk", "reading")


@lru_cache(maxsize=2)
def _built(keyed: Keyed) -> tuple[Box, dict[tuple[str, str], Variants], dict[str, Any]]:
    from ddmr_cli.config.variants import BuiltParts, Variants

    box = Box.from_config(keyed.value.study)
    configs = study_configs(keyed.value)
    parts = BuiltParts()  # the configs share the sections they build alike
    variants = {key: Variants(one, parts) for key, one in configs.items()}
    return box, variants, box.faithful_across(list(configs.values()))


def study_models(cfg: DictConfig) -> tuple[Box, dict[tuple[str, str], Variants], dict[str, Any]]:
    """What a study job simulates its samples on: the box, each (controller, scenario) config validated and built
    once (:class:`~ddmr_cli.config.variants.Variants`) and the faithful reading.

    Kept per process for the last two study configs that differ only in :data:`JOB_SETTINGS` (and the ``hydra``
    node): a launcher's worker runs many jobs of one stage (the calibration's trials: one sample each), and
    building the 8 configs took about a third of such a job. Built anew (and raising) for a config refused."""
    from ddmr_cli.config.build import container_digest

    container = OmegaConf.to_container(cfg, resolve=True)
    container.pop("hydra", None)
    for key in JOB_SETTINGS:
        container["study"].pop(key, None)
    return _built(Keyed(container_digest(container), cfg))


def study_setup(cfg: DictConfig, sweep_dir: Path | None = None
                ) -> tuple[Box, dict[tuple[str, str], DictConfig], dict[str, Any], Design]:
    """The box, the per controller and scenario configs, the faithful reading (each parameter read from the first
    config that has its keys: the NN's from SMC-NDO-NNO's) and the stage's design (``sweep_dir``: the stage's)."""
    box = Box.from_config(cfg.study)
    configs = study_configs(cfg)
    faithful = box.faithful_across(list(configs.values()))
    return box, configs, faithful, build(cfg.study, box, faithful, sweep_dir)



__all__ = ["STUDY_ROWS", "STUDY_CSV", "JOB_SETTINGS", "study_configs", "study_models", "study_setup"]
