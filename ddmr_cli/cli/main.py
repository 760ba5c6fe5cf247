"""The ``ddmr`` command: ``run`` (Hydra), ``report`` and ``bench``.

``ddmr run`` hands its arguments to Hydra, so every Hydra feature works (overrides, ``--multirun``, ``--cfg``,
``--help``, ``--info``, shell completion). Before Hydra makes any directory, the CLI composes every job of the
run or sweep with Hydra's compose API and validates it: a bad value prints one line naming the key, the value
and the rule, and exits with status 2, leaving nothing behind.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Sequence

EXIT_USAGE = 2
EXIT_FAILED = 1

USAGE = """\
usage: ddmr <command> [args]

Trajectory-tracking experiments for differential-drive mobile robots (SMC, NDO, RBF-NN observers on rough
terrain), reproducing and extending "SMC integrated with NDO and RBF neural network ... considering terrain".

commands:
  run [OVERRIDES...]      run a job (or a sweep with -m) from Hydra configs; `ddmr run --help` lists the
                          config groups and every key with its value, unit and meaning. Examples:
                            ddmr run                                  # paper scenario 1, SMC-NDO-NNO, 50 seeds
                            ddmr run controller=pid scenario=paper_2 run.n_runs=10
                            ddmr run -m +experiment=table4            # Table 4: 4 controllers x 2 scenarios
                            ddmr run -m controller=smc,smc_ndo controller.switching_gain=4,8,12
                            ddmr run -m +experiment=table4 launcher=slurm cluster.partition=compute
                            ddmr run -m +tune=smc_ndo                 # tune gains (Optuna); ddmr report it
                          add report=true to write the report when the run or sweep ends
  explain KEY [OVERRIDES] a config key's meaning, unit, value, valid range and docs/model.md section
  report [PATH] [--out DIR] [--margin 0.05mm|2%] [--no-figures]
                          markdown report, tables (CSV) and figures (PNG) from a sweep or run dir
                          (default PATH: the latest sweep under ./outputs)
  bench [--quick]         print engine and end-to-end performance figures for this machine
  sensitivity [--out DIR] [OVERRIDES]  the sensitivity of the paper's claims and the reading nearest its Table 4
                          (every stage a sweep, the calibration ddmr's Optuna sweeper; study=quick for the CI
                          size; docs/model.md §11)
  --version               print the version
