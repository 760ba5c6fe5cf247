"""A warm kernel cache runs exactly the code a cold one compiles (issue 31; ddmr_cli/engine/kernels.py).

The mechanism: the compiled step loop's on-disk copy was named after the controller's law module and state layout
only, so every other argument type (the run record, whose delay line's length then depended on ``actuator.delay``;
the sensor's state; the World) shared one copy, and numba's index beside it collected one entry per signature (16
after ordinary use). numba's index is not safe against two processes saving different signatures of one function
at once: both read it, both choose data file 1, and the index can end up naming one signature while the file
holds the other's code; the next process running that layout loads the other layout's code (``TypeError: can't
unbox array`` where the record sizes differ; where they agree it would run). Two sweep workers compiling one
controller for two delays did that. The copy's name now holds the call's complete argument types, so each copy's
index holds one signature, and what numba hands back is checked against the call before the first step. Since
the delay line left the run record (an array beside it: its length is not its type), every delay runs one loop;
two state layouts of one law module (SMC's and SMC-NDO's records) are what two workers compile at once now.

Tests: the race made deterministic; a swapped entry named and recompiled; one loop for every delay; warm numbers
equal cold ones bit for bit, across processes, in mixed orders and in a reused joblib worker (fast: pid x 3
delays; slow: every controller preset x 6 realism points x both scenarios, 144 jobs). The cold numbers come from
the two processes that fill the cache, each compiling every loop it runs (checked by numba's cache counters), so
each signature is compiled once: the 144-job matrix took 705 s of the suite when a separate cold pass compiled
everything again, 261-313 s when each delay compiled its own loop.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest

from ddmr_cli.compiled import AVAILABLE, jit_enabled

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="the disk cache is numba's")

#: runs each job given as controller:scenario:realism (``-`` for none) and prints {job: per-seed metrics}
_SCRIPT = textwrap.dedent("""
    import json, sys
    from ddmr_cli import paper_simulation, simulate
    from ddmr_cli.errors import ConfigError

    def job(spec):
        controller, scenario, realism = spec.split(":")
        overrides = [f"controller={controller}", f"scenario={scenario}", "simulation.duration=0.06"]
        if "=" in realism:  # an override of its own (controller.nn.n_neurons=5)
            overrides.append(realism)
        elif realism != "-":
            overrides.append(f"+realism={realism}")
        try:
            r = simulate(paper_simulation(*overrides), [3, 4])
        except ConfigError as exc:  # a controller that refuses a realism point (e.g. 250 Hz) refuses it warm too
            return [f"refused: {exc}"]
        return [float(v).hex() for name in ("deviation_mae", "e_x_mae", "chattering", "d_est_mae")
                for v in r.metric(name)]

    def jobs(specs):
        return {spec: job(spec) for spec in specs}

    def cache_counts():  # step loops (signatures of run_chunk copies) this process loaded from the cache, compiled
        loops = [m.run_chunk for name, m in list(sys.modules.items())
                 if name.startswith(("ddmr_stepper_", "ddmr_lanes_"))]
        return [sum(len(f.stats.cache_hits) for f in loops),  # signatures, each counted once
                sum(len(f.stats.cache_misses) for f in loops)]

    if __name__ == "__main__":
        if sys.argv[1] == "joblib":  # one reused loky worker runs every batch, one after another
            from joblib import Parallel, delayed
            batches = [sys.argv[2:][i::2] for i in range(2)] * 2
            out = {}
            for part in Parallel(n_jobs=1, backend="loky")(delayed(jobs)(b) for b in batches):
                for spec, values in part.items():
                    assert out.setdefault(spec, values) == values, spec
        else:
            out = jobs(sys.argv[1:])
        print(json.dumps({"jobs": out, "loaded_compiled": cache_counts()}))
