"""What makes a job dir trustworthy: safe names, staged outputs, file digests, and one writer per output dir.

- :func:`safe_name`: a job dir name from its overrides that is a single path component of bounded length (a
  readable prefix and a short hash when the overrides hold ``/``, spaces, quotes or run long); the full
  overrides are recorded inside the job dir (``summary.json``, ``.hydra/overrides.yaml``).
- :class:`Stage`: a job writes every output file into a temporary sibling dir (``.<name>.<pid>.tmp``, marked as
  ddmr's by a ``.ddmr-stage`` file), then moves them into the job dir and writes ``summary.json`` last (sealed:
  :func:`ddmr_cli.storage.io.seal`), with the size and SHA-256 of every file. Before that, :func:`begin` removes the
  old ``summary.json`` first, then the old outputs the old summary lists, and stale temporaries ddmr named.
- Nothing else is ever deleted: :func:`check_clear` refuses a dir where a file or dir sits at an output's name
  that no summary of that dir lists (a user's ``config.yaml``, ``plots/holiday.png``), and a listed file whose
  bytes differ from its digest is kept, renamed ``<name>.changed``.
- :func:`verify`: a summary's files are there with the recorded sizes and hashes and, when resuming, the summary
  is unchanged (its seal) and was written with the same output options (``run.plots``).
- :class:`DirLock`: an exclusive lock (filelock: ``flock``) on ``<dir>/.ddmr.lock`` for the whole ``ddmr run``; a second
  writer is refused with the holder's pid, host and command, and so is a dir inside, or containing, the dir of
  another run or sweep (a ``.ddmr.lock`` above or below it), or a single run into a sweep's dir and back.
- :func:`inside`: a path resolved (symlinks followed) lies strictly under the dir that owns it.
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import os
import re
import shutil
import socket
import sys
import time
from pathlib import Path

from ddmr_cli.storage import io

log = logging.getLogger("ddmr")

LOCK = ".ddmr.lock"
#: the file that marks a staging dir as ddmr's: ``{"pid": ..., "host": ...}``
STAGE_MARK = ".ddmr-stage"
#: the digests of the files being moved in, written before the moves and removed after the summary
COMMIT = ".ddmr-commit.json"
#: the name whose staging dir (``.sweep-tables.<pid>.tmp``) a sweep writes its tables into
TABLES_STAGE = "sweep-tables"
#: output options that change which files a job writes but not its numbers (outside the config hash)
OUTPUT_OPTIONS = ("run.plots",)
#: a temporary file of :func:`ddmr_cli.storage.io.atomic_write`: ``.<name>.<pid>.<8 hex>.tmp``
_ATOMIC_TMP = re.compile(r"\.(?P<name>.+)\.(?P<pid>\d+)\.[0-9a-f]{8}\.tmp")
#: most dirs looked at below an output dir for the lock of another run (a bound for ``hydra.run.dir=~``)
_MAX_WALK = 20000
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


def output_options(cfg) -> dict:
    """The values of :data:`OUTPUT_OPTIONS` in ``cfg``: a job is complete only for the options it ran with."""
    from omegaconf import OmegaConf

    return {key: OmegaConf.select(cfg, key, default=None) for key in OUTPUT_OPTIONS}


def verify(job_dir: Path, summary: dict, strict: bool = True, options: dict | None = None) -> str | None:
    """None when every file ``summary`` records is in ``job_dir`` with its size and hash; else the reason.

    ``strict=False`` (reading results, not resuming) lets the files only figures need (``series.npz``,
    ``plots/``) be missing, as when a user drops them to save space; a file that is there must still match.
    ``strict=True`` (resuming) also needs the summary as the job wrote it (its seal) and, given ``options``,
    the same output options (:func:`output_options`)."""
    digests = summary.get("digests")
    if not isinstance(digests, dict) or not digests:
        return "its summary records no file digests"
    if strict and summary.get("seal") != io.seal(summary):
        return f"{io.SUMMARY} was changed after the job wrote it (its seal does not match)"
    if options is not None and "options" in summary and summary["options"] != options:  # (study tasks: none)
        return f"it was written with {summary.get('options')}, this run asks for {options}"
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


# --- what a job may delete -----------------------------------------------------------------------------------


def _is_summary(data) -> bool:
    """A summary ddmr wrote (complete or failed), not a user's ``summary.json``."""
    return isinstance(data, dict) and data.get("status") in ("complete", "failed")


