"""One compiled step loop per controller and call signature, made from the template :mod:`ddmr_cli.engine.stepper`.

numba inlines the laws a compiled function calls, so the step loop must be compiled once per controller law
module. Its copy for a controller is the template's source with the four imports from the controller slot
(:mod:`ddmr_cli.engine.controller_slot`, whose docstring shows them) pointed at that controller's module, written
to a cache directory and imported; numba caches the copy's compiled
code on disk beside it, and later processes load it instead of compiling. Without numba the same copy runs as
Python. Another template of the same kind, whose laws come from the same slot, is copied the same way
(:func:`copy_for`, :func:`compiled_copy`): the loop by blocks of runs (:mod:`ddmr_cli.engine.lanes`) and the loop
that times a controller's laws alone (:mod:`ddmr_cli.bench.control_loop`).

The copy's file name is its identity: a hash of everything it was compiled for (:func:`stepper_for`):

- the sources the copy inlines (:func:`inlined_sources`): the template's and the controller module's, and every
  ``ddmr_cli`` module they import, transitively (the slot's default controller only where it is used); the
  controller's module may live outside the package (a user's controller). numba's own cache does not notice an
  edit in a callee's file; an edit in one controller's module recompiles that controller's loop only;
- the complete type of every argument of the call (:func:`call_identity`): every record layout it touches (the
  run record with the sensor's and the actuator's state; the controller's state, whose network's size is a
  field's shape; the metric accumulators), the World, plant and parameter tuples field by field, every array's
  dtype, rank and layout (an array's sizes are not its type: the actuator's delay lines, one array beside the
  run records, serve every delay with one loop);
- the Python, numba and llvmlite versions and the CPU target numba compiles for.

So each copy's numba index holds exactly one compiled signature. numba's index alone is not enough: it is not
safe against two processes saving different signatures of one function at once (both read the index, both
choose data file 1, and the index can end up naming one signature while the data file holds the other's code).
Two sweep workers compiling one controller for two actuator delays did that (the delay line was then a field
of the run record), and the next process running one of the delays loaded the other's code (issue 31,
tests/test_kernel_cache.py; before that, SMC-NDO's and
SMC-NDO-NNO's state records, tests/test_engine.py). With one signature per copy, the processes that save into
one copy save the same code.

:func:`compiled_run_chunk` loads (or compiles) the loop before the first step and checks that what numba handed
back was compiled for exactly this call; if not, it says which cache entry, deletes it and recompiles.
After the first chunk the engine checks that no second signature was compiled (:func:`check_single_signature`).

The cache directory is ``$DDMR_CACHE_DIR``, else ``$XDG_CACHE_HOME/ddmr``, else ``~/.cache/ddmr``, else a
directory under the system's temporary directory when those are not writable.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import re
import sys
import tempfile
from functools import lru_cache
from pathlib import Path
from types import ModuleType
from typing import Callable

from ddmr_cli.compiled import AVAILABLE, cached_law, jit_enabled
from ddmr_cli.engine.controller_slot import DEFAULT_MODULE
from ddmr_cli.keyed import Keyed

_TEMPLATE_MODULE = "ddmr_cli.engine.stepper"
_SLOT_MODULE = "ddmr_cli.engine.controller_slot"
_LAW_IMPORT = re.compile(r"^from ddmr_cli\.engine\.controller_slot import (\w+) as (controller_\w+)  # controller laws$",
                         re.MULTILINE)
#: any import statement that names the slot (after the law imports are replaced, none may be left)
_ANY_SLOT_IMPORT = re.compile(r"^\s*(from|import)\s[^\n]*\bcontroller_slot\b", re.MULTILINE)


def cache_dir(kind: str = "kernels") -> Path:
    """Where generated step loops and their compiled code live (see the module docstring); another ``kind`` is a
    sibling directory of ddmr's cache (``skeletons``: :mod:`ddmr_cli.config.skeleton_cache`)."""
    candidates = [os.environ.get("DDMR_CACHE_DIR"),
                  os.path.join(os.environ["XDG_CACHE_HOME"], "ddmr") if os.environ.get("XDG_CACHE_HOME") else None,
                  os.path.join(os.path.expanduser("~"), ".cache", "ddmr"),
                  os.path.join(tempfile.gettempdir(), f"ddmr-cache-{os.getuid() if hasattr(os, 'getuid') else 0}")]
    for candidate in filter(None, candidates):
        path = Path(candidate) / kind
        try:
            path.mkdir(parents=True, exist_ok=True)
            if os.access(path, os.W_OK):
                return path
        except OSError:
            continue
    raise OSError("no writable cache directory for the compiled step loop (set DDMR_CACHE_DIR)")


