"""Sweeps: the plan of jobs, and the sweep-level tables written when a multirun ends.

The aggregation is a Hydra callback (``hydra.callbacks.sweep_table``) that runs in the launching process once
every job has returned, whatever the launcher (joblib, submitit, ray). It writes into the sweep dir:
``sweep_jobs.csv`` (one row per job: status, runs, diverged, headline statistics), ``sweep_metrics.csv``
(every job and seed) and ``sweep_segments.csv`` (every job, seed, zone and phase).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from ddmr_cli.cli import io

log = logging.getLogger("ddmr")

PLAN = "sweep_plan.json"
JOBS_CSV = "sweep_jobs.csv"
SWEEP_METRICS_CSV = "sweep_metrics.csv"
SWEEP_SEGMENTS_CSV = "sweep_segments.csv"

#: The plan of the sweep being launched, set by the CLI after it validated every job.
pending_plan: list[dict] | None = None
#: The outcome of the last sweep aggregated in this process (read by the CLI for its exit status).
last_sweep: "SweepState | None" = None


def expand_jobs(overrides: list[str], sweeper_params: dict[str, Any]) -> list[list[str]]:
    """The job override lists Hydra's basic sweeper will launch (sweeper params first, then the command line)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    params = [f"{k}={v}" for k, v in sweeper_params.items()] + list(overrides)
    parsed = OverridesParser.create().parse_overrides(params)
    return BasicSweeper.split_arguments(parsed, None)[0]


def job_dirname(job_overrides: list[str], exclude_keys, item_sep: str = ",", kv_sep: str = "=") -> str:
    """The sub-directory name Hydra gives a job (``hydra.job.override_dirname``)."""
    from hydra._internal.config_loader_impl import get_overrides_dirname
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed = OverridesParser.create().parse_overrides(list(job_overrides))
    return get_overrides_dirname(parsed, exclude_keys=list(exclude_keys), item_sep=item_sep, kv_sep=kv_sep)


@dataclass
class SweepState:
    """What a sweep dir holds: complete, failed and missing jobs."""

    sweep_dir: Path
    complete: list[tuple[Path, dict]] = field(default_factory=list)
    failed: list[tuple[Path, dict]] = field(default_factory=list)
    missing: list[dict] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failed and not self.missing


def load_sweep(sweep_dir: Path) -> SweepState:
    """Read a sweep dir (or a single run dir): the jobs with a summary, and the planned jobs without one."""
    sweep_dir = Path(sweep_dir)
    state = SweepState(sweep_dir)
    if io.read_summary(sweep_dir) is not None:  # a single run dir
        candidates = [sweep_dir]
    else:
        candidates = sorted(d for d in sweep_dir.iterdir() if d.is_dir() and not d.name.startswith("."))
    planned: dict[str, dict] = {}
    plan_path = sweep_dir / PLAN
    if plan_path.is_file():
        for job in json.loads(plan_path.read_text(encoding="utf-8"))["jobs"]:
            planned[job["dir"]] = job
            if not (sweep_dir / job["dir"]).is_dir():
                state.missing.append(job)
    for job_dir in candidates:
        summary = io.read_summary(job_dir)
        if summary is None:
            if job_dir.name in planned or (job_dir / ".hydra").is_dir():
                state.missing.append(planned.get(job_dir.name, {"dir": job_dir.name, "overrides": []}))
            continue
        (state.complete if summary.get("status") == "complete" else state.failed).append((job_dir, summary))
    return state


def aggregate(sweep_dir: Path) -> SweepState:
    """Write the sweep-level tables and print one line per job; returns the sweep's state."""
    import pandas as pd

    state = load_sweep(sweep_dir)
    rows, metric_frames, segment_frames = [], [], []
    for job_dir, summary in state.complete + state.failed:
        stats = summary.get("statistics", {})
        rows.append({"job": job_dir.name, "controller": summary.get("controller"), "scenario": summary.get("scenario"),
                     "status": summary.get("status"), "runs": stats.get("runs"), "diverged": stats.get("diverged"),
                     **{k: stats.get(k) for k in ("deviation_mae_mean", "deviation_mae_sd", "e_x_mae_mean",
                                                  "e_y_mae_mean", "e_theta_mae_mean", "chattering_mean",
                                                  "d_est_mae_mean")},
                     "wall_time": summary.get("wall_time"), "error": summary.get("error", "")})
        if summary.get("status") == "complete":
            for name, frames in ((io.METRICS_CSV, metric_frames), (io.SEGMENTS_CSV, segment_frames)):
                frame = pd.read_csv(job_dir / name)
                frame.insert(0, "job", job_dir.name)
                frames.append(frame)
    for job in state.missing:
        rows.append({"job": job["dir"], "status": "missing"})
    jobs = pd.DataFrame(rows)
    io.write_csv(state.sweep_dir / JOBS_CSV, jobs)
    if metric_frames:
        io.write_csv(state.sweep_dir / SWEEP_METRICS_CSV, pd.concat(metric_frames, ignore_index=True))
        io.write_csv(state.sweep_dir / SWEEP_SEGMENTS_CSV, pd.concat(segment_frames, ignore_index=True))
    print(f"\nddmr sweep: {len(state.complete)} complete, {len(state.failed)} failed, {len(state.missing)} missing "
          f"-> {state.sweep_dir}")
    for row in rows:
        if row["status"] == "complete":
            print(f"  {row['controller']:>18s} {row['scenario']:>8s}  runs {row['runs']:>5d} diverged {row['diverged']:>3d}"
                  f"  deviation {row['deviation_mae_mean']:.5f} +- {row['deviation_mae_sd']:.5f} m"
                  f"  e_x {row['e_x_mae_mean']:.5f}  e_y {row['e_y_mae_mean']:.5f}  e_th {row['e_theta_mae_mean']:.5f}")
        else:
            print(f"  {row['job']}: {row['status']} {row.get('error', '')}")
    print(f"  tables: {JOBS_CSV}, {SWEEP_METRICS_CSV}, {SWEEP_SEGMENTS_CSV}; report: ddmr report {state.sweep_dir}")
    return state


class SweepAggregator(Callback):
    """Hydra callback: writes the sweep plan at the start and the sweep tables at the end of a multirun."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        global pending_plan
        if pending_plan is not None:
            sweep_dir = Path(config.hydra.sweep.dir)
            io.write_json(sweep_dir / PLAN, {"jobs": pending_plan})
            pending_plan = None

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        global last_sweep
        last_sweep = aggregate(Path(config.hydra.sweep.dir))
        _shutdown_joblib_workers()


def _shutdown_joblib_workers() -> None:
    """Stop the joblib launcher's worker processes now rather than after loky's idle timeout."""
    import sys

    if "joblib" in sys.modules:
        from joblib.externals.loky import get_reusable_executor

        get_reusable_executor().shutdown(wait=True)
