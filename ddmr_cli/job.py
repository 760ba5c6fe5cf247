"""One job = one controller x scenario x batch of seeds, simulated and written into its own dir.

It writes into its output dir (Hydra's, for ``ddmr run``): ``config.yaml`` (resolved), ``metrics.csv`` (tidy, one row per seed),
``segments.csv`` (per seed and terrain zone / scenario phase), ``series.npz`` (kept time series),
``plots/*.png`` and, last, ``summary.json`` (status, config hash, across-seed statistics, size and SHA-256 of
every file). The files are written into a temporary sibling dir and moved in before the summary
(:mod:`ddmr_cli.storage.jobdir`). A job whose directory already holds a complete summary with the same config hash
and every recorded file intact is skipped (resume); otherwise its old summary goes first, then its old files.
In a sweep a failing job records its failure and returns, so the other jobs and the aggregation go on; a
single run prints one line (``ddmr: error: <path>: <reason>`` for a file-system fault, exit 1).
"""

from __future__ import annotations

import contextlib
import logging
import platform
import sys
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from omegaconf import DictConfig

from ddmr_cli.storage import io, jobdir
from ddmr_cli.errors import DDMRError
from ddmr_cli.config import build_simulation, config_hash, kept_seeds, seeds_of, validate_config
from ddmr_cli.config.build import result_config

log = logging.getLogger("ddmr")


@dataclass(frozen=True)
class JobPlace:
    """Where a job runs: its output dir, its overrides (as given), whether it is one job of a sweep (then its
    failure is recorded and returned, not raised) and whether that sweep's jobs run one after another in one
    process (Hydra's basic launcher: ``launcher=basic``, and the in-process path of a small local sweep) rather than
    in parallel processes. The Hydra task function (:mod:`ddmr_cli.cli.hydra_main`) reads them from Hydra's
    runtime."""

    out: Path
    overrides: tuple[str, ...] = ()
    in_sweep: bool = False
    one_at_a_time: bool = False

    def threads(self, cfg: DictConfig) -> int:
        """``run.threads``, else one thread for a job of a sweep whose jobs run in parallel processes, else every
        core (a single run, or a sweep's jobs run one after another: table4 in process, 0.8x the wall)."""
        return int(cfg.run.threads) or (1 if self.in_sweep and not self.one_at_a_time else 0)


#: what a job does: ``task(cfg, place, digest, sim) -> summary`` (default :func:`execute`)
Task = Callable[[DictConfig, JobPlace, str, object], dict]


def run_job(cfg: DictConfig, place: JobPlace, task: Task | None = None) -> dict:
    """Run one job and write its outputs into ``place.out``; returns its summary. ``task`` (default
    :func:`execute`) is what the job does; the sensitivity study's jobs pass theirs (:mod:`ddmr_cli.study.task`).

    A directory holding a complete summary with the same config hash and every recorded file intact is skipped
    (resume)."""
    out, overrides = place.out, list(place.overrides)
    if place.in_sweep:
        _exit_with_parent()
    digest = config_hash(cfg)
    previous = io.read_summary(out)
    if previous and previous.get("status") == "complete" and previous.get("config_hash") == digest:
        problem = jobdir.verify(out, previous, options=jobdir.output_options(cfg))
        if problem is None:
            log.info("skipped %s: complete results with the same config hash %s, every file verified", out, digest)
            return previous
        log.info("rerunning %s: %s", out, problem)
    started = time.perf_counter()
    base = {"overrides": overrides, "config_hash": digest, "controller": None, "scenario": None}
    try:
        jobdir.begin(out)  # refuses (nothing changed) when something it did not write is in the way
    except OSError as exc:
        return _failed(exc, base, started, place, record=False)
    try:
        sim = validate_config(cfg)
        base["controller"], base["scenario"] = _names(cfg)
        summary = (task or execute)(cfg, place, digest, sim)
    except Exception as exc:  # recorded, so a sweep carries on; re-raised for a single run
        return _failed(exc, base, started, place)
    return summary


def _failed(exc: Exception, base: dict, started: float, place: JobPlace, record: bool = True) -> dict:
    """A failed job: its summary records the failure (``record``: not when the job was refused because a file
    it did not write is in the way, so nothing of the dir changes); a single run prints one line and exits."""
    out = place.out
    error = f"{type(exc).__name__}: {exc}"
    fault = jobdir.fault(exc, out) if isinstance(exc, OSError) else None
    log.error("job failed: %s", error)
    failed = {**base, "status": "failed", "error": error, "traceback": traceback.format_exc(),
              "wall_time": time.perf_counter() - started}
    if fault is not None:
        failed["fault"] = {"path": fault.path, "reason": fault.reason}
    if record:
        try:
            io.write_summary(out, failed)
        except OSError:  # the fault itself (disk full, read-only): nothing more can be recorded
            pass
    if not place.in_sweep:
        if fault is not None:  # a file-system fault: one line naming the path, exit 1
            print(f"ddmr: error: {fault.path}: {fault.reason}", file=sys.stderr)
            raise SystemExit(1) from None
        if isinstance(exc, (DDMRError, ValueError)):  # a bad value: one line, exit 2, never a traceback
            print(f"ddmr: error: {' '.join(str(exc).split())}", file=sys.stderr)
            raise SystemExit(2) from None
        raise exc
    return {key: failed[key] for key in failed if key != "traceback"}


