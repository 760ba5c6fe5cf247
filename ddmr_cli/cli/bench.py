"""``ddmr bench``: performance figures for this machine (a script that prints, not a timed test).

Prints the machine line, then
1. engine throughput (simulated control steps per second on one core) at batch sizes 1, 50 and 1000 for each
   controller; for smc_ndo and smc_ndo_nno at 50 and 1000 the engine beside the hand-fused reference kernel of
   the same loop on the same noise streams (:mod:`ddmr_cli.bench.reference`), timed in the same process, and the
   ratios, of the engine as ``ddmr run`` runs it and without the seed bands the reference does not compute (the
   target: the engine at most 1.5x slower at equal work), against the kernel computing the engine's numbers (its
   exact layout) and with fast numerics (its lanes layout: numbers the engine cannot take); on every core, beside
   what every core gives independent processes of pure CPU work on this machine (the most threads can give) and
   independent batches of the engine's own work, one a thread (what splitting one batch costs), all three timed in
   the same rounds (:func:`scaling`); as plain Python (the fallback), and the compile and cache-load times;
2. wall time and peak memory of a single ``ddmr run`` (process start to exit, with its plots);
3. wall time of ``ddmr run -m +experiment=table4`` and of the report built from it (and when the report printed
   its verdicts); 3b. of a 200-job sweep of one-seed 0.2 s runs (the per-job overhead), and Hydra's own work per
   job, the floor under it (:func:`hydra_job_floor`);
4. wall time and peak memory of one 10,000-seed scenario-1 run (metrics only);
5. the cost of a control step per controller: ns of its laws alone, operation counts and a Cortex-M4F estimate
   (:mod:`ddmr_cli.bench.cost`; printed after section 1 when ``--skip-e2e``).
6. the physics plant (``plant=mujoco``, the physics extra): plant steps per second of a batch on the paper terrain
   and the share of the wall time in the MuJoCo steps, in the rest of the plant's step and in the loop around it
   (:mod:`ddmr_cli.bench.physics`).
The commands of sections 2-4 are timed warm, as users repeat them: their jobs are composed once before, untimed
(:func:`compose_ahead`), as the compiled step loop is in the disk cache before they run.
``--quick`` shrinks every figure (CI runs it so this script cannot rot): table4 with 2 seeds of 2 s and its report
without the figures (their drawing costs the same at any sweep size, seconds of a quick bench; the tests draw every
one), 10 one-seed jobs, 100 seeds, the cost of two controllers' steps.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, NamedTuple, Sequence

CONTROLLERS = ("pid", "smc", "smc_ndo", "smc_ndo_nno")
#: the controllers the reference kernel runs (ddmr_cli/bench/reference.py)
REFERENCE_CONTROLLERS = ("smc_ndo", "smc_ndo_nno")
#: the engine may be at most this many times slower than the reference kernel (the issue's target)
REFERENCE_TARGET = 1.5
#: alternating repeats of each figure that is a median (the reference comparison; the threads' ratio with --quick)
REPEATS = 3
#: rounds of the threads' ratio and its two ceilings in the full bench (:func:`scaling`), each a pair of all three: the
#: host's two cores drift apart in speed by turns for seconds at a time, and a median of 3 pairs read 1.63x, 1.76x and
#: 1.81x on one tree within 20 minutes (issue 28); timed one after the other, 7 pairs of the threads' line read 1.25x
#: and then 7 of the host's ceiling 1.98x, where the line alone read 1.66-1.83x in four medians of 7 pairs minutes
#: later; a round is about 2.5 s (7 rounds: 18-19 s)
THREAD_REPEATS = 7
#: wall-time targets [s] on a 2-core machine (issue 28), for the full sizes: each line prints its ratio to them
WALL_TARGETS = {
    "run": 1.3,            # a single `ddmr run`, with its plots, caches warm
    "table4": 3.0,         # `ddmr run -m +experiment=table4`, the sweep alone
    "table4+report": 8.0,  # ... with its report
    "job": 0.05,           # a job of the 200-job sweep of one-seed 0.2 s runs, in all (issue 14)
    "quick": 20.0,         # `ddmr bench --quick` from start to end
}


def measuring(what: str):
    """A status line on stderr while one figure is measured, saying what and for how long
    (:func:`ddmr_cli.progress.status`: from 1 s on, redrawn every second on a terminal); stdout is flushed first,
    so that in one log the figures printed so far come before it."""
    from ddmr_cli import progress

    sys.stdout.flush()
    return progress.status(f"ddmr bench: measuring {what}")


def against(wall: float, target: str, quick: bool = False) -> str:
    """``(target <= T s: R x)``, the wall time's ratio to :data:`WALL_TARGETS` (quick sizes: the target only)."""
    limit = WALL_TARGETS[target]
    unit = f"{1000 * limit:g} ms" if limit < 1 else f"{limit:g} s"
    if quick:
        return f"(target <= {unit} at the full size)"
    return f"(target <= {unit}: {wall / limit:.2f}x the target)"


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
            f"python {platform.python_version()}, numpy {np.__version__}, {bytecode_note()}")


