"""The installed ``ddmr`` console script end to end: single run, sweeps through joblib, submitit_local and the
basic launcher (bit-identical numbers), failing jobs, resume, bad input."""

from __future__ import annotations

import json
import math
import shutil
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import ddmr_executable, run_ddmr

from ddmr_cli.storage.io import read_series

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: every controller preset (conf/controller/*.yaml): the smoke sweep sweeps them all, on both scenarios
CONTROLLER_PRESETS = sorted(p.stem for p in (Path(__file__).resolve().parents[1] / "conf" / "controller").glob("*.yaml"))
SMOKE_JOBS = 2 * len(CONTROLLER_PRESETS)
#: presets with no feedback, whose runs may diverge
OPEN_LOOP = {"open_loop"}
pytestmark = pytest.mark.slow


def _metrics(sweep_dir: Path) -> pd.DataFrame:
    frame = pd.read_csv(sweep_dir / "sweep_metrics.csv")
    return frame.sort_values(["controller", "scenario", "seed"]).reset_index(drop=True)


def test_help_lists_commands_and_config_groups(tmp_path):
    top = run_ddmr(["--help"], cwd=tmp_path)
    assert top.returncode == 0 and "run" in top.stdout and "report" in top.stdout and "bench" in top.stdout
    helped = run_ddmr(["run", "--help"], cwd=tmp_path)
    assert helped.returncode == 0
    for group in ("controller", "scenario", "terrain", "robot", "trajectory", "smc_ndo_nno", "paper_2"):
        assert group in helped.stdout, group
    assert not (tmp_path / "outputs").exists()


def test_cfg_job_prints_the_composed_config_and_runs_nothing(tmp_path):
    proc = run_ddmr(["run", "controller=pid", "--cfg", "job"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "kp: 5.0" in proc.stdout and "_target_: ddmr_cli.control.PID" in proc.stdout
    assert not (tmp_path / "outputs").exists()


def test_single_run_writes_every_output(tmp_path):
    proc = run_ddmr(["run", "run.n_runs=3", "simulation.duration=1.0", "controller=smc_ndo_nno",
                     "hydra.run.dir=out"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out = tmp_path / "out"
    assert "deviation_mae" in proc.stderr + proc.stdout and str(out) in proc.stderr + proc.stdout
    # the job's log lines carry units
    log = proc.stdout + proc.stderr
    assert re.search(r"deviation_mae \S+ \+- \S+ m \| .* e_theta_mae \S+ \+- \S+ rad", log), log
    assert re.search(r"chattering \S+ V/s \| d_est_mae \S+ rad/s\^2 \| mean_voltage \S+ V", log), log
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["statistics"]["runs"] == 3
    assert summary["parameters"]["L"] == 50.0 and summary["parameters"]["gamma"] == 50.0
    metrics = pd.read_csv(out / "metrics.csv")
    assert list(metrics.seed) == [0, 1, 2] and np.isfinite(metrics.deviation_mae).all()
    segments = pd.read_csv(out / "segments.csv")
    assert {"total", "zone:flat", "phase:terrain"} <= set(segments.segment)
    series = read_series(out / "series.npz")
    assert list(series) == [0] and series[0]["t"].shape == (1000,)
    for name in ("trajectory", "errors", "control"):
        data = (out / "plots" / f"{name}.png").read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 5000
    assert (out / "config.yaml").read_text().count("hydra") == 0


def test_the_smoke_sweep_sweeps_every_controller_preset():
    from omegaconf import OmegaConf

    smoke = OmegaConf.load(Path(__file__).resolve().parents[1] / "conf" / "experiment" / "smoke.yaml")
    assert sorted(str(smoke.hydra.sweeper.params.controller).split(",")) == CONTROLLER_PRESETS


def test_smoke_sweep_through_joblib(smoke_sweep_dir):
    jobs = pd.read_csv(smoke_sweep_dir / "sweep_jobs.csv")
    assert len(jobs) == SMOKE_JOBS and set(jobs.status) == {"complete"}
    metrics = _metrics(smoke_sweep_dir)
    assert len(metrics) == SMOKE_JOBS * 2
    assert sorted(set(metrics.controller)) == CONTROLLER_PRESETS
    assert set(metrics.scenario) == {"paper_1", "paper_2"}
    assert np.isfinite(metrics[~metrics.controller.isin(OPEN_LOOP)].deviation_mae).all()
    plan = json.loads((smoke_sweep_dir / "sweep_plan.json").read_text())
    assert sorted(j["dir"] for j in plan["jobs"]) == sorted(jobs.job)
    # per-job plots for exactly one job (the smoke preset's choice), time series for every job
    assert [p.parent.parent.name for p in smoke_sweep_dir.glob("*/plots/control.png")] == [
        "controller=smc_ndo_nno,scenario=paper_2"]
    assert len(list(smoke_sweep_dir.glob("*/series.npz"))) == SMOKE_JOBS


