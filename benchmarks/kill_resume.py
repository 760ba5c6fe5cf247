"""Kill a sweep at random moments, resume it, and compare byte for byte with an uninterrupted sweep (issue 12).

Usage: python benchmarks/kill_resume.py [--trials 10] [--seed 12] [--work DIR] [SWEEP OVERRIDES...]

The reference is the same sweep run once without interruption. Each trial starts the sweep in a fresh dir,
kills it with SIGKILL after a random time in [0.2 s, the reference's wall time] (odd trials: the whole process
group, as a crash or power loss; even trials: ``ddmr run`` alone, its workers left to the reaper), looks at
what the dir holds, runs the same command again to completion and compares ``sweep_metrics.csv``,
``sweep_segments.csv`` and every job's ``metrics.csv``, ``segments.csv`` and ``config.yaml`` with the reference,
byte for byte. Prints a markdown table, one row per trial; exits 1 when any trial differs.

The tree lock (issue 26): in each trial, while the sweep runs, a single ``ddmr run`` into one of its job dirs
must be refused (exit 1, one line: inside the sweep dir, in use by its pid), and again after the kill (the dir
of a finished or killed sweep). The report lock and staging (issue 26, ``--reports``): each trial then starts
``ddmr report`` of the resumed sweep, kills it at a random moment, checks what the report dir holds (only files
its manifest lists with their digests, or nothing), runs the report again and compares its tables with the
reference sweep's report, byte for byte.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEFAULT = ["+experiment=smoke", "run.progress=false"]
COMPARED = ("metrics.csv", "segments.csv", "config.yaml")
SWEEP_TABLES = ("sweep_metrics.csv", "sweep_segments.csv")


def ddmr() -> str:
    here = Path(sys.executable).with_name("ddmr")
    return str(here) if here.exists() else shutil.which("ddmr") or "ddmr"


def command(sweep_dir: Path, overrides: list[str]) -> list[str]:
    return [ddmr(), "run", "-m", *overrides, f"hydra.sweep.dir={sweep_dir}"]


def snapshot(sweep_dir: Path) -> dict[str, bytes]:
    """The compared files of a sweep dir, by relative path."""
    files = {name: (sweep_dir / name).read_bytes() for name in SWEEP_TABLES}
    for job in sorted(p for p in sweep_dir.iterdir() if p.is_dir() and not p.name.startswith(".")):
        for name in COMPARED:
            files[f"{job.name}/{name}"] = (job / name).read_bytes()
    return files


def intruder(sweep_dir: Path, env: dict, running: bool) -> tuple[int, str]:
    """A single ``ddmr run`` into the first job dir of ``sweep_dir`` (while the sweep runs and has none yet: into
    the sweep dir itself): its exit status and its last line; -1 when there is no such dir."""
    job = next((p for p in sorted(sweep_dir.iterdir()) if p.is_dir() and not p.name.startswith(".")), None) \
        if sweep_dir.is_dir() else None
    if job is None and running and sweep_dir.is_dir():
        job = sweep_dir
    if job is None:
        return -1, "(no job dir yet)"
    proc = subprocess.run([ddmr(), "run", "controller=pid", "run.n_runs=1", "simulation.duration=0.2",
                           f"hydra.run.dir='{job}'"], capture_output=True, text=True, env=env)
    lines = proc.stderr.strip().splitlines()
    return proc.returncode, lines[-1] if lines else ""


def report_state(out: Path) -> str:
    """What a (killed) report dir holds: ``empty``, ``manifest ok`` (every file there is one its manifest lists,
    with its digest) or what is wrong."""
    from ddmr_cli.storage.jobdir import digest

    if not out.is_dir():
        return "empty"
    files = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() and
                   not p.name.startswith(".ddmr-report.") and not any(part.startswith(".ddmr-report.") and
                                                                     part.endswith(".tmp") for part in p.parts))
    manifest = out / ".ddmr-report.json"
    if not manifest.is_file():
        return "empty" if not files else f"{len(files)} files, no manifest"
    listed = json.loads(manifest.read_text())["digests"]
    stray = [f for f in files if f not in listed]
    wrong = [f for f, want in listed.items() if (out / f).is_file() and digest(out / f) != want]
    return "manifest ok" if not stray and not wrong else f"stray {stray[:2]} changed {wrong[:2]}"


def report_tables(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((out / "tables").glob("*.csv"))}


def state_at_kill(sweep_dir: Path) -> tuple[int, int, int]:
    """(complete summaries, job dirs with outputs but no summary, staging dirs) in a killed sweep dir."""
    if not sweep_dir.is_dir():
        return 0, 0, 0
    jobs = [p for p in sweep_dir.iterdir() if p.is_dir() and not p.name.startswith(".")]
    done = sum((j / "summary.json").is_file() for j in jobs)
    partial = sum(not (j / "summary.json").is_file() and any((j / n).exists() for n in COMPARED) for j in jobs)
    staging = len([p for p in sweep_dir.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")])
    return done, partial, staging


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--seed", type=int, default=12)
    parser.add_argument("--work", default=None, help="scratch dir (default: a temporary dir, removed)")
    parser.add_argument("--reports", action=argparse.BooleanOptionalAction, default=True,
                        help="also kill and rerun a report of each resumed sweep (the report lock and staging)")
    parser.add_argument("overrides", nargs="*", default=DEFAULT)
    args = parser.parse_args(argv)
    work = Path(args.work or tempfile.mkdtemp(prefix="ddmr-kill-"))
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    rng = random.Random(args.seed)
    started = time.perf_counter()
    ref = subprocess.run(command(work / "reference", args.overrides), capture_output=True, text=True, env=env)
    ref_wall = time.perf_counter() - started
    if ref.returncode != 0:
        print(ref.stderr[-3000:], file=sys.stderr)
        return 1
    reference = snapshot(work / "reference")
    print(f"reference: `ddmr run -m {' '.join(args.overrides)}`, {ref_wall:.1f} s, {len(reference)} files compared\n")
    ref_tables, rep_wall = {}, 0.0
    if args.reports:
        started = time.perf_counter()
        rep = subprocess.run([ddmr(), "report", str(work / "reference")], capture_output=True, text=True, env=env)
        rep_wall = time.perf_counter() - started
        ref_tables = report_tables(work / "reference" / "report")
        print(f"reference report: exit {rep.returncode}, {rep_wall:.1f} s, {len(ref_tables)} tables compared\n")
    print("| trial | killed | after [s] | run into a job dir while running | ... after the kill | complete at kill | "
          "partial job dirs | staging dirs | resume exit | ran / skipped | identical | report killed after [s] | "
          "report dir at kill | report rerun exit | report tables identical |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    failures = 0
    for trial in range(1, args.trials + 1):
        sweep_dir = work / f"trial{trial}"
        group = trial % 2 == 1
        delay = rng.uniform(0.2, ref_wall)
        proc = subprocess.Popen(command(sweep_dir, args.overrides), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True, env=env)
        time.sleep(delay / 2)
        during = intruder(sweep_dir, env, True) if proc.poll() is None else (-1, "(sweep already done)")
        time.sleep(max(0.0, delay / 2 - 0.5))
        if group:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        time.sleep(3.0 if not group else 0.5)  # the reaper ends the workers of a lone kill
        done, partial, staging = state_at_kill(sweep_dir)
        after = intruder(sweep_dir, env, False)
        locked = all(code == 1 for code, line in (during, after) if code != -1)
        resumed = subprocess.run(command(sweep_dir, args.overrides), capture_output=True, text=True, env=env)
        log = resumed.stdout + resumed.stderr
        same = resumed.returncode == 0 and snapshot(sweep_dir) == reference and locked
        cells = ["-"] * 4
        if args.reports:
            rdelay = rng.uniform(0.5, max(rep_wall, 0.6))
            rproc = subprocess.Popen([ddmr(), "report", str(sweep_dir)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL, start_new_session=True, env=env)
            time.sleep(rdelay)
            os.killpg(rproc.pid, signal.SIGKILL)
            rproc.wait()
            at_kill = report_state(sweep_dir / "report")
            again = subprocess.run([ddmr(), "report", str(sweep_dir)], capture_output=True, text=True, env=env)
            tables_same = again.returncode == 0 and report_tables(sweep_dir / "report") == ref_tables
            settled = report_state(sweep_dir / "report") == "manifest ok"
            same = same and tables_same and settled and at_kill in ("empty", "manifest ok")
            cells = [f"{rdelay:.2f}", at_kill, str(again.returncode), "yes" if tables_same and settled else "NO"]
        failures += not same
        print(f"| {trial} | {'group' if group else 'ddmr run only'} | {delay:.2f} | {during[0]} | {after[0]} | {done} | "
              f"{partial} | {staging} | {resumed.returncode} | {sum(' - results: ' in line for line in log.splitlines())}"
              f" / {log.count('skipped')} | {'yes' if same else 'NO'} | {' | '.join(cells)} |")
        if during[0] != -1 or after[0] != -1:
            print(f"<!-- trial {trial}: the single run said: {during[1]} / {after[1]} -->")
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)
    print(f"\n{args.trials - failures} of {args.trials} resumed sweeps byte-identical to the reference")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