def bytecode_note() -> str:
    """Whether ddmr's own modules load from compiled bytecode (``.pyc``): a wheel install compiles them; an
    editable install leaves them to the first import, which writes none where ``PYTHONDONTWRITEBYTECODE`` is set
    (a common Docker setting), and every process then compiles ddmr from source (0.1-0.15 s of each start,
    measured; the README's set-up compiles them)."""
    import ddmr_cli.cli.run as module

    cached = getattr(module, "__cached__", None)
    if cached and Path(cached).is_file():
        return "ddmr bytecode compiled"
    return "ddmr imported from source (no .pyc: python -m compileall the package)"


def _simulation(controller: str, duration: float):
    from ddmr_cli.config.presets import paper_simulation

    return paper_simulation(f"controller={controller}", f"simulation.duration={duration}")


def engine_throughput(batch: int, controller: str, duration: float, threads: int = 1, bands: bool = True) -> float:
    """Simulated control steps per second (runs x steps / wall time) of one batch (``bands=False``: without the
    seed bands, which ``ddmr run`` computes by default)."""
    from ddmr_cli.engine.simulation import simulate

    sim = _simulation(controller, duration)
    started = time.perf_counter()
    simulate(sim, range(batch), threads=threads, bands=bands)
    return batch * sim.n_steps / (time.perf_counter() - started)


def _alternating(repeats: int, *measures: Callable[[], float]) -> list[list[float]]:
    """Each of ``measures`` called ``repeats`` times, in turn (A B C A B C ...): a drift of the machine's speed
    moves all of them alike. One list of figures per measure."""
    figures: list[list[float]] = [[] for _ in measures]
    for _ in range(repeats):
        for measure, out in zip(measures, figures):
            out.append(measure())
    return figures


def reference_comparison(batch: int, controller: str, duration: float,
                         repeats: int = REPEATS) -> tuple[float, float, float, float]:
    """Median throughputs [steps/s] of the engine as ``ddmr run`` runs it, of the engine without the seed bands
    (nearer the reference's work: it computes no bands), of the reference kernel in its exact layout (the engine's
    numbers: libm's sine and cosine a lane at a time, no fast-math flag) and in its lanes layout (fdlibm's
    vectorised sine and cosine and fused multiply-adds: faster, its numbers within about 1e-13 of the engine's, not
    the bit), on the same batch, timed alternately ``repeats`` times each in this process, one core; all warmed up
    first (imports, compiled code loaded or compiled)."""
    import statistics

    from ddmr_cli.bench.reference import reference_throughput

    sim = _simulation(controller, duration)
    engine_throughput(1, controller, 0.02)
    engine_throughput(1, controller, 0.02, bands=False)
    for layout in ("exact", "lanes"):
        reference_throughput(_simulation(controller, 0.02), 1, layout)
    figures = _alternating(repeats, lambda: engine_throughput(batch, controller, duration),
                           lambda: engine_throughput(batch, controller, duration, bands=False),
                           lambda: reference_throughput(sim, batch, "exact"),
                           lambda: reference_throughput(sim, batch, "lanes"))
    engine, bare, exact, fast = (statistics.median(f) for f in figures)
    return engine, bare, exact, fast


