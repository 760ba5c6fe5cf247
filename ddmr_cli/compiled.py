"""One definition of every law, run compiled when numba is installed and as plain Python when it is not.

A law is a plain Python function on floats (and named tuples, structured records and arrays), decorated with
:func:`law`. With numba it is compiled on first use, and compiled code that calls it inlines it; without numba,
or with ``NUMBA_DISABLE_JIT=1``, the same function runs as Python. The step loop
(:mod:`ddmr_cli.engine.stepper`) is a law too, so the definition a test exercises is the one that runs.

Laws are not cached on disk one by one: numba's cache of a function does not notice an edit to a function it
calls in another file, so a cached caller could keep running an old law. Only the copies of the step loop are
cached (:func:`cached_law`), under a name that holds a hash of every law's source
(:mod:`ddmr_cli.engine.kernels`).

Importing this module fixes one numba defect that the disk cache exposes (:func:`_content_mangled_records`).
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache

try:
    import numba
    from numba import njit
except ImportError:  # pragma: no cover - exercised by tests/test_fallback.py in a subprocess
    numba, njit = None, None

#: True when numba is installed (laws run compiled unless NUMBA_DISABLE_JIT=1)
AVAILABLE = numba is not None


def _content_mangled_records() -> None:
    """Name compiled functions that take structured records after the record's layout, not after a counter.

    numba (0.68) mangles a record type into symbol names by ``Record._code``, a counter of the types a process has
    made. Two processes can give two different layouts the same number: SMC-NDO's state record (1 neuron) and
    SMC-NDO-NNO's (10 neurons), each compiled first in its own process, both became record number k, so their
    cached step loops defined ``smc.command`` under one symbol name, and a process that loaded both from the disk
    cache linked SMC-NDO-NNO's loop to SMC-NDO's laws (it ran SMC-NDO's numbers, or crashed in LLVM). Mangling
    by a hash of the layout (``Record.name`` spells every field, type, shape and offset) makes equal layouts share
    a name in every process and different ones never. Tested by tests/test_engine.py
    (test_a_warm_cache_keeps_controllers_of_one_module_apart)."""
    from numba.core.types.npytypes import Record

    def mangling_args(self):
        return type(self).__name__, (hashlib.sha256(self.name.encode()).hexdigest()[:16],)

    Record.mangling_args = property(mangling_args)


if AVAILABLE:
    _content_mangled_records()
    from numba.core.caching import FunctionCache

    class LoadingCache(FunctionCache):
        """numba's on-disk cache of a function whose load of compiled code sets up only what machine code needs to
        run: numba's runtime (``rtsys.initialize``: the allocator's symbols and its atomic helpers).

        numba's own load (``Cache.load_overload``) first refreshes the whole compiler context
        (``BaseContext.refresh``): it imports every module of numba's typing and lowering rules (linear algebra,
        typed dicts and sets, datetimes, polynomials, ...) and installs them, which a context needs to *compile*.
        Loaded code is compiled and linked already: a cached step loop holds the laws it inlined and calls none of
        those rules. The refresh took 0.47-0.64 s of CPU and 24 MiB in every process that runs a simulation
        (``ddmr run``, each sweep worker, each study chunk). A compile still refreshes in full: numba's compiler
        does so itself before every compilation (``CompilerBase.__init__``). Used by :func:`cached_law` when the
        installed numba has the two private methods it calls (numba 0.5x-0.68); else numba's own cache is."""

        def load_overload(self, sig, target_context):
            from numba.core.runtime import rtsys

            rtsys.initialize(target_context)
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)

    _LOADS_LEAN = all(hasattr(FunctionCache, name) for name in ("_load_overload", "_guard_against_spurious_io_errors"))


#: numba's options for every law: the GIL released; a float division by zero gives inf or NaN as numpy's does (no
#: test and branch at every division for a ZeroDivisionError; a diverging run is a result, never a crash)
_LAW_OPTIONS = {"nogil": True, "error_model": "numpy"}


def law(fn):
    """Compile ``fn`` (GIL released) when numba is there; else return it unchanged."""
    return njit(**_LAW_OPTIONS)(fn) if AVAILABLE else fn


def inlined_law(fn):
    """As :func:`law`, and inlined by numba itself into every compiled caller (``inline="always"``), for the step
    loop's per-step bookkeeping (:func:`ddmr_cli.engine.metrics.accumulate`): LLVM does not inline a law that size,
    and calling it out of line passes every argument (a dozen arrays among them) at every step. Measured on the
    metrics alone: 198 -> 146 ns per run and step (smc_ndo, 50 runs, one core), the same numbers."""
    return njit(inline="always", **_LAW_OPTIONS)(fn) if AVAILABLE else fn


def cached_law(fn, **options):
    """As :func:`law`, cached on disk: for the self-contained laws Python calls directly (the noise draw), which
    would otherwise compile in every process, and the generated copies of the step loop (:func:`loop_law`; see the
    module docstring); the cache loads compiled code without refreshing numba's compiler (:class:`LoadingCache`).
    Where numba finds no place for the cache (the package imported from a zip), compiled in each process."""
    if not AVAILABLE:
        return fn
    options = {**_LAW_OPTIONS, **options}
    compiled = njit(**options)(fn)
    if not hasattr(compiled, "enable_caching"):  # NUMBA_DISABLE_JIT=1: the plain function
        return compiled
    try:  # what njit(cache=True) does (Dispatcher.enable_caching), with the leaner load where numba allows it
        compiled._cache = (LoadingCache if _LOADS_LEAN else FunctionCache)(fn)
    except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available for file ..."
        if "no locator" not in str(exc):
            raise
    return compiled