"""

# Hydra flags after which no job runs (nothing to validate)
_INFO_FLAGS = frozenset({"--help", "-h", "--hydra-help", "--version", "--info", "-i", "--cfg", "-c",
                         "--shell-completion", "-sc"})
_VALUE_FLAGS = frozenset({"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name",
                          "-cn", "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"})
GROUPS = ("robot", "terrain", "controller", "scenario", "trajectory", "experiment", "launcher", "tune", "objective")


def _split_args(argv: Sequence[str]) -> tuple[list[str], dict[str, str | bool]]:
    overrides, flags = [], {}
    it = iter(argv)
    for arg in it:
        if arg.startswith("-"):
            name, _, value = arg.partition("=")
            if name in _VALUE_FLAGS and not value and name not in ("--info", "-i", "--cfg", "-c",
                                                                   "--shell-completion", "-sc"):
                value = next(it, "")
            flags[name] = value or True
        else:
            overrides.append(arg)
    return overrides, flags


def _explain(exc: BaseException, overrides: list[str]) -> str:
    """One line for a composition error: the key, the value and what is wrong."""
    from hydra.errors import MissingConfigException, OverrideParseException
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException

    from ddmr_cli.cli.config import group_options

    if isinstance(exc, OverrideParseException):
        return f"{exc.override}: cannot parse override ({str(exc.message).splitlines()[0]})" if hasattr(
            exc, "override") else f"cannot parse overrides: {str(exc).splitlines()[0]}"
    for ov in overrides:
        key, sep, value = ov.lstrip("+~").partition("=")
        if sep and key in GROUPS:
            options = group_options(key)
            for v in value.split(","):
                if v and v not in options:
                    return f"{key}={v}: unknown {key}; available: {', '.join(options)}"
    cause = exc
    while cause.__cause__ is not None and not isinstance(cause, OmegaConfBaseException):
        cause = cause.__cause__
    if isinstance(cause, OmegaConfBaseException):
        key = getattr(cause, "full_key", None) or "?"
        # the value the user typed: the last override of the key (Hydra applies the last one)
        value = next((ov.partition("=")[2] for ov in reversed(overrides) if ov.lstrip("+~").partition("=")[0] == key),
                     None)
        msg = str(getattr(cause, "msg", cause)).splitlines()[0]
        if isinstance(cause, ConfigKeyError) and "not in" in msg:
            return f"{key}={value}: unknown key ({msg})"
        return f"{key}={value}: {msg}" if value is not None else f"{key}: {msg}"
    if isinstance(exc, MissingConfigException):
        return str(exc).splitlines()[0]
    return " ".join(str(exc).split())


def _fail(message: str) -> int:
    print(f"ddmr: error: {message}", file=sys.stderr)
    return EXIT_USAGE


class UsageError(Exception):
    """Bad input found before anything ran: printed as one line, exit status 2."""


#: Hydra launcher plugins that come with an extra of this package: launcher config name -> extra
_LAUNCHER_EXTRAS = (("ray", "ray"), ("submitit_slurm", "slurm"), ("submitit_local", "slurm"))


def _missing_plugin(exc: BaseException, overrides: list[str]) -> str | None:
    """One line naming the pip extra when a launcher preset needs a Hydra plugin that is not installed."""
    from hydra.errors import MissingConfigException

    missing = getattr(exc, "missing_cfg_file", None) if isinstance(exc, MissingConfigException) else None
    if not missing or not str(missing).startswith("hydra/launcher/"):
        return None
    name = str(missing).rsplit("/", 1)[-1]
    extra = dict(_LAUNCHER_EXTRAS).get(name)
    given = next((ov for ov in overrides if ov.lstrip("+").partition("=")[0] in ("launcher", "hydra/launcher")),
                 f"hydra/launcher={name}")
    if extra is None:
        return f"{given}: Hydra's {name} launcher plugin is not installed"
    return (f"{given}: Hydra's {name} launcher plugin is not installed; "
            f"pip install 'ddmr-cli[{extra}]' (or pip install -e '.[{extra}]' in a checkout)")


def _override_value(value: str | Path) -> str:
    """A value as a Hydra override value: quoted when it has characters the override grammar would read."""
    text = str(value)
    if all(c.isalnum() or c in "/._-:+@" for c in text) and text:
        return text
    return "'" + text.replace("'", "\\'") + "'"


@dataclass(frozen=True)
class Launch:
    """What the CLI knows before Hydra starts: the output dir (pinned), the planned jobs, the report setting."""

    multirun: bool
    out_dir: Path
    argv: tuple[str, ...]
    plan: tuple[dict, ...] = ()
    report: bool = False
    margin: float | None = None
    study: bool = False    # an Optuna study (a tuning study or the sensitivity study's calibration search)
    search: bool = False   # the calibration search (ddmr_cli.study.search)


def prepare(argv: list[str], overrides: list[str], multirun: bool, config_name: str = "config",
            config_dir: str | None = None, search_dir: str | None = None) -> Launch:
    """Compose and validate every job of the run or sweep, resolve its output dir and plan its jobs.

    Raises :class:`UsageError` (one line) on the first bad value, before anything is written: a value, a key a
    schema does not have (``+run.nruns=5``), a class of the wrong kind, a derived number that is not finite, a
    memory estimate over ``run.max_memory_gb``, an empty sweep, or two jobs that would share one dir. The output
    dir (``hydra.run.dir`` / ``hydra.sweep.dir``, usually ``outputs/<experiment>/<time>``) is resolved here and
    passed to Hydra as an override, so the CLI reads exactly this run's results afterwards. ``config_dir`` and
    ``search_dir`` are the absolute ``--config-path`` and ``--config-dir`` of the command line."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.cli import budget, sweep
    from ddmr_cli.cli.config import JobComposer, compose_config
    from ddmr_cli.cli.config.validate import check_additions, job_estimate, message, validate_config
    from ddmr_cli.errors import ConfigError

    extra = [f"hydra.searchpath=[{_override_value('file://' + search_dir)}]"] if search_dir else []

    def compose(job_overrides: list[str], hydra_node: bool = False):
        return compose_config([*job_overrides, *extra], config_name, return_hydra_config=hydra_node,
                              config_dir=config_dir)

    current = overrides
    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        if not multirun and len(fixed) != len(parsed):
            sweep_ov = next(o.input_line for o in parsed if o.is_sweep_override())
            raise UsageError(f"{sweep_ov}: a sweep needs --multirun (-m)")
        _refuse_huge_sweeps(parsed)
        base = compose(fixed, hydra_node=True)
        margin = base.report.margin
        try:
            from ddmr_cli.report.stats import Margin

            Margin.parse(margin)
        except ValueError as exc:
            raise UsageError(f"report.margin={margin}: {exc}") from None
        from ddmr_cli.cli import tuning
        from ddmr_cli.study import search

        searching = multirun and search.is_search(base)  # the sensitivity study's calibration search (Optuna)
        study = multirun and (tuning.is_study(base) or searching)
        # checks; the rest of the budget
        session = [] if not study else search.prepare_search(base) if searching else \
            tuning.prepare_study(base, overrides)
        plan = [] if study else (sweep.plan_jobs(overrides, base) if multirun else
                                 [{"dir": "", "overrides": overrides}])
        if multirun and not study and not plan:
            empty = next((o.input_line for o in parsed if o.is_sweep_override() and not list(o.sweep_string_iterator())),
                         "hydra.sweeper.params")
            raise UsageError(f"{empty}: the sweep has no jobs (an empty range or list); nothing to run")
        if multirun:
            _refuse_escapes(plan, [o for o in overrides if o.startswith("hydra.sweep.subdir=")])
        _refuse_shared_dirs(plan, [o for o in overrides if o.startswith("hydra.sweep.subdir=")])
        largest = None
        jobs = JobComposer(config_name, config_dir, extra)  # the defaults tree once per set of group choices
        for job in plan:
            current = job["overrides"]
            cfg = jobs.compose(current) if multirun else base
            check_additions(cfg, current)
            sim = validate_config(cfg)  # builds the model: derived numbers (J^-1, controller gains) fail here
            est = job_estimate(cfg, sim)
            largest = est if largest is None or est.total > largest.total else largest
        if multirun and largest is not None:
            at_once = budget.at_once(str(base.hydra.launcher.get("_target_", "")), base.hydra.launcher.get("n_jobs"),
                                     len(plan))
            budget.check(largest, base.run.get("max_memory_gb"), at_once, (base.get("cluster") or {}).get("mem_gb"))
        dir_key = "hydra.sweep.dir" if multirun else "hydra.run.dir"
        out_dir = Path(str(base.hydra.sweep.dir if multirun else base.hydra.run.dir))
    except ConfigError as exc:
        raise UsageError(message(exc, current)) from None
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        raise UsageError(_missing_plugin(exc, overrides) or _explain(exc, overrides)) from None
    except (MemoryError, OverflowError) as exc:  # a value too large to plan or validate
        raise UsageError(f"{' '.join(current)}: too large to plan ({type(exc).__name__}); lower the largest value")
    pinned = [a for a in argv if a.partition("=")[0] != dir_key] + [f"{dir_key}={_override_value(out_dir)}", *session]
    return Launch(multirun, out_dir, tuple(pinned), tuple(plan) if multirun else (), bool(base.report.auto), margin,
                  study, searching)


