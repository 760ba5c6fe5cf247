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
from dataclasses import dataclass
from pathlib import Path
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
                          add report=true to write the report when the run or sweep ends
  explain KEY [OVERRIDES] a config key's meaning, unit, value, valid range and docs/model.md section
  report [PATH] [--out DIR] [--margin 0.1mm]  markdown report, tables (CSV) and figures (PNG) from a sweep or run dir
                          (default PATH: the latest sweep under ./outputs)
  bench [--quick]         print engine and end-to-end performance figures for this machine
  sensitivity [--out DIR] [OVERRIDES]  the sensitivity of the paper's claims and the reading nearest its Table 4
                          (every stage a sweep; study=quick for the CI size; docs/model.md §9)
  --version               print the version
"""

# Hydra flags after which no job runs (nothing to validate)
_INFO_FLAGS = frozenset({"--help", "-h", "--hydra-help", "--version", "--info", "-i", "--cfg", "-c",
                         "--shell-completion", "-sc"})
_VALUE_FLAGS = frozenset({"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name",
                          "-cn", "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"})
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


def prepare(argv: list[str], overrides: list[str], multirun: bool, config_name: str = "config") -> Launch:
    """Compose and validate every job of the run or sweep, resolve its output dir and plan its jobs.

    Raises :class:`UsageError` (one line) on the first bad value, before anything is written. The output dir
    (``hydra.run.dir`` / ``hydra.sweep.dir``, usually ``outputs/<experiment>/<time>``) is resolved here and
    passed to Hydra as an override, so the CLI reads exactly this run's results afterwards."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.cli import sweep
    from ddmr_cli.cli.config import compose_config, validate_config
    from ddmr_cli.errors import ConfigError

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
        fixed = [o.input_line for o in parsed if not o.is_sweep_override()]
        if not multirun and len(fixed) != len(parsed):
            sweep_ov = next(o.input_line for o in parsed if o.is_sweep_override())
            raise UsageError(f"{sweep_ov}: a sweep needs --multirun (-m)")
        base = compose_config(fixed, config_name, return_hydra_config=True)
        margin = base.report.margin
        try:
            from ddmr_cli.report.stats import Margin

            Margin.parse(margin)
        except ValueError as exc:
            raise UsageError(f"report.margin={margin}: {exc}") from None
        plan = sweep.plan_jobs(overrides, base.hydra) if multirun else [{"dir": "", "overrides": overrides}]
        for job in plan:
            cfg = compose_config(job["overrides"], config_name) if multirun else base
            validate_config(cfg)  # builds the model: derived numbers (J^-1, controller gains) fail here, not in a job
        dir_key = "hydra.sweep.dir" if multirun else "hydra.run.dir"
        out_dir = Path(str(base.hydra.sweep.dir if multirun else base.hydra.run.dir))
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    except (HydraException, OmegaConfBaseException, ValueError) as exc:
        raise UsageError(_missing_plugin(exc, overrides) or _explain(exc, overrides)) from None
    pinned = [a for a in argv if a.partition("=")[0] != dir_key] + [f"{dir_key}={_override_value(out_dir)}"]
    if multirun:
        print(f"ddmr: sweep of {len(plan)} jobs validated -> {out_dir}", file=sys.stderr)
    return Launch(multirun, out_dir, tuple(pinned), tuple(plan) if multirun else (), bool(base.report.auto), margin)


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
    """The exit status from the output dir as it is on disk, and the report when asked for."""
    from ddmr_cli.cli import io, sweep

    if launch.multirun:
        state = sweep.read_state(launch.out_dir, plan=list(launch.plan))
        status = 0 if state.ok else EXIT_FAILED
    else:
        summary = io.read_summary(launch.out_dir)
        status = 0 if summary and summary.get("status") == "complete" else EXIT_FAILED
    if launch.report:
        status = max(status, write_report(launch.out_dir, None, launch.margin, failure=EXIT_FAILED))
    return status


def write_report(path: Path, out: str | None, margin: float | None, failure: int = EXIT_USAGE) -> int:
    from ddmr_cli.errors import DDMRError
    from ddmr_cli.report import build_report

    try:
        written = build_report(path, out, **({"margin": margin} if margin is not None else {}))
    except (DDMRError, FileNotFoundError) as exc:
        print(f"ddmr: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return failure
    print(f"ddmr: report written to {written}")
    return 0


def cmd_run(argv: list[str]) -> int:
    argv = _normalise(argv)
    overrides, flags = _split_args(argv)
    config_name = str(flags.get("--config-name") or flags.get("-cn") or "config")
    if {"--help", "-h"} & flags.keys():
        return run_help(overrides, config_name)
    multirun = bool(flags.get("-m") or flags.get("--multirun"))
    launch = None
    if not (_INFO_FLAGS & flags.keys()) and not ({"--config-path", "-cp", "--config-dir", "-cd"} & flags.keys()):
        try:
            launch = prepare(argv, overrides, multirun, config_name)
        except UsageError as exc:
            return _fail(str(exc))
        argv = list(launch.argv)
    from ddmr_cli.cli.hydra_main import main as hydra_main

    # shell completion registers and queries the program `ddmr` (see `main`); everything else is `ddmr run`
    completing = bool({"-sc", "--shell-completion"} & flags.keys())
    sys.argv = ["ddmr" if completing else "ddmr run", *argv]
    try:
        hydra_main()
    except SystemExit as exc:  # Hydra exits 1 after printing a job's error
        code = int(exc.code or 0) if not isinstance(exc.code, str) else EXIT_FAILED
        if code or launch is None:
            return code
    return 0 if launch is None else finish(launch)


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
        prefix = "+" if group == "experiment" else ""
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


def cmd_report(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="ddmr report", description="Markdown report, tables (CSV) and figures "
                                     "(PNG) from a sweep dir or a single run dir, beside the paper's numbers.")
    parser.add_argument("path", nargs="?", default=None,
                        help="a sweep dir (ddmr run -m ...) or a single run dir (default: the latest sweep under "
                             "./outputs)")
    parser.add_argument("--out", default=None, help="output dir (default: PATH/report)")
    parser.add_argument("--margin", default=None,
                        help="practical margin of the verdicts: a length (0.1mm, the default; 1e-4 in metres) for "
                             "the metrics in metres, 5%% of the reference's mean for the others; or a percentage "
                             "(5%%) for every metric. A paired difference whose 95%% CI lies inside it is a tie")
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
    return write_report(Path(path), args.out, args.margin)


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
    except BrokenPipeError:  # `ddmr run --help | head`: the reader left; say nothing more
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
