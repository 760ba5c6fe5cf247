"""Issue 12, the pieces in-process and fast: job dir names, digests and their verification, staged outputs,
the lock, the umask, kept series, the memory estimate, sweep plans and the state of a sweep dir."""

from __future__ import annotations

import dataclasses
import errno
import os
import socket
import types

import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import budget

from ddmr_cli.storage import io, jobdir, sweep
from ddmr_cli.config import plan as sweep_plan
from ddmr_cli.config.validate import DerivedError, kept_seeds, message
from ddmr_cli.errors import ConfigError


# --- names ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["controller=pid,scenario=paper_1", "controller.switching_gain=4.5", "a+b=-1"])
def test_safe_names_stay_as_they_are(name):
    assert jobdir.safe_name(name) == name


@pytest.mark.parametrize("name", ["scenario.name=a/b", "x=" + "y" * 300, "x='a b'", ".hidden=1", "x=é", "x=a\nb"])
def test_unsafe_names_become_one_bounded_component(name):
    safe = jobdir.safe_name(name)
    assert "/" not in safe and not safe.startswith(".") and len(safe.encode()) <= jobdir.MAX_NAME
    assert all(c.isascii() and (c.isalnum() or c in "._,=+-") for c in safe)
    assert safe != name and safe == jobdir.safe_name(name)  # deterministic


def test_unsafe_names_that_look_alike_stay_apart():
    names = ["scenario.name=a/b", "scenario.name=a_b__x", "scenario.name=a b", "scenario.name=a:b",
             "x=" + "y" * 300, "x=" + "y" * 299 + "z"]
    assert len({jobdir.safe_name(n) for n in names}) == len(names)
    assert jobdir.safe_name("") == "default"


# --- digests and staged outputs ------------------------------------------------------------------------------


def _job(tmp_path):
    out = tmp_path / "job"
    with jobdir.Stage(out) as stage:
        io.write_text(stage.path / io.CONFIG, "a: 1\n")
        io.write_text(stage.path / io.METRICS_CSV, "seed,x\n0,1.0\n1,2.0\n")
        io.write_text(stage.path / io.SEGMENTS_CSV, "seed,segment\n0,total\n")
        io.write_text(stage.path / io.SERIES, "series")
        io.write_text(stage.path / "plots" / "a.png", "png")
        summary = stage.commit({"status": "complete"})
    return out, summary


def test_a_committed_job_records_every_file_and_verifies(tmp_path):
    out, summary = _job(tmp_path)
    assert summary["files"] == ["config.yaml", "metrics.csv", "plots/a.png", "segments.csv", "series.npz"]
    assert summary["digests"]["metrics.csv"]["size"] == len("seed,x\n0,1.0\n1,2.0\n")
    assert io.read_summary(out) == summary and jobdir.verify(out, summary) is None
    assert [p.name for p in tmp_path.iterdir()] == ["job"]  # the staging dir is gone


@pytest.mark.parametrize("change,reason", [
    (lambda out: (out / "metrics.csv").write_text("seed,x\n0,1.0\n"), "metrics.csv has 13 bytes, 19 recorded"),
    (lambda out: (out / "metrics.csv").write_text("seed,x\n0,1.0\n1,2.5\n"), "metrics.csv differs from its"),
    (lambda out: (out / "metrics.csv").unlink(), "metrics.csv is missing"),
    (lambda out: (out / "series.npz").unlink(), "series.npz is missing"),
    (lambda out: (out / "plots" / "a.png").write_bytes(b"\0" * 3), "plots/a.png differs"),
])
def test_any_changed_or_missing_file_fails_verification(tmp_path, change, reason):
    out, summary = _job(tmp_path)
    change(out)
    assert reason in jobdir.verify(out, summary)


def test_reading_results_tolerates_dropped_series_but_not_dropped_tables(tmp_path):
    out, summary = _job(tmp_path)
    (out / "series.npz").unlink()
    assert jobdir.verify(out, summary, strict=False) is None
    (out / "segments.csv").unlink()
    assert jobdir.verify(out, summary, strict=False) == "segments.csv is missing"
    assert jobdir.verify(out, {"status": "complete"}) == "its summary records no file digests"


