"""A run's figures drawn in forked processes that get ready before the run exists (``ddmr run``'s plots).

matplotlib holds the GIL while it imports (about 0.3 s) and draws, so a thread cannot overlap either with the
job. :class:`PlotProcesses` forks one drawing process: it imports matplotlib and lays out and draws the frame of
every figure (:mod:`.run`: axes, labels, grids, ticks, fonts), then forks a copy of itself per further share of
:data:`~.run.FIGURES`; each waits for the run (its share's channels, :meth:`PlotProcesses.send`), draws it into
its frames, saves them into the job's directory and reports the paths (:meth:`PlotProcesses.collect`), while
the job writes its other files. The ``ddmr run`` program starts these processes first thing
(:meth:`PlotProcesses.started`, :func:`ddmr_cli.cli.main.console`), from a process that has imported next to
nothing, so that they get ready on the processor its imports, Hydra and the loading of the compiled step loop
leave idle; the job takes them (:meth:`PlotProcesses.take`), or starts its own. Measured on the 2-core machine:
the frames are ready 0.66 s into ``ddmr run``, before the simulation ends (0.95-1.0 s), and the figures then take
0.11/0.14/0.17 s of CPU each (trajectory/errors/control; 0.16/0.21/0.25 s drawn from nothing), finishing about
0.25 s after it; ``ddmr run`` 1.24 s against 1.40 s with processes forked just before the simulation that imported
matplotlib then (medians of 21 paired runs).

Processes are forked only on Linux, where a fork copies the forking thread alone; the drawing processes take no
lock of the job's other threads (they import, draw and write their own files; CPython re-initialises the import
and logging locks at a fork). Elsewhere, or when a process fails in any way, its figures are drawn in the job's
own process: the same files.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import sys
from contextvars import ContextVar
from pathlib import Path

#: the figures each process draws: one each (three processes for two cores: each figure's drawing is mostly the
#: same fixed cost of ticks and text, and the three finish together), the longest to draw first (its frame is made
#: first and its run sent first)
SHARES = (("control",), ("errors",), ("trajectory",))


def _serve(conns, job_ends, shares: tuple[tuple[str, ...], ...]) -> None:
    """The drawing process: import matplotlib, lay out and draw the frame of every figure once (:mod:`.run`: one
    after another, in one process, so that it takes one processor from the job at most), then fork a copy of
    itself for every further share; each draws the run it is then sent on its own pipe into the frames of its
    share (None or a closed pipe: quit). A run (or the job's end) that comes before every frame is ready leaves
    the others to be laid out when it is drawn.

    Each process keeps only its own pipe's end: the job's ends (``job_ends``, inherited by the fork) and the other
    shares' are closed, so that a job that dies closes every pipe, and a drawing process that dies closes its
    own (its reader sees the end of the pipe, not a wait). Ctrl-C is ignored (the job, told, ends them), and there
    is no cyclic garbage collection: the processes make three figures and end (its collections walked matplotlib's
    objects, 30 ms)."""
    import gc
    import os

    _take_signals()
    gc.disable()
    for end in job_ends:
        end.close()
    ready = {}
    try:
        from ddmr_cli.plots.run import FIGURES

        for name in (name for share in shares for name in share):
            if conns[0].poll():
                break
            ready[name] = FIGURES[name](warm=True)
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
            run, series = job
            conn.send(("ok", [str((ready.get(name) or FIGURES[name]()).finish(run, series))
                              for name in shares[mine]]))
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


class _Stop(SystemExit):
    """SIGTERM in a drawing process (:meth:`PlotProcesses.close` of processes never sent a run): a
    :class:`SystemExit`, so that what the process was doing unwinds (with its files and locks; matplotlib's font
    cache has one) before it ends."""


def _quit(*_signal) -> None:
    """The drawing processes' SIGTERM handler: raise :class:`_Stop`."""
    raise _Stop(0)


def _ignore_stop(unraisable, default) -> None:
    """``sys.unraisablehook`` of a drawing process: a :class:`_Stop` raised where Python cannot propagate it (an
    at-fork hook, a weakref callback, a ``__del__``) is dropped silently; anything else goes to ``default``.

    The process then goes on to its next wait, where the ``None`` that :meth:`PlotProcesses.close` sent before its
    SIGTERM ends it. Without this, Python prints "Exception ignored in ... SystemExit: 0" into the job's stderr
    (seen once in about 120 stops under load: the signal came while logging's after-fork hook ran)."""
    if not isinstance(unraisable.exc_value, _Stop):
        default(unraisable)


def _take_signals() -> None:
    """A drawing process's signals: Ctrl-C ignored (it is the job's, which then ends these processes,
    :meth:`PlotProcesses.close`), SIGTERM raising :class:`_Stop`, and a stop that cannot propagate dropped
    (:func:`_ignore_stop`)."""
    import functools
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _quit)
    sys.unraisablehook = functools.partial(_ignore_stop, default=sys.unraisablehook)