def _refuse_shared_dirs(plan: list[dict], subdir: list[str]) -> None:
    """Two jobs of one plan that would write into one dir: refused, naming the ``hydra.sweep.subdir`` override
    or the keys that tell them apart (left out of the dir names)."""
    from ddmr_cli.cli import sweep

    clash = sweep.shared_dir(plan)
    if clash is None:
        return
    a, b = clash
    differ = sorted({ov.lstrip("+~").partition("=")[0] for ov in set(a["overrides"]) ^ set(b["overrides"])})
    raise UsageError(f"{subdir[-1] if subdir else ', '.join(differ) or 'hydra.sweep.subdir'}: jobs {' '.join(a['overrides'])!r} and "
                     f"{' '.join(b['overrides'])!r} would write into one job dir {a['dir']!r}; sweep a key that names "
                     f"the dir (not one of hydra.job.config.override_dirname.exclude_keys) or give hydra.sweep.subdir "
                     f"a per-job value")


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


def _refuse_escapes(plan: list[dict], subdir: list[str]) -> None:
    """A planned job dir that is not a path strictly inside the sweep dir (``hydra.sweep.subdir=../x``, an
    absolute path, ``.``): refused, naming the ``hydra.sweep.subdir`` override."""
    import os

    for job in plan:
        norm = os.path.normpath(job["dir"])
        if os.path.isabs(norm) or norm == "." or norm.split(os.sep)[0] == "..":
            raise UsageError(f"{subdir[-1] if subdir else 'hydra.sweep.subdir'}: job {' '.join(job['overrides'])!r} "
                             f"would write into {job['dir']!r}, not a dir inside the sweep dir; give "
                             f"hydra.sweep.subdir a relative path below it")


