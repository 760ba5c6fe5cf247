"""Issue 26's catalogue: bad inputs and faults against the promise "nothing of the user's lost, nothing mixed",
by class (1 deletes, 2 escapes, 3 tree lock, 4 report staging and lock, 5 resume verification, 6 tracebacks and
silent exits, 7 accepted nonsense, 8 messages). Each case is a function of a scratch dir that runs the installed
``ddmr`` and asserts what the issue asks; ``tests/test_integrity_catalogue.py`` runs them (the first case of each
class in the fast tier) and ``benchmarks/integrity_catalogue.py`` counts them by class, also against older code.

A case is registered with :func:`case` (its class and whether it is bad ``input`` (exit 2) or a ``fault`` (exit
1)); helpers assert one line ``ddmr: error: <key or path>: <what>``, the exit status, and that the tree the case
set up is unchanged.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
from pathlib import Path
from typing import Callable, NamedTuple

from conftest import run_ddmr

TINY = ["controller=pid", "run.n_runs=1", "simulation.duration=0.3", "run.progress=false", "run.plots=false"]
SWEEP = ["-m", "controller=pid,smc", "scenario=paper_1", "launcher=basic", *TINY[1:]]
JOB = "controller=pid,run.n_runs=1,scenario=paper_1,simulation.duration=0.3"  # the dir Hydra names
CLASSES = {1: "deletes", 2: "escapes", 3: "tree lock", 4: "report staging and lock", 5: "resume verification",
           6: "tracebacks and silent exits", 7: "accepted nonsense", 8: "messages"}


class Case(NamedTuple):
    cls: int
    kind: str   # "input" (exit 2) or "fault" (exit 1)
    name: str
    run: Callable[[Path], None]


CASES: list[Case] = []


def case(cls: int, kind: str):
    def register(fn):
        CASES.append(Case(cls, kind, fn.__name__.removeprefix("c_").replace("_", " "), fn))
        return fn
    return register


# --- helpers -------------------------------------------------------------------------------------------------


def ddmr(tmp: Path, *args: str, timeout: float = 300):
    return run_ddmr(list(args), cwd=tmp, timeout=timeout)


def ok(proc) -> None:
    assert proc.returncode == 0, proc.stderr[-3000:]


def refused(proc, code: int, *parts: str, only: bool = True) -> str:
    """The run ended with exit ``code`` and one ``ddmr: error:`` line holding ``parts``, no traceback (``only``:
    and nothing else on stderr). Returns the line."""
    err = proc.stderr.strip()
    errors = [line for line in err.splitlines() if line.startswith("ddmr: error: ")]
    assert proc.returncode == code, f"exit {proc.returncode}, wanted {code}: {err[-2000:]}"
    assert "Traceback" not in err + proc.stdout, err[-3000:]
    assert len(errors) == 1, err[-2000:]
    if only:
        assert err.splitlines() == errors, err[-2000:]
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def refused_unchanged(tmp: Path, args: list[str], code: int, *parts: str) -> None:
    """``ddmr ARGS`` is refused (:func:`refused`) and every file under ``tmp`` is as it was."""
    before = tree(tmp)
    refused(ddmr(tmp, *args), code, *parts)
    assert tree(tmp) == before


def tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` (dirs as None, symlinks as their target), to compare before and after."""
    out: dict[str, bytes | None] = {}
    for p in sorted(Path(root).rglob("*")):
        rel = p.relative_to(root).as_posix()
        out[rel] = (b"->" + os.readlink(p).encode()) if p.is_symlink() else (None if p.is_dir() else p.read_bytes())
    return out


