"""The Hydra task function behind ``ddmr run``: one job = one controller x scenario x batch of seeds.

It writes into Hydra's output dir: ``config.yaml`` (resolved), ``metrics.csv`` (tidy, one row per seed),
``segments.csv`` (per seed and terrain zone / scenario phase), ``series.npz`` (kept time series),
``plots/*.png`` and, last, ``summary.json`` (status, config hash, across-seed statistics).
A job whose directory already holds a complete summary with the same config hash is skipped (resume).
In a sweep a failing job records its failure and returns, so the other jobs and the aggregation go on.
"""

from __future__ import annotations

import logging
import platform
import sys
import time
import traceback
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from ddmr_cli.cli import io
from ddmr_cli.errors import DDMRError
from ddmr_cli.cli.config import build_simulation, config_hash, seeds_of, validate_config
from ddmr_cli.cli.config.build import result_config

log = logging.getLogger("ddmr")


class ProgressLog:
    """Logs ``label: steps done/total (percent), elapsed`` every ``every`` seconds and at the end."""

    def __init__(self, label: str, n_runs: int, every: float = 2.0) -> None:
        self.label, self.n_runs, self.every = label, n_runs, every
        self.start = self.last = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        if now - self.last >= self.every or done == total:
            self.last = now
            log.info("%s: %d runs, step %d/%d (%.0f%%), %.1f s elapsed", self.label, self.n_runs, done, total,
                     100.0 * done / total, now - self.start)


def _job_info() -> tuple[Path, list[str]]:
    from hydra.core.hydra_config import HydraConfig

    hc = HydraConfig.get()
    return Path(hc.runtime.output_dir), list(hc.overrides.task)


def _in_sweep() -> bool:
    """True inside a job of a multirun (False for a single run and outside Hydra, e.g. the Python API)."""
    from hydra.core.hydra_config import HydraConfig

    if not HydraConfig.initialized():
        return False
    return "MULTIRUN" in str(HydraConfig.get().mode)


def run_job(cfg: DictConfig, task=None) -> dict:
    """Run one job and write its outputs; returns its summary. ``task`` (default :func:`execute`, same
    signature) is what the job does; the sensitivity study's jobs pass theirs (:mod:`ddmr_cli.study.task`)."""
    out, overrides = _job_info()
    digest = config_hash(cfg)
    previous = io.read_summary(out)
    if previous and previous.get("status") == "complete" and previous.get("config_hash") == digest:
        log.info("skipped %s: complete results with the same config hash %s", out, digest)
        return previous
    started = time.perf_counter()
    base = {"overrides": overrides, "config_hash": digest, "controller": None, "scenario": None}
    try:
        sim = validate_config(cfg)
        base["controller"], base["scenario"] = _names(cfg)
        summary = (task or execute)(cfg, out, overrides, digest, sim)
    except Exception as exc:  # recorded, so a sweep carries on; re-raised for a single run
        error = f"{type(exc).__name__}: {exc}"
        log.error("job failed: %s", error)
        io.write_json(out / io.SUMMARY, {**base, "status": "failed", "error": error,
                                         "traceback": traceback.format_exc(),
                                         "wall_time": time.perf_counter() - started})
        if not _in_sweep():
            if isinstance(exc, (DDMRError, ValueError)):  # a bad value: one line, exit 2, never a traceback
                print(f"ddmr: error: {' '.join(str(exc).split())}", file=sys.stderr)
                raise SystemExit(2) from None
            raise
        return {**base, "status": "failed", "error": error}
    return summary


def _names(cfg: DictConfig) -> tuple[str, str]:
    from ddmr_cli.cli.config.build import controller_name

    return controller_name(cfg.controller), str(cfg.scenario.name)


def execute(cfg: DictConfig, out: Path, overrides: list[str] | None = None, digest: str | None = None,
            sim=None) -> dict:
    """Simulate the config's seeds and write every output file into ``out``; returns the summary."""

    from ddmr_cli.engine.simulation import simulate

    sim = sim if sim is not None else build_simulation(cfg)  # run_job passes the one it validated
    seeds = seeds_of(cfg)
    # a sweep already runs jobs in parallel processes: one thread each unless asked otherwise
    threads = int(cfg.run.threads) or (1 if _in_sweep() else 0)
    label = f"{sim.controller.name}/{sim.scenario.name}"
    progress = ProgressLog(label, len(seeds)) if cfg.run.progress else None
    result = simulate(sim, seeds, keep_series=list(cfg.run.keep_series), progress=progress, threads=threads,
                      bands=bool(cfg.run.bands))
    io.write_text(out / io.CONFIG, OmegaConf.to_yaml(OmegaConf.create(result_config(cfg)), resolve=True))
    io.write_csv(out / io.METRICS_CSV, result.rows())
    io.write_csv(out / io.SEGMENTS_CSV, result.rows(segments=True))
    files = [io.CONFIG, io.METRICS_CSV, io.SEGMENTS_CSV]
    if result.bands:
        io.write_bands(out / io.BANDS, result.bands)
        files.append(io.BANDS)
    if result.series:
        io.write_series(out / io.SERIES, result.series)
        files.append(io.SERIES)
        if cfg.run.plots:
            from ddmr_cli.report.run_plots import run_plots

            seed = next(iter(result.series))
            for path in run_plots(result.series[seed], result.controller, result.scenario, seed, out / io.PLOTS_DIR):
                files.append(str(path.relative_to(out)))
    summary = {
        "status": "complete",
        "controller": result.controller,
        "scenario": result.scenario,
        "overrides": overrides or [],
        "config_hash": digest or config_hash(cfg),
        "parameters": sim.controller.parameters(),
        "seeds": [result.seeds[0], result.seeds[-1]],
        "series_seeds": list(result.series),
        "statistics": result.summary(),
        "simulated_time": result.duration,
        "dt": result.dt,
        "wall_time": result.wall_time,
        "engine": result.engine,
        "files": files,
        "python": platform.python_version(),
    }
    io.write_json(out / io.SUMMARY, summary)
    stats = summary["statistics"]
    log.info("%s: %d runs (%d diverged) in %.2f s", label, stats["runs"], stats["diverged"], result.wall_time)
    log.info("  " + " | ".join(f"{m} {stats[m + '_mean']:.4g} +- {stats[m + '_sd']:.2g} {io.unit_of(m)}"
                               for m in io.HEADLINE[:4]))
    log.info("  " + " | ".join(f"{m} {stats[m + '_mean']:.4g} {io.unit_of(m)}" for m in io.HEADLINE[4:]))
    log.info("results: %s", out)
    return summary


__all__ = ["run_job", "execute"]
