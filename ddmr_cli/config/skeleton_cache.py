"""Whole compositions kept on disk between processes (issue 28: compose once, cached).

A ``ddmr run`` composes with Hydra once per distinct defaults tree (:class:`ddmr_cli.config.compose_once.
CompositionMemo`): the primary config, and a sweep's skeletons, one per set of group choices (``controller=pid
scenario=paper_2 ...``, about 0.13 s each; table4's 8 jobs have 8); values are applied to a copy. A composition
depends on nothing but those overrides, the search path and the config it reads, so it is kept, pickled, in
ddmr's cache (``$DDMR_CACHE_DIR/skeletons``, beside the compiled step loops) under a name that hashes everything
it was composed from:

- the config name, the search path, the overrides it was composed from (the group choices and the ``hydra``
  node's overrides that are not values; every override but the ``hydra`` node's values when the call sweeps a
  value), and whether it was composed for a multirun. Not the working directory: what a composition records of
  its process, Hydra's ``hydra.runtime.cwd`` and ``hydra.job.env_set``, is set again on each load, so a
  composition made in one directory serves a run in another;
- every file of each packaged source of the search path (``pkg://ddmr_cli.conf``, ``pkg://hydra.conf``: name and
  bytes) and the schema module that registers the structured configs (``ddmr_cli/config/schema.py``);
- the Python, Hydra and OmegaConf versions and the source of every ``hydra_plugins`` module installed (a
  plugin's structured config is composed into the ``hydra`` node: an edit or an upgrade makes a new key).

A later process with the same key loads it (about 2 ms) instead of composing; an edit of any config file, the
schema or a version makes a new key. A file that does not load (truncated by a crash, another version's pickle,
a config whose classes this process cannot import: a plugin's, kept by a process that had the plugin) is
composed again, by Hydra, which reports what is missing, and replaced; every write is atomic (a temporary file
renamed), so concurrent processes never read half a file, and they write the same bytes. Only a search path of
packaged sources is cached: with a user's config dir (``--config-dir``), or a search path an override names
(``hydra.searchpath=[...]``, read after the key is made), everything composes as Hydra does.
``DDMR_SKELETON_CACHE=0`` turns it off.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
import tempfile
from functools import lru_cache
from pathlib import Path
from typing import Callable

__all__ = ["cached_composition", "config_digest", "enabled"]

#: the environment variable that turns the cache off (``0``)
SWITCH = "DDMR_SKELETON_CACHE"
#: the module that registers the structured configs (``structured://``), hashed with the config files
SCHEMA_MODULE = "ddmr_cli.config.schema"


def enabled() -> bool:
    """False when ``DDMR_SKELETON_CACHE=0``."""
    return os.environ.get(SWITCH, "1") != "0"


@lru_cache(maxsize=None)
def config_digest(search_path: tuple = (("main", "pkg://ddmr_cli.conf"),)) -> str:
    """The hash of what a composition on ``search_path`` (``(provider, path)`` pairs) is composed from, but its
    overrides (module docstring): every file of each ``pkg://`` source, the schema module, the versions and the
    source of the installed ``hydra_plugins``; read once per process and search path (a few ms)."""
    import importlib.util
    from importlib import resources

    import hydra
    import omegaconf

    digest = hashlib.sha256(f"python={sys.version} hydra={hydra.__version__} omegaconf={omegaconf.__version__}"
                            .encode())
    try:  # every plugin's source: their structured configs (a launcher's, a sweeper's) are composed into hydra.*
        import hydra_plugins

        plugins = sorted(_plugin_files(hydra_plugins.__path__))
    except (ImportError, OSError):
        plugins = []
    for name, data in plugins:
        digest.update(name.encode())
        digest.update(data)
    for _, source in search_path:
        if str(source).startswith("pkg://"):
            module = str(source)[len("pkg://"):].replace("/", ".")
            for name, data in sorted(_files(resources.files(module))):
                digest.update(f"{module}/{name}".encode())
                digest.update(data)
    digest.update(Path(importlib.util.find_spec(SCHEMA_MODULE).origin).read_bytes())
    return digest.hexdigest()


def _plugin_files(paths) -> list[tuple[str, bytes]]:
    """``(name, bytes)`` of every file of the ``hydra_plugins`` namespace (``paths``: its ``__path__``), named
    relative to it (:func:`_files` of each directory; an entry that is no directory, such as an editable install's
    path hook, holds none): an edit or an upgrade of a plugin changes the key, not only a plugin added or removed."""
    return [entry for path in map(Path, paths) if path.is_dir() for entry in _files(path)]


def _files(node, prefix: str = ""):
    """``(relative name, bytes)`` of every file under a resources Traversable (the packaged config: a directory
    in an editable install, inside the wheel's package otherwise), ``__pycache__`` left out."""
    for child in node.iterdir():
        name = f"{prefix}{child.name}"
        if child.is_dir():
            if child.name != "__pycache__":
                yield from _files(child, name + "/")
        elif child.is_file():
            yield name, child.read_bytes()


def cached_composition(key: tuple, multirun: bool, compose: Callable[[], tuple]) -> tuple[tuple, bool]:
    """A whole composition of :class:`~ddmr_cli.config.compose_once.CompositionMemo` (``compose()``: the kept
    tuple, its config pickled) from ddmr's cache when a process made it before from the same config, search path
    and overrides (``key``) for the same mode; else ``compose()``, saved for the next. Returns the
    tuple and whether it was loaded. Only a search path of packaged sources (``pkg://``: ddmr's config, Hydra's,
    its plugins'; ``structured://``: the schemas) is cached: a user's config dir composes as Hydra does."""
    _, search_path, _ = key
    if not enabled() or any(not str(path).startswith(("pkg://", "structured://")) for _, path in search_path):
        return compose(), False
    from ddmr_cli.engine.kernels import cache_dir

    try:
        directory = cache_dir("skeletons")
    except OSError:  # no writable cache: compose, as without one
        return compose(), False
    text = f"{config_digest(tuple(search_path))}\0{key!r}\0multirun={multirun}"
    name = hashlib.sha256(text.encode()).hexdigest()[:32]
    path = directory / f"{name}.pkl"
    try:
        kept = pickle.loads(path.read_bytes())
        if isinstance(kept, tuple) and len(kept) == 3 and isinstance(kept[1], bytes):
            pickle.loads(kept[1])  # the config itself loads here (its classes import in this process)
            return kept, True
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError, TypeError, ValueError):
        pass  # none yet, or not loadable: composed again below and replaced
    kept = compose()
    _write(directory, name, pickle.dumps(kept, protocol=pickle.HIGHEST_PROTOCOL))
    return kept, False


def _write(directory: Path, name: str, blob: bytes) -> None:
    """``directory/name.pkl`` atomically (a temporary file renamed); nothing on a full disk or a read-only cache."""
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=directory)
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.replace(tmp, directory / f"{name}.pkl")
    except OSError:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
