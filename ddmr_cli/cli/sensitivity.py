"""``ddmr sensitivity``: the whole sensitivity study of the paper's claims (docs/model.md §11), stage after stage.

Each stage is an ordinary ``ddmr run -m +experiment=sensitivity_<stage>`` sweep (same validation, launchers,
resume and output dirs), into ``OUT/<stage>``; the calibration stage's sweep is ddmr's Optuna sweeper
(:mod:`ddmr_cli.study.search`). The driver only chains them: Morris's most influential parameters become the Sobol
stage's (``study.sobol.parameters``), the ``lhs`` stage's table warm-starts the calibration search
(``study.calibration.warm_start_from``), the calibration's best reading joins the ``points`` stage (50 seeds).
Then it writes the report section (:mod:`ddmr_cli.report.sensitivity`) into ``OUT``.
Extra arguments are overrides for every stage (``study=quick``, ``launcher=slurm cluster.partition=...``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Sequence

from ddmr_cli.cli.usage import EXIT_FAILED, INTERRUPTED
from ddmr_cli.study.stages import STAGES

SUMMARY = "study_summary.json"
#: the study dir's own lock: one `ddmr sensitivity` at a time writes a study (its summary, its stages in turn, its
#: report); each stage's sweep also holds its stage dir's lock (``.ddmr.lock``), a file of another name
STUDY_LOCK = ".ddmr-study.lock"


def top_parameters(morris_csv: Path, k: int) -> list[str]:
    """The ``k`` parameters with the largest mu* of any claim, each claim's mu* scaled by its largest."""
    import pandas as pd

    table = pd.read_csv(morris_csv)
    table["scaled"] = table["mu_star"] / table.groupby("claim")["mu_star"].transform("max")
    ranked = table.groupby("parameter", sort=False)["scaled"].max().sort_values(ascending=False, kind="mergesort")
    return [str(p) for p in ranked.index[:k]]


def stage_extra(stage: str, out: Path, overrides: list[str]) -> list[str]:
    """What a stage takes from the earlier ones (none when they did not run)."""
    from ddmr_cli.config import compose_config

    if stage == "sobol" and (out / "morris" / "morris.csv").is_file():
        cfg = compose_config(["+experiment=sensitivity_sobol", *overrides])
        names = top_parameters(out / "morris" / "morris.csv", int(cfg.study.morris.top))
        return [f"study.sobol.parameters=[{','.join(names)}]"]
    lhs = out / "lhs" / "study.csv"
    if stage == "calibration" and lhs.is_file():  # the search starts from the uniform sample's best readings
        from ddmr_cli.cli.args import override_value

        return [f"study.calibration.warm_start_from={override_value(lhs.resolve())}"]
    path = out / "calibration" / "calibration.json"
    if stage == "points" and path.is_file() and json.loads(path.read_text()).get("distance") is not None:
        return ["study.calibrated=true"]
    return []


def main(argv: Sequence[str]) -> int:
    from ddmr_cli.cli.usage import fail

    parser = argparse.ArgumentParser(
        prog="ddmr sensitivity", description="Sensitivity of the paper's claims to its unspecified constants and "
        "the reading nearest its Table 4 (docs/model.md §11): OAT curves, Morris, Sobol, the NN map, the share of the "
        "box (Latin hypercube), the calibration search (Optuna), then the report. Each stage is a "
        "`ddmr run -m +experiment=sensitivity_<stage>` sweep into OUT/<stage>.")
    parser.add_argument("--out", default=None, help="study dir (default: outputs/sensitivity/<time>)")
    parser.add_argument("--stages", default=",".join(STAGES),
                        help=f"comma-separated stages to run, in this order: {','.join(STAGES)}")
    parser.add_argument("--report-only", action="store_true", help="only (re)write the report of OUT")
    parser.add_argument("overrides", nargs="*", help="overrides for every stage (study=quick, launcher=basic, ...)")
    args = parser.parse_args(list(argv))
    stages = [s for s in args.stages.split(",") if s]
    bad = [s for s in stages if s not in STAGES]
    if bad:
        return fail(f"--stages={args.stages}: unknown stage {bad[0]!r}; available: {', '.join(STAGES)}")
    out = Path(args.out or f"outputs/sensitivity/{time.strftime('%Y-%m-%d_%H-%M-%S')}")
    from ddmr_cli.storage.jobdir import DirLock, FaultError

    try:
        with DirLock(out, name=STUDY_LOCK):
            return _study(out, stages, args)
    except FaultError as exc:  # another `ddmr sensitivity` on OUT, OUT cannot be made, or its summary not written
        print(f"ddmr: error: {exc.path}: {exc.reason}", file=sys.stderr)
        return EXIT_FAILED


