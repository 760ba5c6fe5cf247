"""The cost of a control step (docs/model.md §10): time of the controller's laws alone, their operation counts and
an estimate for a Cortex-M4F.

* **Time**: the controller's ``command`` and ``update`` laws, compiled, for one run over ``n`` control steps of
  recorded-like inputs (:func:`control_steps`), timed warm (after a first call) ``repeats`` times; min and median
  ns per step on this CPU. Nothing else of the loop (outer loop, plant, metrics) is inside.
* **Operation counts**: by instrumenting the pure-Python fallback (:func:`count_operations`, run where numba is
  off: ``NUMBA_DISABLE_JIT=1``): every float the laws see (inputs, parameters, state) is a counting float whose
  arithmetic records additions, multiplications, divisions, comparisons and calls of ``exp``/``tanh``/... The
  counts are of the laws as written (``(e - e_prev) * (1 / dt)`` is a division and a multiplication each step:
  a port would precompute ``1 / dt``), averaged over the same inputs.
* **Cortex-M4F estimate**: :data:`M4F_CYCLES` per operation in single precision (Arm Cortex-M4 TRM: VADD, VSUB,
  VMUL, VNEG, VABS 1 cycle, VDIV and VSQRT 14, a compare 1 plus 1 to move the flags), an assumed 100 cycles
  for a libm ``expf``/``tanhf``, times :data:`M4F_OVERHEAD` for the loads, stores and branches around each
  operation; at :data:`M4F_CLOCK_HZ` the fraction of a 1 kHz control period.
"""

from __future__ import annotations

import contextlib
import math
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ddmr_cli.storage.io import write_text

#: Cortex-M4F cycles per single-precision operation (docs/model.md §10; module docstring)
M4F_CYCLES = {"add": 1, "mul": 1, "div": 14, "sqrt": 14, "cmp": 2, "other": 1, "transcendental": 100}
#: factor for the loads, stores and branches around each floating-point operation (an assumption)
M4F_OVERHEAD = 2.0
M4F_CLOCK_HZ = 168e6
#: the control period whose budget the estimate is a fraction of [s]
BUDGET_PERIOD = 1e-3
#: math functions the laws call, counted as transcendental (sqrt apart)
TRANSCENDENTAL = ("exp", "tanh", "sin", "cos", "atan2", "log", "hypot")
#: the functions of :mod:`ddmr_cli.model.elementary` the laws call, and the transcendental functions each one is
#: (its arithmetic is libm's work, which a port calls: counted as libm's, not operation by operation)
ELEMENTARY = {"exp_neg": 1, "sincos": 2}


#: the template of the loop that runs a controller's laws alone (one cached copy per controller)
CONTROL_LOOP = "ddmr_cli.bench.control_loop"


def control_steps(controller, p, state, w, wd, wdd) -> float:
    """Run ``controller``'s laws for ``len(w)`` control steps on ``state[0]`` (``start``, then per step ``command``
    and ``update``), compiled: its copy of :mod:`ddmr_cli.bench.control_loop`, cached on disk. Returns the sum of
    the voltages."""
    return _compiled_control_steps(controller, p, state, w, wd, wdd)(p, state, w, wd, wdd)


def _compiled_control_steps(controller, *args):
    from ddmr_cli.engine.kernels import compiled_copy

    return compiled_copy(CONTROL_LOOP, controller.laws.__name__, "control_steps", args)