def test_launchers_and_batch_sizes_give_bit_identical_numbers(smoke_sweep_dir, tmp_path):
    """joblib (fixture), submitit_local and the basic launcher; and seed 1 alone vs inside a batch."""
    subset = ["controller=pid,smc_ndo_nno", "scenario=paper_2"]
    reference = _metrics(smoke_sweep_dir)
    reference = reference[reference.controller.isin(["pid", "smc_ndo_nno"]) & (reference.scenario == "paper_2")]
    reference = reference.drop(columns="job").reset_index(drop=True)
    for launcher in ("launcher=submitit_local", "launcher=basic"):
        sweep_dir = tmp_path / launcher.split("=")[1]
        proc = run_ddmr(["run", "-m", "+experiment=smoke", launcher, *subset, f"hydra.sweep.dir={sweep_dir}"],
                        cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr[-3000:]
        got = _metrics(sweep_dir).drop(columns="job")
        pd.testing.assert_frame_equal(got, reference, check_exact=True)
    alone = tmp_path / "alone"
    proc = run_ddmr(["run", "+experiment=smoke", "controller=smc_ndo_nno", "scenario=paper_2", "run.base_seed=1",
                     "run.n_runs=1", f"hydra.run.dir={alone}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    single = pd.read_csv(alone / "metrics.csv")
    in_batch = reference[(reference.controller == "smc_ndo_nno") & (reference.seed == 1)].reset_index(drop=True)
    pd.testing.assert_frame_equal(single, in_batch, check_exact=True)


def test_a_failing_job_is_recorded_and_does_not_stop_the_sweep(tmp_path):
    import errno

    from faults import fault_env

    sweep_dir = tmp_path / "sweep"
    # one job's output files cannot be written (a full disk, injected): that job fails at its first write
    env = fault_env(tmp_path / "site", errno.ENOSPC, "/.controller=smc,scenario=paper_1.")
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "controller=pid,smc", "scenario=paper_1",
                     f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path, env=env)
    assert proc.returncode == 1
    jobs = pd.read_csv(sweep_dir / "sweep_jobs.csv").set_index("job")
    assert jobs.loc["controller=smc,scenario=paper_1", "status"] == "failed"
    assert "No space left on device" in jobs.loc["controller=smc,scenario=paper_1", "error"]
    assert jobs.loc["controller=pid,scenario=paper_1", "status"] == "complete"
    assert set(pd.read_csv(sweep_dir / "sweep_metrics.csv").controller) == {"pid"}
    assert "1 failed" in proc.stdout


def test_resume_skips_complete_jobs_and_reruns_missing_ones(tmp_path):
    sweep_dir = tmp_path / "sweep"
    args = ["run", "-m", "+experiment=smoke", "controller=pid,smc,smc_ndo", "scenario=paper_1",
            f"hydra.sweep.dir={sweep_dir}", "launcher=basic"]
    first = run_ddmr(args, cwd=tmp_path)
    assert first.returncode == 0, first.stderr[-2000:]
    before = _metrics(sweep_dir)
    shutil.rmtree(sweep_dir / "controller=smc,scenario=paper_1")  # a missing job: rerun, the others skipped
    second = run_ddmr(args, cwd=tmp_path)
    assert second.returncode == 0, second.stderr[-2000:]
    log = second.stdout + second.stderr
    assert log.count("skipped") == 2, log[-3000:]
    pd.testing.assert_frame_equal(_metrics(sweep_dir), before, check_exact=True)
    # a changed config (another seed range) is not skipped
    third = run_ddmr([*args, "run.base_seed=5"], cwd=tmp_path)
    assert third.returncode == 0 and "skipped" not in third.stdout + third.stderr
    # a job dir whose summary.json is gone holds files nothing proves ddmr wrote: refused in one line, kept
    job = sweep_dir / "controller=smc,scenario=paper_1"
    (job / "summary.json").unlink()
    kept = sorted(p.name for p in job.iterdir())
    fourth = run_ddmr(args, cwd=tmp_path)
    assert fourth.returncode == 1 and "in the way" in fourth.stderr, fourth.stderr[-2000:]
    assert sorted(p.name for p in job.iterdir()) == kept


@pytest.mark.parametrize("override,message", [
    ("robot.mass=-1", "robot.mass=-1.0: must be > 0"),
    ("controller=foo", "controller=foo: unknown controller; available: "),
    ("simulation.dt=0", "simulation.dt=0.0: must be > 0"),
    ("robot.masss=3", "masss"),
    ("controller._target_=os.system", "only ddmr_cli"),
])
def test_bad_input_is_one_line_exit_2_and_leaves_nothing(tmp_path, override, message):
    proc = run_ddmr(["run", override], cwd=tmp_path)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_bad_value_inside_a_sweep_is_refused_before_any_job(tmp_path):
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "controller.switching_gain=4,-1", "controller=smc"], cwd=tmp_path)
    assert proc.returncode == 2 and "controller.switching_gain[0]=-1" not in proc.stderr
    assert "switching_gain" in proc.stderr and "-1" in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_killed_sweep_resumes_to_the_same_totals(tmp_path, smoke_sweep_dir):
    """Kill the sweep's parent mid-way, resume into the same dir: only unfinished jobs run again."""
    sweep_dir = tmp_path / "sweep"
    args = ["run", "-m", "+experiment=smoke", f"hydra.sweep.dir={sweep_dir}", "launcher=basic"]
    proc = subprocess.Popen([ddmr_executable(), *args], cwd=tmp_path, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 120
    while time.time() < deadline and len(list(sweep_dir.glob("*/summary.json"))) < 3:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(sweep_dir.glob("*/summary.json")))
    assert 3 <= done < SMOKE_JOBS
    resumed = run_ddmr(args, cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert (resumed.stdout + resumed.stderr).count("skipped") == done
    pd.testing.assert_frame_equal(_metrics(sweep_dir).drop(columns="job"),
                                  _metrics(smoke_sweep_dir).drop(columns="job"), check_exact=True)


def _ray_launcher_installed() -> bool:
    import importlib.util

    return importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is not None


@pytest.mark.skipif(not _ray_launcher_installed(),
                    reason="the ray extra is not installed (pip install -e '.[ray]'); .ci/run installs it and runs this")
def test_smoke_sweep_through_ray_gives_the_same_numbers(smoke_sweep_dir, tmp_path):
    sweep_dir = tmp_path / "ray"
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "launcher=ray", "controller=pid,smc_ndo_nno", "scenario=paper_1",
                     f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    reference = _metrics(smoke_sweep_dir)
    reference = reference[reference.controller.isin(["pid", "smc_ndo_nno"]) & (reference.scenario == "paper_1")]
    pd.testing.assert_frame_equal(_metrics(sweep_dir).drop(columns="job"),
                                  reference.drop(columns="job").reset_index(drop=True), check_exact=True)


def test_shell_completion_completes_groups_options_and_keys(tmp_path):
    script = run_ddmr(["run", "-sc", "install=bash"], cwd=tmp_path)
    assert script.returncode == 0 and "complete -o nospace -o default -F hydra_bash_completion ddmr" in script.stdout
    options = run_ddmr(["-sc", "query=bash"], cwd=tmp_path,
                       env={"COMP_LINE": "ddmr run controller=smc_", "COMP_POINT": "24"})
    assert options.returncode == 0
    assert set(options.stdout.split()) == {"controller=smc_ndo", "controller=smc_ndo_nno", "controller=smc_ndo_nno_text",
                                           "controller=smc_nno"}
    keys = run_ddmr(["-sc", "query=bash"], cwd=tmp_path, env={"COMP_LINE": "ddmr run controller.n", "COMP_POINT": "22"})
    assert "controller.ndo." in keys.stdout.split()


# A sitecustomize that makes a Hydra launcher plugin look uninstalled: Hydra's plugin scan does not list it and
# importing it fails, as when the pip extra was never installed.
_HIDE_PLUGIN = """
import importlib.abc, pkgutil, sys
HIDDEN = {hidden!r}

class _Hide(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == HIDDEN or name.startswith(HIDDEN + "."):
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, _Hide())
_walk = pkgutil.walk_packages

def walk_packages(path=None, prefix="", onerror=None):
    return (m for m in _walk(path, prefix, onerror) if not m.name.startswith(HIDDEN))

pkgutil.walk_packages = walk_packages
"""


@pytest.mark.parametrize("launcher", ["slurm", "submitit_local"])
def test_launcher_without_its_plugin_names_the_pip_extra(tmp_path, launcher):
    hide = tmp_path / "hide"
    hide.mkdir()
    (hide / "sitecustomize.py").write_text(_HIDE_PLUGIN.format(hidden="hydra_plugins.hydra_submitit_launcher"))
    work = tmp_path / "work"
    work.mkdir()
    env = {"PYTHONPATH": os.pathsep.join([str(hide), os.environ.get("PYTHONPATH", "")])}
    check = subprocess.run([sys.executable, "-c", "import importlib.util as u; "
                            "print(u.find_spec('hydra_plugins.hydra_submitit_launcher'))"],
                           env={**os.environ, **env}, capture_output=True, text=True)
    assert check.returncode != 0 and "No module named" in check.stderr  # the plugin is hidden in that env
    for args in (["run", "-m", "+experiment=smoke", f"launcher={launcher}"], ["run", f"launcher={launcher}"]):
        proc = run_ddmr(args, cwd=work, env=env)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert lines == [f"ddmr: error: launcher={launcher}: Hydra's {'submitit_slurm' if launcher == 'slurm' else launcher}"
                         f" launcher plugin is not installed; pip install 'ddmr-cli[slurm]' (or pip install -e "
                         f"'.[slurm]' in a checkout)"], lines
        assert list(work.iterdir()) == []


def test_report_true_writes_the_report_and_ddmr_report_takes_the_latest_sweep(tmp_path, smoke_sweep_dir):
    import shutil

    older = tmp_path / "outputs" / "older" / "2020-01-01_00-00-00"
    shutil.copytree(smoke_sweep_dir, older, ignore=shutil.ignore_patterns("report", "series.npz", "plots"))
    for name in ("sweep_plan.json", "multirun.yaml"):
        os.utime(older / name, (1.6e9, 1.6e9))  # written long ago
    proc = run_ddmr(["run", "-m", "+experiment=smoke", "controller=pid,smc", "scenario=paper_1", "launcher=basic",
                     "run.progress=false", "report=true"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (sweep_dir,) = (tmp_path / "outputs" / "smoke").iterdir()  # the default dir outputs/smoke/<time>
    assert (sweep_dir / "report" / "report.md").stat().st_size > 1000
    assert f"ddmr: report written to {sweep_dir.resolve() / 'report'}" in proc.stdout
    jobs = pd.read_csv(sweep_dir / "sweep_jobs.csv")
    assert sorted(jobs.job) == ["controller=pid,scenario=paper_1", "controller=smc,scenario=paper_1"]  # report.* not in dir names
    shutil.rmtree(sweep_dir / "report")
    latest = run_ddmr(["report"], cwd=tmp_path)
    assert latest.returncode == 0, latest.stderr
    assert f"latest sweep under ./outputs: {Path('outputs') / 'smoke' / sweep_dir.name}" in latest.stderr
    assert (sweep_dir / "report" / "report.md").is_file() and not (older / "report").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    none = run_ddmr(["report"], cwd=empty)
    assert none.returncode == 2 and none.stderr.startswith("ddmr: error: path=(none): no sweep under ")
    assert len(none.stderr.strip().splitlines()) == 1


def test_bench_times_the_line_a_command_prints_its_answer_with(tmp_path):
    """`ddmr bench` times when a command's stdout first prints a marked line (the report's verdicts), and drains
    the rest of its output (a full pipe would stop the command)."""
    from ddmr_cli.cli.bench import _ddmr

    wall, peak, marked = _ddmr(["run", "--help"], tmp_path, mark="ddmr run")
    assert marked is not None and 0 < marked <= wall and peak > 0
    assert _ddmr(["--help"], tmp_path, mark="no such line")[2] is None


def test_bench_reads_a_commands_own_peak_memory_not_the_benchs(tmp_path):
    """A command's peak memory in `ddmr bench` is its own: with 300 MB more in this process than a `ddmr --help`
    needs, the command still reads far below this process's size (forked from the bench itself, Linux would count
    the bench's memory as the command's)."""
    import resource

    from ddmr_cli.cli.bench import _ddmr

    ballast = np.ones(300 * 2**20 // 8)  # 300 MB, every page touched
    own_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    wall, peak, _ = _ddmr(["--help"], tmp_path)
    assert own_mb > 300 and 0 < peak < own_mb - 200 and wall > 0, (own_mb, peak)
    del ballast


def test_bench_times_hydras_own_work_per_job():
    """The floor under section 3b: Hydra's run_job around a task that does nothing, timed per job."""
    from ddmr_cli.cli.bench import hydra_job_floor

    low, median = hydra_job_floor(3)
    assert 0 < low <= median < 10_000


def test_bench_composes_a_commands_jobs_ahead_into_the_disk_cache_it_reads(tmp_path, monkeypatch):
    """The bench times its commands warm: their jobs are composed once before, untimed, into ddmr's disk cache of
    compositions (one per set of group choices), which the timed process then reads. table4 has 8 such sets."""
    from ddmr_cli.cli.bench import compose_ahead

    monkeypatch.setenv("DDMR_CACHE_DIR", str(tmp_path / "cache"))
    seconds = compose_ahead(["-m", "+experiment=table4", "run.n_runs=2", "simulation.duration=2",
                             f"hydra.sweep.dir={tmp_path / 'sweep'}", "run.progress=false"])
    assert seconds > 0 and not (tmp_path / "sweep").exists()  # planned only: nothing written where it would run
    assert len(list((tmp_path / "cache" / "skeletons").iterdir())) >= 8


def test_the_program_and_the_task_function_collect_the_youngest_generation_less_often(monkeypatch):
    """The ddmr program and Hydra's task function (what a sweep's worker runs) raise the youngest generation's
    threshold; the Python API leaves the interpreter's alone."""
    import gc

    from ddmr_cli.cli import hydra_main, main as cli_main
    from ddmr_cli.cli.collector import YOUNGEST

    saved = gc.get_threshold()
    try:
        gc.set_threshold(700, 10, 10)
        assert cli_main.console(["--version"]) == 0 and gc.get_threshold() == (700, 10, 10)
        monkeypatch.setattr(sys, "argv", ["ddmr", "--version"])
        assert cli_main.console() == 0 and gc.get_threshold() == (YOUNGEST, 10, 10)
        gc.unfreeze()  # the program freezes what it loaded before it exits

        class Reached(Exception):
            pass

        def reached():
            raise Reached

        gc.set_threshold(700, 10, 10)
        monkeypatch.setattr(hydra_main, "job_place", reached)
        with pytest.raises(Reached):
            hydra_main.main.__wrapped__(None)
        assert gc.get_threshold() == (YOUNGEST, 10, 10)
    finally:
        gc.unfreeze()
        gc.set_threshold(*saved)


def test_the_program_loads_openblas_on_one_thread_and_keeps_the_users_choice(monkeypatch):
    """The ddmr program sets OPENBLAS_NUM_THREADS=1 before numpy loads, so OpenBLAS starts no pool of spinning
    threads (a process of its own, as the program is: the thread count after importing numpy, against the same
    import without the program's entry); a value the user set stays; the Python API sets nothing."""
    import gc

    from ddmr_cli.cli import main as cli_main
    from ddmr_cli.cli.blas import VARIABLE

    monkeypatch.delenv(VARIABLE, raising=False)
    assert cli_main.console(["--version"]) == 0 and VARIABLE not in os.environ
    monkeypatch.setenv(VARIABLE, "3")
    monkeypatch.setattr(sys, "argv", ["ddmr", "--version"])
    assert cli_main.console() == 0 and os.environ[VARIABLE] == "3"
    gc.unfreeze()  # the program freezes what it loaded before it exits
    script = ("import os, sys; sys.argv = ['ddmr', '--version']\n"
              "from ddmr_cli.cli.main import console\n"
              "if {program}: console()\n"
              "import numpy; print(os.environ.get('{var}'), len(os.listdir('/proc/self/task')))")
    env = {k: v for k, v in os.environ.items() if k != VARIABLE}
    out = {program: subprocess.run([sys.executable, "-c", script.format(program=program, var=VARIABLE)], env=env,
                                   capture_output=True, text=True, check=True).stdout.split()[-2:]
           for program in (True, False)}
    assert out[True] == ["1", "1"], out  # the program: one thread, numpy's own included
    if (os.cpu_count() or 1) > 1:
        assert out[False][0] == "None" and int(out[False][1]) > 1, out  # without it, OpenBLAS's pool


def test_bench_reads_the_threads_ratio_and_its_ceilings_round_by_round():
    """The threads' line and its two ceilings: each ceiling cores x (one alone) / (cores at once), the ratios and
    the shares medians over the rounds, each share of a round's own figures; the round's six timings are taken in
    turn (a drift of the host moves all three alike)."""
    from ddmr_cli.cli.bench import scaling

    calls = []
    rounds = iter([(1.0, 1.5, 1.0, 0.5, 1.0, 1.0),    # ratio 1.5, host 4.0 (a fast pair), own 2.0
                   (1.0, 1.8, 1.0, 1.0, 1.0, 1.25),   # ratio 1.8, host 2.0, own 1.6
                   (1.0, 1.2, 1.0, 2.0, 1.0, 2.0)])   # ratio 1.2, host 1.0, own 1.0
    current = []

    def measure(i):
        def timed():
            if i == 0:
                current[:] = next(rounds)
            calls.append(i)
            return current[i]
        return timed

    sc = scaling(2, 1, "smc", 0.1, repeats=3, measures=[measure(i) for i in range(6)])
    assert calls == list(range(6)) * 3
    assert abs(sc.ratio - 1.5) < 1e-12 and abs(sc.host - 2.0) < 1e-12 and abs(sc.own - 1.6) < 1e-12
    assert abs(sc.of_host - 0.9) < 1e-12  # shares 0.375, 0.9, 1.2
    assert abs(sc.of_own - 1.125) < 1e-12  # shares 0.75, 1.125, 1.2
    real = scaling(2, 4, "smc", 0.05, iterations=1000, repeats=1)  # the real timings run end to end
    assert all(math.isfinite(v) and v > 0.0 for v in real)


def test_bench_names_whether_ddmr_loads_from_bytecode(monkeypatch, tmp_path):
    """The machine line says whether ddmr's modules load from .pyc or compile from source in every process."""
    import importlib.util

    import ddmr_cli.cli.run as module
    from ddmr_cli.cli.bench import bytecode_note, machine_line

    compiled = tmp_path / "run.cpython.pyc"
    compiled.write_bytes(importlib.util.MAGIC_NUMBER)
    monkeypatch.setattr(module, "__cached__", str(compiled))
    assert bytecode_note() == "ddmr bytecode compiled" and machine_line().endswith(bytecode_note())
    monkeypatch.setattr(module, "__cached__", str(tmp_path / "absent.pyc"))
    assert "from source" in bytecode_note() and machine_line().endswith(bytecode_note())