def _study(out: Path, stages: list[str], args) -> int:
    """The stages and the report of the study in ``out``, holding its lock."""
    from ddmr_cli.cli.run import cmd_run
    from ddmr_cli.storage import io, jobdir

    summary_path = out / SUMMARY
    record = json.loads(summary_path.read_text()) if summary_path.is_file() else {"stages": {}}
    status = 0
    if not args.report_only:
        for stage in stages:
            extra = stage_extra(stage, out, list(args.overrides))
            started = time.perf_counter()
            code = cmd_run(["-m", f"+experiment=sensitivity_{stage}", f"hydra.sweep.dir={out / stage}",
                            *args.overrides, *extra])
            record["stages"][stage] = {"wall_time": time.perf_counter() - started, "exit": code,
                                       "overrides": [*args.overrides, *extra], **_counts(out / stage)}
            try:  # atomically: a study killed or out of disk here keeps its last summary whole
                io.write_text(summary_path, json.dumps(record, indent=2))
            except OSError as exc:  # one error line, exit 1: main's, for every fault of the study dir
                raise jobdir.fault(exc) from None
            if code == INTERRUPTED:  # Ctrl-C stops the study; the same command resumes it
                print(f"ddmr: study interrupted in stage {stage}; run the same command again to resume",
                      file=sys.stderr)
                return INTERRUPTED
            if code:
                print(f"ddmr: stage {stage} failed (exit {code}); later stages still run", file=sys.stderr)
                status = code
    from ddmr_cli import progress
    from ddmr_cli.report.sensitivity import write_report

    with progress.status("ddmr sensitivity: writing the report", enabled=_progress(args.overrides)):
        path = write_report(out)
    total = sum(s["wall_time"] for s in record["stages"].values())
    runs = sum(s.get("runs", 0) for s in record["stages"].values())
    print(f"ddmr sensitivity: {runs} runs, {total:.0f} s wall time; report written to {path}")
    return status


def _progress(overrides: list[str]) -> bool:
    """Whether the study shows its progress: ``run.progress`` as the stages compose it (the study's preset, then
    the command line's overrides; the preset's alone where the overrides do not compose: every stage has then
    refused them with its own error line)."""
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    from ddmr_cli.config import compose_config

    try:
        return bool(compose_config(["+experiment=sensitivity", *overrides]).run.progress)
    except (HydraException, OmegaConfBaseException, ValueError):
        return bool(compose_config(["+experiment=sensitivity"]).run.progress)


def _counts(stage_dir: Path) -> dict:
    """Samples and runs (and of those, the ones reused: :class:`~ddmr_cli.study.task.RunMemo`) of a stage dir (from its
    jobs' summaries)."""
    from ddmr_cli.storage.sweep import read_state

    state = read_state(stage_dir)
    return {"jobs": len(state.complete), "samples": sum(int(s.get("samples", 0)) for _, s in state.complete),
            "runs": sum(int(s.get("statistics", {}).get("runs", 0)) for _, s in state.complete),
            "reused": sum(int(s.get("statistics", {}).get("reused", 0)) for _, s in state.complete),
            "job_time": sum(float(s.get("wall_time", 0.0)) for _, s in state.complete)}


__all__ = ["main", "top_parameters", "stage_extra", "STAGES"]
