"""Plots of one job's first kept seed (``run.plots=true``): trajectory, errors, control signal.

Uses the report's styles, decimation and saver (:mod:`.common`); matplotlib is imported only when a plot is made,
and not its pyplot (:func:`.common.figure`). Errors are in millimetres (heading in mrad); every time axis shades
the terrain zones and the start-up transient (``t < settle_time``, the window the steady-state metrics skip), and
the linear axes fit the steady state, so the transient does not flatten them; the deviation is on a log scale
over the whole run, and the control signals have a full-resolution zoom into the steady state.

Each figure is drawn in two steps (:class:`_Figure`): its frame, the same for every run, then the run into it; a
drawing process (:mod:`.processes`) makes and draws the frames before the run exists. The frames and the drawing
need matplotlib and numpy only; what they take from the configuration and the engine (label, style, estimators:
:class:`Run`) is made in the job's process.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddmr_cli.plots.common import (DPI, OKABE_ITO, REFERENCE_STYLE, equal_aspect, figure, label_of, log_scale,
                                   save, style_of, thin, warm_up)

#: the zoom of the control signals (s)
ZOOM_WIDTH = 0.3


def _plot(ax, x, y, full: bool = False, **kw):
    idx = np.arange(len(y)) if full else thin(y)
    return ax.plot(np.asarray(x)[idx], np.asarray(y)[idx], **kw)


def _log(ax, y) -> None:
    """Log scale when ``y`` has positive values (a run that tracks exactly has none)."""
    y = np.asarray(y, float)
    if (y[np.isfinite(y)] > 0).any():
        log_scale(ax)


def _shade(ax, t: np.ndarray, zone: np.ndarray | None, settle: float) -> None:
    """Every other terrain zone light grey; the start-up transient hatched."""
    if zone is not None and len(zone) == len(t):
        cuts = np.flatnonzero(np.diff(np.asarray(zone).astype(int))) + 1
        for i, (a, b) in enumerate(zip(np.r_[0, cuts], np.r_[cuts, len(t)])):
            if i % 2:
                ax.axvspan(t[a], t[b - 1], color="0.93", zorder=0, lw=0)
    if settle > t[0]:
        ax.axvspan(t[0], min(settle, t[-1]), facecolor="none", edgecolor="0.8", hatch="///", lw=0, zorder=0)


def _fit(ax, t: np.ndarray, arrays, settle: float, margin: float = 0.15) -> bool:
    """The y range of the steady state (t >= settle; the whole run when that is empty); True when the start-up
    transient is off-scale."""
    steady = t >= settle
    if not steady.any():
        return False
    vals = np.concatenate([np.asarray(a)[steady] for a in arrays])
    vals = vals[np.isfinite(vals)]
    if not vals.size:
        return False
    lo, hi = float(vals.min()), float(vals.max())
    pad = margin * (hi - lo or abs(hi) or 1.0)
    ax.set_ylim(lo - pad, hi + pad)
    early = np.concatenate([np.asarray(a)[~steady] for a in arrays])
    early = early[np.isfinite(early)]
    return bool(early.size and (early.min() < lo - pad or early.max() > hi + pad))


def _zoom(t: np.ndarray, settle: float) -> tuple[float, float]:
    """ZOOM_WIDTH seconds in the middle of the steady state (of the run when it has none)."""
    start = settle if settle < t[-1] else t[0]
    mid = 0.5 * (start + t[-1])
    width = min(ZOOM_WIDTH, t[-1] - start) or ZOOM_WIDTH
    return mid - width / 2, mid + width / 2


@dataclass(frozen=True)
class RunInfo:
    """What a run's figures show besides its series, all known before the run is simulated: the controller,
    scenario and seed, the directory the PNGs go to and ``metrics.settle_time`` (the start of the steady state
    the axes fit)."""

    controller: str
    scenario: str
    seed: int
    out_dir: Path
    settle_time: float = 3.0


@dataclass(frozen=True)
class Run:
    """What the figures of a run share: :class:`RunInfo` with the controller's label and style (from the
    controllers' configs), and the estimators whose estimates of d its series carry. Made in the job's process
    (:meth:`of`), which has the configuration and the engine imported; a drawing process needs neither."""

    label: str
    title: str
    style: dict
    settle: float
    note: str
    out_dir: Path
    estimators: tuple[str, ...] = ()

    @classmethod
    def of(cls, info: RunInfo, series: dict[str, np.ndarray]) -> "Run":
        from ddmr_cli.engine.series import estimate_names

        settle, label = float(info.settle_time), label_of(info.controller)
        return cls(label, f"{label}, {info.scenario}, seed {info.seed}",
                   style_of(info.controller).kwargs(), settle,
                   f"hatched: start-up (t < {settle:g} s); grey bands: terrain zones", Path(info.out_dir),
                   tuple(estimate_names(series)))


class _Figure:
    """One figure of a run, in two steps: the constructor lays out what is the same for every run (the figure,
    its axes, their labels and grids) and, with ``warm``, draws that frame once, so that its ticks, fonts and
    text are ready before the run exists (a drawing process waiting for it: :mod:`.processes`); :meth:`finish`
    draws the run into the frame and saves the PNG. The same file either way."""

    #: the PNG's name in the run's plot dir
    file = ""
    #: inches
    size = (9.0, 6.5)
    #: the channels of the series it draws (:meth:`channels`)
    CHANNELS: tuple[str, ...] = ()
    #: the ticks a warm frame makes on each axis, so that the run's draw makes none (ticks are made as an axis
    #: first needs them, 1 ms each): major ones (at most 11 on an axis of the packaged runs' figures) and, on the
    #: log axes (:meth:`_log_axes`), minor ones (at most 48)
    MAJOR_TICKS, MINOR_TICKS = 12, 50

    def __init__(self, warm: bool = False) -> None:
        self.fig = figure(figsize=self.size, dpi=DPI)
        self._frame()
        if warm:
            for ax in self.fig.axes:
                ax.xaxis.get_major_ticks(self.MAJOR_TICKS)
                ax.yaxis.get_major_ticks(self.MAJOR_TICKS)
            for axis in self._log_axes():
                axis.get_minor_ticks(self.MINOR_TICKS)
            warm_up(self.fig)

    def _frame(self) -> None:
        raise NotImplementedError

    def _log_axes(self) -> list:
        """The axes (x or y) that a run usually puts on a log scale."""
        return []

    def _draw(self, run: Run, series: dict) -> None:
        raise NotImplementedError

    @classmethod
    def channels(cls, series: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """What :meth:`finish` draws of ``series`` (what a drawing process is sent): :attr:`CHANNELS`, in the
        series' order."""
        return {key: value for key, value in series.items() if key in cls.CHANNELS}

    def finish(self, run: Run, series: dict[str, np.ndarray]) -> Path:
        """Draw ``run`` (its ``series``) into the frame and save the figure in ``run.out_dir``; its path."""
        self._draw(run, series)
        return save(self.fig, run.out_dir / self.file, tight=False)