def inputs(n: int, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wheel speeds, references and reference derivatives like a run's: cruising at 33.3 rad/s (1 m/s), the
    wheels a few rad/s off and oscillating [rad/s, rad/s, rad/s^2], shape ``(n, 2)`` each."""
    t = np.arange(n) * dt
    wd = np.stack([33.3 + 2.0 * np.sin(2.0 * t), 33.3 - 2.0 * np.sin(2.0 * t)], axis=1)
    w = wd + np.stack([0.5 * np.sin(40.0 * t), -0.4 * np.cos(31.0 * t)], axis=1)
    wdd = np.stack([4.0 * np.cos(2.0 * t), -4.0 * np.cos(2.0 * t)], axis=1)
    return w, wd, wdd


def time_per_step(controller, nominal, dt: float, n: int = 2000, repeats: int = 30) -> tuple[float, float]:
    """(min, median) ns per control step of ``controller``'s laws, compiled, one run, warm."""
    params = controller.law_parameters(nominal, dt)
    w, wd, wdd = inputs(n, dt)
    state = controller.initial_state(1)
    steps = _compiled_control_steps(controller, params, state, w, wd, wdd)  # loaded or compiled
    steps(params, state, w, wd, wdd)  # warm up
    samples = []
    for _ in range(repeats):
        started = time.perf_counter_ns()
        steps(params, state, w, wd, wdd)
        samples.append((time.perf_counter_ns() - started) / n)
    return min(samples), statistics.median(samples)


def _counting_float(counts: dict):
    """A float type whose arithmetic adds to ``counts`` (a fresh class per count, no shared state)."""

    def op(kind, fn):
        def method(self, *args):
            counts[kind] += 1
            out = fn(float(self), *(float(a) for a in args))
            return Counted(out) if isinstance(out, float) else out
        return method

    class Counted(float):
        __add__ = op("add", float.__add__)
        __radd__ = op("add", float.__radd__)
        __sub__ = op("add", float.__sub__)
        __rsub__ = op("add", float.__rsub__)
        __mul__ = op("mul", float.__mul__)
        __rmul__ = op("mul", float.__rmul__)
        __truediv__ = op("div", float.__truediv__)
        __rtruediv__ = op("div", float.__rtruediv__)
        __pow__ = op("mul", float.__pow__)  # the laws square (x ** 2)
        __neg__ = op("other", float.__neg__)
        __abs__ = op("other", float.__abs__)
        __lt__ = op("cmp", float.__lt__)
        __le__ = op("cmp", float.__le__)
        __gt__ = op("cmp", float.__gt__)
        __ge__ = op("cmp", float.__ge__)

    return Counted


def _wrap(value, counted):
    if isinstance(value, float) and not isinstance(value, bool):
        return counted(value)
    if isinstance(value, tuple) and hasattr(value, "_fields"):
        return type(value)(*(_wrap(v, counted) for v in value))
    if isinstance(value, tuple):
        return tuple(_wrap(v, counted) for v in value)
    if isinstance(value, np.ndarray) and value.dtype.kind == "f":
        out = np.empty(value.shape, dtype=object)
        out.flat[:] = [counted(float(v)) for v in value.flat]
        return out
    return value


def count_operations(controller, nominal, dt: float, n: int = 200) -> dict[str, float]:
    """Operations per control step of ``controller``'s laws (module docstring), averaged over ``n`` steps.

    Runs the laws as plain Python, so it needs numba off (``NUMBA_DISABLE_JIT=1`` or no numba):
    :func:`operation_counts` runs it in such a subprocess."""
    from ddmr_cli.compiled import jit_enabled
    from ddmr_cli.model import elementary

    if jit_enabled():
        raise RuntimeError("count_operations runs the pure-Python laws: set NUMBA_DISABLE_JIT=1")
    counts = dict.fromkeys(M4F_CYCLES, 0) | {"sqrt": 0}
    counted = _counting_float(counts)

    def counting(name):
        fn = getattr(math, name)

        def call(*args):
            counts["sqrt" if name == "sqrt" else "transcendental"] += 1
            return counted(fn(*(float(a) for a in args)))
        return call

    def counting_elementary(name):
        fn, calls = getattr(elementary, name), ELEMENTARY[name]

        def call(*args):
            counts["transcendental"] += calls
            out = fn(*(float(a) for a in args))
            return tuple(counted(v) for v in out) if isinstance(out, tuple) else counted(out)
        return call

    fake_math = SimpleNamespace(**{name: getattr(math, name) for name in dir(math) if not name.startswith("_")})
    for name in (*TRANSCENDENTAL, "sqrt"):
        setattr(fake_math, name, counting(name))
    # every ddmr module that calls math, this one apart: it restores the others from its own ``math`` below
    modules = [m for m in list(sys.modules.values()) if getattr(m, "__name__", "").startswith("ddmr_cli.")
               and m is not sys.modules[__name__] and getattr(m, "math", None) is math]
    # and every one that imported a function of ``elementary`` by name (elementary's own code is not counted)
    elementary_names = [(m, name) for m in list(sys.modules.values())
                        if getattr(m, "__name__", "").startswith("ddmr_cli.") and m is not elementary
                        for name in ELEMENTARY if getattr(m, name, None) is getattr(elementary, name)]
    counting_versions = {name: counting_elementary(name) for name in ELEMENTARY}
    laws = controller.laws
    params = _wrap(controller.law_parameters(nominal, dt), counted)
    record = controller.initial_state(1)[0]
    st = {name: np.zeros(record[name].shape, dtype=object) for name in record.dtype.names}
    for arr in st.values():
        arr.flat[:] = [counted(0.0)] * arr.size
    w, wd, wdd = (_wrap(a, counted) for a in inputs(n, dt))
    try:
        for m in modules:
            m.math = fake_math
        for m, name in elementary_names:
            setattr(m, name, counting_versions[name])
        laws.start(params, st, w[0, 0], w[0, 1])
        for key in counts:
            counts[key] = 0
        for i in range(n):
            u_R, u_L = laws.command(params, st, i, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], wdd[i, 0], wdd[i, 1])
            laws.update(params, st, w[i, 0], w[i, 1], wd[i, 0], wd[i, 1], u_R, u_L, u_R, u_L, False, False)
    finally:
        for m in modules:
            m.math = math
        for m, name in elementary_names:
            setattr(m, name, getattr(elementary, name))
    return {key: value / n for key, value in counts.items()}


