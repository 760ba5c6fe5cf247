"""The ``@hydra.main`` entry behind ``ddmr run`` (configs from the installed package ``ddmr_cli.conf``)."""

from __future__ import annotations

import hydra
from omegaconf import DictConfig

from ddmr_cli.cli import config  # noqa: F401  (registers the config schemas)
from ddmr_cli.cli.app import run_job


@hydra.main(version_base="1.3", config_path="pkg://ddmr_cli.conf", config_name="config")
def main(cfg: DictConfig) -> None:
    if cfg.get("study") is not None:  # a job of the sensitivity study (+experiment=sensitivity_*)
        from ddmr_cli.study.task import execute_study

        run_job(cfg, task=execute_study)
    else:
        run_job(cfg)