class _Trajectory(_Figure):
    """The path against the reference (equal axes), and the deviation along it (log)."""

    file, size = "trajectory.png", (9, 6.5)
    CHANNELS = ("t", "x_ref", "y_ref", "x", "y", "distance", "deviation")

    def _frame(self) -> None:
        self.ax, self.ax2 = self.fig.subplots(2, 1, gridspec_kw={"height_ratios": [1.2, 1]})
        self.ax.set(xlabel="x [m]", ylabel="y [m]")
        self.ax2.set(xlabel="distance travelled [m]", ylabel="deviation [mm] (log)",
                     title="zoom: distance to the reference point along the path")
        for a in (self.ax, self.ax2):
            a.grid(alpha=0.3, which="both")
        self.fig.subplots_adjust(left=0.1, right=0.97, bottom=0.09, top=0.94, hspace=0.4)

    def _log_axes(self) -> list:
        return [self.ax2.yaxis]

    def _draw(self, run: Run, series: dict) -> None:
        ax, ax2 = self.ax, self.ax2
        settle, style, t = run.settle, run.style, series["t"]
        ax.set_title(f"Trajectory (equal axes): {run.title}")
        _plot(ax, series["x_ref"], series["y_ref"], label="reference", zorder=10, **REFERENCE_STYLE)
        _plot(ax, series["x"], series["y"], label=run.label, **style)
        equal_aspect(ax)
        ax.legend(loc="best")
        dist = series.get("distance", t)
        steady = t >= settle
        _plot(ax2, dist, 1000 * series["deviation"], color=style["color"], lw=0.8)
        _log(ax2, series["deviation"])
        if steady.any():
            ax2.axvline(float(dist[np.argmax(steady)]), color="0.3", ls=":", lw=1.0)
            ax2.text(float(dist[np.argmax(steady)]), 0.97, f" steady state (t ≥ {settle:g} s)",
                     transform=ax2.get_xaxis_transform(), ha="left", va="top", fontsize=8, color="0.3")


