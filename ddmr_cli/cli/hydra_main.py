"""The ``@hydra.main`` entry behind ``ddmr run`` (configs from the installed package ``ddmr_cli.conf``).

The only place that reads Hydra's runtime (the job's output dir, its overrides, whether it is one job of a
multirun, the sweeper's sampled keys) and hands them to the job, trial or study task as plain values.
"""

from __future__ import annotations

from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.core.plugins import Plugins
from hydra_plugins.ddmr_optuna_sweeper.optuna_sweeper import DdmrOptunaSweeper
from hydra_plugins.ddmr_sweeper.ddmr_sweeper import DdmrSweeper
from omegaconf import DictConfig

from ddmr_cli import config  # noqa: F401  (registers the config schemas)
from ddmr_cli.cli.collector import collect_less_often
from ddmr_cli.job import JobPlace, run_job

# hydra/sweeper=ddmr (conf/launcher/*.yaml) and hydra/sweeper=ddmr_optuna (conf/tuning, the calibration search):
# Hydra's plugin scan does not see an editable install's hydra_plugins
Plugins.instance().register(DdmrSweeper)
Plugins.instance().register(DdmrOptunaSweeper)


def job_place() -> JobPlace:
    """This job's output dir, overrides, whether it runs inside a multirun and whether that multirun's jobs run one
    after another in this process (Hydra's basic launcher), from Hydra's runtime."""
    hc = HydraConfig.get()
    serial = str(hc.launcher.get("_target_", "")).endswith(".BasicLauncher")
    return JobPlace(Path(hc.runtime.output_dir), tuple(hc.overrides.task), "MULTIRUN" in str(hc.mode), serial)


@hydra.main(version_base="1.3", config_path="pkg://ddmr_cli.conf", config_name="config")
def main(cfg: DictConfig) -> float | list[float] | None:
    collect_less_often()  # a sweep's worker process (the ddmr program has done so already)
    place = job_place()
    if cfg.get("tuning") is not None:  # a trial of a tuning study: the objective goes back to the Optuna sweeper
        from ddmr_cli.study.tuning import run_trial

        return run_trial(cfg, place, [str(k) for k in (HydraConfig.get().sweeper.get("params") or {})])
    if cfg.get("study") is not None:  # a job of the sensitivity study (+experiment=sensitivity_*)
        from ddmr_cli.study import search
        from ddmr_cli.study.task import execute_study

        summary = run_job(cfg, place, task=execute_study)
        # a trial of the calibration search: its objective goes back to the Optuna sweeper
        return search.objective_of(summary) if search.is_search(cfg) else None
    run_job(cfg, place)
    return None
