"""Issue 12 end to end through the console script: verified resume, staged job outputs, foreign jobs left
alone, one writer per dir, faults and Ctrl-C as one line, workers that die with their parent, safe job dir names,
kept series for any base_seed, the report of a sweep over the step, outputs that follow the umask."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from conftest import ddmr_executable, run_ddmr
from faults import fault_env

from ddmr_cli.storage import jobdir

pytestmark = pytest.mark.slow
SMOKE = ["+experiment=smoke", "run.progress=false"]
FOUR = [*SMOKE, "controller=pid,smc,smc_ndo,smc_ndo_nno", "scenario=paper_1", "launcher=basic", "run.plots=false"]


def _tables(sweep_dir: Path) -> dict[str, bytes]:
    return {name: (sweep_dir / name).read_bytes() for name in ("sweep_metrics.csv", "sweep_segments.csv")}


def _log(proc) -> str:
    return proc.stdout + proc.stderr


def _popen(args, cwd, **kw):
    return subprocess.Popen([ddmr_executable(), *args], cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env={**os.environ, "PYTHONHASHSEED": "0"}, **kw)


def test_resume_reruns_exactly_the_jobs_whose_files_changed_and_gives_identical_tables(tmp_path):
    sweep_dir = tmp_path / "sweep"
    args = ["run", "-m", *FOUR, f"hydra.sweep.dir={sweep_dir}"]
    first = run_ddmr(args, cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    before = _tables(sweep_dir)
    jobs = {c: sweep_dir / f"controller={c},scenario=paper_1" for c in ("pid", "smc", "smc_ndo", "smc_ndo_nno")}
    metrics = jobs["pid"] / "metrics.csv"
    metrics.write_bytes(metrics.read_bytes()[: len(metrics.read_bytes()) // 2])       # truncated
    segments = jobs["smc"] / "segments.csv"
    segments.write_bytes(segments.read_bytes().replace(b"0", b"9", 1))                 # same size, other bytes
    (jobs["smc_ndo"] / "series.npz").unlink()                                           # deleted
    second = run_ddmr(args, cwd=tmp_path)
    assert second.returncode == 0, second.stderr[-2000:]
    log = _log(second)
    assert "metrics.csv has" in log and "segments.csv differs from its recorded SHA-256" in log
    assert "series.npz is missing" in log
    assert log.count("rerunning") == 3 and log.count("skipped") == 1, log[-3000:]
    assert _tables(sweep_dir) == before  # byte for byte


def test_a_changed_job_file_is_not_read_as_results(tmp_path):
    """Aggregation (and the report) take a job whose table differs from its digest as corrupt, not as data."""
    sweep_dir = tmp_path / "sweep"
    proc = run_ddmr(["run", "-m", *FOUR[:2], "controller=pid,smc", "scenario=paper_1", "launcher=basic",
                     "run.plots=false", f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    from ddmr_cli.storage import sweep

    metrics = sweep_dir / "controller=pid,scenario=paper_1" / "metrics.csv"
    metrics.write_text(metrics.read_text().splitlines()[0] + "\n")  # header only: 0 of 2 seeds
    state = sweep.read_state(sweep_dir)
    assert [d.name for d, _ in state.complete] == ["controller=smc,scenario=paper_1"]
    assert state.failed[0][1]["status"] == "corrupt" and "metrics.csv has" in state.failed[0][1]["error"]


def test_an_interrupted_rerun_with_another_config_never_leaves_a_mixed_job(tmp_path):
    run_dir = tmp_path / "run"
    small = ["run", *SMOKE, "controller=pid", "run.n_runs=3", f"hydra.run.dir={run_dir}"]
    first = run_ddmr(small, cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    reference = (run_dir / "metrics.csv").read_bytes()
    big = _popen(["run", *SMOKE, "controller=pid", "run.n_runs=20000", f"hydra.run.dir={run_dir}"], cwd=tmp_path)
    deadline = time.time() + 120
    while time.time() < deadline and (run_dir / "summary.json").exists():
        time.sleep(0.02)
    time.sleep(0.5)  # mid-run, its staging dir in place
    os.killpg(big.pid, signal.SIGKILL)
    big.wait()
    assert not (run_dir / "summary.json").exists() and not (run_dir / "metrics.csv").exists()
    again = run_ddmr(small, cwd=tmp_path)
    assert again.returncode == 0 and "skipped" not in _log(again)
    assert (run_dir / "metrics.csv").read_bytes() == reference
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["statistics"]["runs"] == 3 and not list(tmp_path.glob(".run.*.tmp"))


def test_an_earlier_sweep_in_the_dir_is_foreign_and_left_alone(tmp_path):
    sweep_dir = tmp_path / "sweep"
    old = run_ddmr(["run", "-m", *SMOKE, "controller=pid,smc", "scenario=paper_1", "launcher=basic",
                    "run.plots=false", f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert old.returncode == 0
    old_summary = (sweep_dir / "controller=pid,scenario=paper_1" / "summary.json").read_bytes()
    new = run_ddmr(["run", "-m", *SMOKE, "controller=smc_ndo", "scenario=paper_1,paper_2", "launcher=basic",
                    "run.plots=false", f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert new.returncode == 0, new.stderr[-2000:]
    assert "2 complete, 0 failed, 0 missing" in new.stdout and "foreign: 2 job dirs" in new.stdout
    assert (sweep_dir / "controller=pid,scenario=paper_1" / "summary.json").read_bytes() == old_summary
    import ddmr_cli

    assert set(ddmr_cli.load_sweep(sweep_dir).controller) == {"smc_ndo"}
    report = run_ddmr(["report", str(sweep_dir)], cwd=tmp_path)
    assert report.returncode == 0, report.stderr[-2000:]
    assert "smc_ndo" in (sweep_dir / "report" / "tables" / "table4.csv").read_text()
    assert ",pid," not in (sweep_dir / "report" / "tables" / "table4.csv").read_text()


def test_two_sweeps_started_at_once_into_one_dir(tmp_path):
    sweep_dir = tmp_path / "sweep"
    a = _popen(["run", "-m", *SMOKE, "controller=pid,smc", "scenario=paper_1", "launcher=basic",
                f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    b = _popen(["run", "-m", *SMOKE, "controller=smc_ndo", "scenario=paper_1,paper_2", "launcher=basic",
                f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    results = {p.pid: (p.wait(timeout=300), *p.communicate()) for p in (a, b)}
    codes = sorted(code for code, _, _ in results.values())
    assert codes == [0, 1], results
    winner = next(pid for pid, (code, _, _) in results.items() if code == 0)
    loser_err = next(err for code, _, err in results.values() if code == 1)
    assert loser_err.strip().splitlines() == [loser_err.strip()]  # one line
    assert f"in use by pid {winner} on " in loser_err and "ddmr run -m +experiment=smoke" in loser_err
    plan = json.loads((sweep_dir / "sweep_plan.json").read_text())["jobs"]
    expected = ({"controller=pid,scenario=paper_1", "controller=smc,scenario=paper_1"} if winner == a.pid else
                {"controller=smc_ndo,scenario=paper_1", "controller=smc_ndo,scenario=paper_2"})
    assert {job["dir"] for job in plan} == expected
    assert {p.name for p in sweep_dir.iterdir() if p.is_dir()} == expected


def test_ctrl_c_is_one_line_exit_130_and_the_rerun_resumes(tmp_path, smoke_sweep_dir):
    sweep_dir = tmp_path / "sweep"
    args = ["run", "-m", "+experiment=smoke", f"hydra.sweep.dir={sweep_dir}"]
    # SIGINT's default action, as a terminal's foreground job has it: a test run started in the background by a
    # non-interactive shell (`cmd &`) has SIGINT ignored, and so would the ddmr it starts (POSIX shells do that)
    proc = _popen(args, cwd=tmp_path, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.time() + 120
    while time.time() < deadline and len(list(sweep_dir.glob("*/summary.json"))) < 2:
        time.sleep(0.05)
    assert proc.poll() is None, "the sweep ended before the Ctrl-C"
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal sends on Ctrl-C
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert err.strip().splitlines()[-1] == "ddmr: interrupted; run the same command again to resume"
    assert "Traceback" not in err + out
    resumed = run_ddmr(args, cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert _tables(sweep_dir) == _tables(smoke_sweep_dir)


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc")
def test_workers_stop_when_the_parent_is_killed(tmp_path):
    proc = _popen(["run", "-m", "+experiment=smoke", "run.n_runs=20", "launcher=local", f"hydra.sweep.dir={tmp_path / 's'}"],
                  cwd=tmp_path)
    deadline = time.time() + 120
    workers: list[int] = []
    while time.time() < deadline and not workers:
        workers = [p for p in _children(proc.pid) if b"popen_loky" in Path(f"/proc/{p}/cmdline").read_bytes()]
        time.sleep(0.1)
    assert workers
    time.sleep(1.0)  # the workers are running jobs
    os.kill(proc.pid, signal.SIGKILL)  # the parent only, not its process group
    proc.wait()
    deadline = time.time() + 15
    while time.time() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.2)
    left = [p for p in workers if _alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert left == []


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS])
def test_a_fault_while_writing_results_is_one_line_and_leaves_no_partial_results(tmp_path, code):
    run_dir = tmp_path / "run"
    env = fault_env(tmp_path / "site", code, "/.run.")  # the run's staging dir: its results cannot be written
    proc = run_ddmr(["run", *SMOKE, "controller=pid", f"hydra.run.dir={run_dir}"], cwd=tmp_path, env=env)
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"ddmr: error: {run_dir}/") and last.endswith(os.strerror(code)), last
    assert "Traceback" not in proc.stderr
    assert not (run_dir / "metrics.csv").exists() and not list(tmp_path.glob(".run.*.tmp"))
    assert json.loads((run_dir / "summary.json").read_text())["status"] == "failed"
    sweep_dir = tmp_path / "sweep"
    proc = run_ddmr(["run", "-m", *SMOKE, "controller=pid,smc", "scenario=paper_1", "launcher=basic",
                     f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path,
                    env=fault_env(tmp_path / "site", code, f"{sweep_dir}/.controller="))
    assert proc.returncode == 1
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"ddmr: error: {sweep_dir}/controller=") and "(2 jobs failed on file-system faults)" in last
    assert not (sweep_dir / "sweep_metrics.csv").exists() and not list(sweep_dir.glob("*/metrics.csv"))


def test_job_dir_names_are_safe_bounded_and_unique(tmp_path):
    long = "q" * 300
    sweep_dir = tmp_path / "sweep"
    proc = run_ddmr(["run", "-m", *SMOKE, "controller=pid", "scenario=paper_1", "launcher=basic", "run.n_runs=1",
                     "simulation.duration=0.5", f"scenario.name=a/b,{long},plain", f"hydra.sweep.dir={sweep_dir}"],
                    cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    dirs = sorted(p.name for p in sweep_dir.iterdir() if p.is_dir())
    assert len(dirs) == 3 and all(len(d.encode()) <= jobdir.MAX_NAME for d in dirs)
    assert sum("scenario.name=plain," in d for d in dirs) == 1  # a safe name is kept as it is
    assert not any(p.name.endswith("scenario.name=a") for p in sweep_dir.iterdir())  # no dir nested by the "/"
    overrides = [json.loads((sweep_dir / d / "summary.json").read_text())["overrides"] for d in dirs]
    assert ["scenario.name=a/b" in o for o in overrides].count(True) == 1
    assert [f"scenario.name={long}" in o for o in overrides].count(True) == 1
    assert "3 complete, 0 failed, 0 missing" in proc.stdout


@pytest.mark.parametrize("keep,seeds", [(None, [1000]), ("first:3", [1000, 1001, 1002]), ("[1199]", [1199])])
def test_kept_series_for_any_base_seed(tmp_path, keep, seeds):
    """The README recipe ``run.base_seed=1000 run.n_runs=200`` saves series and plots (shorter runs here)."""
    from ddmr_cli.storage.io import read_series

    run_dir = tmp_path / "run"
    args = ["run", "run.base_seed=1000", "run.n_runs=200", "simulation.duration=0.5", f"hydra.run.dir={run_dir}"]
    proc = run_ddmr(args + ([f"run.keep_series={keep}"] if keep else []), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert sorted(read_series(run_dir / "series.npz")) == seeds
    assert sorted(p.name for p in (run_dir / "plots").iterdir()) == ["control.png", "errors.png", "trajectory.png"]


def test_report_of_a_sweep_over_the_step_and_the_duration(tmp_path):
    sweep_dir = tmp_path / "sweep"
    proc = run_ddmr(["run", "-m", *SMOKE, "controller=pid,smc_ndo_nno", "scenario=paper_1", "launcher=basic",
                     "run.plots=false", "simulation.dt=0.002,0.004", "simulation.duration=2,3",
                     f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = run_ddmr(["report", str(sweep_dir)], cwd=tmp_path)
    assert report.returncode == 0, report.stderr[-3000:]
    assert (sweep_dir / "report" / "report.md").stat().st_size > 1000


def test_outputs_follow_the_umask(tmp_path):
    run_dir = tmp_path / "run"
    proc = subprocess.run([ddmr_executable(), "run", *SMOKE, "controller=pid", "run.plots=true", f"hydra.run.dir={run_dir}"],
                          cwd=tmp_path, capture_output=True, text=True, preexec_fn=lambda: os.umask(0o027))
    assert proc.returncode == 0, proc.stderr[-2000:]
    modes = {p.name: p.stat().st_mode & 0o777 for p in [*run_dir.iterdir(), *(run_dir / "plots").iterdir()]}
    assert modes["plots"] == 0o750 and modes["metrics.csv"] == 0o640 and modes["summary.json"] == 0o640
    assert all(m in (0o640, 0o750) for m in modes.values()), modes


def test_a_config_path_run_is_validated_and_runs(tmp_path):
    from integrity_cases import CASES, prepare

    case = next(c for c in CASES if c.setup == "conf")
    prepare(case, tmp_path)
    run_dir = tmp_path / "run"
    proc = run_ddmr(["run", "-cp", "myconf", "run.n_runs=2", "simulation.duration=0.5", "controller=pid",
                     f"hydra.run.dir={run_dir}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads((run_dir / "summary.json").read_text())["statistics"]["runs"] == 2
