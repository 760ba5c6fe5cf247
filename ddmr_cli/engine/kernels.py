"""One compiled step loop per controller, made from the template :mod:`ddmr_cli.engine.stepper`.

numba inlines the laws a compiled function calls, so the step loop must be compiled once per controller law
module. Its copy for a controller is the template's source with the three imports of the controller's laws
pointed at that controller's module, written to a cache directory under a name that holds a hash of every law
module's source, of the controller's module (so an edited law gets a fresh loop: numba's own cache would not
notice an edit in a callee's file) and of the layout of the controller's state record (numba's on-disk index does
not tell apart two record types that differ only in a nested array's shape, e.g. SMC-NDO's 1-neuron and
SMC-NDO-NNO's 10-neuron weights: sharing one copy made a warm cache run the other's code), and imported; numba caches the copy's compiled code on disk beside it, and
later processes load it instead of compiling. Without numba the same copy runs as Python.

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

import ddmr_cli
from ddmr_cli.compiled import AVAILABLE

_TEMPLATE_MODULE = "ddmr_cli.engine.stepper"
_LAW_IMPORT = re.compile(r"^from ddmr_cli\.control\.open_loop import (\w+) as (controller_\w+)  # controller laws$",
                         re.MULTILINE)
#: packages whose sources the compiled loop inlines (any edit there gives a new cache key)
_LAW_PACKAGES = ("compiled.py", "model", "control", "engine")


def cache_dir() -> Path:
    """Where generated step loops and their compiled code live (see the module docstring)."""
    candidates = [os.environ.get("DDMR_CACHE_DIR"),
                  os.path.join(os.environ["XDG_CACHE_HOME"], "ddmr") if os.environ.get("XDG_CACHE_HOME") else None,
                  os.path.join(os.path.expanduser("~"), ".cache", "ddmr"),
                  os.path.join(tempfile.gettempdir(), f"ddmr-cache-{os.getuid() if hasattr(os, 'getuid') else 0}")]
    for candidate in filter(None, candidates):
        path = Path(candidate) / "kernels"
        try:
            path.mkdir(parents=True, exist_ok=True)
            if os.access(path, os.W_OK):
                return path
        except OSError:
            continue
    raise OSError("no writable cache directory for the compiled step loop (set DDMR_CACHE_DIR)")


@lru_cache(maxsize=1)
def _law_sources_digest() -> str:
    root = Path(ddmr_cli.__file__).parent
    digest = hashlib.sha256(f"{sys.version_info[:2]} numba={AVAILABLE}".encode())
    for entry in _LAW_PACKAGES:
        paths = [root / entry] if entry.endswith(".py") else sorted((root / entry).rglob("*.py"))
        for path in paths:
            digest.update(str(path.relative_to(root)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _source_for(law_module: str) -> str:
    template = inspect.getsource(importlib.import_module(_TEMPLATE_MODULE))
    source, count = _LAW_IMPORT.subn(lambda m: f"from {law_module} import {m.group(1)} as {m.group(2)}", template)
    # the copy's own functions are cached on disk (its name holds the hash of every law it inlines)
    source, cached = re.subn(r"^from ddmr_cli\.compiled import law$", "from ddmr_cli.compiled import cached_law as law",
                             source, flags=re.MULTILINE)
    if count != 3 or cached != 1:
        raise RuntimeError(f"{_TEMPLATE_MODULE}: expected 3 controller-law imports and 1 law import to replace, "
                           f"found {count} and {cached}")
    return f"# generated from {_TEMPLATE_MODULE} for {law_module}; do not edit\n" + source


@lru_cache(maxsize=None)
def stepper_for(law_module: str, layout: str = "") -> ModuleType:
    """The step-loop module for the controller whose laws live in ``law_module`` and whose state record has the
    ``layout`` given (its dtype's description; generated, imported, cached).

    The cache key covers every law module of the package, the controller's own module, which may live outside
    the package (a user's controller), and the layout."""
    module_file = Path(inspect.getfile(importlib.import_module(law_module)))
    key = (_law_sources_digest() + law_module + layout).encode() + module_file.read_bytes()
    digest = hashlib.sha256(key).hexdigest()[:16]
    name = f"ddmr_stepper_{law_module.replace('.', '_')}_{digest}"
    path = cache_dir() / f"{name}.py"
    source = _source_for(law_module)
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


__all__ = ["stepper_for", "cache_dir"]
