"""A sweep's first compositions shared between processes: the skeletons ddmr's cache lacks, composed at once.

A sweep is composed once per set of group choices (a *skeleton*: :class:`~ddmr_cli.config.JobComposer`), and each
skeleton is kept on disk (:mod:`~ddmr_cli.config.skeleton_cache`): a later process loads it in a few ms. The first
sweep after an edit of ``conf/``, an upgrade or on a new machine composes every skeleton with Hydra, about 0.3 s
each, one after the other in the CLI's process while the other cores wait: the realism table's 152 sets took 45 s
of its 75 s. :func:`share` finds that case (the sweep's first set was composed, not loaded) and composes the sets
left in this process and in one helper process per other core (``python -m ddmr_cli.config``), each its share,
into the disk cache, as many processes as get :data:`MIN_SETS` sets or more each (none below 16 sets left on 2
cores); the CLI's validation then loads them. The realism table on 2 cores, compositions cold: 45.5 s of
validation -> 22.6 s. A helper is Hydra's compose API in another process: it writes only the cache's files
(atomically, the bytes any process composing that set writes). A helper that fails or is slow leaves its sets to
the validation, which composes them, and reports their errors, as it would without helpers. A helper runs in its
own session (the terminal's Ctrl-C reaches ddmr only) and ends when its stdin closes: when the CLI ends, however it
ends.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
from typing import Callable, ContextManager, Sequence

#: the fewest sets a process composes: a helper's start (its imports, about 0.8 s) costs more than it saves on
#: fewer (each about 0.3 s)
MIN_SETS = 8
#: how long the CLI waits for a helper after composing its own share, per set of the helper's share [s]: far
#: longer than a composition takes (0.3 s); a helper still running after that is stopped and its sets composed here
WAIT_PER_SET = 5.0


def share(sets: Sequence[tuple[str, ...]], compose: Callable[[tuple[str, ...]], bool], config_name: str,
          workers: int, while_composing: Callable[[int, int], ContextManager] | None = None) -> int:
    """Compose ``sets`` (each the group choices of a skeleton, override lines) into ddmr's cache.

    ``compose(groups)`` composes one set in this process and says whether Hydra composed it (False: it was loaded
    from the cache). The first set is composed here; when it was loaded, the cache is warm and nothing else is
    done. Otherwise the others go in equal shares to this process and ``workers - 1`` helpers, inside
    ``while_composing(n_sets, n_processes)`` (a progress line; None: nothing). Returns the helpers started."""
    if not sets or not compose(sets[0]):
        return 0
    rest = list(sets[1:])
    processes = min(max(1, workers), max(1, len(rest) // MIN_SETS))
    if processes < 2:
        return 0
    shares = [rest[i::processes] for i in range(processes)]
    helpers = [_start(config_name, part) for part in shares[1:]]
    try:
        with while_composing(len(rest), processes) if while_composing else contextlib.nullcontext():
            for groups in shares[0]:
                compose(groups)
            for helper, part in zip(helpers, shares[1:]):
                if helper is not None:
                    _finish(helper, WAIT_PER_SET * len(part))
    finally:  # interrupted (Ctrl-C): the helpers go now, not when this process ends
        for helper in helpers:
            if helper is not None and helper.poll() is None:
                _finish(helper, 0.0)
    return sum(h is not None for h in helpers)


def _start(config_name: str, sets: list[tuple[str, ...]]) -> subprocess.Popen | None:
    """A helper composing ``sets`` (None when it cannot be started: its sets are then composed by validation)."""
    try:
        process = subprocess.Popen([sys.executable, "-m", "ddmr_cli.config"], stdin=subprocess.PIPE,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    except OSError:
        return None
    try:
        process.stdin.write((json.dumps([config_name, [list(s) for s in sets]]) + "\n").encode())
        process.stdin.flush()
    except OSError:
        _finish(process, 0.0)
        return None
    return process


def _finish(helper: subprocess.Popen, timeout: float) -> None:
    """Wait up to ``timeout`` s for the helper to end, then stop it; its stdin is closed either way."""
    try:
        helper.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        helper.kill()
        helper.wait()
    finally:
        with contextlib.suppress(OSError):
            helper.stdin.close()


def _end_with_parent() -> None:
    """End this helper when its stdin closes (the CLI that started it ended, or stopped it)."""
    def watch() -> None:  # the descriptor itself: a thread blocked in sys.stdin would hold its lock at exit
        while os.read(0, 65536):
            pass
        os._exit(0)

    threading.Thread(target=watch, name="ddmr-compose-ahead-parent", daemon=True).start()


def helper(compose: Callable[[str, list[str]], object]) -> int:
    """A helper's work (``python -m ddmr_cli.config``): reads ``[config_name, [groups, ...]]`` (one JSON line) from
    stdin and composes each set, ``compose(config_name, groups)`` (Hydra's compose API, into ddmr's cache); a set
    that does not compose is left (validation reports it)."""
    line = sys.stdin.buffer.readline()
    _end_with_parent()
    config_name, sets = json.loads(line)
    for groups in sets:
        with contextlib.suppress(Exception):
            compose(config_name, list(groups))
    return 0


__all__ = ["MIN_SETS", "helper", "share"]
