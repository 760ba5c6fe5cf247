"""What every stage of the sensitivity study shares: its files' names and, from a study config, the box, the
per controller and scenario configs, the faithful reading and the stage's design."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from ddmr_cli.study.design import Design, build
from ddmr_cli.study.space import Box

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


def study_setup(cfg: DictConfig, sweep_dir: Path | None = None
                ) -> tuple[Box, dict[tuple[str, str], DictConfig], dict[str, Any], Design]:
    """The box, the per controller and scenario configs, the faithful reading (each parameter read from the first
    config that has its keys: the NN's from SMC-NDO-NNO's) and the stage's design (``sweep_dir``: the stage's)."""
    box = Box.from_config(cfg.study)
    configs = study_configs(cfg)
    faithful = box.faithful_across(list(configs.values()))
    return box, configs, faithful, build(cfg.study, box, faithful, sweep_dir)



__all__ = ["STUDY_ROWS", "STUDY_CSV", "study_configs", "study_setup"]
