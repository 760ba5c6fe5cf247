"""What makes a job dir trustworthy: safe names, staged outputs, file digests, and one writer per output dir.

- :func:`safe_name`: a job dir name from its overrides that is a single path component of bounded length (a
  readable prefix and a short hash when the overrides hold ``/``, spaces, quotes or run long); the full
  overrides are recorded inside the job dir (``summary.json``, ``.hydra/overrides.yaml``).
- :class:`Stage`: a job writes every output file into a temporary sibling dir (``.<name>.<pid>.tmp``), then
  moves them into the job dir and writes ``summary.json`` last, with the size and SHA-256 of every file. Before
  that, :func:`begin` removes the old ``summary.json`` first, then the old outputs and stale ``*.tmp`` leftovers,
  so a dir never shows an old summary beside new files.
- :func:`verify`: a summary's files are there with the recorded sizes and hashes (resume reruns a job otherwise).
- :class:`DirLock`: an exclusive ``fcntl`` lock on ``<dir>/.ddmr.lock`` for the whole ``ddmr run``; a second
  writer is refused with the holder's pid, host and command.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import socket
import sys
import time
from pathlib import Path

from ddmr_cli.cli import io

LOCK = ".ddmr.lock"
#: job outputs (besides summary.json) a job writes; removed before a job writes new ones
OUTPUTS = (io.CONFIG, io.METRICS_CSV, io.SEGMENTS_CSV, io.SERIES, io.BANDS, io.PLOTS_DIR)
#: the files a job's results cannot do without (tables and config); series and plots serve figures only
REQUIRED = (io.CONFIG, io.METRICS_CSV, io.SEGMENTS_CSV)
#: longest job dir name (bytes); file systems allow 255
MAX_NAME = 120
_SAFE = re.compile(r"[A-Za-z0-9._,=+\-]+")
_HASH_CHARS = 10


class FaultError(OSError):
    """A file-system fault (disk full, read-only, not a directory, name too long) on ``path``: the CLI prints
    ``ddmr: error: <path>: <reason>`` and exits 1."""

    def __init__(self, path, reason: str) -> None:
        super().__init__(f"{path}: {reason}")
        self.path, self.reason = str(path), reason


class LockedError(FaultError):
    """The output dir is held by another ``ddmr run``."""


def fault(exc: OSError, out: Path | None = None) -> FaultError:
    """An OSError as a :class:`FaultError` naming its path (a file of ``out``'s staging dir by its place in
    ``out``) and reason."""
    if isinstance(exc, FaultError):
        return exc
    path = str(exc.filename) if exc.filename is not None else "?"
    if out is not None:
        stage = str(Stage(out).path)
        path = str(Path(out) / os.path.relpath(path, stage)) if path.startswith(stage + os.sep) else path
    if exc.errno in (errno.EEXIST, errno.ENOTDIR):
        return FaultError(path, "a file is in the way of an output dir (it exists and is not a directory)")
    return FaultError(path, exc.strerror or str(exc))


# --- names ---------------------------------------------------------------------------------------------------


def safe_name(name: str) -> str:
    """A job dir name for an override dirname: unchanged when it is already safe (letters, digits and
    ``._,=+-``, not starting with ``.``, at most :data:`MAX_NAME` bytes), else the safe characters of it
    (others as ``_``) cut to 60 characters plus ``__`` and the first 10 hex digits of its SHA-256.
    An empty name (every override excluded) is ``default``."""
    if not name:
        return "default"
    if _SAFE.fullmatch(name) and not name.startswith(".") and len(name) <= MAX_NAME:
        return name
    prefix = re.sub(r"[^A-Za-z0-9._,=+\-]+", "_", name).lstrip(".")[:60]
    return f"{prefix}__{hashlib.sha256(name.encode()).hexdigest()[:_HASH_CHARS]}"


# --- digests -------------------------------------------------------------------------------------------------


def digest(path: Path) -> dict:
    """``{"size": bytes, "sha256": hex}`` of a file."""
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
            size += len(block)
    return {"size": size, "sha256": h.hexdigest()}


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def verify(job_dir: Path, summary: dict, strict: bool = True) -> str | None:
    """None when every file ``summary`` records is in ``job_dir`` with its size and hash; else the reason.

    ``strict=False`` (reading results, not resuming) lets the files only figures need (``series.npz``,
    ``plots/``) be missing, as when a user drops them to save space; a file that is there must still match."""
    digests = summary.get("digests")
    if not isinstance(digests, dict) or not digests:
        return "its summary records no file digests"
    for name, want in digests.items():
        path = Path(job_dir) / name
        if not path.is_file():
            if not strict and name not in REQUIRED:
                continue
            return f"{name} is missing"
        if path.stat().st_size != want.get("size"):
            return f"{name} has {path.stat().st_size} bytes, {want.get('size')} recorded"
        if digest(path)["sha256"] != want.get("sha256"):
            return f"{name} differs from its recorded SHA-256"
    return None


# --- staged outputs ------------------------------------------------------------------------------------------


def _stale_stages(out: Path) -> list[Path]:
    """Staging dirs of ``out`` left by killed processes: ``.<name>.<pid>.tmp`` beside it."""
    pattern = re.compile(re.escape(f".{out.name}.") + r"\d+\.tmp")
    return [p for p in out.parent.iterdir() if pattern.fullmatch(p.name)] if out.parent.is_dir() else []


def begin(out: Path) -> None:
    """Make ``out`` hold no results before a job writes new ones: its ``summary.json`` goes first (so no old
    summary ever sits beside new files), then the outputs of an earlier job, stale temporary files of atomic
    writes and stale staging dirs (this job's dir is locked and planned once, so nothing else writes them)."""
    out = Path(out)
    (out / io.SUMMARY).unlink(missing_ok=True)
    for name in OUTPUTS:
        path = out / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    if out.is_dir():
        for tmp in out.glob(".*.tmp"):
            _remove(tmp)
    for stale in _stale_stages(out):
        _remove(stale)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


class Stage:
    """A temporary sibling dir a job writes into; :meth:`commit` moves the files into the job dir with
    ``summary.json`` (and the files' digests) last; leaving the ``with`` block without a commit removes it."""

    def __init__(self, out: Path) -> None:
        self.out = Path(out)
        self.path = self.out.parent / f".{self.out.name}.{os.getpid()}.tmp"

    def __enter__(self) -> "Stage":
        self.out.mkdir(parents=True, exist_ok=True)
        _remove(self.path)
        self.path.mkdir()
        return self

    def __exit__(self, *exc) -> None:
        _remove(self.path)

    def commit(self, summary: dict) -> dict:
        """Record the digest of every staged file in ``summary``, move the files into the job dir, then write
        ``summary.json``; returns the summary."""
        files = _files(self.path)
        summary = {**summary, "files": files, "digests": {name: digest(self.path / name) for name in files}}
        for name in files:
            target = self.out / name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.path / name, target)
        io.write_json(self.out / io.SUMMARY, summary)
        return summary