def test_a_job_that_fails_while_staging_shows_nothing(tmp_path):
    out, _ = _job(tmp_path)
    jobdir.begin(out)
    with pytest.raises(RuntimeError):
        with jobdir.Stage(out) as stage:
            io.write_text(stage.path / io.METRICS_CSV, "half")
            raise RuntimeError("killed")
    assert sorted(p.name for p in out.iterdir()) == [] and [p.name for p in tmp_path.iterdir()] == ["job"]


def _dead_pid() -> int:
    import subprocess

    proc = subprocess.Popen(["true"])
    proc.wait()
    return proc.pid


def test_begin_removes_the_summary_old_outputs_and_stale_temporaries_only(tmp_path):
    out, _ = _job(tmp_path)
    dead = _dead_pid()
    (out / ".hydra").mkdir()
    (out / "ddmr.log").write_text("log")
    (out / f".metrics.csv.{dead}.0123abcd.tmp").write_text("stale")   # an atomic write of a killed job
    (out / ".venv.tmp").mkdir()                                       # a user's dir that looks temporary
    (out / f".notes.{os.getpid()}.0123abcd.tmp").write_text("live")   # a live process's temporary
    stale = tmp_path / f".job.{dead}.tmp"
    io.write_json(stale / jobdir.STAGE_MARK, {"pid": dead, "host": socket.gethostname()})
    unmarked = tmp_path / f".job.{dead + 1}.tmp"  # the name of a staging dir, but not marked: not ours
    other = tmp_path / ".job.x.4242.tmp"  # the staging dir of another job (named job.x): not ours
    unmarked.mkdir()
    other.mkdir()
    jobdir.begin(out)
    assert sorted(p.name for p in out.iterdir()) == sorted([f".notes.{os.getpid()}.0123abcd.tmp", ".hydra",
                                                            ".venv.tmp", "ddmr.log"])
    assert not stale.exists() and other.exists() and unmarked.exists()


def test_atomic_writes_follow_the_umask_and_name_the_path_of_a_fault(tmp_path):
    old = os.umask(0o027)
    try:
        path = io.write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o640

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device")  # as a zip or csv writer raises it: no filename

    with pytest.raises(OSError) as info:
        io.atomic_write(tmp_path / "b.npz", full)
    assert info.value.filename == str(tmp_path / "b.npz") and info.value.errno == errno.ENOSPC
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_a_fault_in_the_staging_dir_is_named_by_the_job_dir(tmp_path):
    out = tmp_path / "job"
    staged = jobdir.Stage(out).path / "plots" / "a.png"
    f = jobdir.fault(OSError(errno.ENOSPC, "No space left on device", str(staged)), out)
    assert (f.path, f.reason) == (str(out / "plots" / "a.png"), "No space left on device")
    assert "in the way" in jobdir.fault(FileExistsError(errno.EEXIST, "File exists", "x")).reason


# --- the lock ------------------------------------------------------------------------------------------------


def test_one_writer_per_dir_and_the_lock_goes_with_its_holder(tmp_path):
    with jobdir.DirLock(tmp_path / "d"):
        holder = jobdir.read_holder(tmp_path / "d")
        assert holder["pid"] == os.getpid() and holder["command"].startswith("ddmr")
        with pytest.raises(jobdir.LockedError) as info:
            with jobdir.DirLock(tmp_path / "d"):
                pass
        assert f"in use by pid {os.getpid()} on {holder['host']}" in str(info.value)
        assert jobdir.read_holder(tmp_path / "d") == holder  # the refused writer left the record alone
        assert jobdir._held(tmp_path / "d") == holder  # the probe sees it held
    assert jobdir._held(tmp_path / "d") is None and (tmp_path / "d" / jobdir.LOCK).is_file()  # released, kept
    with jobdir.DirLock(tmp_path / "d"):  # released: the next writer gets it
        pass