def dead_pid() -> int:
    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def user_dir(root: Path) -> Path:
    """A user's dir: a config, a holiday photo, a dir that looks temporary."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "config.yaml").write_text("mine: true\n")
    (root / "plots").mkdir()
    (root / "plots" / "holiday.png").write_bytes(b"\x89PNG holiday")
    (root / ".venv.tmp").mkdir()
    (root / ".venv.tmp" / "keep").write_text("x")
    return root


def sweep(tmp: Path, name: str = "s", *extra: str) -> Path:
    ok(ddmr(tmp, "run", *SWEEP, *extra, f"hydra.sweep.dir={tmp / name}"))
    return tmp / name


def single(tmp: Path, name: str = "r", *extra: str) -> Path:
    ok(ddmr(tmp, "run", *TINY, *extra, f"hydra.run.dir={tmp / name}"))
    return tmp / name


# --- 1. a run deletes only what it provably wrote ------------------------------------------------------------


@case(1, "fault")
def c_run_into_a_users_dir_deletes_nothing(tmp):
    mine = user_dir(tmp / "mydir")
    before = tree(mine)
    refused(ddmr(mine, "run", *TINY, "hydra.run.dir=."), 1, "config.yaml: in the way")
    assert tree(mine) == before


@case(1, "fault")
def c_a_users_metrics_csv_in_the_run_dir(tmp):
    (tmp / "r").mkdir()
    (tmp / "r" / "metrics.csv").write_text("my,data\n1,2\n")
    refused_unchanged(tmp, ["run", *TINY, f"hydra.run.dir={tmp / 'r'}"], 1, "metrics.csv: in the way")


@case(1, "fault")
def c_a_users_summary_json_in_the_run_dir(tmp):
    (tmp / "r").mkdir()
    (tmp / "r" / "summary.json").write_text('{"my": "notes"}\n')
    refused_unchanged(tmp, ["run", *TINY, f"hydra.run.dir={tmp / 'r'}"], 1, "summary.json: in the way")


@case(1, "fault")
def c_a_file_added_to_a_runs_plots_survives_a_rerun(tmp):
    run = single(tmp, "r", "run.plots=true")
    (run / "plots" / "mine.png").write_bytes(b"mine")
    before = tree(run)
    refused(ddmr(tmp, "run", *TINY, "run.plots=true", "run.n_runs=2", f"hydra.run.dir={run}"), 1,
            "plots/mine.png: in the way")
    assert tree(run) == before


@case(1, "fault")
def c_a_job_dir_linked_to_a_users_dir_loses_nothing_on_resume(tmp):
    s = sweep(tmp)
    mine = user_dir(tmp / "mine")
    (mine / "plots" / "mine.png").write_bytes(b"mine")
    before = tree(mine)
    job = s / JOB
    import shutil

    shutil.rmtree(job)
    job.symlink_to(mine, target_is_directory=True)
    refused(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}"), 1, JOB)
    assert tree(mine) == before


@case(1, "fault")
def c_a_users_dir_named_like_a_staging_dir_is_left_alone(tmp):
    run = single(tmp, "r")
    theirs = tmp / f".r.{dead_pid()}.tmp"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    ok(ddmr(tmp, "run", *TINY, "run.n_runs=2", f"hydra.run.dir={run}"))  # reruns: the old outputs go
    assert (theirs / "notes.txt").read_text() == "mine"


@case(1, "fault")
def c_a_users_sweep_table_in_the_sweep_dir(tmp):
    (tmp / "s").mkdir()
    (tmp / "s" / "sweep_jobs.csv").write_text("my,table\n")
    refused_unchanged(tmp, ["run", *SWEEP, f"hydra.sweep.dir={tmp / 's'}"], 1, "sweep_jobs.csv: in the way")


@case(1, "fault")
def c_an_output_edited_since_is_kept_when_the_job_reruns(tmp):
    run = single(tmp, "r")
    edited = (run / "metrics.csv").read_text() + "# my note\n"
    (run / "metrics.csv").write_text(edited)
    ok(ddmr(tmp, "run", *TINY, f"hydra.run.dir={run}"))  # the job reruns (a file differs from its digest)
    assert (run / "metrics.csv.changed").read_text() == edited
    assert json.loads((run / "summary.json").read_text())["status"] == "complete"


# --- 2. every write stays inside its own dir -----------------------------------------------------------------


@case(2, "input")
def c_a_sweep_subdir_above_the_sweep_dir(tmp):
    refused(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={tmp / 's'}", "hydra.sweep.subdir=../escaped_job"), 2,
            "hydra.sweep.subdir=../escaped_job", "not a dir inside the sweep dir")
    assert list(tmp.iterdir()) == []


@case(2, "input")
def c_an_absolute_sweep_subdir(tmp):
    refused(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={tmp / 's'}", f"hydra.sweep.subdir={tmp / 'abs'}"), 2,
            "hydra.sweep.subdir=")
    assert list(tmp.iterdir()) == []


@case(2, "input")
def c_a_sweep_subdir_that_is_the_sweep_dir(tmp):
    refused(ddmr(tmp, "run", "-m", *TINY, f"hydra.sweep.dir={tmp / 's'}", "hydra.sweep.subdir=."), 2,
            "hydra.sweep.subdir=.")
    assert list(tmp.iterdir()) == []


@case(2, "input")
def c_a_scenario_name_with_dots_keeps_the_reports_figures_in_out(tmp):
    run = single(tmp, "r", "scenario.name=../../escape/y")
    ok(ddmr(tmp, "report", str(run), "--out", str(tmp / "deep" / "er" / "rep")))
    outside = [p for p in tmp.rglob("*.png") if not p.is_relative_to(tmp / "deep" / "er" / "rep")]
    assert outside == [] and not (tmp / "deep" / "escape").exists()
    assert list((tmp / "deep" / "er" / "rep" / "figures").glob("*.png"))


@case(2, "fault")
def c_a_job_dir_linked_outside_the_sweep_dir(tmp):
    s = sweep(tmp)
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    import shutil

    shutil.rmtree(s / JOB)
    (s / JOB).symlink_to(elsewhere, target_is_directory=True)
    refused(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}"), 1, "outside the sweep dir")
    assert list(elsewhere.iterdir()) == []


# --- 3. one writer per tree ----------------------------------------------------------------------------------


@case(3, "fault")
def c_a_run_into_a_running_sweeps_job_dir(tmp):
    from ddmr_cli.storage import jobdir

    with jobdir.DirLock(tmp / "s"):  # a sweep running in this dir
        (tmp / "s" / JOB).mkdir()
        refused(ddmr(tmp, "run", *TINY, f"hydra.run.dir='{tmp / 's' / JOB}'"), 1, "inside", "in use by pid")
        assert list((tmp / "s" / JOB).iterdir()) == []


@case(3, "fault")
def c_a_run_into_a_finished_sweep_dir(tmp):
    s = sweep(tmp)
    before = tree(s)
    refused(ddmr(tmp, "run", *TINY, f"hydra.run.dir={s}"), 1, "holds a sweep")
    assert tree(s) == before
    again = ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}")  # the same plan resuming is admitted
    ok(again)
    assert (again.stdout + again.stderr).count("skipped") == 2


@case(3, "fault")
def c_a_run_into_a_finished_sweeps_job_dir(tmp):
    s = sweep(tmp)
    before = tree(s)
    refused(ddmr(tmp, "run", *TINY, f"hydra.run.dir='{s / JOB}'"), 1, "inside")
    assert tree(s) == before


@case(3, "fault")
def c_a_sweep_into_a_dir_that_contains_a_run(tmp):
    single(tmp, "p/r")
    refused_unchanged(tmp, ["run", *SWEEP, f"hydra.sweep.dir={tmp / 'p'}"], 1, "contains")


@case(3, "fault")
def c_a_sweep_into_a_single_runs_dir(tmp):
    run = single(tmp, "r")
    refused_unchanged(tmp, ["run", *SWEEP, f"hydra.sweep.dir={run}"], 1, "holds a single run")


@case(3, "fault")
def c_a_run_inside_another_runs_dir(tmp):
    run = single(tmp, "r")
    refused_unchanged(tmp, ["run", *TINY, f"hydra.run.dir={run / 'sub'}"], 1, "inside")


# --- 4. a report is staged, moved in whole, under a lock -----------------------------------------------------


@case(4, "fault")
def c_a_report_into_an_out_another_report_writes(tmp):
    from ddmr_cli.storage import jobdir
    from ddmr_cli.report.build import REPORT_LOCK

    run = single(tmp, "r")
    with jobdir.DirLock(tmp / "rep", name=REPORT_LOCK):
        refused(ddmr(tmp, "report", str(run), "--out", str(tmp / "rep"), "--no-figures"), 1, "in use by pid")
        assert sorted(p.name for p in (tmp / "rep").iterdir()) == [REPORT_LOCK]


@case(4, "fault")
def c_a_reused_out_keeps_no_figure_of_the_earlier_report(tmp):
    run = single(tmp, "r")
    ok(ddmr(tmp, "report", str(run), "--out", str(tmp / "rep")))
    assert list((tmp / "rep" / "figures").glob("*.png"))
    ok(ddmr(tmp, "report", str(run), "--out", str(tmp / "rep"), "--no-figures"))
    assert not list((tmp / "rep").rglob("*.png")) and (tmp / "rep" / "report.md").is_file()


@case(4, "fault")
def c_a_users_report_md_in_out(tmp):
    run = single(tmp, "r")
    (tmp / "rep").mkdir()
    (tmp / "rep" / "report.md").write_text("my report\n")
    refused(ddmr(tmp, "report", str(run), "--out", str(tmp / "rep"), "--no-figures"), 1, "report.md: in the way")
    assert sorted(p.name for p in (tmp / "rep").iterdir() if p.name != ".ddmr-report.lock") == ["report.md"]
    assert (tmp / "rep" / "report.md").read_text() == "my report\n"


@case(4, "fault")
def c_two_reports_at_once_into_one_out(tmp):
    from conftest import ddmr_executable

    run = single(tmp, "r")
    procs = [subprocess.Popen([ddmr_executable(), "report", str(run), "--out", str(tmp / "rep")], cwd=tmp,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    assert sorted(code for code, _, _ in results) == [0, 1], results
    loser = next(err for code, _, err in results if code == 1)
    # the lock's holder names its pid once it has recorded itself; in the moment before, the loser says so
    assert loser.strip().startswith("ddmr: error: ") and ("in use by pid" in loser or
                                                          "in use by another ddmr process" in loser), loser
    manifest = json.loads((tmp / "rep" / ".ddmr-report.json").read_text())["digests"]
    from ddmr_cli.storage.jobdir import digest

    assert all(digest(tmp / "rep" / name) == want for name, want in manifest.items())  # one report's files


# --- 5. resume verifies, cleans what is provably its own, and counts output options ---------------------------


@case(5, "fault")
def c_an_edited_summary_is_not_carried_into_the_tables(tmp):
    s = sweep(tmp)
    path = s / JOB / "summary.json"
    summary = json.loads(path.read_text())
    summary["statistics"]["deviation_mae_mean"] = 999.0
    path.write_text(json.dumps(summary))
    proc = ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}")
    ok(proc)
    import csv

    with open(s / "sweep_jobs.csv", newline="") as fh:
        means = {row["job"]: float(row["deviation_mae_mean"]) for row in csv.DictReader(fh)}
    assert 0 < means[JOB] < 1, means
    assert "seal" in proc.stdout + proc.stderr


@case(5, "fault")
def c_a_stale_staging_dir_of_a_skipped_job_goes(tmp):
    s = sweep(tmp)
    pid = dead_pid()
    stale = s / f".{JOB}.{pid}.tmp"
    stale.mkdir()
    (stale / "metrics.csv").write_text("half")
    (stale / ".ddmr-stage").write_text(json.dumps({"pid": pid, "host": socket.gethostname()}))
    ok(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}"))
    assert not stale.exists()


@case(5, "fault")
def c_a_stale_temporary_in_a_skipped_job_goes(tmp):
    s = sweep(tmp)
    stale = s / JOB / f".metrics.csv.{dead_pid()}.0123abcd.tmp"
    stale.write_text("half")
    ok(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}"))
    assert not stale.exists()


@case(5, "fault")
def c_a_job_dir_replaced_by_a_file(tmp):
    s = sweep(tmp)
    import shutil

    shutil.rmtree(s / JOB)
    (s / JOB).write_text("a file\n")
    refused(ddmr(tmp, "run", *SWEEP, f"hydra.sweep.dir={s}"), 1, JOB, "a file is in the way")
    assert (s / JOB).read_text() == "a file\n"


@case(5, "fault")
def c_resuming_with_plots_writes_the_plots(tmp):
    run = single(tmp, "r")
    assert not (run / "plots").exists()
    ok(ddmr(tmp, "run", *TINY, "run.plots=true", f"hydra.run.dir={run}"))
    assert sorted(p.name for p in (run / "plots").iterdir()) == ["control.png", "errors.png", "trajectory.png"]


# --- 6. one line and the right exit status, never a traceback or a silent exit ---------------------------------


@case(6, "fault")
def c_report_out_is_a_file(tmp):
    run = single(tmp, "r")
    (tmp / "afile").write_text("x")
    refused(ddmr(tmp, "report", str(run), "--out", str(tmp / "afile"), "--no-figures"), 1, "afile")
    assert (tmp / "afile").read_text() == "x"


@case(6, "fault")
def c_report_out_under_a_file(tmp):
    run = single(tmp, "r")
    (tmp / "afile").write_text("x")
    refused(ddmr(tmp, "report", str(run), "--out", str(tmp / "afile" / "rep"), "--no-figures"), 1, "afile")


@case(6, "input")
def c_a_huge_sweep_range(tmp):
    refused(ddmr(tmp, "run", "-m", *TINY, "run.base_seed=range(0,10000000000)", f"hydra.sweep.dir={tmp / 's'}",
                 timeout=60), 2, "run.base_seed=range(0,10000000000)")
    assert list(tmp.iterdir()) == []


@case(6, "input")
def c_a_huge_kept_series_list(tmp):
    refused(ddmr(tmp, "run", *TINY, "run.n_runs=100000000000", "run.keep_series=all", f"hydra.run.dir={tmp / 'r'}",
                 timeout=60), 2, "run.")
    assert list(tmp.iterdir()) == []


TUNE = ["-m", "+tune=smc", "simulation.duration=0.1", "metrics.settle_time=0.05", "tuning.n_trials=2"]


@case(6, "input")
def c_a_tuning_budget_of_zero_trials(tmp):
    refused(ddmr(tmp, "run", *TUNE, "tuning.n_trials=0", f"hydra.sweep.dir={tmp / 't'}", timeout=60), 2,
            "tuning.n_trials=0")
    assert list(tmp.iterdir()) == []


@case(6, "input")
def c_an_inverted_search_range(tmp):
    refused(ddmr(tmp, "run", *TUNE, "controller.lam=interval(5,1)", f"hydra.sweep.dir={tmp / 't'}", timeout=60), 2,
            "controller.lam", "inverted")
    assert list(tmp.iterdir()) == []


@case(6, "input")
def c_a_log_range_from_zero(tmp):
    refused(ddmr(tmp, "run", *TUNE, "controller.lam=tag(log,interval(0,10))", f"hydra.sweep.dir={tmp / 't'}",
                 timeout=60), 2, "controller.lam", "low > 0")
    assert list(tmp.iterdir()) == []


@case(6, "input")
def c_an_unknown_sampler(tmp):
    refused(ddmr(tmp, "run", *TUNE, "hydra.sweeper.sampler._target_=optuna.samplers.FooSampler",
                 f"hydra.sweep.dir={tmp / 't'}", timeout=60), 2, "hydra.sweeper.sampler._target_", "FooSampler")
    assert list(tmp.iterdir()) == []


@case(6, "fault")
def c_a_corrupt_study_storage(tmp):
    study = tmp / "t"
    study.mkdir()
    (study / "study.db").write_bytes(bytes(range(256)) * 12)
    before = tree(tmp)
    refused(ddmr(tmp, "run", *TUNE, f"hydra.sweep.dir={study}", timeout=60), 1, "study.db", "not a readable")
    assert tree(tmp) == before


@case(6, "input")
def c_a_robot_value_that_overflows(tmp):
    refused(ddmr(tmp, "run", *TINY, "robot.mass=1e308", "robot.wheel_radius=1e308", f"hydra.run.dir={tmp / 'r'}",
                 timeout=60), 2, "robot")
    assert list(tmp.iterdir()) == []


# --- 8. messages name what the user typed ---------------------------------------------------------------------


@case(8, "input")
def c_a_text_where_a_number_goes(tmp):
    refused(ddmr(tmp, "run", "+experiment=smoke", "run.n_runs=abc", f"hydra.run.dir={tmp / 'r'}"), 2,
            "run.n_runs=abc")
    assert list(tmp.iterdir()) == []


@case(8, "input")
def c_margin_without_a_value(tmp):
    refused(ddmr(tmp, "report", str(tmp), "--margin"), 2, "--margin")


@case(8, "fault")
def c_an_output_dir_under_proc(tmp):
    refused(ddmr(tmp, "run", *TINY, "hydra.run.dir=/proc/ddmr-test/run"), 1, "/proc/ddmr-test")


@case(8, "fault")
def c_a_report_out_under_proc(tmp):
    run = single(tmp, "r")
    refused(ddmr(tmp, "report", str(run), "--out", "/proc/ddmr-test", "--no-figures"), 1, "/proc/ddmr-test")