def preflight(launch: "Launch") -> None:
    """Refuse, before anything is written, an output dir where a run or sweep would delete or overwrite what it
    did not write (:func:`ddmr_cli.cli.jobdir.check_clear`), a planned job dir that is a file or resolves outside
    the sweep dir (a symlink), or sweep tables and a plan ddmr did not write. Raises ``FaultError`` (exit 1)."""
    from ddmr_cli.cli import jobdir, sweep

    if not launch.multirun:
        jobdir.check_clear(launch.out_dir)
        return
    if launch.study:
        return
    sweep.check_dir(launch.out_dir)
    for job in launch.plan:
        job_dir = launch.out_dir / job["dir"]
        if not os.path.lexists(job_dir):
            continue
        if not jobdir.inside(job_dir, launch.out_dir):
            raise jobdir.FaultError(job_dir, f"resolves to {job_dir.resolve()}, outside the sweep dir; a job writes "
                                             "only inside its sweep dir; remove the link or choose another dir")
        jobdir.check_clear(job_dir)


#: flags naming config dirs: the primary config's (``--config-path``) and an extra one (``--config-dir``)
_DIR_FLAGS = MappingProxyType({"--config-path": "path", "-cp": "path", "--config-dir": "dir", "-cd": "dir"})


def _config_dirs(argv: list[str]) -> tuple[list[str], str | None, str | None]:
    """``argv`` with the ``--config-path`` / ``--config-dir`` values made absolute against the current dir (Hydra
    would read a relative --config-path against its own module's dir), and those two dirs (or None)."""
    out, dirs = [], {"path": None, "dir": None}
    it = iter(argv)
    for arg in it:
        name, sep, value = arg.partition("=")
        if name not in _DIR_FLAGS:
            out.append(arg)
            continue
        value = value if sep else next(it, "")
        if not value.startswith("pkg://"):
            value = str(Path(value.removeprefix("file://")).expanduser().resolve())
            dirs[_DIR_FLAGS[name]] = value
        out.append(f"{name}={value}")
    return out, dirs["path"], dirs["dir"]