def test_a_running_holder_is_another_live_process_that_recorded_itself(tmp_path):
    """running_holder reads the lock record only: another live process (a child started before the record) is
    running; this process, an ended one, a reused pid (the process started after the record) and no record are
    not; a holder on another host is taken at its word."""
    import json
    import subprocess
    import sys
    import time

    d = tmp_path / "d"
    d.mkdir()
    assert jobdir.running_holder(d) is None  # no record

    def record(pid, started, host=None):
        (d / jobdir.LOCK).write_text(json.dumps({"pid": pid, "host": host or socket.gethostname(), "command": "ddmr",
                                                 "started": time.strftime("%Y-%m-%d %H:%M:%S",
                                                                          time.localtime(started))}))

    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        time.sleep(0.2)
        record(child.pid, time.time() + 1)
        assert jobdir.running_holder(d)["pid"] == child.pid
        assert "pid %d on" % child.pid in jobdir.describe_holder(jobdir.running_holder(d))
        record(child.pid, time.time() - 3600)  # a record older than the process with that pid: a reused pid
        assert jobdir.running_holder(d) is None
        record(os.getpid(), time.time())
        assert jobdir.running_holder(d) is None  # this process (a report written by the sweep itself)
        record(child.pid, time.time() + 1, host="elsewhere.invalid")
        assert jobdir.running_holder(d)["host"] == "elsewhere.invalid"
    finally:
        child.kill()
        child.wait()
    record(child.pid, time.time())
    assert jobdir.running_holder(d) is None  # ended


@pytest.mark.parametrize("make,reason", [
    (lambda p: p.write_text("file"), "a file is in the way"),
    (lambda p: None, "File name too long"),
])
def test_the_lock_names_the_path_of_a_fault(tmp_path, make, reason):
    target = tmp_path / "afile"
    make(target)
    target = target if reason != "File name too long" else tmp_path / ("x" * 300)
    with pytest.raises(jobdir.FaultError) as info:
        with jobdir.DirLock(target):
            pass
    assert reason in info.value.reason and info.value.path == str(target)


def test_ddmr_run_in_process_gives_the_caller_its_argv_back(tmp_path, monkeypatch):
    """Hydra reads sys.argv, so ``ddmr run`` sets it; run in-process (the Python API, a test) it puts the caller's
    back, so a lock taken afterwards names the caller's own command (it named the last in-process run's, and a
    test that looked for a word in a refusal found it in that command)."""
    from ddmr_cli.cli import run

    monkeypatch.setattr("sys.argv", ["caller", "--own"])
    assert run.hydra(["--help"]) == 0
    import sys

    assert sys.argv == ["caller", "--own"]
    with jobdir.DirLock(tmp_path, kind="sweep"):
        assert jobdir.read_holder(tmp_path)["command"] == "ddmr --own"


# --- kept series ---------------------------------------------------------------------------------------------


def _run(keep, base=1000, n=200):
    return OmegaConf.create({"base_seed": base, "n_runs": n, "keep_series": keep})


@pytest.mark.parametrize("keep,seeds", [
    ("first:1", [1000]), ("first:3", [1000, 1001, 1002]), ("first:0", []), ("first:999", list(range(1000, 1200))),
    ("all", list(range(1000, 1200))), ("none", []), ([1199, 1005, 1199], [1199, 1005]), ([], []),
])
def test_kept_series_forms(keep, seeds):
    assert kept_seeds(_run(keep)) == seeds


@pytest.mark.parametrize("keep,key", [([0], "run.keep_series[0]"), ([1200], "run.keep_series[0]"),
                                      ("first:-1", "run.keep_series"), ("last:2", "run.keep_series"),
                                      (3, "run.keep_series"), ([1.5], "run.keep_series[0]")])
def test_kept_series_outside_the_job_are_refused(keep, key):
    with pytest.raises(ConfigError) as info:
        kept_seeds(_run(keep))
    assert info.value.key == key


# --- memory estimate -----------------------------------------------------------------------------------------


def test_the_estimate_adds_its_terms_and_the_state_in_python_integers():
    est = budget.Estimate(n_runs=10, n_steps=1000, n_kept=2, state_bytes=24)
    assert est.total == (budget.BASE_BYTES + 10 * (budget.BYTES_PER_RUN + 48) + 1000 * budget.BYTES_PER_STEP
                         + 2 * 1000 * budget.BYTES_PER_KEPT_STEP)
    fields = [("w", "f8", (2, 100_000_000)), ("phi", "f8", (100_000_000,)), ("s", "f8", (2,)), ("k", "i8")]
    assert budget.state_bytes(fields) == 8 * (300_000_000 + 3)


