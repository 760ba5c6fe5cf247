"""Plots of one job's first kept seed (``run.plots=true``): trajectory, errors, control signal.

Uses the report's styles, decimation and saver (:mod:`.common`); matplotlib is imported only when a plot is made,
and not its pyplot (:func:`.common.figure`). Errors are in millimetres (heading in mrad); every time axis shades
the terrain zones and the start-up transient (``t < settle_time``, the window the steady-state metrics skip), and
the linear axes fit the steady state, so the transient does not flatten them; the deviation is on a log scale
over the whole run, and the control signals have a full-resolution zoom into the steady state.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddmr_cli.plots.common import (OKABE_ITO, REFERENCE_STYLE, StyleBook, equal_aspect, figure, label_of,
                                   log_scale, save, thin)
from ddmr_cli.engine.results import d_hat, estimate_names

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
class _Run:
    """What the three figures of a run share."""

    series: dict
    controller: str
    title: str
    style: dict
    settle: float
    note: str


def run_plots(series: dict[str, np.ndarray], controller: str, scenario: str, seed: int, out_dir: Path,
              settle_time: float = 3.0, figures: tuple[str, ...] | None = None) -> list[Path]:
    """Trajectory, errors and control signal of one run: three PNGs in ``out_dir`` (``figures``: some of
    :data:`FIGURES` only); ``settle_time`` is ``metrics.settle_time`` (the start of the steady state the axes
    fit)."""
    settle = float(settle_time)
    run = _Run(series, controller, f"{label_of(controller)}, {scenario}, seed {seed}",
               StyleBook([controller])[controller].kwargs(), settle,
               f"hatched: start-up (t < {settle:g} s); grey bands: terrain zones")
    return [FIGURES[name](run, Path(out_dir)) for name in (figures or FIGURES)]


def _trajectory(run: _Run, out_dir: Path) -> Path:
    series, controller, title, style, settle = run.series, run.controller, run.title, run.style, run.settle
    color, t = style["color"], series["t"]
    fig = figure(figsize=(9, 6.5))
    ax, ax2 = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1.2, 1]})
    _plot(ax, series["x_ref"], series["y_ref"], label="reference", zorder=10, **REFERENCE_STYLE)
    _plot(ax, series["x"], series["y"], label=label_of(controller), **style)
    equal_aspect(ax)
    ax.set(xlabel="x [m]", ylabel="y [m]", title=f"Trajectory (equal axes): {title}")
    ax.legend(loc="best")
    dist = series.get("distance", t)
    steady = t >= settle
    _plot(ax2, dist, 1000 * series["deviation"], color=color, lw=0.8)
    _log(ax2, series["deviation"])
    if steady.any():
        ax2.axvline(float(dist[np.argmax(steady)]), color="0.3", ls=":", lw=1.0)
        ax2.text(float(dist[np.argmax(steady)]), 0.97, f" steady state (t ≥ {settle:g} s)",
                 transform=ax2.get_xaxis_transform(), ha="left", va="top", fontsize=8, color="0.3")
    ax2.set(xlabel="distance travelled [m]", ylabel="deviation [mm] (log)",
            title="zoom: distance to the reference point along the path")
    for a in (ax, ax2):
        a.grid(alpha=0.3, which="both")
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.09, top=0.94, hspace=0.4)
    return save(fig, out_dir / "trajectory.png", tight=False)


def _errors(run: _Run, out_dir: Path) -> Path:
    series, title, settle, note, color = run.series, run.title, run.settle, run.note, run.style["color"]
    t, zone = series["t"], series.get("zone")
    fig = figure(figsize=(9, 8.5))
    axes = fig.subplots(4, 1, sharex=True)
    rows = (("deviation", 1000, "deviation [mm] (log)"), ("e_x", 1000, "e_x [mm]"), ("e_y", 1000, "e_y [mm]"),
            ("e_theta", 1000, "e_θ [mrad]"))
    clipped = False
    for i, (ax, (key, scale, label)) in enumerate(zip(axes, rows)):
        _shade(ax, t, zone, settle)
        _plot(ax, t, scale * series[key], color=color, lw=0.8)
        if key == "deviation":
            _log(ax, series[key])  # the whole run: the transient and the steady state, decades apart
        else:
            ax.axhline(0, color="0.3", lw=0.5)
            clipped |= _fit(ax, t, [scale * series[key]], settle)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
    axes[0].set_title(f"Tracking errors: {title}\n{note}"
                      + ("; e_x, e_y, e_θ fit the steady state (the transient is off-scale)" if clipped else ""),
                      fontsize=9)
    axes[-1].set_xlabel("t [s]")
    fig.subplots_adjust(left=0.11, right=0.98, bottom=0.06, top=0.93, hspace=0.12)
    return save(fig, out_dir / "errors.png", tight=False)


def _control(run: _Run, out_dir: Path) -> Path:
    series, title, settle, note, color = run.series, run.title, run.settle, run.note, run.style["color"]
    t, zone = series["t"], series.get("zone")
    fig = figure(figsize=(11, 7))
    axes = fig.subplots(3, 2, sharex="col", gridspec_kw={"width_ratios": [2.4, 1]})
    t0, t1 = _zoom(t, settle)
    win = (t >= t0) & (t <= t1)
    estimators = estimate_names(series)  # the controller's estimates of d (none: no estimate drawn)
    estimate = d_hat(series, "right")
    signals = ((("u_right", "u_R", {"color": color, "lw": 0.6}), ("u_left", "u_L", {"color": "0.5", "lw": 0.6})),
               (("s_right", "s_R", {"color": color, "lw": 0.6}), ("s_left", "s_L", {"color": "0.5", "lw": 0.6})),
               (("d_true_right", "d true (R)", {**REFERENCE_STYLE, "lw": 0.6}),
                *([(None, f"d̂ {' + '.join(estimators)} (R)", {"color": color, "lw": 0.7})] if estimators else [])))
    clipped = False
    for row, lines, unit in zip(axes, signals, ("voltage [V]", "s [rad/s]", "d [rad/s²]")):
        arrays = [series[key] if key else estimate for key, _, _ in lines]
        _shade(row[0], t, zone, settle)
        row[0].axvspan(t0, t1, color=OKABE_ITO["yellow"], alpha=0.35, zorder=0)
        for y, (_, name, kw) in zip(arrays, lines):
            _plot(row[0], t, y, label=name, **kw)
            _plot(row[1], t[win], y[win], full=True, **kw)
        clipped |= _fit(row[0], t, arrays, settle)
        row[0].set_ylabel(unit)
        row[0].legend(loc="lower right", fontsize=7)
        for ax in row:
            ax.grid(alpha=0.3)
    axes[0, 0].set_title(f"Control signal, sliding variable, disturbance: {title}", fontsize=9)
    axes[0, 1].set_title(f"zoom: t = {t0:.2f}–{t1:.2f} s (highlighted)", fontsize=9)
    axes[-1, 0].set_xlabel("t [s]" + (f" — {note}; y fits the steady state" if clipped else f" — {note}"))
    axes[-1, 1].set_xlabel("t [s]")
    axes[0, 1].set_xlim(t0, t1)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.08, top=0.95, hspace=0.12, wspace=0.15)
    return save(fig, out_dir / "control.png", tight=False)


#: the figures of a run, by name, in the order :func:`run_plots` draws them
FIGURES = {"trajectory": _trajectory, "errors": _errors, "control": _control}