def _normalise(argv: list[str]) -> list[str]:
    """``report=true`` is short for ``report.auto=true`` (``report`` is a node: auto, margin)."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if sep and key == "report" and value.lower() in ("true", "false"):
            arg = f"report.auto={value.lower()}"
        out.append(arg)
    return out


def finish(launch: Launch) -> int:
    """The exit status from the output dir as it is on disk, and the report when asked for. A sweep whose tables
    could not be written, or with a failed job, exits 1; a job's file-system fault is repeated as one line."""
    from ddmr_cli.cli import io, sweep

    if launch.search:
        from ddmr_cli.study.search import finish as finish_search

        status = finish_search(launch.out_dir)
    elif launch.study:
        from ddmr_cli.cli.tuning import finish as finish_study

        status = finish_study(launch.out_dir)
    elif launch.multirun:
        from ddmr_cli.study.task import STUDY_CSV

        state = sweep.read_state(launch.out_dir, plan=list(launch.plan))
        # a sweep writes its tables; a sensitivity-study stage (+experiment=sensitivity_*) writes its study table
        tables = (launch.out_dir / sweep.JOBS_CSV).is_file() or (launch.out_dir / STUDY_CSV).is_file()
        status = 0 if state.ok and tables else EXIT_FAILED
        faults = [s["fault"] for _, s in state.failed if isinstance(s.get("fault"), dict)]
        if faults:
            more = f" ({len(faults)} jobs failed on file-system faults)" if len(faults) > 1 else ""
            print(f"ddmr: error: {faults[0]['path']}: {faults[0]['reason']}{more}", file=sys.stderr)
    else:
        summary = io.read_summary(launch.out_dir)
        status = 0 if summary and summary.get("status") == "complete" else EXIT_FAILED
    if launch.report:
        status = max(status, write_report(launch.out_dir, None, launch.margin, failure=EXIT_FAILED))
    return status


