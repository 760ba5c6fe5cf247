"""The ``ddmr`` command: ``run`` (Hydra), ``explain``, ``report``, ``bench`` and ``sensitivity``.

``ddmr run`` hands its arguments to Hydra, so every Hydra feature works (overrides, ``--multirun``, ``--cfg``,
``--help``, ``--info``, shell completion); :mod:`ddmr_cli.cli.run` composes and validates every job first
(:mod:`ddmr_cli.cli.modes`). This module only dispatches.
"""

from __future__ import annotations

import gc
import logging
import sys
from typing import Sequence

from ddmr_cli.cli.blas import single_threaded_blas
from ddmr_cli.cli.collector import collect_less_often

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


def cmd_run(argv: list[str]) -> int:
    from ddmr_cli.cli.run import cmd_run as run

    return run(argv)


def cmd_explain(argv: list[str]) -> int:
    from ddmr_cli.cli.help import cmd_explain as explain

    return explain(argv)


def cmd_report(argv: list[str]) -> int:
    from ddmr_cli.cli.reporting import cmd_report as report

    return report(argv)


def cmd_sensitivity(argv: list[str]) -> int:
    from ddmr_cli.cli.sensitivity import main as sensitivity_main

    return sensitivity_main(argv)


def cmd_bench(argv: list[str]) -> int:
    from ddmr_cli.cli.bench import main as bench_main

    return bench_main(argv)


#: the subcommands, in the order ``ddmr --help`` lists them (tab completion offers them too)
COMMANDS = ("run", "explain", "report", "bench", "sensitivity")
#: what a word after ``ddmr`` may also be
TOP_FLAGS = ("--help", "--version")


def _complete(argv: list[str]) -> int:
    """Answer a shell-completion query (``ddmr -sc query=bash``, asked by the script ``ddmr run -sc install=bash``
    installs; the line so far in ``COMP_LINE``, the cursor in ``COMP_POINT``).

    The first word: the subcommands. After ``run`` and ``sensitivity``: Hydra completes the overrides (groups,
    options, keys). After ``explain``: its topics (:func:`~ddmr_cli.cli.help.explain_topics`), then Hydra for the
    overrides. After ``report`` and ``bench``: nothing, so the shell offers paths (the script's ``-o default``)."""
    import os

    line = os.environ.get("COMP_LINE", "")
    point = int(os.environ.get("COMP_POINT", len(line)))
    words = line[:point].split(" ")
    sep = " " if "query=bash" in argv else "\n"
    if len(words) <= 2:
        print(sep.join(w for w in (*COMMANDS, *TOP_FLAGS) if w.startswith(words[-1])))
        return 0
    command = words[1]
    if command == "explain" and len(words) == 3:
        from ddmr_cli.cli.help import explain_topics

        print(sep.join(explain_topics(words[2])))
        return 0
    if command not in ("run", "sensitivity", "explain"):
        return 0
    skip = words[:3] if command == "explain" else words[:2]  # Hydra sees `ddmr OVERRIDES...`
    cut = len(" ".join(skip)) + 1
    os.environ["COMP_LINE"] = words[0] + " " + line[cut:]
    os.environ["COMP_POINT"] = str(max(0, point - cut + len(words[0]) + 1))
    return cmd_run(argv)


def main(argv: Sequence[str] | None = None) -> int:
    from ddmr_cli.cli.usage import EXIT_USAGE, INTERRUPTED, INTERRUPTED_MESSAGE, fail

    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(USAGE)
        return 0 if argv else EXIT_USAGE
    if argv[0] == "--version":
        from ddmr_cli.version import __version__

        print(f"ddmr {__version__}")
        return 0
    if argv[0] in ("-sc", "--shell-completion"):  # the installed completion script asks `ddmr -sc query=...`
        return _complete(argv)
    command, rest = argv[0], argv[1:]
    commands = dict(zip(COMMANDS, (cmd_run, cmd_explain, cmd_report, cmd_bench, cmd_sensitivity)))
    if command not in commands:
        return fail(f"unknown command {command!r}; available: {', '.join(commands)} (ddmr --help)")
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


def _plot_processes(argv: list[str] | None):
    """For ``ddmr run [KEY=VALUE ...]`` (no flag, so no sweep; not ``run.plots=false``) run as the program, the
    drawing processes of its figures, started first thing (:meth:`~ddmr_cli.plots.processes.PlotProcesses.started`):
    forked from a process that has imported next to nothing, they import matplotlib and draw the figures' frames
    on the processor the job's own imports, Hydra and the loading of the compiled step loop leave idle; for
    anything else, nothing (the job starts its own when its config asks for plots)."""
    import contextlib

    if not argv or argv[0] != "run" or any(arg.startswith("-") or _plots_off(arg) for arg in argv[1:]):
        return contextlib.nullcontext()
    from ddmr_cli.plots.processes import PlotProcesses

    return PlotProcesses.started()


def _plots_off(override: str) -> bool:
    """Whether a command-line override sets ``run.plots`` to false."""
    key, _, value = override.partition("=")
    return key.strip().lstrip("+~") == "run.plots" and value.strip().lower() in ("false", "0", "no", "off", "null", "")


def _freeze_the_run_modules() -> None:
    """Import what a single run imports anyway (the command line, the configuration, Hydra, the job, the engine and
    numba) and freeze it (:func:`gc.freeze`): the garbage collections during the run then walk only what the run
    makes, not these modules' objects, which live to the end anyway (a full collection while the compiled step
    loop loads: 28 -> 10 ms; the run 2 % faster, measured)."""
    import ddmr_cli.cli.run  # noqa: F401
    import ddmr_cli.engine.simulation  # noqa: F401
    import ddmr_cli.job  # noqa: F401

    gc.freeze()


def console(argv: Sequence[str] | None = None) -> int:
    """The ``ddmr`` command: :func:`main`; run as the program (``argv`` None), with the garbage collector's
    youngest generation collected less often (:func:`~ddmr_cli.cli.collector.collect_less_often`), OpenBLAS on one
    thread (:func:`~ddmr_cli.cli.blas.single_threaded_blas`, before numpy loads), a single run's
    drawing processes started first (:func:`_plot_processes`) and its modules frozen (:func:`_freeze_the_run_modules`),
    then :func:`gc.freeze`, so that the interpreter's exit does not walk every object the command loaded (numba's,
    Hydra's, matplotlib's) in its last garbage collections: 0.15 s of a 1 s ``ddmr run`` (measured). Frozen objects
    are left to the process's end, as the exit would leave them; files are closed by then (every output is written
    atomically and closed by its writer)."""
    program = argv is None
    if program:
        collect_less_often()
        single_threaded_blas()
    with _plot_processes(sys.argv[1:] if program else None) as drawing:
        if drawing is not None:
            _freeze_the_run_modules()
        code = main(argv)
    if program:
        gc.freeze()
    return code


if __name__ == "__main__":
    sys.exit(console())