def loop_law(fn):
    """As :func:`cached_law`, for the generated copies of the step loop (:mod:`ddmr_cli.engine.kernels`), compiled
    without numba's reference counting (``_nrt=False``).

    A compiled function counts references to the arrays it holds: each time a value is bound to a name it adds
    one, and it subtracts one where the name dies, with an atomic instruction that also waits for every pending
    store to reach the cache. numba removes the pairs it can match within a block, not across the step's branches,
    and so the step loop paid several of them at every step (the batch's tables taken out of ``World``, the
    arguments of the laws numba inlines). The loop allocates nothing, and every array it touches is owned by the
    Python caller for the whole call, so it needs no count: without it, 114 -> 70 ns per run and step (smc_ndo,
    50 runs, one core), 221 -> 158 (smc_ndo_nno), the same numbers to the bit. ``_nrt`` is numba's own option
    (its tests use it); a law that allocates fails to compile in the loop, not silently. A numba without the
    option (:func:`without_counting`) compiles the loop with counting: slower, the same numbers.

    Any other cached loop Python calls that allocates nothing (its caller passes every array it needs) is compiled
    the same way: the seed bands' windowed pass (:func:`ddmr_cli.engine.band_windows.reduce_points`). Loading a
    cached function that allocates made a process that had loaded the step loop 3.4 MiB larger (numba links its
    allocator into it); one compiled without counting, about nothing."""
    return cached_law(fn, **without_counting())


def without_counting() -> dict:
    """numba's option that compiles a function without reference counting (``{"_nrt": False}``), or ``{}`` for a
    numba that no longer has it (every release since numba 0.4x does; it is not public API, so this asks
    numba's own table of options rather than fail at the first compile)."""
    try:
        from numba.core.cpu import CPUTargetOptions
        from numba.core.options import TargetOptions
    except ImportError:
        return {}
    return {"_nrt": False} if isinstance(getattr(CPUTargetOptions, "_nrt", None), TargetOptions.Mapping) else {}


def _stack_matrix_python(rows, columns):
    """A ``(rows, columns)`` float64 array for scratch a compiled law owns alone (as Python: a zeroed numpy array).

    Compiled (an intrinsic), it lives in the law's stack frame: an LLVM ``alloca`` in its entry block,
    uninitialised, so no allocation (which the step loop, compiled without reference counting, cannot make:
    :func:`loop_law`), and LLVM knows that no argument points into it, which it must to vectorise a loop that
    writes it. ``rows`` and ``columns`` must be constants of the compiled code (module-level ints). A law calls it
    as ``compiled.stack_matrix`` (the module's attribute): the intrinsic is made when a law that calls it is
    compiled, not when a process loads compiled code from the disk cache."""
    import numpy as np

    return np.zeros((rows, columns))


@lru_cache(maxsize=None)
def _stack_matrix_intrinsic():
    """The compiled :func:`_stack_matrix_python`: numba's ``intrinsic`` (made once a process, on first use)."""
    from numba import types
    from numba.core import cgutils
    from numba.extending import intrinsic

    @intrinsic
    def stack_matrix(typingctx, rows, columns):
        if not (isinstance(rows, types.IntegerLiteral) and isinstance(columns, types.IntegerLiteral)):
            return None
        n_rows, n_columns = rows.literal_value, columns.literal_value
        array_type = types.Array(types.float64, 2, "C")

        def codegen(context, builder, signature, args):
            import llvmlite.ir as ir
            from numba.np.arrayobj import populate_array

            data = cgutils.alloca_once(builder, ir.DoubleType(), size=n_rows * n_columns)
            array = context.make_array(array_type)(context, builder)
            itemsize = context.get_abi_sizeof(context.get_data_type(types.float64))
            intp = lambda v: context.get_constant(types.intp, v)  # noqa: E731
            populate_array(array, data=data, shape=[intp(n_rows), intp(n_columns)],
                           strides=[intp(n_columns * itemsize), intp(itemsize)], itemsize=intp(itemsize), meminfo=None)
            return array._getvalue()

        return array_type(rows, columns), codegen

    stack_matrix.__doc__ = _stack_matrix_python.__doc__
    return stack_matrix


def __getattr__(name):
    """``stack_matrix``: :func:`_stack_matrix_python` without numba or with ``NUMBA_DISABLE_JIT``, else its
    intrinsic, made on first use (its docstring says why)."""
    if name == "stack_matrix":
        return _stack_matrix_intrinsic() if jit_enabled() else _stack_matrix_python
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def plain(fn):
    """The plain Python function behind a law, for set-up code that calls a law once on a few floats: calling the
    compiled law from Python would compile it in every process (about 0.4 s). Python rounds every operation;
    compiled, numba may fuse a multiply and an add into one FMA on CPUs that have one, so the two can differ in
    the last bit (tests/test_properties.py shows one for the RBF exponent). Set-up values come from the plain
    function wherever they are computed (validation and the engine's initial wheel speeds), so they agree with
    each other on every CPU."""
    return getattr(fn, "py_func", fn)


def jit_enabled() -> bool:
    """True when laws run compiled: numba is installed and ``NUMBA_DISABLE_JIT`` is not set."""
    return AVAILABLE and not numba.config.DISABLE_JIT


def thread_count(n: int) -> int:
    """Threads to use for ``n`` (0: every core this process may use)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, int(n) if n else cores)


__all__ = ["AVAILABLE", "cached_law", "inlined_law", "jit_enabled", "law", "loop_law", "plain", "thread_count",
           "without_counting"]