def owned(out: Path) -> dict[str, dict]:
    """The files of ``out`` a job provably wrote: ``{relative path: digest}`` from its summary and from the
    record of a commit cut short (:data:`COMMIT`)."""
    files: dict[str, dict] = {}
    for record in (io.read_json(Path(out) / COMMIT), io.read_summary(Path(out))):
        if isinstance(record, dict) and isinstance(record.get("digests"), dict):
            files.update({str(k): v for k, v in record["digests"].items() if isinstance(v, dict)})
    return files


def _in_the_way(path: Path, what: str = "ddmr did not write it") -> FaultError:
    return FaultError(path, f"in the way: {what} (no summary.json of this dir lists it); nothing was changed; "
                            "move it away or choose another output dir")


def check_clear(out: Path) -> None:
    """Refuse (:class:`FaultError`, exit 1) when ``out`` holds, at one of the names a job writes, anything no
    summary of ``out`` lists: a user's file or dir, a symlink, a ``summary.json`` ddmr did not write. Reads only:
    run before anything is written, and again by :func:`begin`."""
    out = Path(out).absolute()
    if not os.path.lexists(out):
        return
    if not out.is_dir():
        raise FaultError(out, "a file is in the way of an output dir (it exists and is not a directory)")
    summary = out / io.SUMMARY
    if os.path.lexists(summary) and (summary.is_symlink() or not summary.is_file()
                                     or not _is_summary(io.read_json(summary))):
        raise _in_the_way(summary, "it is not a summary ddmr wrote")
    listed = owned(out)
    for name in OUTPUTS:
        path = out / name
        if not os.path.lexists(path):
            continue
        if path.is_symlink():
            raise _in_the_way(path, "a symlink")
        entries = [path] if not path.is_dir() else [p for p in sorted(path.rglob("*")) if not p.is_dir()]
        for entry in entries:
            if entry.is_symlink() or not entry.is_file() or entry.relative_to(out).as_posix() not in listed:
                raise _in_the_way(entry)


def _alive(pid: int, host: str | None = None) -> bool:
    """Whether ``pid`` runs on this host (True when it may: another host, or no permission to ask)."""
    if host not in (None, socket.gethostname()):
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _own_temporaries(out: Path) -> list[Path]:
    """Temporary files of atomic writes into ``out`` whose process is gone (a killed job's)."""
    if not Path(out).is_dir():
        return []
    found = []
    for tmp in Path(out).glob(".*.tmp"):
        m = _ATOMIC_TMP.fullmatch(tmp.name)
        if m and tmp.is_file() and not tmp.is_symlink() and not _alive(int(m["pid"])):
            found.append(tmp)
    return found


def _set_aside(path: Path) -> Path:
    """Rename a file ddmr wrote that was changed since (it may be someone's edit) to ``<name>.changed``."""
    target = path.with_name(path.name + ".changed")
    n = 1
    while os.path.lexists(target):
        n += 1
        target = path.with_name(f"{path.name}.changed{n}")
    os.rename(path, target)
    return target


def begin(out: Path) -> None:
    """Make ``out`` hold no results before a job writes new ones, deleting only what a job provably wrote.

    :func:`check_clear` first (nothing changes when something is in the way); then its ``summary.json`` goes
    (so no old summary ever sits beside new files), then every file the old summary lists: deleted when its
    bytes are still the recorded ones, else kept as ``<name>.changed``; then stale temporaries of atomic writes
    and ddmr's stale staging dirs (marked, their process gone)."""
    out = Path(out)
    check_clear(out)
    listed = owned(out)
    (out / io.SUMMARY).unlink(missing_ok=True)
    for name, want in sorted(listed.items()):
        path = out / name
        if not path.is_file() or path.is_symlink() or Path(os.path.normpath(name)).parts[:1] == ("..",):
            continue
        if digest(path) == {"size": want.get("size"), "sha256": want.get("sha256")}:
            path.unlink()
        else:
            log.warning("kept %s as %s: it differs from what the job wrote", path, _set_aside(path).name)
    plots = out / io.PLOTS_DIR
    if plots.is_dir() and not plots.is_symlink():
        for sub in sorted((p for p in plots.rglob("*") if p.is_dir()), key=lambda p: -len(p.parts)):
            _rmdir_empty(sub)
        _rmdir_empty(plots)
    (out / COMMIT).unlink(missing_ok=True)
    for tmp in _own_temporaries(out):
        tmp.unlink(missing_ok=True)
    for stale in stale_stages(out):
        shutil.rmtree(stale, ignore_errors=True)