# --- one writer per output dir -------------------------------------------------------------------------------


def _holder() -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(), "command": " ".join(["ddmr", *sys.argv[1:]]),
            "started": time.strftime("%Y-%m-%d %H:%M:%S")}


def _describe(holder: dict | None) -> str:
    if not holder:
        return "another ddmr process (it has not recorded itself yet)"
    return (f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('started')} "
            f"({holder.get('command')})")


class DirLock:
    """An exclusive lock on an output dir for as long as the ``with`` block lasts (``fcntl.flock`` on
    ``<dir>/.ddmr.lock``, released by the kernel when the process dies, so a killed run leaves no stale lock).

    Raises :class:`LockedError` naming the holder when another process holds it, :class:`FaultError` when the
    dir cannot be made or written (read-only, a file in the way, name too long)."""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self.fd: int | None = None

    def __enter__(self) -> "DirLock":
        import fcntl

        path = self.directory / LOCK
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as exc:
            raise fault(exc) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise fault(exc) from None
            raise LockedError(self.directory, f"in use by {_describe(read_holder(self.directory))}; wait for it "
                                              "to finish or choose another output dir") from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, (json.dumps(_holder()) + "\n").encode())
        except OSError as exc:
            os.close(fd)
            raise FaultError(path, exc.strerror or str(exc)) from None
        self.fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing releases the flock
            self.fd = None


def read_holder(directory: Path) -> dict | None:
    """What the lock file of ``directory`` says about its holder (None when empty or unreadable)."""
    try:
        return json.loads((Path(directory) / LOCK).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


__all__ = ["safe_name", "digest", "verify", "begin", "Stage", "DirLock", "read_holder", "FaultError",
           "LockedError", "fault", "LOCK", "OUTPUTS", "MAX_NAME"]