def thread_scaling(batch: int, controller: str, duration: float,
                   repeats: int = REPEATS) -> tuple[float, float, float]:
    """Median throughputs [steps/s] on one thread and on every core, and the median of their ratios, pair by pair
    (:func:`_alternating`: a pair's two runs are seconds apart, so a drift of the machine's speed moves both)."""
    import statistics

    engine_throughput(1, controller, 0.02, threads=0)
    one, many = _alternating(repeats, lambda: engine_throughput(batch, controller, duration, threads=1),
                             lambda: engine_throughput(batch, controller, duration, threads=0))
    return statistics.median(one), statistics.median(many), statistics.median(m / o for o, m in zip(one, many))


def _batches_wall(sims: list, batch: int) -> float:
    """Wall seconds of one batch of ``batch`` runs of each of ``sims`` stepped at once, each from start to end by a
    thread of its own (``simulate(threads=1)``: its own simulation, nothing shared with the others)."""
    from concurrent.futures import ThreadPoolExecutor

    from ddmr_cli.engine.simulation import simulate

    with ThreadPoolExecutor(len(sims)) as pool:
        started = time.perf_counter()
        for future in [pool.submit(simulate, sim, range(batch), threads=1) for sim in sims]:
            future.result()
        return time.perf_counter() - started


#: a fixed piece of pure CPU work (no memory traffic, no threads, no library) for the host's ceiling (:func:`scaling`)
_CPU_WORK = "s = 0\nfor i in range({n}):\n    s += i * i\n"


def _processes_wall(n_processes: int, iterations: int) -> float:
    """Wall seconds of ``n_processes`` Python processes started together, each doing the same :data:`_CPU_WORK`."""
    code = _CPU_WORK.format(n=iterations)
    started = time.perf_counter()
    group = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(n_processes)]
    for process in group:
        process.wait()
    return time.perf_counter() - started


class Scaling(NamedTuple):
    """The threads' line and its two ceilings, measured in the same rounds (:func:`scaling`)."""

    one: float  # median throughput on one thread [steps/s]
    many: float  # ... on every core
    ratio: float  # median over the rounds of many / one
    host: float  # the host's ceiling: cores x (one process alone) / (cores processes at once), median over the rounds
    own: float  # the engine's own ceiling: the same of independent batches, one a thread
    of_host: float  # median over the rounds of the round's ratio over its host's ceiling
    of_own: float  # ... over its engine's own ceiling


def _ceiling(cores: int, alone: float, together: float) -> float:
    """Throughput of ``cores`` pieces of work at once over one alone, from their wall seconds."""
    return cores * alone / together


def scaling(cores: int, batch: int, controller: str, duration: float, iterations: int = 10_000_000,
            repeats: int = THREAD_REPEATS, measures: Sequence[Callable[[], float]] | None = None) -> Scaling:
    """One thread against every core, beside what ``cores`` cores give this machine's own CPU work (the host's
    ceiling: ``cores`` independent processes of :data:`_CPU_WORK` at once against one alone; no program's threads
    can scale further, and on a host whose "cores" share a physical core or are taken by other guests it is well
    under ``cores``) and what they give the engine's own work (its ceiling: ``cores`` independent batches at once,
    one a thread, ``simulate(threads=1)`` each, against one alone; the engine's threads split one batch and meet
    at its chunks, around its serial set-up and metrics: their ratio over this one is what the splitting costs).

    Each of ``repeats`` rounds times one pair of each in turn (:func:`_alternating`), so that a drift of the host's
    speed, which lasts seconds to minutes, moves all three alike; each share is the median over the rounds of the
    round's own quotient. ``measures``: the six timings of a round (for tests): throughputs on one thread and on
    every core [steps/s], then wall seconds of one process, of ``cores`` processes, of one batch and of ``cores``
    batches."""
    import statistics

    if measures is None:
        sims = [_simulation(controller, duration) for _ in range(cores)]
        engine_throughput(1, controller, 0.02, threads=0)  # warm-up, untimed: the step loop loaded, first calls made
        _batches_wall(sims[:1], batch)
        measures = (lambda: engine_throughput(batch, controller, duration, threads=1),
                    lambda: engine_throughput(batch, controller, duration, threads=0),
                    lambda: _processes_wall(1, iterations), lambda: _processes_wall(cores, iterations),
                    lambda: _batches_wall(sims[:1], batch), lambda: _batches_wall(sims, batch))
    one, many, process, processes, batch_alone, batches = _alternating(repeats, *measures)
    ratios = [m / o for o, m in zip(one, many)]
    host = [_ceiling(cores, a, t) for a, t in zip(process, processes)]
    own = [_ceiling(cores, a, t) for a, t in zip(batch_alone, batches)]
    median = statistics.median
    return Scaling(median(one), median(many), median(ratios), median(host), median(own),
                   median(r / c for r, c in zip(ratios, host)), median(r / c for r, c in zip(ratios, own)))