""")


#: one process of two that compile one law module for two state layouts into one cache at once, made to save
#: in the one order numba's index does not survive (see test_two_processes_saving_at_once_...)
_RACE = textwrap.dedent("""
    import os, sys, time
    from pathlib import Path
    from numba.core import caching

    sync, role = Path(sys.argv[1]), sys.argv[2]
    other = {"a": "b", "b": "a"}[role]
    save_index, save_data = caching.IndexDataCacheFile._save_index, caching.IndexDataCacheFile._save_data

    def wait(name):
        deadline = time.monotonic() + 300
        while not (sync / name).exists():
            if time.monotonic() > deadline:
                raise TimeoutError(name)
            time.sleep(0.02)

    def signal(name):
        (sync / name).touch()

    def hooked_index(self, overloads):  # both processes have read the index and chosen a data file name
        if "run_chunk" in self._index_name:
            signal(f"{role}_picked")
            wait(f"{other}_picked")
            if role == "b":
                wait("a_index")
        save_index(self, overloads)
        if "run_chunk" in self._index_name:
            signal(f"{role}_index")

    def hooked_data(self, name, data):  # b writes its data, then a writes its own
        if "run_chunk" in self._index_name and role == "a":
            wait("b_data")
        save_data(self, name, data)
        if "run_chunk" in self._index_name:
            signal(f"{role}_data")

    caching.IndexDataCacheFile._save_index = hooked_index
    caching.IndexDataCacheFile._save_data = hooked_data
    from ddmr_cli import paper_simulation, simulate
    simulate(paper_simulation(f"controller={sys.argv[3]}", "scenario=paper_2", "simulation.duration=0.02"), [3])
