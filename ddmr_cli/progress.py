"""Progress of long work on the terminal: tqdm bars (elapsed time, rate, ETA) on a terminal, a plain line every
:data:`LOG_EVERY` seconds when stderr is a file or a pipe (a log, CI), nothing with ``run.progress=false``.

tqdm is the field's convention for progress in Python command-line tools (pip, Hugging Face, Optuna's own
``show_progress_bar``; Optuna already brings it in). A bar redraws one terminal line in place; written into a
log that would be one endless line of carriage returns, so off a terminal :func:`bar` hands tqdm a stream that
turns each refresh into one whole line, and refreshes at most every :data:`LOG_EVERY` seconds.

Who shows what:

- ``ddmr run`` (one job): a bar over the job's steps (:func:`ddmr_cli.job.execute`; on a terminal drawn once the
  command has run :data:`DELAY` s, :func:`delay_since_start`), and before the first step,
  when the step loop must be compiled for this controller and call, :func:`compile_notice`'s line;
- ``ddmr run -m``: a bar over the jobs as they are validated, then one over the jobs as their summaries appear
  (:class:`SweepWatch`, whatever the launcher), then a :func:`status` line while the sweep's tables are written;
  the jobs of a sweep draw no bars of their own; an Optuna session (the gain tuning, the sensitivity study's
  calibration search) a bar over its trials (:class:`TrialWatch`);
- ``ddmr sensitivity``: each stage's sweep bar, the stage's results above it, and a :func:`status` line while it
  writes the report;
- ``ddmr report``: on a terminal a :func:`status` line while it reads the jobs, then a bar over the report's
  sections and figures, both drawn at once when the command has already run for :data:`DELAY` s
  (:func:`delay_since_start`), and the verdicts (:func:`say`) as soon as they are known, before the figures are
  drawn;
- ``ddmr bench``: a :func:`status` line for each measurement, saying what it measures and for how long.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Callable, Iterable, TextIO

from tqdm import tqdm

#: seconds between two plain progress lines when stderr is not a terminal
LOG_EVERY = 10.0
#: seconds between two redraws of a bar on a terminal (tqdm's mininterval)
TTY_EVERY = 0.2
#: seconds before a bar is first drawn (tqdm's delay): work done sooner, or refused at once with one error line,
#: draws none; ``DDMR_PROGRESS_DELAY`` sets it (0: every bar at once, so a test does not depend on how fast a
#: machine is)
DELAY = float(os.environ.get("DDMR_PROGRESS_DELAY", "1.0"))
_LINE_FORMAT = "{desc}: {n_fmt}/{total_fmt} {unit} ({percentage:.0f} %), {elapsed} elapsed, {remaining} left"
_STATUS_FORMAT = "{desc} ({elapsed} elapsed)"


def delay_since_start(stream: TextIO | None = None) -> float:
    """The delay of a bar that a command draws late in its start-up: on a terminal (``stream``, default stderr),
    :data:`DELAY` less the time this process has already run (psutil's start time), so that a command silent for
    :data:`DELAY` s since it started shows its progress at once (``ddmr report``'s imports and read of the jobs take
    1-2 s before its bar exists); in a log, :data:`DELAY` (a refused command there prints its one error line only)."""
    if not interactive(stream):
        return DELAY
    import psutil

    try:
        ran = time.time() - psutil.Process().create_time()
    except (psutil.Error, OSError):
        return DELAY
    return min(DELAY, max(0.0, DELAY - ran))


def interactive(stream: TextIO | None = None) -> bool:
    """True when ``stream`` (default stderr) is a terminal."""
    stream = sys.stderr if stream is None else stream
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # closed or not a real stream
        return False


class _Lines:
    """A stream for tqdm off a terminal: each refresh becomes one whole line (no carriage returns, no blanks, no
    line twice in a row: tqdm redraws the last state when it closes)."""

    def __init__(self, stream: TextIO) -> None:
        self.stream = stream
        self.last = ""

    def write(self, text: str) -> None:
        line = text.replace("\r", "").strip()
        if line and line != self.last:
            self.stream.write(line + "\n")
            self.last = line

    def flush(self) -> None:
        self.stream.flush()


class Silent:
    """What :func:`bar` returns when progress is off: tqdm's interface, doing nothing. Not a disabled tqdm,
    which still makes tqdm's multiprocessing lock, a semaphore: a sweep's worker killed on Ctrl-C would leave it
    behind, and the resource tracker would warn of it after ``ddmr: interrupted``."""

    disable, n, total = True, 0, None

    def __init__(self, total=None) -> None:
        self.total = total

    def update(self, n=1) -> None:
        pass

    def refresh(self) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> "Silent":
        return self

    def __exit__(self, *exc) -> None:
        pass


def bar(total: int | float | None, desc: str, unit: str = "it", enabled: bool = True,
        stream: TextIO | None = None, **kwargs) -> "tqdm | Silent":
    """A progress bar on ``stream`` (default stderr): a tqdm bar on a terminal, a plain line every
    :data:`LOG_EVERY` s otherwise (its ``ddmr_every``: how often a :class:`Ticker` redraws it), a
    :class:`Silent` one when not ``enabled`` (``run.progress=false``); first drawn after :data:`DELAY` s unless
    ``delay`` says otherwise."""
    stream = sys.stderr if stream is None else stream
    if not enabled:
        return Silent(total)
    kwargs.setdefault("delay", DELAY)
    if interactive(stream):
        b = tqdm(total=total, desc=desc, unit=unit, file=stream, mininterval=TTY_EVERY, dynamic_ncols=True,
                 **kwargs)
        b.ddmr_every = 1.0
    else:
        kwargs.setdefault("bar_format", _LINE_FORMAT)
        b = tqdm(total=total, desc=desc, unit=unit, file=_Lines(stream), mininterval=LOG_EVERY,
                 maxinterval=LOG_EVERY, **kwargs)
        b.ddmr_every = LOG_EVERY
    return b


def say(lines: Iterable[str], stream: TextIO | None = None) -> None:
    """Lines of a result on ``stream`` (default stdout) while a bar may be drawn on stderr: a watch whose work has
    all ended is closed first (:func:`_settle`); a bar still going on is cleared by tqdm, the lines written, and
    the bar drawn again below them."""
    stream = sys.stdout if stream is None else stream
    _settle()
    tqdm.write("\n".join(lines), file=stream)  # one clear and redraw of the bar for all of them
    stream.flush()


def each(items: Iterable, total: int, desc: str, unit: str = "it", enabled: bool = True, **kwargs):
    """Iterate ``items`` with a :func:`bar` over them (``kwargs``: tqdm's)."""
    with bar(total, desc, unit, enabled, **kwargs) as b:
        for item in items:
            yield item
            b.update(1)


class Ticker:
    """Redraws a bar from a daemon thread, so its elapsed time and ETA move while nothing finishes (a compile, a
    long job): checked every second, drawn first once tqdm's ``delay`` has passed, then every ``ddmr_every``
    seconds (1 s on a terminal, :data:`LOG_EVERY` in a log). ``poll()``, when given, is called each second and
    returns how far to advance; the bar is closed, and the thread ends, once it is full."""

    def __init__(self, b: "tqdm | Silent", poll: Callable[[], int] | None = None) -> None:
        self.bar, self.poll = b, poll
        self.every = getattr(b, "ddmr_every", 1.0)
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._thread = None
        if not b.disable:  # a silent bar (run.progress=false) needs no thread
            self._thread = threading.Thread(target=self._run, name="ddmr-progress", daemon=True)
            self._thread.start()

    def _due(self) -> bool:
        b = self.bar
        if b.format_dict["elapsed"] < getattr(b, "delay", 0):
            return False
        return b.last_print_t <= b.start_t or time.time() - b.last_print_t >= self.every

    def tick(self) -> bool:
        """One round: advance the bar by ``poll()``, redraw it when due, and close it once it is full (before what
        follows is printed: a sweep's summary). True once the bar is closed. The thread runs one a second; a
        watch's :meth:`_FileWatch.settle` runs one at once, under the same lock."""
        with self._lock:
            if self.bar.disable:  # closed by an earlier round
                return True
            advanced = self.poll() if self.poll is not None else 0
            if advanced:
                self.bar.n += advanced  # counted now, drawn when due (tqdm's update would wait for mininterval)
            if self._due():
                self.bar.refresh()
                self.bar.last_print_t = time.time()  # tqdm's record of its last draw (refresh leaves it)
            if self.poll is not None and self.bar.total is not None and self.bar.n >= self.bar.total:
                self.bar.close()
                return True
            return False

    def _run(self) -> None:
        while not self._stop.wait(1.0):
            if self.tick():
                return

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()

    def __enter__(self) -> "Ticker":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


@contextmanager
def status(what: str, enabled: bool = True, stream: TextIO | None = None, **kwargs):
    """A line saying ``what`` is being done and for how long, for work without a count (one measurement of
    ``ddmr bench``): drawn after :data:`DELAY` s, its elapsed time redrawn every second on a terminal (every
    :data:`LOG_EVERY` s in a log) by a :class:`Ticker`, and cleared from a terminal when the work ends (what is
    printed next is its result). A watch's bar whose work has all ended is closed first (:func:`_settle`), so that
    the status takes the cursor's line, not the one below a bar about to close."""
    _settle()
    with bar(None, what, enabled=enabled, stream=stream, bar_format=_STATUS_FORMAT, leave=False, **kwargs) as b, \
            Ticker(b):
        yield b


class StepBar:
    """The engine's ``progress(steps_done, steps_total)`` callback as a bar over one job's ``total`` steps, drawn
    from the start and redrawn every second (so the compile before the first chunk is not a frozen bar). It is made
    after ``ddmr run``'s imports and composition (about 1 s): on a terminal it is drawn once the process has run
    :data:`DELAY` s (:func:`delay_since_start`), not :data:`DELAY` s after it is made."""

    def __init__(self, label: str, n_runs: int, total: int, enabled: bool = True) -> None:
        self._bar = bar(total, f"{label} ({n_runs} runs)", "steps", enabled, delay=delay_since_start())
        self._ticker = Ticker(self._bar)

    def __call__(self, done: int, total: int) -> None:
        self._bar.update(done - self._bar.n)

    def compiling(self, controller: str) -> None:
        """Say :func:`compile_notice`'s line above the bar (the bar is cleared, the line written, the bar redrawn)."""
        if isinstance(self._bar, tqdm):
            self._bar.clear()
            compile_notice(controller, self._bar.fp)
            self._bar.refresh()
        else:
            compile_notice(controller)

    def close(self) -> None:
        self._ticker.stop()
        self._bar.close()


def compile_notice(controller: str, stream: TextIO | None = None) -> None:
    """The line said before the step loop is compiled (first use of a controller, or of a new call signature:
    another actuator delay, control rate or sensor). On a terminal it starts by clearing the line, which may hold
    the bar of another process (a sweep's, drawn by ``ddmr run`` while its workers compile). Written directly,
    not with ``tqdm.write``, which would make tqdm's lock in a sweep's worker (see :class:`Silent`)."""
    stream = sys.stderr if stream is None else stream
    clear = "\r\033[K" if interactive(stream) else ""
    stream.write(f"{clear}ddmr: compiling the step loop for {controller} (first use only, about 10 s)\n")
    stream.flush()


def quiet_sweep_logging(hydra_cfg) -> list[str]:
    """Hydra overrides that keep a sweep's INFO log lines (Hydra's list of launched jobs, each job's results) off
    the terminal while :class:`SweepWatch` draws its bar there; warnings and errors still show, and every line
    is still in the log files. Only for Hydra's default logging (a ``console`` handler), else none."""
    return [f"+hydra.{node}.handlers.console.level=WARNING" for node in ("hydra_logging", "job_logging")
            if "console" in (hydra_cfg.get(node) or {}).get("handlers", {})]


#: the watch (:class:`SweepWatch`, :class:`TrialWatch`) drawing its bar in this context, if any: :func:`say` and
#: :func:`status` settle it first (:func:`_settle`)
WATCHING: ContextVar["_FileWatch | None"] = ContextVar("ddmr_watching", default=None)


def _settle() -> None:
    """Before a result or a status line is printed while a watch draws its bar: count what has ended now, and close
    the bar if everything has. A sweep's callback prints its summary as soon as Hydra's launcher returns, that is,
    when every job has ended but before the watch's next once-a-second poll; settled, the bar ends at 100 % above
    the summary, not below it."""
    watch = WATCHING.get()
    if watch is not None:
        watch.settle()


class _FileWatch:
    """A bar over work done in other processes, advanced as the files that mark each piece's end appear (any
    launcher: the jobs may run in worker processes or on other hosts sharing the file system); polled and redrawn
    every second by a :class:`Ticker`, so the elapsed time and the ETA move between pieces too. On a terminal it is
    drawn once the command has run :data:`DELAY` s (:func:`delay_since_start`: it is made after the planning)."""

    desc, unit = "", ""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self._bar: tqdm | None = None
        self._ticker: Ticker | None = None
        self._token = None

    def _start(self) -> tuple[int, int]:
        """``(total, done already)``, read when the watch starts."""
        raise NotImplementedError

    def _poll(self) -> int:
        """How many more pieces have ended since the last poll."""
        raise NotImplementedError

    def settle(self) -> None:
        """Count what has ended now, and close the bar if everything has (:func:`_settle`)."""
        if self._ticker is not None:
            self._ticker.tick()

    def __enter__(self):
        if self.enabled:
            total, done = self._start()
            self._bar = bar(total, self.desc, self.unit, initial=done, delay=delay_since_start())
            self._ticker = Ticker(self._bar, poll=self._poll)
            self._token = WATCHING.set(self)
        return self

    def __exit__(self, *exc) -> None:
        if self._token is not None:
            WATCHING.reset(self._token)
            self._token = None
        if self._ticker is not None:
            self._ticker.stop()
            self._ticker.tick()  # the last count; closes the bar if its work has all ended
            self._bar.close()


class SweepWatch(_FileWatch):
    """A bar over a sweep's jobs, advanced as their ``marker`` files (``summary.json``) appear. Jobs already
    complete when it starts (a resumed sweep) are counted from the start, outside the rate."""

    desc, unit = "sweep", "jobs"

    def __init__(self, out_dir: Path, job_dirs: list[str], marker: str, enabled: bool = True) -> None:
        super().__init__(enabled and bool(job_dirs))
        self.paths = [Path(out_dir) / d / marker for d in job_dirs]
        self._pending: list[Path] = []

    def _start(self) -> tuple[int, int]:
        self._pending = [p for p in self.paths if not p.is_file()]
        return len(self.paths), len(self.paths) - len(self._pending)

    def _poll(self) -> int:
        before = len(self._pending)
        self._pending = [p for p in self._pending if not p.is_file()]
        return before - len(self._pending)


class TrialWatch(_FileWatch):
    """A bar over the ``total`` trials an Optuna session runs (the gain tuning, the study's calibration search),
    advanced as the trials' ``marker`` files appear one or two levels below ``out_dir``: a trial's dir is named from
    its sampled values, so the dirs are not known before the trials run. Files there before the session (a resumed
    study's trials) are not counted, and the count stops at ``total``."""

    desc, unit = "trials", "trials"

    def __init__(self, out_dir: Path, total: int, marker: str, enabled: bool = True) -> None:
        super().__init__(enabled and int(total) > 0)
        self.out_dir, self.total, self.marker = Path(out_dir), int(total), marker
        self._before = self._seen = 0

    def _count(self) -> int:
        return sum(1 for pattern in (f"*/{self.marker}", f"*/*/{self.marker}") for _ in self.out_dir.glob(pattern))

    def _start(self) -> tuple[int, int]:
        self._before = self._count()
        return self.total, 0

    def _poll(self) -> int:
        seen = min(self.total, max(0, self._count() - self._before))
        advanced, self._seen = seen - self._seen, max(seen, self._seen)
        return max(0, advanced)


__all__ = ["DELAY", "LOG_EVERY", "Silent", "SweepWatch", "StepBar", "Ticker", "TrialWatch", "bar", "compile_notice",
           "delay_since_start", "each", "interactive", "quiet_sweep_logging", "status"]