def _versions() -> str:
    """The interpreter's and the compiler's versions and the CPU target (numba's codegen magic tuple: triple, CPU
    name and features); a compiled copy is valid for these only."""
    if not AVAILABLE:
        return f"python={sys.version} numba=none"
    import llvmlite
    import numba
    from numba.core.registry import cpu_target

    target = cpu_target.target_context.codegen().magic_tuple()
    return f"python={sys.version} numba={numba.__version__} llvmlite={llvmlite.__version__} target={target}"


def _module_file(name: str) -> Path | None:
    """The source file of module ``name``; None for a name that is not a module (``ddmr_cli.compiled.law``)."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, AttributeError, ValueError):
        return None
    return Path(spec.origin) if spec is not None and spec.origin and spec.origin.endswith(".py") else None


#: the fields of a statement that hold statements (an import is a statement, never inside an expression)
_STATEMENT_LISTS = ("body", "orelse", "finalbody", "handlers", "cases")


@lru_cache(maxsize=256)
def _import_statements(source: bytes) -> tuple[tuple[str | None, int, tuple[str, ...]], ...]:
    """Every import statement of a module's ``source``, nested ones too (in functions, classes, branches, ``try``,
    ``with`` and ``match`` blocks), as ``(module, level, names)``; ``import a.b`` is ``(None, 0, ("a.b",))``, a
    relative ``from . import x`` is ``(None, 1, ("x",))``.
    Only statements are visited, not expressions (a tenth of the nodes); a source already scanned in this process
    (another controller's copy inlines the same modules) is not parsed again."""
    import ast

    out = []
    todo: list = [ast.parse(source)]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Import):
            out.append((None, 0, tuple(a.name for a in node.names)))
        elif isinstance(node, ast.ImportFrom):
            out.append((node.module, node.level, tuple(a.name for a in node.names)))
        for field in _STATEMENT_LISTS:
            value = getattr(node, field, None)
            if isinstance(value, list):
                todo.extend(value)
    return tuple(out)


def _imported_modules(path: Path) -> set[str]:
    """The ``ddmr_cli`` modules a source file imports (any import, lazy ones too; ``from pkg import sub`` counts
    ``pkg.sub``, not the package)."""
    out: set[str] = set()
    for module, level, imported in _import_statements(path.read_bytes()):
        if level > 0:  # relative: not a ddmr_cli module by name
            continue
        if module is None:  # ``import a.b``
            names = list(imported)
        else:
            submodules = [f"{module}.{name}" for name in imported if _module_file(f"{module}.{name}")]
            # ``from pkg import sub``: the submodule is what is used; ``from mod import name``: the module
            names = submodules or [module]
        out.update(n for n in names if n.split(".")[0] == "ddmr_cli" and _module_file(n) is not None)
    return out


def inlined_sources(law_module: str, template: str = _TEMPLATE_MODULE) -> list[Path]:
    """The source files the copy of ``template`` (the step loop's by default) for ``law_module`` can inline: the
    template's and the controller module's, and every ``ddmr_cli`` module they import, transitively (the slot
    stands for the controller's module; the slot's default module counts only when the controller lacks an
    optional law). Sorted, for a stable key."""
    module = importlib.import_module(law_module)
    start = {template, law_module, "ddmr_cli.compiled"}
    if not hasattr(module, "estimates"):
        start.add(DEFAULT_MODULE)
    seen: set[str] = set()
    todo = list(start)
    while todo:
        name = todo.pop()
        if name in seen or name == _SLOT_MODULE:
            continue
        seen.add(name)
        path = _module_file(name) if name != law_module else Path(inspect.getfile(module))
        if path is not None:
            todo.extend(_imported_modules(path) - seen)
    files = {(_module_file(n) if n != law_module else Path(inspect.getfile(module))) for n in seen - {_SLOT_MODULE}}
    return sorted(p.resolve() for p in files if p is not None)


