"""``ddmr run``: compose and validate every job, pin the output dir, hold its lock, run Hydra, read the outcome.

Before Hydra makes any directory, every job of the run or sweep is composed with Hydra's compose API and
validated (:mod:`ddmr_cli.cli.modes`): a bad value prints one line naming the key, the value and the rule, and
exits with status 2, leaving nothing behind. Hydra then runs with the output dir pinned, so the CLI reads
exactly this run's results afterwards.
"""

from __future__ import annotations

import contextlib
import os
import socket
import sys
from dataclasses import dataclass
from pathlib import Path

from ddmr_cli.cli.args import INFO_FLAGS, config_dirs, normalise, override_value, split_args
from ddmr_cli.cli.modes import Mode, mode_of
from ddmr_cli.cli.usage import EXIT_FAILED, INTERRUPTED, INTERRUPTED_MESSAGE, UsageError, fail, one_line
from ddmr_cli.workers import shutdown_joblib_workers


@dataclass(frozen=True)
class Launch:
    """What the CLI knows before Hydra starts: the mode, the output dir (pinned), the planned jobs, the report
    setting and ``run.progress``."""

    mode: Mode
    out_dir: Path
    argv: tuple[str, ...]
    plan: tuple[dict, ...] = ()
    report: bool = False
    margin: str | None = None
    progress: bool = True

    @property
    def multirun(self) -> bool:
        return self.mode.multirun


