"""The sensitivity study's Hydra job and sweep callback (docs/model.md §11).

A job (``ddmr run -m +experiment=sensitivity_<stage>``, one per ``study.chunk``) computes the stage's design
(:mod:`ddmr_cli.study.design`, the same in every job), takes its share of the samples, and for each sample runs
every controller of ``study.configs.controller`` in every scenario of ``study.configs.scenario`` over the job's
seeds (``run.n_runs`` from ``run.base_seed``, one batch per controller and scenario), with the sample's values set
on the config (:meth:`~ddmr_cli.study.space.Box.apply`). It writes ``study_rows.csv`` (one row per sample: its
values, claim statistics, Table 4 numbers, distance to the paper) and ``summary.json``; it goes through
:func:`ddmr_cli.job.run_job`, so a job with a complete summary of the same config is skipped (resume), and a
failing job is recorded. A sample whose values a model part refuses, or whose run diverges, is a row with status
``failed`` or NaN statistics, not a failed job.

:class:`StudyAggregator` (the stage presets' ``hydra.callbacks.sweep_table``) writes the sweep plan at the start
and, at the end, ``study.csv`` (every job's rows, by sample) and the stage's analysis
(:func:`ddmr_cli.study.analysis.analyse`).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from omegaconf import DictConfig

from ddmr_cli.keyed import Kept
from ddmr_cli.storage import io, jobdir
from ddmr_cli.storage.sweep import read_state
from ddmr_cli.study import claims as claim_stats
from ddmr_cli.study import search
from ddmr_cli.study.design import build, chunk_of
from ddmr_cli.study.setup import STUDY_CSV, STUDY_ROWS, study_models
from ddmr_cli.study.space import Box

if TYPE_CHECKING:
    from ddmr_cli.config.variants import Variants

log = logging.getLogger("ddmr")

class RunMemo(Kept):
    """The per-seed metrics of every (controller, scenario) a study job has simulated, by the values its sample set
    on that config (:meth:`~ddmr_cli.config.variants.Variants.changes`, :func:`~ddmr_cli.config.variants.values_key`).

    A run is a deterministic function of its config and seed, so a sample whose values leave a config as an
    earlier sample left it (a network parameter for a controller without a network, a map of the network's plane
    for the three others, an OAT curve's faithful point) gives that config's earlier numbers, to the bit, without
    simulating it again. Keys compare values by their bits (a no-op when they differ); at most ``size`` configs
    are kept, the oldest dropped first. The arrays kept are copies, read-only; ``reused`` counts runs."""

    def __init__(self, seeds: list[int], size: int = 4096) -> None:
        super().__init__(size, weight=len(seeds))
        self.seeds = tuple(seeds)

    def put(self, key: tuple, value: tuple[dict, int]) -> None:
        metrics, _ = value
        for values in metrics.values():
            values.setflags(write=False)
        super().put(key, value)


def simulate_sample(box: Box, configs: dict[tuple[str, str], Variants], sample: dict, seeds: list[int],
                    threads: int, memo: RunMemo | None = None) -> tuple[dict, int, int]:
    """Every controller and scenario at one reading: per (controller, scenario) the per-seed metrics
    (:data:`~ddmr_cli.study.claims.METRICS`), and the counts of runs and diverged runs. ``configs``: each
    (controller, scenario) config built once (:class:`~ddmr_cli.config.variants.Variants`), the sample's values
    set on it (:meth:`~ddmr_cli.study.space.Box.key_values`); ``memo``: the job's runs so far (:class:`RunMemo`,
    for ``seeds``), whose numbers a config left as an earlier sample left it takes."""
    from ddmr_cli.config.variants import values_key
    from ddmr_cli.engine.simulation import simulate

    runs, n, diverged = {}, 0, 0
    for key, base in configs.items():
        values = base.changes(box.key_values(sample, base.cfg, base.value))
        memo_key = (key, values_key(values))
        found = memo.get(memo_key) if memo is not None else None
        if found is None:
            result = simulate(base.simulation_with(values), seeds, bands=False, threads=threads)
            found = ({m: result.metric(m).copy() for m in claim_stats.METRICS}, int(result.diverged.sum()))
            if memo is not None:
                memo.put(memo_key, found)
        runs[key] = found[0]
        n += len(seeds)
        diverged += found[1]
    return runs, n, diverged


def sample_row(index: int, label: str, sample: dict, runs: dict | None, scenarios: list[str]) -> dict:
    """One row of ``study_rows.csv``: the sample, its claim statistics, Table 4 and distance (NaN if no runs)."""
    row: dict[str, Any] = {"sample": index, "label": label, **sample}
    if runs is None:
        return row
    row.update(claim_stats.statistics(runs, scenarios))
    table = claim_stats.table4(runs)
    row.update(table)
    row["distance"] = claim_stats.distance(table)
    for (c, s), metrics in runs.items():
        row[f"dev_ss:{c}:{s}"] = float(_nanmean(metrics[claim_stats.DEVIATION]))
    return row


def _nanmean(values) -> float:
    import numpy as np

    values = np.asarray(values, float)
    return float(np.mean(values[np.isfinite(values)])) if np.isfinite(values).any() else float("nan")


def execute_study(cfg: DictConfig, place, digest: str | None = None, sim=None) -> dict:
    """The study job (the ``task`` of :func:`ddmr_cli.job.run_job`): its share of the stage's samples."""
    import pandas as pd

    from ddmr_cli.config import config_hash, seeds_of
    from ddmr_cli.errors import DDMRError

    started = time.perf_counter()
    out, overrides = place.out, list(place.overrides)
    box, variants, faithful = study_models(cfg)
    design = build(cfg.study, box, faithful, out.parent)
    indices = chunk_of(len(design.samples), int(cfg.study.chunk), int(cfg.study.chunks))
    seeds = seeds_of(cfg)
    threads = place.threads(cfg)
    scenarios = list(dict.fromkeys(s for _, s in variants))
    rows, n_runs, n_diverged, failed = [], 0, 0, 0
    memo = RunMemo(seeds)
    for count, i in enumerate(indices):
        sample = design.samples[i]
        try:
            runs, n, d = simulate_sample(box, variants, sample, seeds, threads, memo)
            row = {**sample_row(i, design.labels[i], sample, runs, scenarios), "status": "ok", "error": ""}
            n_runs, n_diverged = n_runs + n, n_diverged + d
            row.update({"runs": n, "diverged": d})
        except (DDMRError, ValueError) as exc:  # a value a model part refuses: this sample only
            failed += 1
            row = {**sample_row(i, design.labels[i], sample, None, scenarios), "status": "failed",
                   "error": " ".join(str(exc).split())}
        rows.append(row)
        if cfg.run.progress and (count + 1) % 10 == 0:
            log.info("study %s chunk %s: %d/%d samples, %.1f s", design.stage, cfg.study.chunk, count + 1,
                     len(indices), time.perf_counter() - started)
    wall = time.perf_counter() - started
    # a trial of the calibration search: what goes back to the Optuna sweeper
    extra = {"objective": search.objective(rows[0])} if design.stage == search.STAGE else {}
    summary = {
        "status": "complete", "controller": "study", "scenario": design.stage, "overrides": overrides or [],
        "config_hash": digest or config_hash(cfg), "stage": design.stage, "samples": len(indices),
        "samples_failed": failed, "design_size": len(design.samples),
        "seeds": [seeds[0], seeds[-1]],
        "statistics": {"runs": n_runs, "diverged": n_diverged, "reused": memo.reused},
        "wall_time": wall, **extra,
    }
    # staged and moved in with the summary (and every file's digest) last, as any job (storage/jobdir.py)
    with jobdir.Stage(out) as stage:
        io.write_csv(stage.path / STUDY_ROWS, pd.DataFrame(rows))
        summary = stage.commit(summary)
    log.info("study %s chunk %s: %d samples (%d failed), %d runs (%d diverged; %d the numbers of an identical "
             "earlier run) in %.1f s -> %s", design.stage, cfg.study.chunk, len(indices), failed, n_runs, n_diverged,
             memo.reused, wall, out)
    return summary