def sources_digest(law_module: str, read=Path.read_bytes, template: str = _TEMPLATE_MODULE) -> str:
    """The hash of :func:`inlined_sources` (each file's name and bytes, ``read`` to read them) and the versions."""
    digest = hashlib.sha256(_versions().encode())
    for path in inlined_sources(law_module, template):
        digest.update(path.name.encode())
        digest.update(read(path))
    return digest.hexdigest()[:16]


@lru_cache(maxsize=None)
def _sources_digest_cached(law_module: str, template: str) -> str:
    return sources_digest(law_module, template=template)


def _source_for(law_module: str, template_module: str = _TEMPLATE_MODULE) -> str:
    """The template's source with its controller-law imports pointed at ``law_module`` and its ``law`` decorator
    made :func:`~ddmr_cli.compiled.loop_law` (the copy is cached on disk, compiled without reference counting).
    RuntimeError if the template's lines are not in the form this replaces (the step loop has 4 law imports)."""
    # the template's text, read, not imported: a module's compiled laws are numba dispatchers, about 110 KB each
    # made at import, and nothing runs the template itself
    template = _module_file(template_module).read_text(encoding="utf-8")
    module = importlib.import_module(law_module)

    def point(m):  # a law the controller does not define (only ``estimates`` is optional) keeps the slot's default
        optional_default = m.group(1) == "estimates" and not hasattr(module, "estimates")
        source_module = DEFAULT_MODULE if optional_default else law_module
        return f"from {source_module} import {m.group(1)} as {m.group(2)}"

    source, count = _LAW_IMPORT.subn(point, template)
    # the copy's own functions are cached on disk (its name holds the hash of every law it inlines)
    source, cached = re.subn(r"^from ddmr_cli\.compiled import law$", "from ddmr_cli.compiled import loop_law as law",
                             source, flags=re.MULTILINE)
    expected = 4 if template_module == _TEMPLATE_MODULE else count
    if count != expected or count == 0 or cached != 1 or _ANY_SLOT_IMPORT.search(source):
        raise RuntimeError(f"{template_module}: expected {expected or 'some'} controller-law imports (and no other "
                           f"import of the slot) and 1 law import to replace, found {count} and {cached}")
    return f"# generated from {template_module} for {law_module}; do not edit\n" + source


def _type_identity(ty) -> str:
    """A numba type spelled out completely: named tuples by their class's full name and every field's type,
    records by numba's name for them (every field's name, type, nested shape and offset), arrays by dtype, rank,
    layout and flags."""
    from numba.core import types

    if isinstance(ty, types.BaseNamedTuple):
        cls = ty.instance_class
        fields = ",".join(f"{name}:{_type_identity(t)}" for name, t in zip(ty.fields, ty.types))
        return f"{cls.__module__}.{cls.__qualname__}({fields})"
    if isinstance(ty, types.BaseTuple):
        return "(" + ",".join(_type_identity(t) for t in ty.types) + ")"
    if isinstance(ty, types.Array):
        return f"{ty!s}[{_type_identity(ty.dtype)}]" if isinstance(ty.dtype, types.Record) else str(ty)
    return str(ty)


def call_identity(args) -> str:
    """The complete type of a call's arguments (empty without numba, where nothing is compiled or cached).

    Typing every argument with numba's ``typeof`` costs about 0.8 ms a call (the step loop takes 17, a few of them
    named tuples of 30 fields), a study's thousands of short calls over the same types; so the identity is kept by
    the arguments' :func:`_fingerprint` (what ``typeof`` reads of each), once a process per fingerprint."""
    if not AVAILABLE:
        return ""
    fingerprint = _fingerprint(args)
    if fingerprint is None:
        return _typed_identity(args)
    return _identity_by_fingerprint(Keyed(fingerprint, args))


def _typed_identity(args) -> str:
    from numba import typeof

    return ";".join(_type_identity(typeof(arg)) for arg in args)