def hydra_job_floor(repeats: int) -> tuple[float, float]:
    """Hydra's own work per job in ms of one core, min and median of ``repeats``: ``hydra.core.utils.run_job``
    (what every launcher runs per job: the config copies and the job's three ``.hydra`` YAML files, with the
    emitter and the copies of ddmr's workers: :func:`ddmr_cli.compat.omegaconf_speedups`) around a task that does
    nothing (:func:`ddmr_cli.compat.run_hydra_job`), on section 3b's job config, in this process."""
    import copy
    import statistics

    from ddmr_cli import compat
    from ddmr_cli.config import compose_config

    base = compose_config(["run.n_runs=1", "simulation.duration=0.2", "run.plots=false", "run.progress=false"],
                          return_hydra_config=True)
    times = []
    restore_omegaconf = compat.omegaconf_speedups()
    try:
        with tempfile.TemporaryDirectory(prefix="ddmr-bench-") as tmp:
            base.hydra.sweep.dir = tmp
            for i in range(repeats + 1):  # the first one warms up
                cfg = copy.deepcopy(base)  # a job's own config (Hydra makes the one it ran read-only)
                cfg.hydra.sweep.subdir = str(i)
                started = time.perf_counter()
                compat.run_hydra_job(lambda task_cfg: None, cfg)
                times.append(1000.0 * (time.perf_counter() - started))
    finally:
        restore_omegaconf()
    return min(times[1:]), statistics.median(times[1:])


def python_throughput(controller: str, duration: float) -> float:
    """The same laws run as plain Python (``NUMBA_DISABLE_JIT=1``, the fallback where numba is missing)."""
    code = ("import time; from ddmr_cli.cli.bench import _simulation; from ddmr_cli import simulate; "
            f"sim = _simulation({controller!r}, {duration}); t = time.perf_counter(); simulate(sim, [0, 1]); "
            "print(2 * sim.n_steps / (time.perf_counter() - t))")
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
                         capture_output=True, text=True, check=True).stdout
    return float(out.split()[-1])


#: a first tiny run in a new process, printing its seconds (imports, compiled loop loaded or compiled, the run)
_FIRST_RUN = ("import time; t = time.perf_counter(); from ddmr_cli import paper_simulation, simulate; "
              "simulate(paper_simulation('controller=smc_ndo_nno', 'simulation.duration=0.01'), [0]); "
              "print(time.perf_counter() - t)")


def warm_start_time() -> float:
    """Seconds of a first tiny run in a new process with this machine's on-disk cache (filled by section 1)."""
    return float(subprocess.run([sys.executable, "-c", _FIRST_RUN], capture_output=True, text=True,
                                check=True).stdout)


def compile_time() -> tuple[float, float]:
    """Seconds of a first tiny run with empty caches (compilation) and with the caches filled."""
    code = _FIRST_RUN
    cache = tempfile.mkdtemp(prefix="ddmr-numba-cache-")
    try:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "DDMR_CACHE_DIR": cache}
        cold, warm = (float(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                           check=True).stdout) for _ in range(2))
    finally:
        shutil.rmtree(cache, ignore_errors=True)
    return cold, warm


#: Runs the command named after its first argument, then writes its wall seconds and peak RSS (``wait4``'s
#: ``ru_maxrss``, KiB) to the file named first, and exits with its status. Linux counts in a child's peak the
#: memory of the process it was forked from (the image it replaced by ``exec``), so a command forked from the
#: bench's own process read the bench's 230-270 MB (numba, the engine) as its peak; forked from this small
#: interpreter (``python -I -S``, about 10 MB) it reads its own.
_LAUNCHER = """
import os, sys, time
report, argv = sys.argv[1], sys.argv[2:]
started = time.perf_counter()
pid = os.fork()
if pid == 0:
    try:
        os.execv(argv[0], argv)
    finally:
        os._exit(127)
_, status, usage = os.wait4(pid, 0)
with open(report, "w") as fh:
    fh.write(f"{time.perf_counter() - started!r} {usage.ru_maxrss}")
code = os.waitstatus_to_exitcode(status)
sys.exit(code if code >= 0 else 128 - code)
"""