""")


def _run(cache: Path, *args: str, log: list | None = None, counts: list | None = None) -> dict:
    """The jobs' per-seed numbers from one process with ``cache`` as its cache; ``counts`` gets how many step-loop
    signatures that process loaded from the cache and how many it compiled."""
    script = cache.parent / "cache_job.py"
    script.write_text(_SCRIPT)
    env = {**os.environ, "DDMR_CACHE_DIR": str(cache)}
    p = subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, env=env, timeout=1200)
    assert p.returncode == 0, p.stderr[-3000:]
    if log is not None:
        log.append(p.stderr)
    out = json.loads(p.stdout.strip().splitlines()[-1])
    if counts is not None:
        counts.append(tuple(out["loaded_compiled"]))
    return out["jobs"]


def _entries_per_copy(cache: Path) -> Counter:
    """How many compiled signatures numba's index holds for each generated copy's run_chunk (one .nbc each)."""
    pattern = re.compile(r"^(ddmr_(?:stepper|lanes)_\w+?)\.run_chunk-\d+\.py\d+\.\d+\.nbc$")
    found = (pattern.match(p.name) for p in (cache / "kernels" / "__pycache__").glob("*.nbc"))
    return Counter(m.group(1) for m in found if m)


def _check(tmp_path: Path, halves: tuple[list[str], list[str]]) -> dict:
    """Two processes fill one cache, each with half of the jobs; the halves share no compiled signature, so each
    process compiles every loop it runs and loads none (checked): their numbers are what a cold cache computes.
    Then a third process runs every job in another order and loads every loop, compiling none, and one reused
    joblib worker runs them all twice: both must give the cold numbers bit for bit."""
    warm, counts = tmp_path / "warm", []
    cold = {**_run(warm, *halves[0], counts=counts), **_run(warm, *halves[1][::-1], counts=counts)}
    assert all(loaded == 0 and compiled > 0 for loaded, compiled in counts), counts  # cold: nothing loaded
    jobs = [*halves[0], *halves[1]]
    mixed = _run(warm, *jobs[::-1], counts=counts)  # a third loads every copy, in another order
    assert counts[-1] == (sum(compiled for _, compiled in counts[:2]), 0), counts  # ... and compiles none
    reused = _run(warm, "joblib", *jobs)  # one reused joblib worker runs them all, twice
    for spec in jobs:
        assert mixed[spec] == cold[spec], spec
        assert reused[spec] == cold[spec], spec
    entries = _entries_per_copy(warm)
    assert entries and max(entries.values()) == 1, entries  # one signature per copy: nothing to confuse
    return cold


def test_two_processes_saving_at_once_keep_each_layouts_code_apart(tmp_path):
    """The mechanism of issue 31, made deterministic. numba's index is not safe against two processes that save
    different signatures of one function at once: each reads the index, both choose data file 1, and in the
    order forced here the index ends up naming b's signature while data file 1 holds a's code. The next process
    that runs b's layout loads a's code (``TypeError: can't unbox array``: the record's size differs; where the
    sizes agree it would run). Two sweep workers compiling one law module for two state layouts (SMC's and
    SMC-NDO's records; two delays, when the delay line was in the run record) do just that. With one signature
    per copy, the two processes save to two files and nothing is shared."""
    sync, cache = tmp_path / "sync", tmp_path / "warm"
    sync.mkdir()
    script = tmp_path / "race.py"
    script.write_text(_RACE)
    env = {**os.environ, "DDMR_CACHE_DIR": str(cache)}
    racers = [subprocess.Popen([sys.executable, str(script), str(sync), role, controller], env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
              for role, controller in (("a", "smc"), ("b", "smc_ndo"))]
    for racer in racers:
        _, err = racer.communicate(timeout=600)
        assert racer.returncode == 0, err[-3000:]
    assert len(_entries_per_copy(cache)) == 2  # two layouts of one module: two copies
    job = "smc_ndo:paper_2:-"
    assert _run(cache, job) == _run(tmp_path / "cold", job)


def test_a_cache_entry_compiled_for_another_call_is_named_and_recompiled(tmp_path):
    """Two copies' compiled code swapped on disk (what the race above left behind): each load is caught before a
    step, named on stderr, deleted and recompiled, and the numbers are the cold ones."""
    cache, jobs = tmp_path / "warm", ["smc:paper_2:-", "smc_ndo:paper_2:-"]
    cold = _run(cache, *jobs)
    one, other = sorted((cache / "kernels" / "__pycache__").glob("ddmr_*.run_chunk-*.1.nbc"))
    one_bytes, other_bytes = one.read_bytes(), other.read_bytes()
    one.write_bytes(other_bytes)
    other.write_bytes(one_bytes)
    log = []
    assert _run(cache, *jobs, log=log) == cold
    assert log[0].count("deleting it and recompiling") == 2, log[0][-3000:]
    assert _run(cache, *jobs[::-1], log=log) == cold and "recompiling" not in log[1]  # the new entries load


def test_one_compiled_loop_serves_every_actuator_delay(tmp_path):
    """The delay line is an array beside the run record, so its length is not part of the loop's type: a process
    running no delay and two delays compiles one loop for the three (the loop by blocks of runs); a loop compiled
    first for no delay gives a delay's numbers bit for bit (against a process that compiled for that delay alone); a
    later process loads it and compiles nothing. The delays change the numbers (the line is used)."""
    jobs, counts = ["pid:paper_2:delay_5ms", "pid:paper_2:-", "pid:paper_2:delay_2ms"], []
    alone = _run(tmp_path / "alone", jobs[0], counts=counts)  # compiled for the 5 ms line (6 rows)
    first_ideal = _run(tmp_path / "warm", *jobs[1:], jobs[0], counts=counts)  # no line (1 row), then 3 rows, then 6
    again = _run(tmp_path / "warm", *jobs[::-1], counts=counts)
    assert counts == [(0, 1), (0, 1), (1, 0)], counts
    assert first_ideal[jobs[0]] == alone[jobs[0]]
    assert again == first_ideal
    assert len({tuple(values) for values in first_ideal.values()}) == 3, first_ideal


def test_one_compiled_loop_serves_every_network_size_of_a_block(tmp_path):
    """The state record holds the RBF network in blocks of NEURON_BLOCK neurons, so the sizes 5, 10 and 15 (the
    sensitivity study's first three) share one record layout: a process running the three compiles one loop; that
    loop, compiled first for 10 neurons, gives 5 neurons' numbers bit for bit (against a process that compiled for 5
    alone); the sizes change the numbers (the laws run over n neurons). The next block is another layout."""
    from ddmr_cli.control import rbf
    from ddmr_cli.control.smc import SMC

    def fields(n):
        nn = rbf.RBFNetworkObserver(n_neurons=n, width=2.0, learning_rate=50.0, center_min=-40.0, center_max=40.0)
        return SMC(lam=25.0, switching_gain=12.0, boundary_layer=0.1, surface="proportional", switching="sat",
                   nn=nn).state_fields()

    assert rbf.NEURON_BLOCK == 16 and fields(1) == fields(5) == fields(16) != fields(17) == fields(32)
    jobs, counts = [f"smc_ndo_nno:paper_1:controller.nn.n_neurons={n}" for n in (5, 10, 15)], []
    alone = _run(tmp_path / "alone", jobs[0], counts=counts)
    shared = _run(tmp_path / "warm", jobs[1], jobs[2], jobs[0], counts=counts)
    assert counts == [(0, 1), (0, 1)], counts
    assert shared[jobs[0]] == alone[jobs[0]]
    assert len({tuple(values) for values in shared.values()}) == 3, shared


#: the realism points of the full matrix: ideal, a delay, a control rate, an encoder, speed noise, and all at once
_REALISM = ("-", "delay_5ms", "rate_250hz", "counts_1024", "noise_0.2", "realistic")


@pytest.mark.slow
def test_a_warm_cache_filled_by_every_controller_and_realism_point_runs_cold_numbers(tmp_path):
    """Every controller preset x 6 realism points x both scenarios (144 jobs) in one cache, against cold numbers.

    The cache is filled by two processes, each running every job of half of the controllers, so the halves share
    no compiled signature and both run cold (checked: they load nothing); every signature is compiled once. The
    halves split the controllers by law module: controllers of one module (smc, smc_ndo, smc_nno, ...) share a
    compiled loop wherever their argument types agree, so they go in one half. Cost: see the module
    docstring."""
    from ddmr_cli import paper_simulation

    controllers = sorted(p.stem for p in (Path(__file__).parents[1] / "conf" / "controller").glob("*.yaml"))
    by_module = {}
    for c in controllers:
        by_module.setdefault(paper_simulation(f"controller={c}").controller.laws.__name__, []).append(c)
    halves = ([], [])
    for module in sorted(by_module, key=lambda m: (-len(by_module[m]), m)):  # largest first, to the shorter half
        min(halves, key=len).extend(f"{c}:{s}:{r}" for c in by_module[module] for r in _REALISM
                                    for s in ("paper_1", "paper_2"))
    cold = _check(tmp_path, halves)
    assert len(cold) == 144
    refused = [job for job, values in cold.items() if values[0].startswith("refused")]
    assert len(refused) < len(cold) // 4, refused  # most of the matrix runs (some controllers refuse 250 Hz)


def test_the_identity_spells_nested_shapes_and_tuple_classes():
    import numpy as np

    from ddmr_cli.engine.kernels import call_identity

    one = np.zeros(2, dtype=[("delay_line", "f8", (3, 2))])
    other = np.zeros(2, dtype=[("delay_line", "f8", (6, 2))])
    assert call_identity((one,)) != call_identity((other,))
    assert "(3, 2)" in call_identity((one,)) and "(6, 2)" in call_identity((other,))


@pytest.mark.skipif(not AVAILABLE, reason="numba is not installed")
def test_the_identity_kept_by_fingerprint_is_numbas_typing():
    """call_identity keeps each identity by the arguments' fingerprint: values of one fingerprint have one numba
    type, and the kept identity is the one typing the arguments gives, for every kind of argument the loops take."""
    import itertools
    from collections import namedtuple

    import numpy as np

    from ddmr_cli.engine import kernels

    Pair = namedtuple("Pair", "a b")
    base = np.zeros((3, 4))
    readonly = np.zeros(5)
    readonly.setflags(write=False)
    record = np.dtype([("x", "f8"), ("w", "f8", (2,))])
    values = [
        base, base.T, base[:, ::2], base[0], readonly, np.zeros(5), np.zeros(5, dtype=np.int64),
        np.zeros(5, dtype=np.float32), np.zeros(5, dtype=bool), np.zeros(0), np.zeros(3, dtype=record),
        np.zeros(3, dtype=np.dtype([("x", "f8"), ("w", "f8", (3,))])), np.zeros(3, dtype=np.dtype(
            [("x", "f8"), ("w", "f8", (2,))], align=True)), np.zeros((1, 1)), np.zeros((2, 1), order="F"),
        0, 7, 2 ** 63, -(2 ** 63), True, 1.5, np.float64(1.5), np.int32(3), np.float32(2.0),
        (1.0, 2.0), (1.0, 2), Pair(1.0, 2.0), Pair(np.zeros(2), 1.0), (np.zeros(2), (1, 2.0)),
    ]
    by_fingerprint = {}
    for value in values:
        args = (value,)
        typed = kernels._typed_identity(args)
        assert kernels.call_identity(args) == typed and kernels.call_identity(args) == typed  # kept, then reused
        by_fingerprint.setdefault(kernels._fingerprint(args), set()).add(typed)
    assert all(len(types) == 1 for types in by_fingerprint.values()), by_fingerprint
    for a, b in itertools.combinations(values[:6], 2):  # arrays of other layouts or flags: other identities
        if kernels._typed_identity((a,)) != kernels._typed_identity((b,)):
            assert kernels._fingerprint((a,)) != kernels._fingerprint((b,))


def test_the_cache_key_covers_what_the_loop_inlines_and_only_that():
    """Editing one controller's module changes that controller's key alone; editing a law every loop inlines (the
    stepper, the plant's robot.py) changes every key; the RBF network's module is SMC's, not PID's (issue 27)."""
    from pathlib import Path

    from ddmr_cli.engine import kernels

    modules = ("ddmr_cli.control.pid", "ddmr_cli.control.smc", "ddmr_cli.control.adrc")
    base = {m: kernels.sources_digest(m) for m in modules}

    def edited(name):
        def read(path: Path) -> bytes:
            data = path.read_bytes()
            return data + b"\n# edited\n" if path.name == name else data
        return {m: kernels.sources_digest(m, read=read) for m in modules}

    changed = {name: {m for m, d in edited(name).items() if d != base[m]}
               for name in ("pid.py", "rbf.py", "adrc.py", "stepper.py", "robot.py")}
    assert changed == {"pid.py": {"ddmr_cli.control.pid"}, "rbf.py": {"ddmr_cli.control.smc"},
                       "adrc.py": {"ddmr_cli.control.adrc"}, "stepper.py": set(modules), "robot.py": set(modules)}


def test_the_import_scan_finds_imports_nested_in_any_block():
    """The cache key's import scan visits statements only; an import nested in a function, class, branch, loop,
    ``try`` (body, handler, else, finally), ``with`` or ``match`` block is found as a full walk of the tree finds it."""
    import ast

    from ddmr_cli.engine import kernels

    source = b"""
import top
def f():
    import in_function
    class C:
        from pkg import in_class
    if x:
        import in_if
    else:
        import in_else
    for i in y:
        import in_for
    while z:
        import in_while
    try:
        import in_try
    except E:
        import in_except
    else:
        import in_try_else
    finally:
        import in_finally
    with w:
        from . import relative
    match v:
        case 1:
            import in_case
"""
    scanned = {(m, level, names) for m, level, names in kernels._import_statements(source)}
    walked = {(None, 0, tuple(a.name for a in n.names)) if isinstance(n, ast.Import)
              else (n.module, n.level, tuple(a.name for a in n.names))
              for n in ast.walk(ast.parse(source)) if isinstance(n, (ast.Import, ast.ImportFrom))}
    assert scanned == walked and len(scanned) == 13


def test_a_relative_import_is_not_read_as_an_absolute_one(tmp_path):
    """``from . import ddmr_cli`` names no module of the package (relative imports are left out, as before the scan
    visited statements only); ``import ddmr_cli.engine.bands`` does."""
    from ddmr_cli.engine import kernels

    relative, absolute = tmp_path / "relative.py", tmp_path / "absolute.py"
    relative.write_text("from . import ddmr_cli\n")
    absolute.write_text("import ddmr_cli.engine.bands\n")
    assert kernels._imported_modules(relative) == set()
    assert kernels._imported_modules(absolute) == {"ddmr_cli.engine.bands"}


def test_the_controller_slot_is_the_only_substitution():
    """The template takes the controller's four laws from engine/controller_slot.py; a copy differs from the
    template in exactly those four import lines (and the cached-law import), pointed at the controller's module."""
    import inspect

    from ddmr_cli.engine import kernels, stepper

    template = inspect.getsource(stepper).splitlines()
    copy = kernels._source_for("ddmr_cli.control.smc").splitlines()[1:]  # the first line names the copy's origin
    assert len(copy) == len(template)
    differ = [(a, b) for a, b in zip(template, copy) if a != b]
    assert len(differ) == 5
    slot_lines = [b for a, b in differ if "controller_slot" in a]
    assert len(slot_lines) == 4 and all(b.startswith("from ddmr_cli.control.smc import ") for b in slot_lines[:1])


@pytest.mark.skipif(not AVAILABLE, reason="numba is a dependency; tests/test_fallback.py covers its absence")
def test_the_step_loop_is_compiled_without_reference_counting_and_refuses_to_allocate(tmp_path, monkeypatch):
    """The generated copies of the step loop are compiled by :func:`ddmr_cli.compiled.loop_law`, without numba's
    atomic reference counting (``_nrt=False``), which cost the loop about 40 % of its time; a function that
    allocates cannot compile so (an error, never a loop that frees what it should not)."""
    import numpy as np

    from ddmr_cli.compiled import law, loop_law
    from ddmr_cli.config.presets import paper_simulation
    from ddmr_cli.engine import kernels
    from ddmr_cli.engine.simulation import simulate

    monkeypatch.setenv("DDMR_CACHE_DIR", str(tmp_path))
    simulate(paper_simulation("controller=pid", "simulation.duration=0.01"), [0], lanes=False)
    copies = [m for name, m in sys.modules.items() if name.startswith("ddmr_stepper_ddmr_cli_control_pid_")]
    assert copies and all(m.run_chunk.targetoptions.get("_nrt") is False for m in copies)
    assert "import loop_law as law" in kernels._source_for("ddmr_cli.control.pid")

    source = tmp_path / "allocating.py"
    source.write_text("import numpy as np\n\ndef fresh(n):\n    return np.zeros(n).sum()\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import allocating
    finally:
        sys.path.remove(str(tmp_path))
    assert law(allocating.fresh)(3) == 0.0  # a law compiled with counting allocates
    from numba.core.errors import TypingError

    with pytest.raises(TypingError, match="zeros"):
        loop_law(allocating.fresh)(3)


@pytest.mark.skipif(not AVAILABLE, reason="numba is a dependency; tests/test_fallback.py covers its absence")
def test_a_numba_without_the_option_compiles_the_loop_with_counting(monkeypatch):
    """``_nrt`` is not numba's public API: where a numba lacks it, the loop compiles with counting instead of failing
    at its first compile."""
    from numba.core.cpu import CPUTargetOptions

    from ddmr_cli.compiled import without_counting

    assert without_counting() == {"_nrt": False}
    monkeypatch.setattr(CPUTargetOptions, "_nrt", None, raising=False)  # a numba whose table lacks it
    assert without_counting() == {}


# --- other templates of the step loop's kind: the cost of a control step (ddmr_cli/bench/control_loop.py) -------

def test_a_template_copy_runs_the_controllers_laws_and_is_loaded_from_disk(tmp_path):
    """The cost loop's copy for a controller runs that controller's laws (not the slot's open loop), and a second
    process loads it from the disk cache without compiling."""
    script = textwrap.dedent("""
        import json
        from ddmr_cli import paper_controller, paper_robot
        from ddmr_cli.bench.cost import CONTROL_LOOP, inputs
        from ddmr_cli.engine.kernels import compiled_copy
        from ddmr_cli.model.robot import NominalModel

        pid = paper_controller("pid")
        p = pid.law_parameters(NominalModel.from_robot(paper_robot()), 1e-3)
        w, wd, wdd = inputs(50, 1e-3)
        compiled = []
        steps = compiled_copy(CONTROL_LOOP, pid.laws.__name__, "control_steps", (p, pid.initial_state(1), w, wd, wdd),
                              lambda: compiled.append(True))
        total = steps(p, pid.initial_state(1), w, wd, wdd)
        st, expected = pid.initial_state(1)[0], 0.0  # the same loop in Python over pid's own laws
        pid.laws.start(p, st, w[0, 0], w[0, 1])
        for i in range(len(w)):
            u_R, u_L = pid.laws.command(p, st, i, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], wdd[i, 0], wdd[i, 1])
            pid.laws.update(p, st, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], u_R, u_L, u_R, u_L, False, False)
            expected += u_R + u_L
        print(json.dumps({"compiled": bool(compiled), "total": total, "expected": expected,
                          "module": steps.__module__}))
    """)
    env = {**os.environ, "DDMR_CACHE_DIR": str(tmp_path / "cache")}
    runs = [json.loads(subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                                      check=True).stdout.strip().splitlines()[-1]) for _ in range(2)]
    assert [r["compiled"] for r in runs] == [True, False]
    for r in runs:
        assert abs(r["total"]) > 1.0
        assert r["total"] == pytest.approx(r["expected"], rel=1e-12, abs=1e-12)
        assert r["module"].startswith("ddmr_control_loop_ddmr_cli_control_pid_")


def test_a_template_must_take_its_laws_from_the_slot_in_the_form_replaced(tmp_path, monkeypatch):
    """A template with another kind of import of the slot would keep the open loop's laws there: refused."""
    from ddmr_cli.engine import kernels

    copy = kernels._source_for("ddmr_cli.control.pid", "ddmr_cli.bench.control_loop")
    assert "from ddmr_cli.control.pid import command as controller_command" in copy
    assert "\nfrom ddmr_cli.engine.controller_slot" not in copy and "import loop_law as law" in copy
    bad = tmp_path / "bad_template.py"
    bad.write_text("from ddmr_cli.compiled import law\n"
                   "from ddmr_cli.engine.controller_slot import command as controller_command  # controller laws\n"
                   "from ddmr_cli.engine import controller_slot\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(RuntimeError, match="bad_template"):
        kernels._source_for("ddmr_cli.control.pid", "bad_template")


def test_a_copy_recompiled_after_a_bad_entry_keeps_the_options_it_was_made_with(tmp_path):
    """A copy whose cache entry does not load is recompiled with its own options: a step loop's division by zero
    still gives inf (numpy's error model), and the entry saved for later processes is the same code."""
    import importlib.util

    from ddmr_cli.engine.kernels import _checked

    path = tmp_path / "ddmr_recompile_probe.py"
    path.write_text("from ddmr_cli.compiled import loop_law\n\n\n@loop_law\ndef ratio(a, b):\n    return a / b\n")
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    made_with = dict(module.ratio.targetoptions)
    index = Path(module.ratio._cache._cache_file._index_path)
    index.parent.mkdir(exist_ok=True)
    index.write_bytes(b"not an index")  # an entry that does not load
    [ratio] = _checked(module, [("ratio", (1.0, 0.0))], None)
    assert ratio is not module.ratio and ratio.targetoptions == made_with
    assert ratio(1.0, 0.0) == float("inf")


def test_a_process_that_loads_its_step_loop_runs_it_without_numbas_compiler(tmp_path):
    """A cached step loop loads without numba's compiler rules (compiled.LoadingCache): the process that compiled
    the loop imported them (numba.np.linalg among them), the process that loads it does not, and the two give the
    same numbers to the bit."""
    script = ("import sys; from ddmr_cli import paper_simulation, simulate; "
              "r = simulate(paper_simulation('controller=pid', 'simulation.duration=0.06'), [3, 4]); "
              "print([float(v).hex() for v in r.metric('deviation_mae')], 'numba.np.linalg' in sys.modules)")
    env = {**os.environ, "DDMR_CACHE_DIR": str(tmp_path)}
    runs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
        runs.append(proc.stdout.strip().rsplit(" ", 1))
    (cold, cold_rules), (warm, warm_rules) = runs
    assert warm == cold and (cold_rules, warm_rules) == ("True", "False")


@pytest.mark.skipif(not jit_enabled(), reason="compiled code only (numba missing or NUMBA_DISABLE_JIT set)")
def test_the_entry_point_past_numbas_typing_only_for_calls_of_the_compiled_types():
    """kernels.entry_point hands the engine the compiled signature's entry point (no typing at every call) only when
    every call's arguments have the types the signature was compiled for; otherwise numba's dispatcher, which types
    them (and compiles or refuses)."""
    import numpy as np
    from numba import njit

    from ddmr_cli.engine.kernels import entry_point

    @njit
    def first_plus(a, k):
        return a[0] + k

    a = np.ones(3)
    first_plus(a, 1)
    direct = entry_point(first_plus, [(a, 1), (np.zeros(3), 2), (a, 3)])
    assert direct is not first_plus and direct(np.full(2, 5.0), 2) == 7.0
    assert entry_point(first_plus, [(a, 1), (np.ones(6)[::2], 2)]) is first_plus  # a strided array: another type
    assert entry_point(first_plus, [(a, 1), (a, 2.0)]) is first_plus  # a float where the int was
    assert entry_point(first_plus, [(a, 1), (a, 2 ** 70)]) is first_plus  # an int past 64 bits
    assert entry_point(first_plus, [(a, 1), (a,)]) is first_plus
    first_plus(a, 1.5)  # a second signature: the dispatcher chooses
    assert entry_point(first_plus, [(a, 1)]) is first_plus