def prepare(argv: list[str], overrides: list[str], multirun: bool, config_name: str = "config",
            config_dir: str | None = None, search_dir: str | None = None) -> Launch:
    """Compose and validate every job of the run or sweep, resolve its output dir and plan its jobs.

    Raises :class:`~ddmr_cli.cli.usage.UsageError` (one line) on the first bad value, before anything is
    written: a value, a key a schema does not have (``+run.nruns=5``), a class of the wrong kind, a derived
    number that is not finite, a memory estimate over ``run.max_memory_gb``, an empty sweep, or two jobs that
    would share one dir. The output dir (``hydra.run.dir`` / ``hydra.sweep.dir``, usually
    ``outputs/<experiment>/<time>``) is resolved here and passed to Hydra as an override. ``config_dir`` and
    ``search_dir`` are the absolute ``--config-path`` and ``--config-dir`` of the command line."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config import JobComposer, compose_config
    from ddmr_cli.config.validate import message
    from ddmr_cli.errors import ConfigError
    from ddmr_cli.progress import interactive, quiet_sweep_logging
    from ddmr_cli.report.stats import Margin

    extra = [f"hydra.searchpath=[{override_value('file://' + search_dir)}]"] if search_dir else []
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        if not multirun and len(fixed) != len(parsed):
            sweep_ov = next(o.input_line for o in parsed if o.is_sweep_override())
            raise UsageError(f"{sweep_ov}: a sweep needs --multirun (-m)")
        _refuse_huge_sweeps(parsed)
        base = compose_config([*fixed, *extra], config_name, return_hydra_config=True, config_dir=config_dir)
        margin = base.report.margin
        try:
            Margin.parse(margin)
        except ValueError as exc:
            raise UsageError(f"report.margin={margin}: {exc}") from None
        mode = mode_of(base, multirun)
        jobs = JobComposer(config_name, config_dir, extra)  # the defaults tree once per set of group choices
        plan = mode.plan(base, overrides, parsed, jobs)
        dir_key = "hydra.sweep.dir" if multirun else "hydra.run.dir"
        out_dir = Path(str(base.hydra.sweep.dir if multirun else base.hydra.run.dir))
    except ConfigError as exc:
        raise UsageError(message(exc, overrides)) from None
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        raise UsageError(one_line(exc, overrides)) from None
    except (MemoryError, OverflowError) as exc:  # a value too large to plan
        raise UsageError(f"{' '.join(overrides)}: too large to plan ({type(exc).__name__}); lower the largest value")
    shown = bool(base.run.get("progress", True))
    quiet = quiet_sweep_logging(base.hydra) if mode.draws_bar and shown and interactive() else []
    pinned = [a for a in argv if a.partition("=")[0] != dir_key] + [f"{dir_key}={override_value(out_dir)}",
                                                                    *plan.session, *quiet]
    return Launch(mode, out_dir, tuple(pinned), tuple(plan.jobs) if multirun else (), bool(base.report.auto), margin,
                  shown)


#: the most jobs a sweep may plan (a Hydra sweep composes every job; a million would take hours to plan)
MAX_JOBS = 100_000


def _refuse_huge_sweeps(parsed) -> None:
    """A sweep whose job count (the product of its swept values, counted without listing them) is over
    :data:`MAX_JOBS`: refused, naming the largest swept override, before anything is expanded."""
    import math

    from hydra.core.override_parser.types import ChoiceSweep, RangeSweep

    total, largest = 1, (0, None)
    for o in parsed:
        value = o.value() if o.is_sweep_override() else None
        if isinstance(value, RangeSweep):
            start, stop, step = value.start, value.stop, value.step or 1
            count = max(0, math.ceil((stop - start) / step)) if step else 0
        elif isinstance(value, ChoiceSweep):
            count = len(value.list)
        else:
            continue
        total *= max(count, 1)
        largest = max(largest, (count, o.input_line), key=lambda c: c[0])
    if total > MAX_JOBS:
        raise UsageError(f"{largest[1]}: the sweep would have {total} jobs, more than {MAX_JOBS}; sweep fewer values")


def cmd_run(argv: list[str]) -> int:
    """``ddmr run [OVERRIDES...]``: a run, a sweep (``-m``), a tuning study or the calibration search."""
    from ddmr_cli.cli.help import run_help

    argv = normalise(argv)
    overrides, flags = split_args(argv)
    config_name = str(flags.get("--config-name") or flags.get("-cn") or "config")
    if {"--help", "-h"} & flags.keys():
        return run_help(overrides, config_name)
    multirun = bool(flags.get("-m") or flags.get("--multirun"))
    if INFO_FLAGS & flags.keys():  # no job runs: Hydra prints what was asked for
        return hydra(argv, completing=bool({"-sc", "--shell-completion"} & flags.keys()))
    argv, config_dir, search_dir = config_dirs(argv)
    from ddmr_cli.compat import omegaconf_speedups
    from ddmr_cli.config.compose_once import compositions_once

    restore_omegaconf = omegaconf_speedups()  # the jobs' .hydra files and config copies Hydra makes in this process
    try:
        with compositions_once():  # our validation, Hydra's get_mode and its run compose the config once (issue 28)
            try:
                launch = prepare(argv, overrides, multirun, config_name, config_dir, search_dir)
            except UsageError as exc:
                return fail(str(exc))
            except OSError as exc:  # a fault found while planning (an unreadable study storage): one line, exit 1
                print(f"ddmr: error: {exc}", file=sys.stderr)
                return EXIT_FAILED
            return run_locked(launch)
    finally:
        restore_omegaconf()


def run_locked(launch: Launch) -> int:
    """Run Hydra on a prepared launch holding the output dir's lock; file-system faults and Ctrl-C end it with
    one line (exit 1 and 130)."""
    from ddmr_cli.storage import jobdir

    reaper = None
    mode = launch.mode
    try:
        mode.preflight(launch.out_dir, launch.plan)  # reads only: a refused dir is left as it was
        with jobdir.DirLock(launch.out_dir, kind=mode.lock_kind):
            mode.preflight(launch.out_dir, launch.plan)  # again, now that no other ddmr writes the tree
            mode.before_launch(launch.out_dir, launch.plan)
            if launch.plan:  # jobs in worker processes: they end when we are gone
                os.environ["DDMR_PARENT"] = f"{socket.gethostname()}:{os.getpid()}"
                reaper = _start_reaper()
            with _ctrl_c_to_this_process_only(), mode.watch(launch.out_dir, launch.plan, launch.progress):
                code = hydra(list(launch.argv))
            return code or finish(launch)
    except jobdir.FaultError as exc:
        print(f"ddmr: error: {exc.path}: {exc.reason}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        shutdown_joblib_workers(kill=True)
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        return INTERRUPTED
    finally:
        if reaper is not None:
            reaper.stdin.close()  # the reaper ends what is left of the workers (nothing, after a normal end)


def finish(launch: Launch) -> int:
    """The exit status from the output dir as it is on disk, and the report when asked for."""
    from ddmr_cli.cli.reporting import write_report

    status = launch.mode.finish(launch.out_dir, launch.plan)
    if launch.report:
        status = max(status, write_report(launch.out_dir, None, launch.margin, failure=EXIT_FAILED,
                                          progress=launch.progress))
    return status


@contextlib.contextmanager
def _ctrl_c_to_this_process_only():
    """Ctrl-C reaches ``ddmr run`` but not the processes it starts (loky/submitit workers), which would print
    their own KeyboardInterrupt tracebacks, even while importing: SIGINT is blocked in this thread, so every thread
    and process started from here on inherits the block, and a thread started before the block stays open to it
    (the kernel hands it the terminal's SIGINT; Python raises KeyboardInterrupt in the main thread as usual).
    ``ddmr run`` then stops the workers itself."""
    import signal
    import threading

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # the standard library's resource tracker unblocks SIGINT after it starts (SIG_UNBLOCK, not the old mask):
    # started now, before the block, joblib finds it running and leaves the mask alone
    resource_tracker.ensure_running()
    threading.Thread(target=threading.Event().wait, name="ddmr-sigint", daemon=True).start()
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _start_reaper():
    """Start :mod:`ddmr_cli.cli.reaper` (a script, in its own session) to end this run's workers when this
    process ends or is killed; None when it cannot be started."""
    import subprocess

    try:
        return subprocess.Popen([sys.executable, str(Path(__file__).with_name("reaper.py")), str(os.getpid()),
                                 socket.gethostname()], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        return None


def hydra(argv: list[str], completing: bool = False) -> int:
    """Hydra's exit status for ``ddmr run ARGV`` (0 when it returns)."""
    from ddmr_cli.cli.hydra_main import main as hydra_main

    # shell completion registers and queries the program `ddmr` (see `main`); everything else is `ddmr run`. Hydra
    # reads sys.argv; it is put back after, so a caller in this process (the Python API, a test) keeps its own
    saved, sys.argv = sys.argv, ["ddmr" if completing else "ddmr run", *argv]
    try:
        hydra_main()
    except SystemExit as exc:  # Hydra exits 1 after printing a job's error
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_FAILED
    finally:
        sys.argv = saved
    return 0


__all__ = ["Launch", "prepare", "cmd_run", "run_locked", "finish", "hydra", "MAX_JOBS"]
