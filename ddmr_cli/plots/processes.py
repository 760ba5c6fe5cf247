"""A run's figures drawn in forked processes that start before the simulation (``ddmr run``'s plots).

matplotlib holds the GIL while it imports (about 0.3 s) and draws (about 0.55 s for a run's three figures), so
a thread cannot overlap either with the job. :class:`PlotProcesses` forks one drawing process before the job
simulates: it imports matplotlib and draws a throw-away figure (loading the fonts) while the job loads its
compiled step loop and simulates, then forks a warm copy of itself per further share of :data:`~.run.FIGURES`;
each waits for the series, draws its share into the job's directory and reports the paths. Measured on the
2-core machine, ``ddmr run`` with its plots: 1.96-2.09 s drawing in the job's process (the figures began 0.86 s
in and took 0.86 s), 1.33-1.38 s with these processes (and the console script's exit without its last garbage
collections, :func:`ddmr_cli.cli.main.console`).

Processes are forked only on Linux, where a fork copies the forking thread alone and is cheap after the job's
imports; the drawing processes take no lock of the job's other threads (they import, draw and write their own
files; CPython re-initialises the import and logging locks at a fork). Elsewhere, or when a process fails in any
way, its figures are drawn in the job's own process: the same files.
"""

from __future__ import annotations

import multiprocessing
import sys
from pathlib import Path

#: the figures each process draws: one each (three processes for two cores: each figure's drawing is mostly the
#: same fixed cost of ticks and text, and the three finish together)
SHARES = (("trajectory",), ("errors",), ("control",))


def _serve(conns, job_ends, shares: tuple[tuple[str, ...], ...]) -> None:
    """The drawing process: import and warm up matplotlib once, fork a warm copy of itself for every further
    share, then each draws its share of the run it is sent on its own pipe (None or a closed pipe: quit).

    Each process keeps only its own pipe's end: the job's ends (``job_ends``, inherited by the fork) and the other
    shares' are closed, so that a job that dies closes every pipe, and a drawing process that dies closes its
    own (its reader sees the end of the pipe, not a wait)."""
    import os

    for end in job_ends:
        end.close()
    try:
        from ddmr_cli.plots.common import figure
        from ddmr_cli.plots.run import run_plots

        warm = figure(figsize=(1, 1))
        warm.text(0.5, 0.5, "warm-up: fonts 0.1")
        warm.canvas.draw()  # Agg canvas, fonts and text layout loaded before the series arrive
    except BaseException:  # noqa: BLE001 - no matplotlib here: every pipe closes, the job draws its figures
        for conn in conns:
            conn.close()
        return
    mine, copies = 0, []
    for i in range(1, len(shares)):
        pid = os.fork()
        if pid == 0:
            mine, copies = i, []
            break
        copies.append(pid)
    for i, other in enumerate(conns):
        if i != mine:
            other.close()
    conn = conns[mine]
    try:
        job = conn.recv()
        if job is not None:
            args, kwargs = job
            conn.send(("ok", [str(p) for p in run_plots(*args, figures=shares[mine], **kwargs)]))
    except BaseException as exc:  # noqa: BLE001 - reported to the job, which then draws these figures itself
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
        except (OSError, ValueError):
            pass
    finally:
        conn.close()
        if mine:  # a forked copy: no interpreter clean-up (it is the drawing process's)
            os._exit(0)
        for pid in copies:
            os.waitpid(pid, 0)


class PlotProcesses:
    """Processes that draw a run's figures (module docstring); a context manager that ends them.

    Use ``draw`` with :func:`~ddmr_cli.plots.run.run_plots`'s arguments once the series exists; it returns the
    paths of every figure, whichever process drew it.
    """

    def __init__(self, shares: tuple[tuple[str, ...], ...] = SHARES) -> None:
        self._conns: list = []
        self._shares = shares
        self._process = None
        if not sys.platform.startswith("linux"):
            return
        context = multiprocessing.get_context("fork")
        pipes = [context.Pipe() for _ in shares]
        process = context.Process(target=_serve, args=([child for _, child in pipes], [job for job, _ in pipes],
                                                       shares),
                                  name="ddmr-plots", daemon=False)  # it forks a copy of itself per further share
        try:
            process.start()
        except OSError:  # no process to be had (limits): the job draws the figures itself
            for parent, _ in pipes:
                parent.close()
            return
        finally:
            for _, child in pipes:
                child.close()
        self._process, self._conns = process, [parent for parent, _ in pipes]

    def __enter__(self) -> "PlotProcesses":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def draw(self, *args, **kwargs) -> list[Path]:
        """Every figure of :func:`~ddmr_cli.plots.run.run_plots` (same arguments), drawn by the processes and,
        for a share whose process is missing or failed, here."""
        from ddmr_cli.plots.run import FIGURES, run_plots

        sent = []
        for share, conn in zip(self._shares, self._conns):
            try:
                conn.send((args, kwargs))
                sent.append((share, conn))
            except (OSError, ValueError):
                pass
        drawn: dict[str, Path] = {}
        for share, conn in sent:
            try:
                status, value = conn.recv()
            except (EOFError, OSError):
                status, value = "error", "the drawing process ended without an answer"
            if status == "ok":
                drawn.update(zip(share, map(Path, value)))
        missing = tuple(name for name in FIGURES if name not in drawn)
        if missing:
            drawn.update(zip(missing, run_plots(*args, figures=missing, **kwargs)))
        return [drawn[name] for name in FIGURES]

    def close(self) -> None:
        """Tell the processes to quit and wait for them (killed when they do not end within 5 s)."""
        for conn in self._conns:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
            conn.close()
        if self._process is not None:
            self._process.join(5.0)
            if self._process.is_alive():
                self._process.kill()
                self._process.join()
        self._conns, self._process = [], None


__all__ = ["PlotProcesses", "SHARES"]