def _rmdir_empty(path: Path) -> None:
    try:
        path.rmdir()
    except OSError:
        pass


def clean_leftovers(sweep_dir: Path, names) -> int:
    """Remove what killed jobs of a sweep left that is provably ddmr's: stale staging dirs beside the planned
    job dirs ``names`` and stale temporaries in the sweep dir and in those job dirs. Returns how many."""
    sweep_dir = Path(sweep_dir)
    removed = 0
    for stale in stale_stages(sweep_dir / TABLES_STAGE):
        shutil.rmtree(stale, ignore_errors=True)
        removed += 1
    for tmp in _own_temporaries(sweep_dir):
        tmp.unlink(missing_ok=True)
        removed += 1
    for name in names:
        out = sweep_dir / name
        for stale in stale_stages(out):
            shutil.rmtree(stale, ignore_errors=True)
            removed += 1
        if out.is_dir() and not out.is_symlink():
            for tmp in _own_temporaries(out):
                tmp.unlink(missing_ok=True)
                removed += 1
    return removed


# --- staged outputs ------------------------------------------------------------------------------------------


def _stage_owner(path: Path) -> dict | None:
    """The pid and host a staging dir records (None: not a ddmr staging dir)."""
    if path.is_symlink() or not path.is_dir():
        return None
    mark = io.read_json(path / STAGE_MARK)
    return mark if isinstance(mark, dict) and isinstance(mark.get("pid"), int) else None


def stale_stages(out: Path) -> list[Path]:
    """ddmr's staging dirs of ``out`` left by killed processes: ``.<name>.<pid>.tmp`` beside it, marked with
    :data:`STAGE_MARK`, whose process is gone; anything else of that name is left alone."""
    out = Path(out)
    pattern = re.compile(re.escape(f".{out.name}.") + r"\d+\.tmp")
    if not out.parent.is_dir():
        return []
    found = []
    for p in out.parent.iterdir():
        owner = _stage_owner(p) if pattern.fullmatch(p.name) else None
        if owner is not None and not _alive(owner["pid"], owner.get("host")):
            found.append(p)
    return found


class Stage:
    """A temporary sibling dir a job writes into; :meth:`commit` moves the files into the job dir with
    ``summary.json`` (and the files' digests) last; leaving the ``with`` block without a commit removes it."""

    def __init__(self, out: Path, create: bool = True) -> None:
        self.out, self.create = Path(out), create
        self.path = self.out.parent / f".{self.out.name}.{os.getpid()}.tmp"

    def __enter__(self) -> "Stage":
        if self.create:
            self.out.mkdir(parents=True, exist_ok=True)
        if os.path.lexists(self.path):
            if _stage_owner(self.path) is None:  # not ours: a user's dir of that name
                raise _in_the_way(self.path, "not a staging dir of ddmr")
            shutil.rmtree(self.path)
        self.path.mkdir()
        try:
            io.write_json(self.path / STAGE_MARK, {"pid": os.getpid(), "host": socket.gethostname()})
        except BaseException:
            shutil.rmtree(self.path, ignore_errors=True)
            raise
        return self

    def __exit__(self, *exc) -> None:
        shutil.rmtree(self.path, ignore_errors=True)  # made by this process in __enter__

    def commit(self, summary: dict) -> dict:
        """Record the digest of every staged file in ``summary``, move the files into the job dir, then write
        ``summary.json`` (sealed); returns the summary. The digests are written first (:data:`COMMIT`), so a
        job killed during the moves leaves only files a later job can prove it may delete."""
        files = [f for f in _files(self.path) if f != STAGE_MARK]
        digests = {name: digest(self.path / name) for name in files}
        summary = {**summary, "files": files, "digests": digests}
        io.write_json(self.out / COMMIT, {"digests": digests})
        for name in files:
            target = self.out / name
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.path / name, target)
        summary = io.write_summary(self.out, summary)
        (self.out / COMMIT).unlink(missing_ok=True)
        return summary


