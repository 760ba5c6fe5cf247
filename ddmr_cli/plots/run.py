"""Plots of one job's first kept seed (``run.plots=true``): trajectory, errors, control signal.

Uses the report's styles, decimation and saver (:mod:`.plotting`); matplotlib is imported only when a plot is made, and
not its pyplot (:func:`.plotting.figure`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddmr_cli.plots.common import REFERENCE_STYLE, StyleBook, equal_aspect, figure, label_of, save, thin
from ddmr_cli.engine.results import d_hat, estimate_names


def _plot(ax, x, y, **kw):
    idx = thin(y)
    return ax.plot(np.asarray(x)[idx], np.asarray(y)[idx], **kw)


def run_plots(series: dict[str, np.ndarray], controller: str, scenario: str, seed: int, out_dir: Path) -> list[Path]:
    """Trajectory, errors and control signal of one run: three PNGs in ``out_dir``."""
    out_dir = Path(out_dir)
    title = f"{label_of(controller)}, {scenario}, seed {seed}"
    style = StyleBook([controller])[controller].kwargs()
    color = style["color"]
    t = series["t"]
    paths = []

    fig = figure(figsize=(8, 3.5))
    ax = fig.subplots()
    _plot(ax, series["x_ref"], series["y_ref"], label="reference", zorder=10, **REFERENCE_STYLE)
    _plot(ax, series["x"], series["y"], label=label_of(controller), **style)
    equal_aspect(ax)
    ax.set(xlabel="x [m]", ylabel="y [m]", title=f"Trajectory (equal axes): {title}")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.14, top=0.9)
    paths.append(save(fig, out_dir / "trajectory.png", tight=False))

    fig = figure(figsize=(8, 8))
    axes = fig.subplots(4, 1, sharex=True)
    for ax, key, label in zip(axes, ("deviation", "e_x", "e_y", "e_theta"),
                              ("deviation [m]", "e_x [m]", "e_y [m]", "e_theta [rad]")):
        _plot(ax, t, series[key], color=color, lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Tracking errors: {title}")
    axes[-1].set_xlabel("t [s]")
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.07, top=0.95, hspace=0.12)
    paths.append(save(fig, out_dir / "errors.png", tight=False))

    fig = figure(figsize=(8, 7))
    axes = fig.subplots(3, 1, sharex=True)
    for ax, key, unit in ((axes[0], "u", "voltage [V]"), (axes[1], "s", "s [rad/s]")):
        _plot(ax, t, series[f"{key}_right"], color=color, lw=0.6, label=f"{key}_R")
        _plot(ax, t, series[f"{key}_left"], color="0.5", lw=0.6, alpha=0.7, label=f"{key}_L")
        ax.set_ylabel(unit)
        ax.legend(loc="best")
    _plot(axes[2], t, series["d_true_right"], label="d true (R)", **{**REFERENCE_STYLE, "lw": 0.6})
    estimators = estimate_names(series)
    if estimators:
        _plot(axes[2], t, d_hat(series, "right"), color=color, lw=0.7, label=f"d_hat {' + '.join(estimators)} (R)")
    axes[2].set_ylabel("d [rad/s^2]")
    axes[2].legend(loc="best")
    axes[0].set_title(f"Control signal, sliding variable, disturbance: {title}")
    axes[-1].set_xlabel("t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.11, right=0.98, bottom=0.08, top=0.94, hspace=0.12)
    paths.append(save(fig, out_dir / "control.png", tight=False))
    return paths