def collect(sweep_dir: Path) -> "pd.DataFrame":
    """Every complete job's rows of a study sweep dir, by sample index (``job``: the job dir's name)."""
    import pandas as pd

    state = read_state(Path(sweep_dir))
    frames = [pd.read_csv(d / STUDY_ROWS).assign(job=d.name) for d, _ in state.complete
              if (d / STUDY_ROWS).is_file()]
    if not frames:
        return pd.DataFrame()
    return pd.concat(frames, ignore_index=True).sort_values("sample", kind="mergesort").reset_index(drop=True)


def start_stage(config: DictConfig) -> None:
    """A study stage's multirun starts (:class:`ddmr_cli.cli.callbacks.StudyAggregator`): the sweep plan (the
    calibration search: its record and warm start instead, :func:`ddmr_cli.study.search.start_session`; the
    Optuna sweeper plans nothing ahead)."""
    from ddmr_cli.config.plan import plan_jobs
    from ddmr_cli.storage.sweep import write_plan

    if search.is_search(config):
        search.start_session(config)
    else:
        write_plan(Path(config.hydra.sweep.dir), plan_jobs(config.hydra.overrides.task, config))


def end_stage(config: DictConfig) -> None:
    """A study stage's multirun ends: ``study.csv`` and the stage's analysis."""
    from ddmr_cli.progress import say
    from ddmr_cli.study.analysis import analyse

    sweep_dir = Path(config.hydra.sweep.dir)
    state = read_state(sweep_dir)
    rows = collect(sweep_dir)
    if search.is_search(config):  # one row per complete trial, numbered as Optuna's trials
        search.end_session(sweep_dir)
        rows = search.trial_rows(sweep_dir, rows, state.complete)
    io.write_csv(sweep_dir / STUDY_CSV, rows)
    runs = int(sum(s.get("statistics", {}).get("runs", 0) or 0 for _, s in state.complete))
    reused = int(sum(s.get("statistics", {}).get("reused", 0) or 0 for _, s in state.complete))
    wall = sum(float(s.get("wall_time") or 0) for _, s in state.complete)
    lines = [f"\nddmr study {config.study.stage}: {len(state.complete)} jobs complete, {len(state.failed)} failed, "
             f"{len(state.missing)} missing; {len(rows)} samples, {runs} runs ({runs - reused} simulated, {reused} "
             f"the numbers of an identical earlier run), {wall:.1f} s in jobs -> {sweep_dir}"]
    if not rows.empty and not state.missing and not state.failed:
        lines += ["  " + line for line in analyse(sweep_dir, config, rows)]
    say(lines)  # after the sweep's bar, which say() closes first once every job has ended


__all__ = ["execute_study", "RunMemo", "simulate_sample", "sample_row", "collect", "start_stage", "end_stage"]