def inside(path: Path, root: Path) -> bool:
    """Whether ``path``, resolved (``..`` and symlinks followed), lies strictly under ``root`` resolved."""
    real, base = Path(path).resolve(), Path(root).resolve()
    return real != base and base in real.parents


# --- one writer per output dir -------------------------------------------------------------------------------


def _holder() -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(), "command": " ".join(["ddmr", *sys.argv[1:]]),
            "started": time.strftime("%Y-%m-%d %H:%M:%S")}


def describe_holder(holder: dict | None) -> str:
    """``pid N on HOST since TIME (COMMAND)``: a lock holder as the CLI names it."""
    if not holder:
        return "another ddmr process (it has not recorded itself yet)"
    return (f"pid {holder.get('pid')} on {holder.get('host')} since {holder.get('started')} "
            f"({holder.get('command')})")


def running_holder(directory: Path) -> dict | None:
    """The record of the other process that holds ``directory``'s lock, while it still runs; None when the dir has
    no lock record, its holder has ended, or is this process. Reads the record only: the lock itself is never
    probed, so a reader (``ddmr report`` of a sweep in progress) can never make a run starting at that instant
    see its dir in use. A holder pid that a later process reused is told apart by its start time (psutil)."""
    holder = read_holder(directory)
    if not holder or not isinstance(holder.get("pid"), int):
        return None
    pid, host = holder["pid"], holder.get("host")
    if host not in (None, socket.gethostname()):
        return holder  # another host, on a shared file system: taken at its word
    if pid == os.getpid() or not _alive(pid, host):
        return None
    import psutil

    try:
        started = time.mktime(time.strptime(str(holder.get("started")), "%Y-%m-%d %H:%M:%S"))
        if psutil.Process(pid).create_time() > started + 1.0:  # the pid now names a process started later
            return None
    except psutil.NoSuchProcess:  # it ended meanwhile
        return None
    except (ValueError, OverflowError, psutil.Error):
        pass  # no usable start time (or not ours to ask): the live pid is taken at its word
    return holder


#: what marks a dir as a sweep's (its plan) and as a single run's (its summary at the top)
_SWEEP_MARKS = ("sweep_plan.json", "multirun.yaml")


def _held(directory: Path) -> dict | None:
    """The holder of ``directory``'s lock while another process holds it, else None (a finished run's dir; or a
    lock file this process may not open for writing, which it cannot probe)."""
    from filelock import FileLock, Timeout

    path = Path(directory) / LOCK
    if not path.is_file():
        return None
    probe = FileLock(path, timeout=0)
    try:
        probe.acquire()
    except Timeout:
        return read_holder(directory) or {}
    except OSError:
        return None
    probe.release()
    return None


def _claimed_below(directory: Path) -> Path | None:
    """The first dir strictly below ``directory`` holding a ``.ddmr.lock`` (hidden dirs skipped; at most
    :data:`_MAX_WALK` dirs looked at)."""
    seen = 0
    for root, dirs, files in os.walk(directory):
        seen += 1
        if seen > _MAX_WALK:
            return None
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        if LOCK in files and Path(root) != Path(directory):
            return Path(root)
    return None


def tree_conflict(directory: Path, kind: str) -> str | None:
    """Why ``directory`` may not be the output dir of a ``kind`` (``"run"`` or ``"sweep"``): it is inside, or
    contains, the dir of another run or sweep (a ``.ddmr.lock`` above or below it), or it holds the other kind
    (a single run into a sweep's dir, a sweep into a run's dir). None when it may."""
    directory = Path(directory).resolve()
    for parent in directory.parents:
        if (parent / LOCK).is_file():
            holder = _held(parent)
            state = (f"in use by {describe_holder(holder)}" if holder is not None
                     else "a finished or stopped run's or sweep's dir")
            return f"inside {parent}, the output dir of another ddmr run or sweep ({state}); choose a dir outside it"
    below = _claimed_below(directory) if directory.is_dir() else None
    if below is not None:
        return (f"contains {below}, the output dir of another ddmr run or sweep; choose a dir that holds no other "
                f"run's results")
    if kind == "run" and any((directory / m).is_file() for m in _SWEEP_MARKS):
        return "holds a sweep (sweep_plan.json); a single run would mix its files with the sweep's; choose another dir"
    if kind == "sweep" and _is_summary(io.read_json(directory / io.SUMMARY)):
        return "holds a single run (summary.json); a sweep would mix its files with the run's; choose another dir"
    return None