def _fingerprint(arg):
    """What numba's ``typeof`` reads of a value, as a hashable key, at least as fine as its type: an array's dtype,
    rank, contiguity, writability and alignment; a tuple's class and each element's fingerprint; a scalar's
    class (a Python int also whether it fits 64 signed bits). None for any other kind of value."""
    import numpy as np

    if isinstance(arg, np.ndarray):
        flags = arg.flags
        return (np.ndarray, arg.dtype, arg.dtype.isalignedstruct, arg.ndim, flags.c_contiguous, flags.f_contiguous,
                flags.writeable, flags.aligned)
    if isinstance(arg, tuple):
        parts = tuple(_fingerprint(a) for a in arg)
        return None if any(p is None for p in parts) else (type(arg), parts)
    if isinstance(arg, bool) or arg is None or type(arg) is float:
        return type(arg)
    if type(arg) is int:
        return (int, -(2 ** 63) <= arg < 2 ** 63)
    if isinstance(arg, np.generic):
        return (type(arg), arg.dtype, arg.dtype.isalignedstruct)
    return None


@lru_cache(maxsize=256)
def _identity_by_fingerprint(call: Keyed) -> str:
    """The identity of the arguments ``call`` carries, kept by their fingerprint (the arguments are dropped)."""
    identity = _typed_identity(call.value)
    call.value = None
    return identity


def stepper_for(law_module: str, identity: str = "") -> ModuleType:
    """The step-loop module for the controller whose laws live in ``law_module``, compiled for the call whose
    argument types :func:`call_identity` spells as ``identity`` (generated, imported, cached on disk).

    The cache key covers the sources the copy inlines, the call's complete argument types and the Python and
    compiler versions (see the module docstring)."""
    return copy_for(_TEMPLATE_MODULE, law_module, identity)


@lru_cache(maxsize=None)
def copy_for(template: str, law_module: str, identity: str = "") -> ModuleType:
    """The copy of the module ``template`` (a template of the step loop's kind: laws taken from the controller slot,
    compiled with ``law``) for the controller whose laws live in ``law_module``, for the call ``identity``; the
    step loop's is :func:`stepper_for`. Others: the cost of a control step (:mod:`ddmr_cli.bench.control_loop`)."""
    key = (_sources_digest_cached(law_module, template) + law_module + identity).encode()
    digest = hashlib.sha256(key).hexdigest()[:16]
    kind = template.rsplit(".", 1)[-1]
    name = f"ddmr_{kind}_{law_module.replace('.', '_')}_{digest}"
    path = cache_dir() / f"{name}.py"
    source = _source_for(law_module, template)
    if not path.is_file() or path.read_text(encoding="utf-8") != source:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(source)
        os.replace(tmp, path)  # atomic: concurrent processes write the same text
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def compiled_run_chunk(law_module: str, args: tuple, compiling: Callable[[], None] | None = None):
    """The step loop's ``run_chunk`` for a call with these arguments, loaded from the disk cache or compiled now
    (``compiling()`` is called first then: the copy has no cache entry yet, about 10 s of compiling follows).

    What numba's cache hands back is checked against the call's own signature (a cheap set comparison); an
    entry compiled for another call is named on stderr, deleted, and the loop recompiled, so a stale or
    corrupted cache entry never runs (issue 31)."""
    return compiled_copy(_TEMPLATE_MODULE, law_module, "run_chunk", args, compiling)


def compiled_copy(template: str, law_module: str, function: str, args: tuple,
                  compiling: Callable[[], None] | None = None):
    """``function`` of the copy of ``template`` for ``law_module`` (:func:`copy_for`), for a call with these
    arguments, loaded from the disk cache or compiled now, and checked as :func:`compiled_run_chunk` checks the
    step loop."""
    module = copy_for(template, law_module, call_identity(args))
    [compiled] = _checked(module, [(function, args)], compiling)
    return compiled


def compiled_external_step(law_module: str, control_args: tuple, account_args: tuple,
                           compiling: Callable[[], None] | None = None):
    """The external plant's two halves of a step, ``external_control`` and ``external_account``, for calls with
    these arguments: one copy of the step loop holds both (its name hashes both calls' types), checked as
    :func:`compiled_run_chunk` checks its loop."""
    identity = "external:" + call_identity(control_args) + "|" + call_identity(account_args)
    module = stepper_for(law_module, identity)
    return tuple(_checked(module, [("external_control", control_args), ("external_account", account_args)],
                          compiling))


#: the attribute of a generated copy's module that holds the functions :func:`_checked` verified in this process
_VERIFIED = "_ddmr_verified"


