"""The ``ddmr`` command: ``run`` (Hydra), ``report`` and ``bench``.

``ddmr run`` hands its arguments to Hydra, so every Hydra feature works (overrides, ``--multirun``, ``--cfg``,
``--help``, ``--info``, shell completion). Before Hydra makes any directory, the CLI composes every job of the
run or sweep with Hydra's compose API and validates it: a bad value prints one line naming the key, the value
and the rule, and exits with status 2, leaving nothing behind.
"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Sequence

EXIT_USAGE = 2
EXIT_FAILED = 1

USAGE = """\
usage: ddmr <command> [args]

Trajectory-tracking experiments for differential-drive mobile robots (SMC, NDO, RBF-NN observers on rough
terrain), reproducing and extending "SMC integrated with NDO and RBF neural network ... considering terrain".

commands:
  run [OVERRIDES...]      run a job (or a sweep with -m) from Hydra configs; `ddmr run --help` lists the
                          config groups and options. Examples:
                            ddmr run                                  # paper scenario 1, SMC-NDO-NNO, 50 seeds
                            ddmr run controller=pid scenario=paper_2 run.n_runs=10
                            ddmr run -m +experiment=table4            # Table 4: 4 controllers x 2 scenarios
                            ddmr run -m controller=smc,smc_ndo controller.switching_gain=4,8,12
                            ddmr run -m +experiment=table4 launcher=slurm cluster.partition=compute
  report PATH [--out DIR] markdown report, tables (CSV) and figures (PNG) from a sweep or run dir
  bench [--quick]         print engine and end-to-end performance figures for this machine
  --version               print the version
"""

# Hydra flags after which no job runs (nothing to validate)
_INFO_FLAGS = {"--help", "-h", "--hydra-help", "--version", "--info", "-i", "--cfg", "-c", "--shell-completion",
               "-sc"}
_VALUE_FLAGS = {"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name", "-cn",
                "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"}
GROUPS = ("robot", "terrain", "controller", "scenario", "trajectory", "experiment", "launcher")


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
        value = next((ov.partition("=")[2] for ov in overrides if ov.lstrip("+~").partition("=")[0] == key), None)
        msg = str(getattr(cause, "msg", cause)).splitlines()[0]
        if isinstance(cause, ConfigKeyError) and "not in" in msg:
            return f"{key}={value}: unknown key ({msg})"
        return f"{key}={value!r}: {msg}" if value is not None else f"{key}: {msg}"
    if isinstance(exc, MissingConfigException):
        return str(exc).splitlines()[0]
    return " ".join(str(exc).split())


def _fail(message: str) -> int:
    print(f"ddmr: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def prevalidate(overrides: list[str], multirun: bool, config_name: str = "config") -> int:
    """Compose and validate every job of the run or sweep; 0 when all are valid, else prints why and returns 2."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.cli import sweep
    from ddmr_cli.cli.config import build_simulation, compose_config, validate_config
    from ddmr_cli.errors import ConfigError

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        if not multirun and len(fixed) != len(parsed):
            sweep_ov = next(o.input_line for o in parsed if o.is_sweep_override())
            return _fail(f"{sweep_ov}: a sweep needs --multirun (-m)")
        base = compose_config(fixed, config_name, return_hydra_config=True)
        jobs = [overrides]
        if multirun:
            params = dict(base.hydra.sweeper.get("params") or {})
            jobs = sweep.expand_jobs(overrides, params)
        od = base.hydra.job.config.override_dirname
        plan = []
        for i, job in enumerate(jobs):
            cfg = base if (i == 0 and job == fixed) else compose_config(job, config_name)
            validate_config(cfg)
            build_simulation(cfg)  # derived model numbers (J^-1, controller gains) fail here, not in a job
            plan.append({"dir": sweep.job_dirname(job, od.exclude_keys, od.item_sep, od.kv_sep), "overrides": job})
    except ConfigError as exc:
        return _fail(str(exc))
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        return _fail(_explain(exc, overrides))
    if multirun:
        sweep.pending_plan = plan
        print(f"ddmr: sweep of {len(plan)} jobs validated", file=sys.stderr)
    return 0


def cmd_run(argv: list[str]) -> int:
    from ddmr_cli.cli import sweep

    overrides, flags = _split_args(argv)
    multirun = bool(flags.get("-m") or flags.get("--multirun"))
    if not (_INFO_FLAGS & flags.keys()) and not ({"--config-path", "-cp", "--config-dir", "-cd"} & flags.keys()):
        status = prevalidate(overrides, multirun, str(flags.get("--config-name") or flags.get("-cn") or "config"))
        if status:
            return status
    from ddmr_cli.cli.hydra_main import main as hydra_main

    # shell completion registers and queries the program `ddmr` (see `main`); everything else is `ddmr run`
    completing = bool({"-sc", "--shell-completion"} & flags.keys())
    sys.argv = ["ddmr" if completing else "ddmr run", *argv]
    sweep.last_sweep = None
    try:
        hydra_main()
    except SystemExit as exc:  # Hydra exits 1 after printing a job's error
        return int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_FAILED
    state = sweep.last_sweep
    if state is not None and not state.ok:
        return EXIT_FAILED
    return 0


def cmd_report(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="ddmr report", description="Markdown report, tables (CSV) and figures "
                                     "(PNG) from a sweep dir or a single run dir, beside the paper's numbers.")
    parser.add_argument("path", help="a sweep dir (ddmr run -m ...) or a single run dir")
    parser.add_argument("--out", default=None, help="output dir (default: PATH/report)")
    parser.add_argument("--margin", default=None,
                        help="practical margin of the verdicts: a length (0.1mm, the default; 1e-4 in metres) for "
                             "the metrics in metres, 5%% of the reference's mean for the others; or a percentage "
                             "(5%%) for every metric. A paired difference whose 95%% CI lies inside it is a tie")
    args = parser.parse_args(argv)
    from ddmr_cli.errors import DDMRError
    from ddmr_cli.report import build_report
    from ddmr_cli.report.stats import Margin

    try:
        margin = Margin.parse(args.margin)
    except ValueError as exc:
        return _fail(str(exc))
    try:
        out = build_report(args.path, args.out, margin)
    except (DDMRError, FileNotFoundError) as exc:
        return _fail(str(exc))
    print(f"ddmr: report written to {out}")
    return 0


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
    commands = {"run": cmd_run, "report": cmd_report, "bench": cmd_bench}
    if command not in commands:
        return _fail(f"unknown command {command!r}; available: {', '.join(commands)} (ddmr --help)")
    logging.getLogger("matplotlib").setLevel(logging.WARNING)
    return commands[command](rest)


if __name__ == "__main__":
    sys.exit(main())