class _Errors(_Figure):
    """The deviation (log) and the pose errors over time, the linear ones fitting the steady state."""

    file, size = "errors.png", (9, 8.5)
    CHANNELS = ("t", "zone", "deviation", "e_x", "e_y", "e_theta")
    #: (channel, scale, axis label) of each row
    ROWS = (("deviation", 1000, "deviation [mm] (log)"), ("e_x", 1000, "e_x [mm]"), ("e_y", 1000, "e_y [mm]"),
            ("e_theta", 1000, "e_θ [mrad]"))

    def _frame(self) -> None:
        self.axes = self.fig.subplots(4, 1, sharex=True)
        for ax, (_, _, label) in zip(self.axes, self.ROWS):
            ax.set_ylabel(label)
            ax.grid(alpha=0.3, which="both")
        self.axes[-1].set_xlabel("t [s]")
        self.fig.subplots_adjust(left=0.11, right=0.98, bottom=0.06, top=0.93, hspace=0.12)

    def _log_axes(self) -> list:
        return [self.axes[0].yaxis]

    def _draw(self, run: Run, series: dict) -> None:
        axes = self.axes
        settle, color = run.settle, run.style["color"]
        t, zone = series["t"], series.get("zone")
        clipped = False
        for ax, (key, scale, _) in zip(axes, self.ROWS):
            _shade(ax, t, zone, settle)
            _plot(ax, t, scale * series[key], color=color, lw=0.8)
            if key == "deviation":
                _log(ax, series[key])  # the whole run: the transient and the steady state, decades apart
            else:
                ax.axhline(0, color="0.3", lw=0.5)
                clipped |= _fit(ax, t, [scale * series[key]], settle)
        axes[0].set_title(f"Tracking errors: {run.title}\n{run.note}"
                          + ("; e_x, e_y, e_θ fit the steady state (the transient is off-scale)" if clipped else ""),
                          fontsize=9)