@pytest.mark.parametrize("est,hint", [
    (budget.Estimate(10_000_000, 15_000, 1, 100), "lower run.n_runs (about "),
    (budget.Estimate(50, 10**12, 1, 100), "raise simulation.dt or lower simulation.duration"),
    (budget.Estimate(50, 10**8, 50, 100), "keep fewer series"),
    (budget.Estimate(50, 15_000, 1, 10**9), "the controller's state takes 1 GB per run"),
])
def test_over_budget_is_one_line_with_what_to_change(est, hint):
    with pytest.raises(ConfigError) as info:
        budget.check(est, 8.0)
    text = str(info.value)
    assert text.startswith("run.max_memory_gb=8.0: the job needs about ") and hint in text and "\n" not in text
    budget.check(budget.Estimate(10, 100, 1, 100), 8.0)  # well within


def test_the_lowered_n_runs_fits():
    est = budget.Estimate(10_000_000, 15_000, 1, 100)
    with pytest.raises(ConfigError) as info:
        budget.check(est, 4.0)
    fit = int(str(info.value).split("about ")[2].split(" fit")[0])
    budget.check(dataclasses.replace(est, n_runs=fit), 4.0)
    with pytest.raises(ConfigError):
        budget.check(dataclasses.replace(est, n_runs=fit + 1000), 4.0)


@pytest.mark.skipif(not os.path.isfile("/proc/meminfo"), reason="compares with Linux's /proc/meminfo")
def test_available_memory_is_memavailable_of_proc_meminfo():
    """psutil (issue 29) reads the number the hand-written parser read: MemAvailable, in kB."""
    def mem_available() -> int:
        line = next(x for x in open("/proc/meminfo", encoding="ascii") if x.startswith("MemAvailable:"))
        return int(line.split()[1]) * 1024

    before, ours, after = mem_available(), budget.available_bytes(), mem_available()
    assert min(before, after) - 64 * 2**20 <= ours <= max(before, after) + 64 * 2**20  # other processes move it


def test_the_default_budget_and_jobs_at_once():
    limit, source = budget.budget_bytes(None)
    assert 0 < limit <= budget.available_bytes() and "of the" in source
    assert budget.budget_bytes(None, 4)[0] == 4 * budget.GB and budget.budget_bytes(2.5, 4)[0] == 2.5 * budget.GB
    cores = os.cpu_count() or 1
    assert budget.at_once("hydra_plugins.hydra_joblib_launcher.JoblibLauncher", -1, 100) == cores
    assert budget.at_once("hydra_plugins.hydra_joblib_launcher.JoblibLauncher", 3, 2) == 2
    assert budget.at_once("hydra._internal.core_plugins.basic_launcher.BasicLauncher", None, 9) == 1
    assert budget.at_once("hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher", None, 9) == 1


# --- messages of derived numbers -----------------------------------------------------------------------------


def test_a_derived_number_is_named_by_the_overrides_of_its_section():
    exc = DerivedError("trajectory", "the reference at t = 7.5 s is not finite")
    assert message(exc, ["controller=pid", "trajectory.speed=1e308"]) == (
        "trajectory.speed=1e308: the reference at t = 7.5 s is not finite")
    assert message(exc, ["controller=pid"]) == "trajectory: the reference at t = 7.5 s is not finite"
    assert message(ConfigError("robot", {"mass": 1e308}, "no J"), ["robot.mass=1e308"]) == "robot.mass=1e308: no J"
    assert message(ConfigError("robot.mass", -1.0, "must be > 0")) == "robot.mass=-1.0: must be > 0"


# --- plans and sweep state -----------------------------------------------------------------------------------