def _checked(module: ModuleType, calls: list[tuple[str, tuple]], compiling: Callable[[], None] | None) -> list:
    """The copy's functions ``calls`` names, each compiled (or loaded) for exactly its call's signature.

    A copy is checked once per process: its name fixes the complete signature of every call it serves
    (:func:`stepper_for`), so the functions verified first are recorded on the copy's module and returned to every
    later call (a study simulates thousands of samples a process; the check lists the cache directory and
    re-types every argument, about 2 ms a call)."""
    names = tuple(name for name, _ in calls)
    verified = getattr(module, _VERIFIED, {})
    if names in verified:
        return verified[names]
    functions = [getattr(module, name) for name, _ in calls]
    if not jit_enabled():
        return functions
    from numba import typeof

    signatures = [tuple(typeof(arg) for arg in args) for _, args in calls]
    path = Path(module.__file__)
    entries = sorted((path.parent / "__pycache__").glob(f"{path.stem}.*"))
    if not entries and compiling is not None:
        compiling()
    try:
        for function, signature in zip(functions, signatures):
            function.compile(signature)
        problem = None if all(set(f.overloads) == {sig} for f, sig in zip(functions, signatures)) \
            else "was compiled for another call"
    except Exception as exc:  # noqa: BLE001 - a cache entry that does not even load is as stale as a wrong one
        if not entries:
            raise  # nothing was loaded: a genuine compile error
        problem = f"does not load ({type(exc).__name__}: {exc})"
    if problem is None:
        setattr(module, _VERIFIED, {**verified, names: functions})
        return functions
    print(f"ddmr: warning: the cached compiled copy {path} (entries {', '.join(p.name for p in entries)}) {problem}; "
          f"deleting it and recompiling", file=sys.stderr)
    for entry in entries:
        entry.unlink(missing_ok=True)
    # recompiled with the options it was made with (numba's error model, no reference counting: loop_law)
    functions = [cached_law(f.py_func, **{k: v for k, v in f.targetoptions.items() if k != "nopython"})
                 for f in functions]
    for function, signature in zip(functions, signatures):
        function.compile(signature)
        if set(function.overloads) != {signature}:
            raise RuntimeError(f"{path}: the recompiled copy does not match its call (delete {cache_dir()} "
                               f"and report this)")
    setattr(module, _VERIFIED, {**verified, names: functions})
    return functions


def entry_point(function, calls: list[tuple]):
    """The one compiled signature's entry point of ``function`` for ``calls`` (their argument tuples), else
    ``function`` itself.

    numba's dispatcher types every argument at every call, holding the GIL: about 11 us for the step loop's 18
    arguments, against about 1 us through the entry point of the signature it compiled (a 1,000-run batch calls it
    128 times). The entry point does not check the types, so it is returned only when ``function`` holds exactly one
    signature and every call's arguments have the first call's fingerprints (:func:`_fingerprint`, at least as fine
    as numba's type; an argument that is the first call's own object is not looked at again). The first call's
    arguments must be those the signature was compiled for (:func:`compiled_copy` checks it)."""
    overloads = getattr(function, "overloads", None)
    if not calls or not overloads or len(overloads) != 1:
        return function
    first, first_prints = calls[0], {}  # the first call's fingerprints, by position, each taken once
    for call in calls[1:]:
        if len(call) != len(first):
            return function
        for i, arg in enumerate(call):
            if arg is not first[i]:
                if i not in first_prints:
                    first_prints[i] = _fingerprint(first[i])
                fingerprint = _fingerprint(arg)
                if fingerprint is None or fingerprint != first_prints[i]:
                    return function
    [compiled] = overloads.values()
    return compiled.entry_point


def check_single_signature(function) -> None:
    """Raise RuntimeError if a compiled copy holds more than one signature (its file name promises one)."""
    signatures = getattr(function, "signatures", None)
    if signatures is not None and len(signatures) > 1:
        raise RuntimeError(f"{function.__module__}: the compiled step loop holds {len(signatures)} signatures; "
                           f"its cache key must name one (delete {cache_dir()} and report this)")


__all__ = ["cache_dir", "call_identity", "check_single_signature", "compiled_copy", "compiled_external_step",
           "compiled_run_chunk", "copy_for", "entry_point", "inlined_sources", "sources_digest", "stepper_for"]