def compose_ahead(args: list[str]) -> float:
    """Compose and validate the jobs of ``ddmr run <args>`` once in this process, untimed by the command's wall, as
    the command itself does first (:func:`ddmr_cli.cli.run.prepare`); returns the seconds it took.

    ddmr keeps the composition of each set of config-group choices on disk (:mod:`ddmr_cli.config.skeleton_cache`),
    keyed by every file of ``conf/``: the first composition of a set after an edit of ``conf/``, or on a new
    machine, is a full Hydra composition (about 0.35 s here; table4 composes 8 sets), every later one a copy. The
    timed commands are the warm ones users repeat, as the compiled step loop is loaded warm (section 1); what the
    first composition costs is printed beside table4's wall."""
    from ddmr_cli.cli.args import normalise, split_args
    from ddmr_cli.cli.run import prepare

    argv = normalise(list(args))
    overrides, flags = split_args(argv)
    started = time.perf_counter()
    prepare(argv, overrides, bool(flags.get("-m") or flags.get("--multirun")))
    return time.perf_counter() - started


def _ddmr(args: list[str], cwd: Path, mark: str | None = None) -> tuple[float, float, float | None]:
    """Run the console script; returns (wall seconds, peak RSS in MB of its largest process: itself or a worker it
    waited for, read by ``wait4`` in a small launcher the command is forked from (:data:`_LAUNCHER`), so neither
    the bench's own memory nor a command run before it counts; the seconds until its stdout first printed a line
    starting with ``mark``, None without one). Both times are the command's own, from its fork (the launcher's
    start-up, about 20 ms, is not in them)."""
    import threading

    exe = shutil.which("ddmr") or str(Path(sys.executable).with_name("ddmr"))
    marked: list[float] = []
    started = time.perf_counter()
    with tempfile.TemporaryFile() as err, tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "usage"
        proc = subprocess.Popen([sys.executable, "-I", "-S", "-c", _LAUNCHER, str(report), exe, *args], cwd=cwd,
                                stdout=subprocess.PIPE, stderr=err)

        def read() -> None:  # drains stdout (a full pipe would stop the command), timing the marked line
            for line in proc.stdout:
                if mark and not marked and line.decode(errors="replace").startswith(mark):
                    marked.append(time.perf_counter() - started)

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        proc.wait()
        outside = time.perf_counter() - started
        reader.join()
        proc.stdout.close()
        if proc.returncode != 0:
            err.seek(0)
            raise RuntimeError(f"ddmr {' '.join(args)} failed:\n{err.read().decode(errors='replace')[-2000:]}")
        wall, peak_kib = report.read_text().split()
    wall = float(wall)
    launcher = max(outside - wall, 0.0)  # the launcher's own start-up and exit
    return wall, int(peak_kib) / 1024.0, (max(marked[0] - launcher, 0.0) if marked else None)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ddmr bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="tiny sizes (seconds): keeps the script from rotting")
    parser.add_argument("--skip-e2e", action="store_true", help="engine figures only")
    args = parser.parse_args(argv)
    quick = args.quick
    started = time.perf_counter()
    print(machine_line())
    print(f"numbers: {'QUICK (tiny sizes, not the targets)' if quick else 'full'}")

    from ddmr_cli.compiled import thread_count

    print("\n1. engine throughput, simulated control steps per second (runs x steps / wall)")
    batches = (1, 10) if quick else (1, 50, 1000)
    durations = {1: 0.3, 10: 0.3} if quick else {1: 3.0, 50: 5.0, 1000: 1.0}
    print(f"   one core (1 thread)" + "".join(f"{'batch ' + str(b):>16}" for b in batches))
    for controller in CONTROLLERS:
        with measuring(f"the engine's throughput, {controller}"):
            engine_throughput(1, controller, 0.02)  # warm-up (imports, cache load)
            figures = [engine_throughput(b, controller, durations[b]) for b in batches]
        print(f"   {controller:<18}" + "".join(f"{f / 1e6:>12.3f} M/s" for f in figures))
    reference_lines(tuple(b for b in batches if b > 1), durations)
    cores, big = thread_count(0), batches[-1]
    if cores > 1 and not quick:  # quick: a tenth of a second of work is too short to read the machine by
        pairs = THREAD_REPEATS
        with measuring(f"one thread against {cores} cores, beside {cores} independent processes and batches"):
            sc = scaling(cores, big, "smc_ndo_nno", durations[big], repeats=pairs)
        one = sc.one
        print(f"   all {cores} cores, batch {big}, smc_ndo_nno: {sc.many / 1e6:.3f} M/s ({sc.ratio:.2f}x one thread; one "
              f"thread {sc.one / 1e6:.3f} M/s), the median of {pairs} rounds, each timing a pair of this line and of "
              f"each ceiling below in turn, so that the host's drift moves the three alike")
        print(f"   this machine's own ceiling: {cores} independent processes of pure CPU work at once run at "
              f"{sc.host:.2f}x one alone, the most {cores} threads can give here; the engine's threads reach "
              f"{sc.of_host:.0%} of it (the median of the rounds' own quotients)")
        print(f"   the engine's own ceiling: {cores} independent batches of the same runs at once, one a thread "
              f"(nothing shared), run at {sc.own:.2f}x one alone; one batch split over {cores} threads reaches "
              f"{sc.of_own:.0%} of it (the rest: the meeting points of its chunks, its serial set-up and metrics)")
    else:
        pairs = REPEATS
        with measuring(f"one thread against {cores} cores"):
            one, many, ratio = thread_scaling(big, "smc_ndo_nno", durations[big], repeats=pairs)
        print(f"   all {cores} cores, batch {big}, smc_ndo_nno: {many / 1e6:.3f} M/s ({ratio:.2f}x one thread: the "
              f"median of {pairs} alternating pairs; one thread {one / 1e6:.3f} M/s)")
    with measuring("the laws as plain Python"):
        python = python_throughput("smc_ndo_nno", 0.05 if quick else 0.2)
    print(f"   the same laws as plain Python (the fallback without numba), smc_ndo_nno: {python / 1e6:.4f} M/s; "
          f"compiled is {one / python:.0f}x that")
    if quick:  # an empty cache compiles every law of the loop (about 30 s): the largest part of a quick bench
        with measuring("a first run in a new process"):
            warm = warm_start_time()
        print(f"   warm-up: with the on-disk cache {warm:.2f} s (every later process; the first run with empty "
              "caches is measured without --quick)")
    else:
        with measuring("a first run with empty caches (compiling, about 30 s) and one with the cache"):
            cold, warm = compile_time()
        print(f"   warm-up: first run with empty caches {cold:.2f} s (compilation), with the on-disk cache {warm:.2f} s "
              "(every later process)")
    if args.skip_e2e:
        control_step_cost(quick)
        physics_lines(quick)
        return 0

    work = Path(tempfile.mkdtemp(prefix="ddmr-bench-"))
    try:
        print("\n2. single `ddmr run` (process start to exit, with plots)")
        extra: list[str] = []
        run_args = ["run", "run.progress=false", f"hydra.run.dir={work / 'single'}", *extra]
        if quick:
            run_args += ["simulation.duration=1.0", "run.n_runs=5"]
        with measuring("a single `ddmr run`"):
            compose_ahead(run_args[1:])
            wall, peak, _ = _ddmr(run_args, work)
        print(f"   wall {wall:.2f} s, peak memory {peak:.0f} MB   {against(wall, 'run', quick)}")

        tiny = ["run.n_runs=2", "simulation.duration=2"] if quick else []
        print(f"\n3. `ddmr run -m +experiment=table4{' ' + ' '.join(tiny) if tiny else ''}` and its report")
        sweep_dir = work / "table4"
        table4_args = ["run", "-m", "+experiment=table4", *tiny, f"hydra.sweep.dir={sweep_dir}", "run.progress=false",
                       *extra]
        with measuring("the table4 sweep"):
            ahead = compose_ahead(table4_args[1:])
            wall, peak, _ = _ddmr(table4_args, work)
        print(f"   sweep wall {wall:.2f} s, peak memory per process {peak:.0f} MB   {against(wall, 'table4', quick)}; "
              f"its jobs composed and validated once before, untimed: {ahead:.2f} s (a first composition after an "
              "edit of conf/ is about 0.35 s a set of group choices)")
        sweep_wall = wall
        from ddmr_cli.cli.reporting import VERDICTS_HEADER

        figures = ["--no-figures"] if quick else []  # drawing costs the same at any size; tests draw every figure
        with measuring("its report"):
            wall, peak, answer = _ddmr(["report", str(sweep_dir), "--out", str(work / "report"), *figures], work,
                                       VERDICTS_HEADER)
        verdicts = f" (its verdicts printed after {answer:.2f} s)" if answer is not None else ""
        both = sweep_wall + wall
        print(f"   report wall{' without its figures (--quick)' if quick else ''} {wall:.2f} s{verdicts}, peak memory "
              f"{peak:.0f} MB; sweep and report {both:.2f} s   {against(both, 'table4+report', quick)}")

        n_jobs = 10 if quick else 200
        print(f"\n3b. a sweep of {n_jobs} jobs of one seed and 0.2 s each (per-job overhead)")
        jobs_args = ["run", "-m", "run.n_runs=1", "simulation.duration=0.2", f"run.base_seed=range(0,{n_jobs})",
                     "run.plots=false", "run.progress=false", f"hydra.sweep.dir={work / 'jobs'}"]
        with measuring(f"a sweep of {n_jobs} jobs"):
            compose_ahead(jobs_args[1:])
            wall, peak, _ = _ddmr(jobs_args, work)
        print(f"   wall {wall:.2f} s, {1000 * wall / n_jobs:.0f} ms a job in all, peak memory per process {peak:.0f} MB"
              f"   {against(wall / n_jobs, 'job', quick)}")
        with measuring("Hydra's own work per job"):
            low, median = hydra_job_floor(10 if quick else 30)
        cores = os.cpu_count() or 1
        print(f"   Hydra's own work per job (hydra.core.utils.run_job around a task that does nothing: its config copies "
              f"and the job's three .hydra files): {low:.0f} ms min, {median:.0f} ms median of one core, so at least "
              f"{low / cores:.0f} ms a job on {cores} cores before any of ddmr's own work")

        n_seeds = 100 if quick else 10_000
        print(f"\n4. one {n_seeds}-seed scenario-1 run of 15 s (metrics only)")
        many_args = ["run", f"run.n_runs={n_seeds}", "run.keep_series=[]", "run.plots=false", "run.progress=false",
                     f"hydra.run.dir={work / 'many'}", *extra]
        with measuring(f"a run of {n_seeds:,} seeds"):
            compose_ahead(many_args[1:])
            wall, peak, _ = _ddmr(many_args, work)
        print(f"   wall {wall:.2f} s, peak memory {peak:.0f} MB   (target < 200 MB for 10,000 seeds)")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    control_step_cost(quick)
    physics_lines(quick)
    wall = time.perf_counter() - started
    print(f"\nddmr bench{' --quick' if quick else ''}: {wall:.1f} s in all"
          + (f"   {against(wall, 'quick')}" if quick else ""))
    return 0