#: the drawing processes a command started for a single run's figures before it knew the run (the ``ddmr run``
#: program: :func:`ddmr_cli.cli.main.console`), for the job to take (:meth:`PlotProcesses.take`); None: none
STARTED: ContextVar["PlotProcesses | None"] = ContextVar("ddmr_plot_processes", default=None)


class PlotProcesses:
    """Processes that draw a run's figures (module docstring); a context manager that ends them.

    Use ``draw`` with :func:`~ddmr_cli.plots.run.run_plots`'s arguments once the series exists; it returns the
    paths of every figure, whichever process drew it.
    """

    def __init__(self, shares: tuple[tuple[str, ...], ...] = SHARES) -> None:
        self._conns: list = []
        self._shares = shares
        self._process = None
        self._sent = None
        self._used = False
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

    @classmethod
    @contextlib.contextmanager
    def started(cls):
        """Start drawing processes now, for a job of this context to take (:meth:`take`); ended on the way out
        when no job took them."""
        processes = cls()
        token = STARTED.set(processes)
        try:
            yield processes
        finally:
            STARTED.reset(token)
            processes.close()

    @classmethod
    def take(cls) -> "PlotProcesses":
        """The processes :meth:`started` for this context (once), else new ones."""
        processes = STARTED.get()
        if processes is None:
            return cls()
        STARTED.set(None)
        return processes

    def __enter__(self) -> "PlotProcesses":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def send(self, series: dict, controller: str, scenario: str, seed: int, out_dir: Path,
             settle_time: float = 3.0) -> None:
        """Hand a run (:func:`~ddmr_cli.plots.run.run_plots`'s arguments) to the processes, each the channels of
        its share's figures: they draw while the job goes on; :meth:`collect` waits for them."""
        from ddmr_cli.plots.run import FIGURES, Run, RunInfo

        run = Run.of(RunInfo(controller, scenario, seed, Path(out_dir), settle_time), series)
        sent = []
        for share, conn in zip(self._shares, self._conns):
            part: dict = {}
            for name in share:
                part.update(FIGURES[name].channels(series))
            try:
                conn.send((run, part))
                sent.append((share, conn))
            except (OSError, ValueError):
                pass
        self._sent, self._used = (run, series, sent), True

    def collect(self) -> list[Path]:
        """The paths of every figure of the run :meth:`send` handed over, in :data:`~ddmr_cli.plots.run.FIGURES`'
        order, those of a share whose process is missing or failed drawn here."""
        from ddmr_cli.plots.run import FIGURES, draw_run

        run, series, sent = self._sent
        self._sent = None
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
            drawn.update(zip(missing, draw_run(run, series, missing)))
        return [drawn[name] for name in FIGURES]

    def draw(self, series: dict, controller: str, scenario: str, seed: int, out_dir: Path,
             settle_time: float = 3.0) -> list[Path]:
        """Every figure of :func:`~ddmr_cli.plots.run.run_plots` (same arguments): :meth:`send`, then
        :meth:`collect`."""
        self.send(series, controller, scenario, seed, out_dir, settle_time)
        return self.collect()

    def close(self) -> None:
        """Tell the processes to quit and wait for them (killed when they do not end within 5 s). Processes that
        were never sent a run are stopped at once (SIGTERM, which they turn into :class:`SystemExit`, so they
        unwind cleanly, even in matplotlib's import): a run that fails its config check does not wait for them."""
        for conn in self._conns:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
            conn.close()
        if self._process is not None:
            if not self._used:
                self._process.terminate()
            self._process.join(5.0)
            if self._process.is_alive():
                self._process.kill()
                self._process.join()
        self._conns, self._process = [], None


__all__ = ["PlotProcesses", "SHARES"]
