"""Kill a sweep at random moments, resume it, and compare byte for byte with an uninterrupted sweep (issue 12).

Usage: python benchmarks/kill_resume.py [--trials 10] [--seed 12] [--work DIR] [SWEEP OVERRIDES...]

The reference is the same sweep run once without interruption. Each trial starts the sweep in a fresh dir,
kills it with SIGKILL after a random time in [0.2 s, the reference's wall time] (odd trials: the whole process
group, as a crash or power loss; even trials: ``ddmr run`` alone, its workers left to the reaper), looks at
what the dir holds, runs the same command again to completion and compares ``sweep_metrics.csv``,
``sweep_segments.csv`` and every job's ``metrics.csv``, ``segments.csv`` and ``config.yaml`` with the reference,
byte for byte. Prints a markdown table, one row per trial; exits 1 when any trial differs.
"""

from __future__ import annotations

import argparse
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
    print("| trial | killed | after [s] | complete at kill | partial job dirs | staging dirs | resume exit | "
          "ran / skipped | identical |")
    print("|---|---|---|---|---|---|---|---|---|")
    failures = 0
    for trial in range(1, args.trials + 1):
        sweep_dir = work / f"trial{trial}"
        group = trial % 2 == 1
        delay = rng.uniform(0.2, ref_wall)
        proc = subprocess.Popen(command(sweep_dir, args.overrides), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True, env=env)
        time.sleep(delay)
        if group:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        time.sleep(3.0 if not group else 0.5)  # the reaper ends the workers of a lone kill
        done, partial, staging = state_at_kill(sweep_dir)
        resumed = subprocess.run(command(sweep_dir, args.overrides), capture_output=True, text=True, env=env)
        log = resumed.stdout + resumed.stderr
        same = resumed.returncode == 0 and snapshot(sweep_dir) == reference
        failures += not same
        print(f"| {trial} | {'group' if group else 'ddmr run only'} | {delay:.2f} | {done} | {partial} | {staging} | "
              f"{resumed.returncode} | {sum(' - results: ' in line for line in log.splitlines())} / "
              f"{log.count('skipped')} | {'yes' if same else 'NO'} |")
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)
    print(f"\n{args.trials - failures} of {args.trials} resumed sweeps byte-identical to the reference")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