def operation_counts(names: list[str], keys: dict[str, str] | None = None,
                     cache: Path | None = None) -> dict[str, dict[str, float]]:
    """:func:`count_operations` for the packaged controllers ``names`` (conf/controller), in a subprocess with
    ``NUMBA_DISABLE_JIT=1``; ``{name: counts}``.

    With a ``cache`` directory and each controller's :func:`counts_key` in ``keys``, counts found there under their
    key are read, and the others counted and kept there: the counts are a function of what the key hashes, and
    the subprocess takes 1.7 s (its imports, and the laws run on counting floats)."""
    import json

    paths = {name: cache / f"counts_{keys[name]}.json" for name in names} if cache and keys else {}
    found = {}
    for name, path in paths.items():
        with contextlib.suppress(OSError, ValueError):
            found[name] = json.loads(path.read_text(encoding="utf-8"))
    missing = [name for name in names if name not in found]
    if missing:
        code = ("import json, sys; from ddmr_cli.bench.cost import packaged_counts; "
                "print(json.dumps(packaged_counts(sys.argv[1:])))")
        out = subprocess.run([sys.executable, "-c", code, *missing], env={**os.environ, "NUMBA_DISABLE_JIT": "1"},
                             capture_output=True, text=True, check=True).stdout
        counted = json.loads(out.strip().splitlines()[-1])
        for name in missing:
            found[name] = counted[name]
            if name in paths:
                with contextlib.suppress(OSError):  # a cache that cannot be written only costs the next count
                    write_text(paths[name], json.dumps(counted[name]))
    return {name: found[name] for name in names}


def counts_key(controller, nominal, dt: float) -> str:
    """What a controller's operation counts are a function of, hashed: the sources its laws inline (and the
    compiler's version: :func:`~ddmr_cli.engine.kernels.sources_digest`), this module (the counting and the
    inputs), the laws' parameters and state layout, and ``dt``."""
    import hashlib

    from ddmr_cli.engine.kernels import sources_digest

    digest = hashlib.sha256(sources_digest(controller.laws.__name__).encode())
    digest.update(Path(__file__).read_bytes())

    def feed(value) -> None:  # every number's bytes, nested tuples (named ones too) element by element
        if isinstance(value, (tuple, list)):
            digest.update(f"({len(value)}".encode())
            for item in value:
                feed(item)
            digest.update(b")")
            return
        array = np.asarray(value)
        digest.update(f"{array.dtype.str}{array.shape}".encode())
        digest.update(array.tobytes())

    feed((controller.law_parameters(nominal, dt), float(dt)))
    digest.update(str(controller.initial_state(1).dtype.descr).encode())
    return digest.hexdigest()[:16]