def _exit_with_parent() -> None:
    """In a worker process of a local sweep (joblib/loky, submitit_local), a daemon thread that ends the
    process when the ``ddmr run`` that launched it is gone (killed), so no worker outlives it.
    ``ddmr run`` names itself in ``DDMR_PARENT`` (host:pid); jobs on other hosts (SLURM) are left alone."""
    import os
    import socket
    import threading

    host, _, pid = os.environ.get("DDMR_PARENT", "").rpartition(":")
    if not pid.isdigit() or host != socket.gethostname() or int(pid) == os.getpid():
        return
    if any(t.name == "ddmr-parent-watch" for t in threading.enumerate()):
        return

    def watch() -> None:
        while True:
            try:
                os.kill(int(pid), 0)
            except ProcessLookupError:
                os._exit(1)
            except PermissionError:
                pass
            time.sleep(0.5)

    threading.Thread(target=watch, name="ddmr-parent-watch", daemon=True).start()


def _names(cfg: DictConfig) -> tuple[str, str]:
    from ddmr_cli.config.build import controller_name

    return controller_name(cfg.controller), str(cfg.scenario.name)


def execute(cfg: DictConfig, place: JobPlace, digest: str | None = None, sim=None) -> dict:
    """Simulate the config's seeds and write every output file into ``place.out`` (staged, then moved in with the
    summary last); returns the summary."""
    sim = sim if sim is not None else build_simulation(cfg)  # run_job passes the one it validated
    seeds = seeds_of(cfg)
    out = place.out
    with jobdir.Stage(out) as stage:
        summary = _simulate_and_write(cfg, sim, seeds, stage.path, list(place.overrides), digest,
                                      place.threads(cfg), bars=not place.in_sweep)
        summary = stage.commit(summary)
    stats = summary["statistics"]
    label = f"{summary['controller']}/{summary['scenario']}"
    log.info("%s: %d runs (%d diverged) in %.2f s", label, stats["runs"], stats["diverged"], summary["wall_time"])
    log.info("  " + " | ".join(f"{m} {stats[m + '_mean']:.4g} +- {stats[m + '_sd']:.2g} {io.unit_of(m)}"
                               for m in io.HEADLINE[:4]))
    log.info("  " + " | ".join(f"{m} {stats[m + '_mean']:.4g} {io.unit_of(m)}" for m in io.HEADLINE[4:]))
    log.info("results: %s", out)
    return summary


def _simulate_and_write(cfg: DictConfig, sim, seeds: list[int], out: Path, overrides, digest, threads: int,
                        bars: bool = True) -> dict:
    """Simulate and write every output file into ``out`` (the staging dir); returns the summary to commit.
    With ``run.progress``, a bar over the steps (``bars``: not in a sweep, whose launching process draws one bar
    over its jobs) and the line said before the step loop is compiled (:mod:`ddmr_cli.progress`)."""
    from ddmr_cli.engine.simulation import simulate
    from ddmr_cli.progress import StepBar

    label = f"{sim.controller.name}/{sim.scenario.name}"
    keep = kept_seeds(cfg.run)
    # a single run's figures: the drawing processes the program started (or started now) get ready while this one
    # simulates (plots/processes.py)
    drawing = _plot_processes() if cfg.run.plots and keep and bars else contextlib.nullcontext()
    with drawing as plot_processes:
        progress = StepBar(label, len(seeds), sim.n_steps, enabled=bool(cfg.run.progress) and bars)
        try:
            result = simulate(sim, seeds, keep_series=keep, progress=progress, threads=threads,
                              bands=bool(cfg.run.bands),
                              compiling=(lambda: progress.compiling(sim.controller.name)) if cfg.run.progress
                              else None)
        finally:
            progress.close()
        summary = _write(cfg, sim, result, out, overrides, digest, plot_processes)
    return summary


def _plot_processes():
    """The drawing processes of a single run's figures: those the ``ddmr run`` program started, else new ones."""
    from ddmr_cli.plots.processes import PlotProcesses

    return PlotProcesses.take()


def _write(cfg: DictConfig, sim, result, out: Path, overrides, digest, plot_processes) -> dict:
    """Every output file of a simulated job into ``out``; the figures by ``plot_processes`` when given, which
    draw them while this writes the other files."""
    plots = bool(cfg.run.plots and result.series)
    seed = next(iter(result.series), None)
    if plots and plot_processes is not None:
        plot_processes.send(result.series[seed], result.controller, result.scenario, seed, out / io.PLOTS_DIR,
                            settle_time=float(cfg.metrics.settle_time))
    io.write_text(out / io.CONFIG, io.yaml_text(result_config(cfg, display=True)))
    for name, segments in ((io.METRICS_CSV, False), (io.SEGMENTS_CSV, True)):
        columns, rows = result.table(segments)
        io.write_csv(out / name, rows, columns=columns)
    if result.bands:
        io.write_bands(out / io.BANDS, result.bands)
    if result.series:
        io.write_series(out / io.SERIES, result.series)
    if plots and plot_processes is not None:
        plot_processes.collect()
    elif plots:
        from ddmr_cli.plots.run import run_plots

        run_plots(result.series[seed], result.controller, result.scenario, seed, out / io.PLOTS_DIR,
                  settle_time=float(cfg.metrics.settle_time))
    return {
        "status": "complete",
        "controller": result.controller,
        "scenario": result.scenario,
        "overrides": overrides or [],
        "config_hash": digest or config_hash(cfg),
        "options": jobdir.output_options(cfg),
        "parameters": sim.controller.parameters(),
        "estimators": list(sim.controller.estimators()),
        "diagnostics": [{"name": c.name, "kind": c.kind, "description": c.description}
                        for c in sim.controller.diagnostics()],
        "seeds": [result.seeds[0], result.seeds[-1]],
        "series_seeds": list(result.series),
        "statistics": result.summary(),
        "simulated_time": result.duration,
        "dt": result.dt,
        "wall_time": result.wall_time,
        "engine": result.engine,
        "python": platform.python_version(),
    }


__all__ = ["JobPlace", "Task", "run_job", "execute"]