def physics_lines(quick: bool) -> None:
    """Section 6: the physics plant's speed (:mod:`ddmr_cli.bench.physics`), or why it is skipped."""
    import importlib.util

    from ddmr_cli.plant.mujoco import EXTRA_HINT

    print("\n6. physics plant (plant=mujoco): plant steps per second on the paper terrain, dt 1 ms")
    if importlib.util.find_spec("mujoco") is None:
        print(f"   (skipped: {EXTRA_HINT})")
        return
    from ddmr_cli.bench.physics import plant_throughput

    runs, seconds = (6, 0.2) if quick else (50, 2.0)
    for threads in (1, 0):
        with measuring(f"the physics plant, {'1 thread' if threads == 1 else 'every core'}"):
            r = plant_throughput(runs, seconds, threads)
        print(f"   {r.runs} runs x {r.steps} steps, {r.threads} thread(s): {r.rate:,.0f} steps/s; of the wall "
              f"{r.mujoco / r.wall:.0%} in MuJoCo, {r.plant / r.wall:.0%} in the plant's own Python, "
              f"{1 - (r.mujoco + r.plant) / r.wall:.0%} in the wheel-speed loop; reset {r.reset:.2f} s; "
              f"table4_physics (400 runs x 15 s) at this rate: {400 * 15000 / r.rate / 60:.1f} min")