def packaged_counts(names: list[str]) -> dict[str, dict[str, float]]:
    """:func:`count_operations` of each packaged controller at the packaged ``simulation.dt``."""
    from ddmr_cli.config.presets import paper_controller, paper_robot, paper_config
    from ddmr_cli.model.robot import NominalModel

    nominal, dt = NominalModel.from_robot(paper_robot()), float(paper_config().simulation.dt)
    return {name: count_operations(paper_controller(name), nominal, dt) for name in names}


def m4f_cycles(counts: dict[str, float]) -> float:
    """Estimated Cortex-M4F cycles per control step from operation counts (module docstring)."""
    return M4F_OVERHEAD * sum(M4F_CYCLES[k] * counts.get(k, 0.0) for k in M4F_CYCLES)


def flops(counts: dict[str, float]) -> float:
    """Floating-point operations per step: additions, multiplications, divisions, square roots, comparisons and
    sign/abs (transcendental calls apart)."""
    return sum(counts.get(k, 0.0) for k in ("add", "mul", "div", "sqrt", "cmp", "other"))


def cost_table(names: list[str], repeats: int = 30, n: int = 2000) -> list[dict]:
    """One row per packaged controller: ns per step (min, median), operation counts, M4F cycles and the fraction
    of a 1 kHz budget at 168 MHz."""
    from ddmr_cli.config.presets import paper_controller, paper_robot, paper_config
    from ddmr_cli.engine.kernels import cache_dir
    from ddmr_cli.model.robot import NominalModel

    nominal, dt = NominalModel.from_robot(paper_robot()), float(paper_config().simulation.dt)
    controllers = {name: paper_controller(name) for name in names}
    counts = operation_counts(names, {name: counts_key(c, nominal, dt) for name, c in controllers.items()},
                              cache_dir("counts"))
    rows = []
    for name in names:
        ns_min, ns_median = time_per_step(controllers[name], nominal, dt, n=n, repeats=repeats)
        c = counts[name]
        cycles = m4f_cycles(c)
        rows.append({"controller": name, "ns_min": ns_min, "ns_median": ns_median, "flops": flops(c),
                     "transcendental": c["transcendental"], "divisions": c["div"], "m4f_cycles": cycles,
                     "m4f_us": cycles / M4F_CLOCK_HZ * 1e6, "budget_1khz": cycles / (M4F_CLOCK_HZ * BUDGET_PERIOD),
                     **{f"n_{k}": v for k, v in c.items()}})
    return rows


def assumptions() -> str:
    """The cycle model, as one line of text."""
    costs = ", ".join(f"{k} {v}" for k, v in M4F_CYCLES.items())
    return (f"Cortex-M4F at {M4F_CLOCK_HZ / 1e6:g} MHz, single precision: cycles per operation {costs} "
            f"(transcendental = libm expf/tanhf, assumed); x{M4F_OVERHEAD:g} for loads, stores and branches; "
            f"budget = {BUDGET_PERIOD * 1e3:g} ms (1 kHz). Counts by instrumenting the pure-Python laws "
            f"(NUMBA_DISABLE_JIT=1), averaged over 200 steps of cruise-like inputs; counted once for each version "
            f"of the laws and their parameters, and kept in ddmr's cache.")


__all__ = ["control_steps", "time_per_step", "count_operations", "counts_key", "operation_counts", "packaged_counts",
           "m4f_cycles", "flops", "cost_table", "assumptions", "M4F_CYCLES", "M4F_OVERHEAD", "M4F_CLOCK_HZ"]
