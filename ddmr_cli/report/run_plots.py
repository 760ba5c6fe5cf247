"""Plots of one job's first kept seed (``run.plots=true``): trajectory, errors, control signal.

Uses the report's colours, decimation and saver (:mod:`.plotting`); matplotlib is imported only when a plot is made.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddmr_cli.report.plotting import color_of, label_of, pyplot, save, thin


def envelope(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` decimated by :func:`~ddmr_cli.report.plotting.thin` (each bin's minimum and maximum kept)."""
    idx = thin(y)
    return np.asarray(x)[idx], np.asarray(y)[idx]


def run_plots(series: dict[str, np.ndarray], controller: str, scenario: str, seed: int, out_dir: Path) -> list[Path]:
    """Trajectory, errors and control signal of one run: three PNGs in ``out_dir``."""
    plt = pyplot()
    out_dir = Path(out_dir)
    title = f"{label_of(controller)}, {scenario}, seed {seed}"
    color = color_of(controller)
    t = series["t"]
    paths = []

    fig, ax = plt.subplots(figsize=(8, 3.5))
    ax.plot(*envelope(series["x_ref"], series["y_ref"]), "k--", lw=1, label="reference")
    ax.plot(*envelope(series["x"], series["y"]), color=color, lw=1.2, label=label_of(controller))
    ax.set(xlabel="x [m]", ylabel="y [m]", title=f"Trajectory: {title}")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.14, top=0.9)
    paths.append(save(fig, out_dir / "trajectory.png", tight=False))

    fig, axes = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for ax, key, label in zip(axes, ("deviation", "e_x", "e_y", "e_theta"),
                              ("deviation [m]", "e_x [m]", "e_y [m]", "e_theta [rad]")):
        ax.plot(*envelope(t, series[key]), color=color, lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Tracking errors: {title}")
    axes[-1].set_xlabel("t [s]")
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.07, top=0.95, hspace=0.12)
    paths.append(save(fig, out_dir / "errors.png", tight=False))

    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    axes[0].plot(*envelope(t, series["u_right"]), color=color, lw=0.6, label="u_R")
    axes[0].plot(*envelope(t, series["u_left"]), color=color, lw=0.6, alpha=0.5, label="u_L")
    axes[0].set_ylabel("voltage [V]")
    axes[0].legend(loc="best")
    axes[1].plot(*envelope(t, series["s_right"]), lw=0.6, color=color, label="s_R")
    axes[1].plot(*envelope(t, series["s_left"]), lw=0.6, color=color, alpha=0.5, label="s_L")
    axes[1].set_ylabel("s [rad/s]")
    axes[1].legend(loc="best")
    axes[2].plot(*envelope(t, series["d_true_right"]), color="0.55", lw=0.5, label="d true (R)")
    axes[2].plot(*envelope(t, series["d_hat_ndo_right"] + series["d_hat_nn_right"]), color=color, lw=0.7,
                 label="d_hat (R)")
    axes[2].set_ylabel("d [rad/s^2]")
    axes[2].legend(loc="best")
    axes[0].set_title(f"Control signal, sliding variable, disturbance: {title}")
    axes[-1].set_xlabel("t [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.subplots_adjust(left=0.11, right=0.98, bottom=0.08, top=0.94, hspace=0.12)
    paths.append(save(fig, out_dir / "control.png", tight=False))
    return paths