class _Control(_Figure):
    """The control signals, sliding variables and disturbance (with its estimate) over time, and a zoom into
    the steady state at full resolution."""

    file, size = "control.png", (11, 7)
    CHANNELS = ("t", "zone", "u_right", "u_left", "s_right", "s_left", "d_true_right")
    #: the controller's whole estimate of d on the right wheel in :meth:`channels`
    ESTIMATE = "estimate_right"
    #: each row's axis label
    UNITS = ("voltage [V]", "s [rad/s]", "d [rad/s²]")

    def _frame(self) -> None:
        self.axes = self.fig.subplots(3, 2, sharex="col", gridspec_kw={"width_ratios": [2.4, 1]})
        for row, unit in zip(self.axes, self.UNITS):
            row[0].set_ylabel(unit)
            for ax in row:
                ax.grid(alpha=0.3)
        self.axes[-1, 1].set_xlabel("t [s]")
        self.fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.95, hspace=0.12, wspace=0.15)

    @classmethod
    def channels(cls, series: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """:attr:`CHANNELS` and, as :attr:`ESTIMATE`, the controller's whole estimate of d on the right wheel
        (:func:`~ddmr_cli.engine.series.d_hat`; none without an estimator)."""
        from ddmr_cli.engine.series import d_hat, estimate_names

        out = super().channels(series)
        if estimate_names(series):
            out[cls.ESTIMATE] = d_hat(series, "right")
        return out

    def _draw(self, run: Run, series: dict) -> None:
        axes = self.axes
        settle, note, color = run.settle, run.note, run.style["color"]
        axes[0, 0].set_title(f"Control signal, sliding variable, disturbance: {run.title}", fontsize=9)
        t, zone = series["t"], series.get("zone")
        t0, t1 = _zoom(t, settle)
        win = (t >= t0) & (t <= t1)
        estimators = run.estimators  # the controller's estimates of d (none: no estimate drawn)
        estimate = series.get(self.ESTIMATE)
        signals = ((("u_right", "u_R", {"color": color, "lw": 0.6}), ("u_left", "u_L", {"color": "0.5", "lw": 0.6})),
                   (("s_right", "s_R", {"color": color, "lw": 0.6}), ("s_left", "s_L", {"color": "0.5", "lw": 0.6})),
                   (("d_true_right", "d true (R)", {**REFERENCE_STYLE, "lw": 0.6}),
                    *([(None, f"d̂ {' + '.join(estimators)} (R)", {"color": color, "lw": 0.7})] if estimators else [])))
        clipped = False
        for row, lines in zip(axes, signals):
            arrays = [series[key] if key else estimate for key, _, _ in lines]
            _shade(row[0], t, zone, settle)
            row[0].axvspan(t0, t1, color=OKABE_ITO["yellow"], alpha=0.35, zorder=0)
            for y, (_, name, kw) in zip(arrays, lines):
                _plot(row[0], t, y, label=name, **kw)
                _plot(row[1], t[win], y[win], full=True, **kw)
            clipped |= _fit(row[0], t, arrays, settle)
            row[0].legend(loc="lower right", fontsize=7)
        axes[0, 1].set_title(f"zoom: t = {t0:.2f}–{t1:.2f} s (highlighted)", fontsize=9)
        axes[-1, 0].set_xlabel("t [s]" + (f" — {note}; y fits the steady state" if clipped else f" — {note}"))
        axes[0, 1].set_xlim(t0, t1)


#: the figures of a run, by name, in the order :func:`run_plots` draws them
FIGURES = {"trajectory": _Trajectory, "errors": _Errors, "control": _Control}


def run_plots(series: dict[str, np.ndarray], controller: str, scenario: str, seed: int, out_dir: Path,
              settle_time: float = 3.0, figures: tuple[str, ...] | None = None) -> list[Path]:
    """Trajectory, errors and control signal of one run: three PNGs in ``out_dir`` (``figures``: some of
    :data:`FIGURES` only); ``settle_time`` is ``metrics.settle_time`` (the start of the steady state the axes
    fit)."""
    return draw_run(Run.of(RunInfo(controller, scenario, seed, Path(out_dir), settle_time), series), series, figures)


def draw_run(run: Run, series: dict[str, np.ndarray], figures: tuple[str, ...] | None = None) -> list[Path]:
    """The figures ``figures`` (every one of :data:`FIGURES` by default) of ``run`` and its ``series``, drawn here
    into new frames: their paths."""
    return [frame.finish(run, frame.channels(series)) for frame in frames(figures)]


def frames(figures: tuple[str, ...] | None = None, warm: bool = False) -> list[_Figure]:
    """The frames of a run's figures (``figures``: some of :data:`FIGURES` only), each ready for a run
    (:meth:`_Figure.finish`); ``warm``: each drawn once already (for a process that waits for the run)."""
    return [FIGURES[name](warm=warm) for name in (figures or FIGURES)]
