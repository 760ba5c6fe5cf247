"""Hydra callbacks (``hydra.callbacks`` in conf/): thin adapters from Hydra's multirun events to the storage,
tuning and study modules, which do the work. They run in the launching process, whatever the launcher."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from ddmr_cli.workers import shutdown_joblib_workers


def _unit_of(config: DictConfig):
    """A swept key's unit from the sweep's composed config (None for a key only some jobs' configs have)."""
    from ddmr_cli.config import key_doc

    def unit_of(key: str) -> str | None:
        try:
            return key_doc(config, key).unit
        except KeyError:
            return None

    return unit_of


class SweepAggregator(Callback):
    """A sweep (``hydra.callbacks.sweep_table``): writes the sweep plan at the start of the multirun and the
    sweep tables at its end (:func:`ddmr_cli.storage.sweep.aggregate`)."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli.config.plan import plan_jobs
        from ddmr_cli.storage.sweep import write_plan

        write_plan(Path(config.hydra.sweep.dir), plan_jobs(config.hydra.overrides.task, config))

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli import progress
        from ddmr_cli.storage.sweep import aggregate

        def writing():  # a line while the jobs are read and the tables written (1-3 s for 72 jobs of 50 seeds)
            return progress.status("sweep: writing its tables", enabled=bool(config.run.get("progress", True)))

        aggregate(Path(config.hydra.sweep.dir), _unit_of(config), writing)
        shutdown_joblib_workers()


class StudyCallback(Callback):
    """A tuning study's session (conf/tuning/default.yaml): :func:`ddmr_cli.study.tuning.start_session` and
    :func:`~ddmr_cli.study.tuning.end_session`."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli.study import tuning

        tuning.start_session(config)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli.study import tuning

        tuning.end_session(config)
        shutdown_joblib_workers()


class StudyAggregator(Callback):
    """A stage of the sensitivity study (conf/experiment/sensitivity.yaml): :func:`ddmr_cli.study.task.start_stage`
    and :func:`~ddmr_cli.study.task.end_stage`."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli.study import task

        task.start_stage(config)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from ddmr_cli.study import task

        task.end_stage(config)
        shutdown_joblib_workers()


__all__ = ["SweepAggregator", "StudyCallback", "StudyAggregator"]