def reference_lines(batches: tuple[int, ...], durations: dict[int, float], repeats: int = REPEATS) -> None:
    """Section 1's comparison with the reference kernel (:func:`reference_comparison`), one line per controller and
    batch size."""
    from ddmr_cli.compiled import jit_enabled
    from ddmr_cli.errors import ConfigError

    print(f"   against the reference kernel (ddmr_cli/bench/reference.py: the same loop and noise streams hand-fused "
          f"into one numba loop, runs as its SIMD axis, Table 4 metrics only), one core, median of {repeats} "
          f"alternating runs each; the engine as `ddmr run` runs it (every metric, segment and seed band) and without "
          f"the seed bands (nearer equal work: it still keeps every metric and segment); the kernel computing the "
          f"engine's numbers (its exact layout: libm's sine and cosine, no fast-math flag) and with fast numerics (its "
          f"lanes layout: fdlibm's vectorised sine and cosine and fused multiply-adds, within about 1e-13 of the "
          f"engine's numbers, not the bit; the engine cannot take them: a last bit grows to 1e-8 in some metrics):")
    if not jit_enabled():
        print("   (skipped: the reference kernel is compiled code, and numba is off)")
        return
    for controller in REFERENCE_CONTROLLERS:
        for batch in batches:
            try:
                with measuring(f"the engine beside the reference kernel, {controller}, batch {batch}"):
                    engine, bare, exact, fast = reference_comparison(batch, controller, durations[batch], repeats)
            except ConfigError as exc:  # the packaged config moved off the loop the kernel runs
                print(f"   {controller:<14}batch {batch:<6}(skipped: {exc})")
                continue
            print(f"   {controller:<14}batch {batch:<6}engine {engine / 1e6:7.3f} M/s, without bands {bare / 1e6:7.3f} "
                  f"M/s; reference {exact / 1e6:7.3f} M/s at the engine's numbers: the engine takes "
                  f"{exact / engine:.2f}x its time, {exact / bare:.2f}x without bands (target <= "
                  f"{REFERENCE_TARGET:g}x at equal work)")
            print(f"   {'':<14}{'':<12}reference with fast numerics {fast / 1e6:7.3f} M/s ({fast / exact:.2f}x the "
                  f"exact layout's speed): the engine takes {fast / engine:.2f}x its time, {fast / bare:.2f}x without "
                  f"bands")


