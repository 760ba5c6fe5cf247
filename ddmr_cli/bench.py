"""``ddmr bench``: performance figures for this machine (a script that prints, not a timed test).

Prints the machine line, then
1. engine throughput (simulated control steps per second on one core) at batch sizes 1, 50 and 1000 for each
   controller, and the ratio to a straightforward baseline: a per-seed Python loop over the same model;
2. wall time and peak memory of a single ``ddmr run`` (process start to exit, with its plots);
3. wall time of ``ddmr run -m +experiment=table4`` and of the report built from it;
4. wall time and peak memory of one 10,000-seed scenario-1 run (metrics only).
``--quick`` shrinks every figure (CI runs it so this script cannot rot).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CONTROLLERS = ("pid", "smc", "smc_ndo", "smc_ndo_nno")


def machine_line() -> str:
    import numpy as np

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"machine: {cpu or 'unknown cpu'}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}, "
            f"python {platform.python_version()}, numpy {np.__version__}")


def _simulation(controller: str, duration: float):
    from .config import build_simulation, compose_config

    cfg = compose_config([f"controller={controller}", f"simulation.duration={duration}"])
    return build_simulation(cfg)


def engine_throughput(batch: int, controller: str, duration: float) -> float:
    """Simulated control steps per second (runs x steps / wall time) of one batch on this core."""
    from .simulation import simulate

    sim = _simulation(controller, duration)
    started = time.perf_counter()
    simulate(sim, range(batch))
    return batch * sim.n_steps / (time.perf_counter() - started)


def per_seed_loop_throughput(n_seeds: int, controller: str, duration: float) -> float:
    """The baseline: the same model, one ``simulate`` call per seed in a Python loop."""
    from .simulation import simulate

    sim = _simulation(controller, duration)
    started = time.perf_counter()
    for seed in range(n_seeds):
        simulate(sim, [seed])
    return n_seeds * sim.n_steps / (time.perf_counter() - started)


def _ddmr(args: list[str], cwd: Path) -> tuple[float, float]:
    """Run the console script; returns (wall seconds, peak RSS in MB of the process tree's largest process)."""
    exe = shutil.which("ddmr") or str(Path(sys.executable).with_name("ddmr"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    started = time.perf_counter()
    proc = subprocess.run([exe, *args], cwd=cwd, capture_output=True, text=True)
    wall = time.perf_counter() - started
    if proc.returncode != 0:
        raise RuntimeError(f"ddmr {' '.join(args)} failed:\n{proc.stderr[-2000:]}")
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(peak, before) / 1024.0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ddmr bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (seconds): keeps the script from rotting")
    parser.add_argument("--skip-e2e", action="store_true", help="engine figures only")
    args = parser.parse_args(argv)
    quick = args.quick
    print(machine_line())
    print(f"numbers: {'QUICK (tiny sizes, not the targets)' if quick else 'full'}")

    print("\n1. engine throughput, simulated control steps per second on one core")
    batches = (1, 10) if quick else (1, 50, 1000)
    durations = {1: 2.0, 10: 0.5, 50: 5.0, 1000: 1.0} if not quick else {1: 0.3, 10: 0.3}
    print(f"   {'controller':<14}" + "".join(f"{'batch ' + str(b):>16}" for b in batches))
    for controller in CONTROLLERS:
        engine_throughput(1, controller, 0.02)  # warm-up (imports, first calls)
        figures = [engine_throughput(b, controller, durations[b]) for b in batches]
        print(f"   {controller:<14}" + "".join(f"{f / 1e6:>12.3f} M/s" for f in figures))
    n_loop, loop_duration = (4, 0.3) if quick else (10, 2.0)
    batch_ref = 10 if quick else 50
    loop = per_seed_loop_throughput(n_loop, "smc_ndo_nno", loop_duration)
    batched = engine_throughput(batch_ref, "smc_ndo_nno", loop_duration)
    print(f"   baseline (per-seed Python loop, smc_ndo_nno): {loop / 1e6:.3f} M/s; "
          f"batched at {batch_ref}: {batched / 1e6:.3f} M/s; ratio {batched / loop:.1f}x")
    target = 1e6
    print(f"   target >= 1.000 M/s per core at batch 50 for every controller"
          + ("" if quick else f": smc_ndo_nno {'met' if batched >= target else 'NOT met'}"))
    if args.skip_e2e:
        return 0

    work = Path(tempfile.mkdtemp(prefix="ddmr-bench-"))
    try:
        print("\n2. single `ddmr run` (process start to exit, with plots)")
        run_args = ["run", "run.progress=false", f"hydra.run.dir={work / 'single'}"]
        if quick:
            run_args += ["simulation.duration=1.0", "run.n_runs=5"]
        wall, peak = _ddmr(run_args, work)
        print(f"   wall {wall:.2f} s, peak memory {peak:.0f} MB   (target < 2 s)")

        experiment = "smoke" if quick else "table4"
        print(f"\n3. `ddmr run -m +experiment={experiment}` and its report")
        sweep_dir = work / experiment
        wall, peak = _ddmr(["run", "-m", f"+experiment={experiment}", f"hydra.sweep.dir={sweep_dir}",
                            "run.progress=false"], work)
        print(f"   sweep wall {wall:.2f} s, peak memory per process {peak:.0f} MB   (target < 15 s for table4)")
        wall, peak = _ddmr(["report", str(sweep_dir), "--out", str(work / "report")], work)
        print(f"   report wall {wall:.2f} s, peak memory {peak:.0f} MB   (target < 15 s)")

        n_seeds = 200 if quick else 10_000
        print(f"\n4. one {n_seeds}-seed scenario-1 run of 15 s (metrics only)")
        wall, peak = _ddmr(["run", f"run.n_runs={n_seeds}", "run.keep_series=[]", "run.plots=false",
                            "run.progress=false", f"hydra.run.dir={work / 'many'}"], work)
        print(f"   wall {wall:.2f} s, peak memory {peak:.0f} MB   (target < 60 s and < 2048 MB for 10,000 seeds)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