def write_report(path: Path, out: str | None, margin: float | None, failure: int = EXIT_USAGE,
                 figures: bool = True) -> int:
    from ddmr_cli.cli import jobdir
    from ddmr_cli.errors import DDMRError
    from ddmr_cli.report import build_report
    from ddmr_cli.report.build import staged

    try:
        from ddmr_cli.report import tuning

        if tuning.is_tuning_dir(path):  # studies: held-out runs at paper and tuned gains, then their report
            final = Path(out).expanduser().resolve() if out is not None else Path(path).expanduser().resolve() / "report"
            written = staged(final, lambda root: tuning.build(path, root, margin))
        else:
            written = build_report(path, out, figures=figures, **({"margin": margin} if margin is not None else {}))
    except jobdir.FaultError as exc:  # a file-system fault or a refused --out: one line naming the path, exit 1
        print(f"ddmr: error: {exc.path}: {exc.reason}", file=sys.stderr)
        return EXIT_FAILED
    except (DDMRError, FileNotFoundError) as exc:  # nothing to report: bad input
        print(f"ddmr: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return failure
    except OSError as exc:
        fault = jobdir.fault(exc)
        print(f"ddmr: error: {fault.path}: {fault.reason}", file=sys.stderr)
        return EXIT_FAILED
    print(f"ddmr: report written to {written}")
    return 0


INTERRUPTED = 130
INTERRUPTED_MESSAGE = "ddmr: interrupted; run the same command again to resume"


def cmd_run(argv: list[str]) -> int:
    argv = _normalise(argv)
    overrides, flags = _split_args(argv)
    config_name = str(flags.get("--config-name") or flags.get("-cn") or "config")
    if {"--help", "-h"} & flags.keys():
        return run_help(overrides, config_name)
    multirun = bool(flags.get("-m") or flags.get("--multirun"))
    if _INFO_FLAGS & flags.keys():  # no job runs: Hydra prints what was asked for
        return _hydra(argv, completing=bool({"-sc", "--shell-completion"} & flags.keys()))
    argv, config_dir, search_dir = _config_dirs(argv)
    try:
        launch = prepare(argv, overrides, multirun, config_name, config_dir, search_dir)
    except UsageError as exc:
        return _fail(str(exc))
    except OSError as exc:  # a fault found while planning (an unreadable study storage): one line, exit 1
        print(f"ddmr: error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    return run_locked(launch)


def run_locked(launch: Launch) -> int:
    """Run Hydra on a prepared launch holding the output dir's lock; file-system faults and Ctrl-C end it with
    one line (exit 1 and 130)."""
    import os
    import socket

    from ddmr_cli.cli import jobdir

    reaper = None
    try:
        preflight(launch)  # reads only: a refused dir is left as it was
        with jobdir.DirLock(launch.out_dir, kind="sweep" if launch.multirun else "run"):
            preflight(launch)  # again, now that no other ddmr writes the tree
            if launch.multirun and not launch.study:
                jobdir.clean_leftovers(launch.out_dir, [job["dir"] for job in launch.plan])
                print(f"ddmr: sweep of {len(launch.plan)} jobs validated -> {launch.out_dir}", file=sys.stderr)
                os.environ["DDMR_PARENT"] = f"{socket.gethostname()}:{os.getpid()}"  # workers end when we are gone
                reaper = _start_reaper()
            with _ctrl_c_to_this_process_only():
                code = _hydra(list(launch.argv))
            return code or finish(launch)
    except jobdir.FaultError as exc:
        print(f"ddmr: error: {exc.path}: {exc.reason}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        _stop_workers()
        print(INTERRUPTED_MESSAGE, file=sys.stderr)
        return INTERRUPTED
    finally:
        if reaper is not None:
            reaper.stdin.close()  # the reaper ends what is left of the workers (nothing, after a normal end)


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
    import os
    import socket
    import subprocess

    try:
        return subprocess.Popen([sys.executable, str(Path(__file__).with_name("reaper.py")), str(os.getpid()),
                                 socket.gethostname()], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        return None


def _hydra(argv: list[str], completing: bool = False) -> int:
    """Hydra's exit status for ``ddmr run ARGV`` (0 when it returns)."""
    from ddmr_cli.cli.hydra_main import main as hydra_main

    # shell completion registers and queries the program `ddmr` (see `main`); everything else is `ddmr run`
    sys.argv = ["ddmr" if completing else "ddmr run", *argv]
    try:
        hydra_main()
    except SystemExit as exc:  # Hydra exits 1 after printing a job's error
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_FAILED
    return 0


def _stop_workers() -> None:
    """Kill the joblib launcher's worker processes (after Ctrl-C they may still be running jobs)."""
    if "joblib" in sys.modules:
        from joblib.externals.loky import get_reusable_executor

        get_reusable_executor().shutdown(wait=False, kill_workers=True)


# --- self-documenting config: ddmr run --help, ddmr explain KEY ---------------------------------------------


def _fmt_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if value is None:
        return "null"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_fmt_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_fmt_value(v)}" for k, v in value.items()) + "}"
    return str(value)


def _compose_for_help(overrides: list[str], config_name: str):
    """The config ``overrides`` compose (sweeps: their first values), with the hydra node."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.cli.config import compose_config

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        return compose_config(fixed, config_name, return_hydra_config=True)
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        raise UsageError(_missing_plugin(exc, overrides) or _explain(exc, overrides)) from None


def _choices(cfg) -> dict[str, str]:
    return {k: v for k, v in cfg.hydra.runtime.choices.items() if not k.startswith("hydra/") and v is not None}


def key_table(docs, indent: str = "  ", value_width: int = 22) -> list[str]:
    """``key  value  [unit]  meaning`` lines, aligned."""
    key_w = max((len(d.key) for d in docs), default=0)
    unit_w = max((len(d.unit) for d in docs), default=0) + 2
    lines = []
    for d in docs:
        value = _fmt_value(d.value)
        unit = f"[{d.unit}]" if d.unit else ""
        lines.append(f"{indent}{d.key:<{key_w}}  {value:<{value_width}}  {unit:<{unit_w}}  {d.help}".rstrip())
    return lines


def run_help(overrides: list[str], config_name: str = "config") -> int:
    """``ddmr run --help``: the config groups and every key of the composed config with value, unit, meaning."""
    from ddmr_cli.cli.config import group_options, key_docs

    try:
        cfg = _compose_for_help(overrides, config_name)
    except UsageError as exc:
        return _fail(str(exc))
    choices = _choices(cfg)
    print(str(cfg.hydra.help.header).rstrip())
    print("\n== Config groups (group=option; * = composed) ==")
    for group in GROUPS:
        options = [f"{o}*" if choices.get(group) == o else o for o in group_options(group)]
        prefix = "+" if group in ("experiment", "tune") else ""
        print(f"  {prefix}{group}: {', '.join(options)}")
    docs = key_docs(cfg)
    print(f"\n== Keys of the composed config ({len(docs)}): key  value  [unit]  meaning ==")
    print("   (ddmr explain KEY: valid range and docs/model.md section; [1] = dimensionless)")
    print("\n".join(key_table(docs)))
    print()
    print(str(cfg.hydra.help.footer).rstrip())
    return 0


def cmd_explain(argv: list[str]) -> int:
    """``ddmr explain KEY [OVERRIDES...]``: one key's meaning, unit, value, valid range and model reference."""
    import difflib

    from ddmr_cli.cli.config import compose_config, group_options, iter_keys, key_doc

    if not argv or argv[0] in ("-h", "--help"):
        print("usage: ddmr explain KEY [OVERRIDES...]\n\nThe meaning, unit, value (composed default, or with the "
              "overrides), valid range and docs/model.md\nsection of a config key. Examples:\n"
              "  ddmr explain controller.switching_gain\n  ddmr explain controller.kp controller=pid\n"
              "  ddmr explain terrain.zones.very_rough.roughness\n  ddmr explain controller")
        return 0 if argv else EXIT_USAGE
    key, overrides = argv[0], argv[1:]
    try:
        cfg = _compose_for_help(overrides, "config")
    except UsageError as exc:
        return _fail(str(exc))
    composed_from = None
    default_choice = _choices(cfg).get(key.split(".", 1)[0], "?")
    try:
        doc = key_doc(cfg, key)
    except KeyError:
        doc = None
        group = key.split(".", 1)[0]
        if group in GROUPS and "." in key and not any(o.partition("=")[0] == group for o in overrides):
            for option in group_options(group):  # a key of another option of the group (controller.kp: pid)
                other = compose_config([*overrides, f"{group}={option}"], return_hydra_config=True)
                try:
                    doc, cfg, composed_from = key_doc(other, key), other, f"{group}={option}"
                    break
                except KeyError:
                    continue
        if doc is None:
            known = [k for k in iter_keys(cfg)] + [k for k in cfg if k != "hydra"]
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            return _fail(f"key={key}: not a key of the composed config{hint} (ddmr run --help lists every key)")
    choices = _choices(cfg)
    print(f"{doc.key} = {_fmt_value(doc.value)}" if doc.is_leaf else doc.key)
    print(f"  meaning: {doc.help or '-'}")
    print(f"  unit:    {doc.unit or '-'}{'  (dimensionless)' if doc.unit == '1' else ''}")
    if doc.is_leaf:
        where = ", ".join(f"{g}={choices[g]}" for g in GROUPS if g in choices and (g == key.split('.')[0]))
        label = "value:  " if overrides else "default:"
        note = f"composed from {composed_from or where or 'config.yaml'}" + (" and the overrides" if overrides else "")
        print(f"  {label} {_fmt_value(doc.value)}  ({note})")
    print(f"  range:   {doc.range or '-'}")
    print(f"  see:     {doc.reference}")
    if composed_from:
        print(f"  note:    not a key of the composed {key.split('.')[0]}={default_choice}; "
              f"set it with {composed_from} (e.g. ddmr run {composed_from} {key}=...)")
    if not doc.is_leaf:
        if key in GROUPS:
            options = [f"{o}*" if choices.get(key) == o else o for o in group_options(key)]
            print(f"  options: {', '.join(options)}   (* = composed; choose with {key}=OPTION)")
        node = cfg
        for part in key.split("."):
            node = node[part]
        print("  keys:")
        print("\n".join(key_table([key_doc(cfg, f"{key}.{k}") for k in iter_keys(node)], indent="    ")))
    return 0


def _latest_sweep(root: Path) -> Path | None:
    """The sweep dir under ``root`` whose plan (or multirun.yaml) was written last."""
    marks = [*root.glob("**/sweep_plan.json"), *root.glob("**/multirun.yaml")]
    return max(marks, key=lambda p: p.stat().st_mtime).parent if marks else None


class _Parser(argparse.ArgumentParser):
    """argparse with the one-line refusal of every ddmr command: ``ddmr: error: --flag: what``, exit 2."""

    def error(self, message: str):
        message = message.removeprefix("argument ")
        self.exit(EXIT_USAGE, f"ddmr: error: {message}\n")


def cmd_report(argv: list[str]) -> int:
    parser = _Parser(prog="ddmr report", description="Markdown report, tables (CSV) and figures "
                                     "(PNG) from a sweep dir or a single run dir, beside the paper's numbers.")
    parser.add_argument("path", nargs="?", default=None,
                        help="a sweep dir (ddmr run -m ...) or a single run dir (default: the latest sweep under "
                             "./outputs)")
    parser.add_argument("--out", default=None, help="output dir (default: PATH/report)")
    parser.add_argument("--margin", default=None,
                        help="practical margin of the verdicts, with its unit: a length (0.05mm, 50um, 5e-5m) "
                             "for the metrics in metres, 5%% of the reference's mean for the others; or a "
                             "percentage (2%%) for every metric; a bare number is refused. Default: 0.1 mm or 5%% of "
                             "the reference's mean, whichever is smaller, for metrics in metres (deviation, e_x, "
                             "e_y); 5%% for the others. A paired difference whose 95%% CI lies inside it refutes a "
                             "claimed improvement (a tie for baseline comparisons)")
    parser.add_argument("--no-figures", action="store_true",
                        help="write report.md and the tables only, without drawing the figures (much faster)")
    args = parser.parse_args(argv)
    from ddmr_cli.report.stats import Margin

    try:
        Margin.parse(args.margin)
    except ValueError as exc:
        return _fail(f"--margin={args.margin}: {exc}")
    path = args.path
    if path is None:
        latest = _latest_sweep(Path("outputs"))
        if latest is None:
            return _fail(f"path=(none): no sweep under {Path('outputs').resolve()}; give PATH or run ddmr run -m first")
        print(f"ddmr: reporting the latest sweep under ./outputs: {latest}", file=sys.stderr)
        path = latest
    return write_report(Path(path), args.out, args.margin, figures=not args.no_figures)


def cmd_sensitivity(argv: list[str]) -> int:
    from ddmr_cli.cli.sensitivity import main as sensitivity_main

    return sensitivity_main(argv)


def cmd_bench(argv: list[str]) -> int:
    from ddmr_cli.cli.bench import main as bench_main

    return bench_main(argv)


def _complete(argv: list[str]) -> int:
    """Answer a shell-completion query for ``ddmr run ...``: Hydra completes the words after ``run``."""
    import os

    line = os.environ.get("COMP_LINE", "")
    words = line.split(" ")
    if len(words) > 1 and words[1] == "run":
        os.environ["COMP_LINE"] = " ".join([words[0], *words[2:]])
        point = int(os.environ.get("COMP_POINT", len(line)))
        os.environ["COMP_POINT"] = str(max(0, point - len("run ")))
    return cmd_run(argv)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(USAGE)
        return 0 if argv else EXIT_USAGE
    if argv[0] == "--version":
        from ddmr_cli import __version__

        print(f"ddmr {__version__}")
        return 0
    if argv[0] in ("-sc", "--shell-completion"):  # the installed completion script asks `ddmr -sc query=...`
        return _complete(argv)
    command, rest = argv[0], argv[1:]
    commands = {"run": cmd_run, "explain": cmd_explain, "report": cmd_report, "bench": cmd_bench,
                "sensitivity": cmd_sensitivity}
    if command not in commands:
        return _fail(f"unknown command {command!r}; available: {', '.join(commands)} (ddmr --help)")
    logging.getLogger("matplotlib").setLevel(logging.WARNING)
    try:
        return commands[command](rest)
    except KeyboardInterrupt:
        print(INTERRUPTED_MESSAGE if command == "run" else "ddmr: interrupted", file=sys.stderr)
        return INTERRUPTED
    except BrokenPipeError:  # `ddmr run --help | head`: the reader left; say nothing more
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
