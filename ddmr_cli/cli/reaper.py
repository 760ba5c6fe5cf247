"""Stops a ``ddmr run``'s worker processes when it is gone, even killed with SIGKILL (Linux).

``ddmr run`` starts this file as a script (``python reaper.py PID HOST``, without importing the package) in a
session of its own, its stdin a pipe only ``ddmr run`` holds. When that pipe closes (``ddmr run`` ended or was
killed), the reaper ends every process whose environment carries ``DDMR_PARENT=HOST:PID`` (the joblib/loky and
submitit_local workers of that run inherited it): SIGTERM, then SIGKILL after 2 s. Idle loky workers would
otherwise wait out their 300 s idle timeout, and busy ones finish their job, after their parent died. The resource
trackers (multiprocessing's and loky's) carry the entry too but are left alone: they are the parent's, not
workers; they end by themselves when it does, after unlinking what it leaked, and a process that runs several
sweeps (``ddmr sensitivity``) keeps using them. Killing them printed KeyError tracebacks from the relaunched
tracker at every later stage.
The processes and their environments are read with psutil. Inside a job, :func:`ddmr_cli.job._exit_with_parent`
does the same for busy workers where another process's environment cannot be read.
"""

from __future__ import annotations

import os
import signal
import sys
import time


#: a process whose command line holds this is a resource tracker, not a worker (module docstring)
TRACKER = "resource_tracker"


def workers(mark: str, exclude: int) -> list[int]:
    """Pids of the processes whose ``DDMR_PARENT`` is ``mark``, resource trackers excepted (processes whose
    environment this user may not read are not this run's)."""
    import psutil

    found = []
    for proc in psutil.process_iter():
        if proc.pid == exclude:
            continue
        try:
            if proc.environ().get("DDMR_PARENT") == mark and TRACKER not in " ".join(proc.cmdline()):
                found.append(proc.pid)
        except (psutil.Error, OSError):  # gone, a zombie, or another user's
            continue
    return found


def reap(pid: int, host: str, grace: float = 2.0) -> list[int]:
    """End the workers of ``ddmr run`` ``pid`` on ``host``; returns their pids."""
    mark = f"{host}:{pid}"
    victims = workers(mark, os.getpid())
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for victim in victims:
            try:
                os.kill(victim, sig)
            except OSError:
                pass
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and workers(mark, os.getpid()):
            time.sleep(0.1)
    return victims


def main(argv: list[str]) -> int:
    pid, host = int(argv[0]), argv[1]
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.stdin.buffer.read()  # returns at end of file: ddmr run closed the pipe or died
    reap(pid, host)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