class DirLock:
    """An exclusive lock on an output dir for as long as the ``with`` block lasts (``filelock.FileLock`` on
    ``<dir>/.ddmr.lock``: an ``flock`` the kernel releases when the process dies, so a killed run leaves no stale
    lock; the file stays, marking the dir as a run's or a sweep's, and records its holder).

    With ``kind`` (``"run"`` or ``"sweep"``) the lock covers the tree: once it holds its own lock it refuses a
    dir inside or containing another run's or sweep's dir (:func:`tree_conflict`); as every writer takes its
    lock before it looks, of two started at once at least one sees the other. A refused lock leaves nothing
    behind: the lock file and the dirs it made are removed.

    Raises :class:`LockedError` naming the holder when another process holds it, :class:`FaultError` when the
    dir cannot be made or written (read-only, a file in the way, name too long) or is refused."""

    def __init__(self, directory: Path, kind: str | None = None, name: str = LOCK) -> None:
        self.directory = Path(directory)
        self.kind, self.name = kind, name
        self.lock = None

    def __enter__(self) -> "DirLock":
        from filelock import FileLock, Timeout

        path = self.directory / self.name
        made = [p for p in [self.directory, *self.directory.parents] if not os.path.lexists(p)]
        existed = os.path.lexists(path)
        lock = FileLock(path, timeout=0)  # never waits: a held lock is refused at once
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            lock.acquire()
        except Timeout:
            raise LockedError(self.directory, f"in use by {describe_holder(_live_holder(self.directory, self.name))}; "
                                              "wait for it to finish or choose another output dir") from None
        except OSError as exc:
            raise fault(exc) from None
        conflict = tree_conflict(self.directory, self.kind) if self.kind else None
        if conflict is not None:
            lock.release()
            if not existed:
                path.unlink(missing_ok=True)
            for made_dir in made:  # deepest first
                _rmdir_empty(made_dir)
            raise FaultError(self.directory, conflict)
        try:  # another descriptor of the file: flock belongs to filelock's, which stays open
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(json.dumps(_holder()) + "\n")
        except OSError as exc:
            lock.release()
            raise FaultError(path, exc.strerror or str(exc)) from None
        self.lock = lock
        return self

    def __exit__(self, *exc) -> None:
        if self.lock is not None:
            self.lock.release()
            self.lock = None


#: how long a refused writer waits for the lock's holder to record itself (it records just after it locks)
HOLDER_WAIT = 2.0


def _live_holder(directory: Path, name: str = LOCK, wait: float = HOLDER_WAIT) -> dict | None:
    """The lock's holder as it records itself, waiting up to ``wait`` seconds for the record: a holder takes the
    lock, checks the tree, then writes its record, so a writer refused in between would read nothing (or an
    earlier, finished holder's record). Returns the first record of a live process, else None."""
    deadline = time.monotonic() + wait
    while True:
        holder = read_holder(directory, name)
        if holder and isinstance(holder.get("pid"), int) and _alive(holder["pid"], holder.get("host")):
            return holder  # (a holder on another host, on a shared file system, is taken at its word)
        if time.monotonic() >= deadline:
            return None
        time.sleep(0.02)


def read_holder(directory: Path, name: str = LOCK) -> dict | None:
    """What the lock file of ``directory`` says about its holder (None when empty or unreadable)."""
    try:
        return json.loads((Path(directory) / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


__all__ = ["safe_name", "digest", "verify", "output_options", "owned", "check_clear", "begin", "clean_leftovers",
           "stale_stages", "Stage", "inside", "tree_conflict", "DirLock", "read_holder", "running_holder",
           "describe_holder", "FaultError", "LockedError",
           "fault", "LOCK", "STAGE_MARK", "COMMIT", "OUTPUT_OPTIONS", "OUTPUTS", "MAX_NAME"]