def cost_lines(rows: list[dict]) -> list[str]:
    """The cost-per-step table as text lines (also the report's, :mod:`ddmr_cli.report.build`)."""
    lines = [f"   {'controller':<14}{'ns/step min':>12}{'median':>9}{'flops':>8}{'exp/tanh':>10}{'div':>6}"
             f"{'M4F cycles':>12}{'M4F us':>8}{'1 kHz budget':>14}"]
    for r in rows:
        lines.append(f"   {r['controller']:<14}{r['ns_min']:>12.1f}{r['ns_median']:>9.1f}{r['flops']:>8.1f}"
                     f"{r['transcendental']:>10.1f}{r['divisions']:>6.1f}{r['m4f_cycles']:>12.0f}"
                     f"{r['m4f_us']:>8.2f}{100 * r['budget_1khz']:>13.2f}%")
    return lines


def control_step_cost(quick: bool) -> None:
    """Section 5: the cost of one control step of each controller's laws (:mod:`ddmr_cli.bench.cost`)."""
    from ddmr_cli.bench.cost import assumptions, cost_table

    print("\n5. cost of a control step (the controller's command + update laws alone, compiled, one run, warm)")
    names = [CONTROLLERS[0], CONTROLLERS[-1]] if quick else list(CONTROLLERS)  # quick: the cheapest and the dearest
    with measuring("the cost of a control step"):
        rows = cost_table(names, repeats=5 if quick else 30, n=200 if quick else 2000)
    print("\n".join(cost_lines(rows)))
    print(f"   {assumptions()}")


if __name__ == "__main__":
    sys.exit(main())
