"""Progress output (issue 29): bars on a terminal, whole lines in a log, nothing with run.progress=false; the
compile notice said exactly when the kernel cache has no compiled copy; the sweep bar counts job summaries."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
import types

import pytest

from ddmr_cli import progress
from ddmr_cli.engine import kernels


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_off_a_terminal_each_refresh_is_one_whole_line():
    out = io.StringIO()
    with progress.bar(4, "validating", "jobs", stream=out, delay=0) as b:
        for _ in range(4):
            b.update(1)
    text = out.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert lines[0].startswith("validating: 0/4 jobs (0 %)")
    assert lines[-1].startswith("validating: 4/4 jobs (100 %)")
    assert all(line.strip() for line in lines)
    assert len(lines) == len(set(lines))  # the last state once, though tqdm draws it again on close


def test_on_a_terminal_the_bar_redraws_in_place():
    out = _Tty()
    with progress.bar(2, "sweep", "jobs", stream=out, delay=0) as b:
        b.update(2)
    assert "\r" in out.getvalue() and "2/2" in out.getvalue()


def test_a_status_says_what_is_measured_and_for_how_long_and_is_cleared_when_it_ends():
    """``ddmr bench``'s line per measurement: its elapsed time moves while nothing else is printed (redrawn every
    second on a terminal), the line is cleared from a terminal at the end, and in a log it is whole lines."""
    import time

    tty, log = _Tty(), io.StringIO()
    for out in (tty, log):
        with progress.status("measuring the table4 sweep", stream=out, delay=0):
            time.sleep(1.3)
    assert "\rmeasuring the table4 sweep (00:00 elapsed)" in tty.getvalue()
    assert "\rmeasuring the table4 sweep (00:01 elapsed)" in tty.getvalue()
    assert tty.getvalue().endswith("\r") and tty.getvalue().rsplit("\r", 2)[-2].strip() == ""  # cleared
    assert "\r" not in log.getvalue()
    assert log.getvalue().splitlines()[0] == "measuring the table4 sweep (00:00 elapsed)"
    quiet = _Tty()
    with progress.status("measuring", stream=quiet, enabled=False):
        pass
    assert quiet.getvalue() == ""


def test_at_a_sweeps_end_its_bar_closes_before_the_results_and_the_status_line(tmp_path, monkeypatch):
    """Hydra's launcher returns when every job has ended, and the sweep's callback prints at once, before the
    watch's once-a-second poll: the watch is settled first, so its bar ends at 2/2 above the results, and the
    tables' status line takes the cursor's line (not the one below the bar, reached by a newline and a cursor-up
    escape)."""
    monkeypatch.setattr(progress, "DELAY", 0.0)
    tty = _Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    out = _Tty()
    dirs = ["a", "b"]
    for d in dirs:
        (tmp_path / d).mkdir()
    with progress.SweepWatch(tmp_path, dirs, "summary.json"):
        for d in dirs:
            (tmp_path / d / "summary.json").write_text("{}")
        progress.say(["ddmr study morris: 2 jobs complete"], stream=out)
        closed = tty.getvalue()
        with progress.status("sweep: writing its tables"):
            pass
    assert re.search(r"2/2 \[[^\r]*\]\n$", closed), closed[-200:]  # the bar's last state, ended by its newline
    assert out.getvalue() == "ddmr study morris: 2 jobs complete\n"  # no bar redrawn below the results
    status = tty.getvalue()[len(closed):]
    assert status.startswith("\rsweep: writing its tables") and "\x1b[A" not in status and "\n" not in status


def test_progress_false_prints_nothing(capsys):
    with progress.bar(3, "sweep", "jobs", enabled=False) as b, progress.Ticker(b):
        b.update(3)
    list(progress.each(range(3), 3, "validating", enabled=False))
    assert capsys.readouterr().err == ""


def test_the_sweep_bar_counts_summaries_and_resumed_jobs(tmp_path, capsys):
    dirs = ["a", "b", "c"]
    for d in dirs:
        (tmp_path / d).mkdir()
    (tmp_path / "a" / "summary.json").write_text("{}")  # resumed: complete before the sweep starts
    with progress.SweepWatch(tmp_path, dirs, "summary.json") as watch:
        assert watch._bar.n == 1
        (tmp_path / "b" / "summary.json").write_text("{}")
        (tmp_path / "c" / "summary.json").write_text("{}")
    assert watch._bar.n == 3 and watch._bar.disable  # counted, then closed
    assert capsys.readouterr().err == ""  # over within progress.DELAY: never drawn


def test_the_trial_bar_counts_the_trials_of_this_session_as_they_end(tmp_path):
    """An Optuna session's bar: trial dirs are named from their sampled values (one or two levels below the sweep
    dir), so it counts their marker files as they appear, not those of an earlier session, and never past its
    total."""
    old = tmp_path / "trials" / "old"
    old.mkdir(parents=True)
    (old / "trial.json").write_text("{}")  # an earlier session's trial
    with progress.TrialWatch(tmp_path, 3, "trial.json") as watch:
        assert watch._bar.n == 0 and watch._bar.total == 3
        for path in (tmp_path / "trials" / "a", tmp_path / "trial-b"):
            path.mkdir()
            (path / "trial.json").write_text("{}")
        (tmp_path / "trials" / "a" / "summary.json").write_text("{}")  # another file: not a trial's end
        assert watch._poll() == 2 and watch._poll() == 0
        watch._bar.n += 2
        for name in ("c", "d"):  # a fourth trial counted in a session of three (a failed one rerun): held at 3
            (tmp_path / "trials" / name).mkdir()
            (tmp_path / "trials" / name / "trial.json").write_text("{}")
    assert watch._bar.n == 3 and watch._bar.disable
    assert not progress.TrialWatch(tmp_path, 0, "trial.json").enabled  # a session with no trial left: no bar


def test_the_long_sessions_show_their_progress():
    """The sensitivity study's stages and the gain tuning run with ``run.progress`` on: a bar over the stage's jobs
    or the session's trials, instead of silence (a default study's stage runs 10-70 s, a tuning session minutes)."""
    from ddmr_cli.config import compose_config

    for preset in ("+experiment=sensitivity_morris", "+experiment=sensitivity_calibration", "+tune=smc_ndo"):
        assert compose_config([preset]).run.progress is True, preset


def test_a_study_says_it_writes_its_report(tmp_path, monkeypatch, capsys):
    """``ddmr sensitivity`` writes its report for several seconds after its last stage: a status line says so
    (here in a log: whole lines), and none with ``run.progress=false``."""
    import time

    from ddmr_cli.cli import run as run_module
    from ddmr_cli.cli import sensitivity

    monkeypatch.setattr(progress, "DELAY", 0.0)
    monkeypatch.setattr(run_module, "cmd_run", lambda argv: 0)

    def slow_report(out):
        time.sleep(0.1)
        return out / "report.md"

    monkeypatch.setattr("ddmr_cli.report.sensitivity.write_report", slow_report)
    assert sensitivity.main(["--out", str(tmp_path / "s"), "--stages", "oat"]) == 0
    assert "ddmr sensitivity: writing the report (00:00 elapsed)" in capsys.readouterr().err
    assert sensitivity.main(["--out", str(tmp_path / "q"), "--stages", "oat", "run.progress=false"]) == 0
    assert "writing the report" not in capsys.readouterr().err
    # overrides that do not compose: every stage refused them (exit 2, its own error line); the report's line
    # follows the study's preset, and the study ends with the stages' status, not a traceback
    monkeypatch.setattr(run_module, "cmd_run", lambda argv: 2)
    assert sensitivity.main(["--out", str(tmp_path / "b"), "--stages", "oat", "no_such_key=1"]) == 2
    assert "writing the report (00:00 elapsed)" in capsys.readouterr().err


def _fake_stepper(tmp_path):
    class Function:
        def __init__(self):
            self.overloads = {}

        def compile(self, signature):
            self.overloads[signature] = object()

    return types.SimpleNamespace(run_chunk=Function(), __file__=str(tmp_path / "ddmr_stepper_fake.py"))


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba not installed")
def test_the_compile_notice_is_given_only_when_no_compiled_copy_is_cached(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_DISABLE_JIT", raising=False)
    if not kernels.jit_enabled():
        pytest.skip("numba's JIT is disabled")
    module = _fake_stepper(tmp_path)
    monkeypatch.setattr(kernels, "copy_for", lambda template, law, identity="": module)
    calls = []
    kernels.compiled_run_chunk("fake", (1.0,), compiling=lambda: calls.append(1))
    assert calls == [1]  # nothing cached: compiled now, said first
    (tmp_path / "__pycache__").mkdir()
    (tmp_path / "__pycache__" / "ddmr_stepper_fake.run_chunk-1.py312.nbi").write_text("")
    module.run_chunk.overloads.clear()
    kernels.compiled_run_chunk("fake", (1.0,), compiling=lambda: calls.append(2))
    assert calls == [1]  # a cache entry: loaded, nothing said


def _ddmr(args, cwd, cache=None, delay=None):
    env = {**os.environ, **({"DDMR_CACHE_DIR": str(cache)} if cache is not None else {}),
           **({"DDMR_PROGRESS_DELAY": str(delay)} if delay is not None else {})}
    return subprocess.run([sys.executable, "-m", "ddmr_cli.cli.main", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


TINY = ["controller=pid", "run.n_runs=1", "simulation.duration=0.05", "run.plots=false"]


@pytest.mark.slow
def test_a_first_run_says_it_compiles_and_a_second_does_not(tmp_path):
    first = _ddmr(["run", *TINY, f"hydra.run.dir={tmp_path / 'one'}"], tmp_path, tmp_path / "cache")
    assert first.returncode == 0, first.stderr
    assert "ddmr: compiling the step loop for pid (first use only, about 10 s)" in first.stderr
    assert "pid/paper_1 (1 runs): 50/50 steps (100 %)" in first.stderr  # the step bar (compiling: > 1 s), as lines
    second = _ddmr(["run", *TINY, f"hydra.run.dir={tmp_path / 'two'}"], tmp_path, tmp_path / "cache")
    assert second.returncode == 0 and "compiling" not in second.stderr
    quiet = _ddmr(["run", *TINY, "run.progress=false", f"hydra.run.dir={tmp_path / 'three'}"], tmp_path,
                  tmp_path / "cold")
    assert quiet.returncode == 0 and "compiling" not in quiet.stderr and "steps" not in quiet.stderr


def test_a_sweep_shows_validation_and_job_progress_as_lines_in_a_log(tmp_path):
    args = ["run", "-m", *TINY, "scenario=paper_1,paper_2", "run.bands=false", f"hydra.sweep.dir={tmp_path / 's'}",
            "launcher=basic"]
    shown = _ddmr(args, tmp_path, delay=0)  # every bar at once, however fast this machine is
    assert shown.returncode == 0, shown.stderr
    assert "validating: 0/2 jobs" in shown.stderr  # validation's bar (leave=False: its last state is not kept)
    assert "sweep: 2/2 jobs (100 %)" in shown.stderr
    assert "sweep: writing its tables (00:00 elapsed)" in shown.stderr  # the callback's status line
    assert "\r" not in shown.stderr
    quiet = _ddmr([*args[:-2], "run.progress=false", f"hydra.sweep.dir={tmp_path / 'q'}", "launcher=basic"],
                  tmp_path, delay=0)
    assert quiet.returncode == 0 and "validating" not in quiet.stderr and "sweep:" not in quiet.stderr


def _started(monkeypatch, seconds_ago: float) -> None:
    """This process started ``seconds_ago`` s ago, as psutil reports it."""
    import time

    import psutil

    monkeypatch.setattr(psutil.Process, "create_time", lambda self: time.time() - seconds_ago)


def test_a_bar_drawn_late_in_a_commands_start_up_waits_only_for_what_is_left_of_the_delay(monkeypatch):
    """On a terminal the delay counts from the process' start: a command silent for DELAY s draws at once; in a
    log it is the whole DELAY (a refused command there prints its one error line only)."""
    monkeypatch.setattr(progress, "DELAY", 1.0)
    _started(monkeypatch, 5.0)
    assert progress.delay_since_start(_Tty()) == 0.0
    _started(monkeypatch, 0.25)
    assert progress.delay_since_start(_Tty()) == pytest.approx(0.75, abs=0.1)
    assert progress.delay_since_start(io.StringIO()) == 1.0


def test_a_report_shows_its_progress_at_once_on_a_terminal_after_a_long_start_up(tmp_path, monkeypatch):
    """``ddmr report`` spends 1-2 s on imports and reading the jobs before its bar exists: on a terminal, the read
    is said and the bar drawn as soon as they start (the process has been silent for over DELAY s); in a log, the
    read is not said."""
    import ddmr_cli
    from ddmr_cli.job import JobPlace, execute
    from ddmr_cli.report.build import build

    overrides = ["controller=pid", "run.n_runs=1", "simulation.duration=0.2", "run.plots=false", "run.progress=false"]
    execute(ddmr_cli.compose_config(overrides), JobPlace(tmp_path / "run", tuple(overrides)))
    monkeypatch.setattr(progress, "DELAY", 1.0)
    _started(monkeypatch, 30.0)
    tty = _Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    build(tmp_path / "run", tmp_path / "rep_tty", figures=False)
    assert "\rreport: reading the jobs (00:00 elapsed)" in tty.getvalue()
    assert re.search(r"\rreport: +0%\|", tty.getvalue())  # the bar, drawn when made
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    build(tmp_path / "run", tmp_path / "rep_log", figures=False)
    assert "reading the jobs" not in log.getvalue()


def test_a_runs_step_bar_on_a_terminal_is_drawn_at_once_when_the_command_has_run_a_while(monkeypatch):
    """``ddmr run``'s bar is made after its imports and composition (about 1 s): on a terminal it is drawn when
    made once the process has run DELAY s, so a 2 s run is not silent to its end; in a log it keeps its delay."""
    monkeypatch.setattr(progress, "DELAY", 1.0)
    _started(monkeypatch, 30.0)
    for stream, drawn in ((_Tty(), True), (io.StringIO(), False)):
        monkeypatch.setattr(sys, "stderr", stream)
        step_bar = progress.StepBar("smc_ndo_nno/paper_1", 50, 15000)
        step_bar(3000, 15000)
        shown = stream.getvalue()
        step_bar.close()
        assert ("smc_ndo_nno/paper_1 (50 runs)" in shown) is drawn, shown
