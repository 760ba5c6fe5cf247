"""``ddmr report``: the markdown report, tables and figures of a sweep, a run or a tuning study (also written
when a run or sweep ends with ``report=true``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ddmr_cli.cli.usage import EXIT_FAILED, EXIT_USAGE, fail


def write_report(path: Path, out: str | None, margin: float | None, failure: int = EXIT_USAGE,
                 figures: bool = True, progress: bool = True, all_figures: bool = False) -> int:
    """Write the report of ``path`` into ``out`` (default ``path/report``); the exit status (``failure`` when
    there is nothing to report)."""
    from ddmr_cli.errors import DDMRError
    from ddmr_cli.storage import jobdir
    from ddmr_cli.report import build_report
    from ddmr_cli.report.build import staged

    running = jobdir.running_holder(Path(path).expanduser())
    if running is not None:  # the report covers the jobs complete so far (it says so too)
        print(f"ddmr: warning: {path} is still being written by {jobdir.describe_holder(running)}; the report "
              f"covers the jobs complete so far", file=sys.stderr)
    try:
        from ddmr_cli.report import tuning

        if tuning.is_tuning_dir(path):  # studies: held-out runs at paper and tuned gains, then their report
            final = Path(out).expanduser().resolve() if out is not None else Path(path).expanduser().resolve() / "report"
            written = staged(final, lambda root: tuning.build(path, root, margin))
        else:
            written = build_report(path, out, figures=figures, progress=progress, all_figures=all_figures,
                                   on_verdicts=_say_verdicts, **({"margin": margin} if margin is not None else {}))
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


#: the line ``ddmr report`` prints its verdicts under (``ddmr bench`` times when it appears)
VERDICTS_HEADER = "ddmr: verdicts on the paper's claims (rules, numbers and figures in the report):"


def _say_verdicts(lines: list[str]) -> None:
    """The verdicts on stdout as soon as the report knows them (the figures are drawn after): the answer first."""
    from ddmr_cli.progress import say

    say([VERDICTS_HEADER, *(f"  {line}" for line in lines)])


def _latest_sweep(root: Path) -> Path | None:
    """The sweep dir under ``root`` whose plan (or multirun.yaml) was written last."""
    marks = [*root.glob("**/sweep_plan.json"), *root.glob("**/multirun.yaml")]
    return max(marks, key=lambda p: p.stat().st_mtime).parent if marks else None


class Parser(argparse.ArgumentParser):
    """argparse with the one-line refusal of every ddmr command: ``ddmr: error: --flag: what``, exit 2."""

    def error(self, message: str):
        message = message.removeprefix("argument ")
        self.exit(EXIT_USAGE, f"ddmr: error: {message}\n")


def cmd_report(argv: list[str]) -> int:
    parser = Parser(prog="ddmr report", description="Markdown report, tables (CSV) and figures "
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
    parser.add_argument("--all-figures", action="store_true",
                        help="every figure of every scenario; by default a scenario on a reference other than the "
                             "paper's line (paper_1@circle, ...) gets its summary figures only (trajectory, "
                             "deviation, spread)")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bar (by default a bar with an ETA on a terminal, a line every 10 s in a log)")
    args = parser.parse_args(argv)
    from ddmr_cli.report.stats import Margin

    try:
        Margin.parse(args.margin)
    except ValueError as exc:
        return fail(f"--margin={args.margin}: {exc}")
    path = args.path
    if path is None:
        latest = _latest_sweep(Path("outputs"))
        if latest is None:
            return fail(f"path=(none): no sweep under {Path('outputs').resolve()}; give PATH or run ddmr run -m first")
        print(f"ddmr: reporting the latest sweep under ./outputs: {latest}", file=sys.stderr)
        path = latest
    return write_report(Path(path), args.out, args.margin, figures=not args.no_figures,
                        progress=not args.no_progress, all_figures=args.all_figures)


__all__ = ["write_report", "cmd_report", "Parser"]