def test_the_plan_names_job_dirs_as_the_jobs_will_and_finds_shared_dirs():
    from ddmr_cli.config import compose_config

    cfg = compose_config([], return_hydra_config=True)
    plan = sweep_plan.plan_jobs(["controller=pid", "scenario.name=a/b,c"], cfg)
    assert [job["dir"] for job in plan] == [jobdir.safe_name("controller=pid,scenario.name=a/b"),
                                            "controller=pid,scenario.name=c"]
    assert sweep_plan.shared_dir(plan) is None
    same = sweep_plan.plan_jobs(["controller=pid,smc", "hydra.sweep.subdir=x"],
                           compose_config(["hydra.sweep.subdir=x"], return_hydra_config=True))
    a, b = sweep_plan.shared_dir(same)
    assert a["dir"] == b["dir"] == "x" and a["overrides"] != b["overrides"]
    numbered = sweep_plan.plan_jobs(["controller=pid,smc,sta", "hydra.sweep.subdir=job${hydra.job.num}"],
                               compose_config(["hydra.sweep.subdir=job${hydra.job.num}"], return_hydra_config=True))
    assert [job["dir"] for job in numbered] == ["job0", "job1", "job2"]  # each job's own number, as Hydra's


def test_a_corrupt_job_is_failed_and_foreign_jobs_are_listed(tmp_path):
    for name in ("a", "b", "old"):
        out = tmp_path / name
        with jobdir.Stage(out) as stage:
            io.write_text(stage.path / io.METRICS_CSV, "seed\n0\n")
            stage.commit({"status": "complete", "overrides": []})
    (tmp_path / "b" / io.METRICS_CSV).write_text("seed\n")
    io.write_json(tmp_path / sweep.PLAN, {"jobs": [{"dir": "a", "overrides": []}, {"dir": "b", "overrides": []}]})
    state = sweep.load_sweep(tmp_path)
    assert [d.name for d, _ in state.complete] == ["a"] and state.unplanned == ["old"]
    (failed, summary), = state.failed
    assert failed.name == "b" and summary["status"] == "corrupt" and "metrics.csv has 5 bytes" in summary["error"]


@pytest.mark.parametrize("module", [jobdir, budget])
def test_new_cli_modules_hold_no_mutable_state(module):
    state = {name: value for name, value in vars(module).items()
             if not name.startswith("__") and not isinstance(value, (types.ModuleType, types.FunctionType, type))
             and (value is None or isinstance(value, (list, dict, set)))}
    assert state == {}


# --- the reaper ----------------------------------------------------------------------------------------------


def test_the_reaper_ends_workers_and_leaves_the_resource_trackers(tmp_path):
    """After a sweep the reaper ends every process marked with the run's DDMR_PARENT, except resource trackers:
    those are the parent's own (a later sweep of the same process, `ddmr sensitivity`, still uses them)."""
    import subprocess
    import sys

    from ddmr_cli.cli import reaper

    env = {**os.environ, "DDMR_PARENT": "test-host:999999999"}
    sleeper = "import time; time.sleep(60)"
    worker = subprocess.Popen([sys.executable, "-c", sleeper], env=env)
    tracker = subprocess.Popen([sys.executable, "-c", f"{sleeper}  # multiprocessing.resource_tracker"], env=env)
    other = subprocess.Popen([sys.executable, "-c", sleeper])  # not this run's
    try:
        ended = reaper.reap(999999999, "test-host", grace=0.5)
        assert ended == [worker.pid]
        assert worker.wait(timeout=5) != 0
        assert tracker.poll() is None and other.poll() is None
    finally:
        for proc in (worker, tracker, other):
            proc.kill()
            proc.wait()


def test_a_writer_refused_before_the_holder_records_itself_names_it_once_it_does(tmp_path):
    """A holder takes the lock, then records itself: a writer refused in between waits (up to
    jobdir.HOLDER_WAIT) for the record and names the holder's pid, not 'another ddmr process'."""
    import json
    import threading

    from filelock import FileLock

    from ddmr_cli.storage import jobdir

    out = tmp_path / "out"
    out.mkdir()
    held = FileLock(out / jobdir.LOCK, timeout=0)
    held.acquire()
    record = {"pid": os.getpid(), "host": socket.gethostname(), "command": "ddmr run", "started": "now"}
    late = threading.Timer(0.3, lambda: (out / jobdir.LOCK).write_text(json.dumps(record) + "\n"))
    late.start()
    try:
        with pytest.raises(jobdir.LockedError) as info:
            with jobdir.DirLock(out):
                pass
    finally:
        late.join()
        held.release()
    assert f"in use by pid {os.getpid()} on {socket.gethostname()}" in str(info.value)
