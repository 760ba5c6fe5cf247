"""Plots of a run's time series (matplotlib, imported only when a plot is made)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ddmr_cli.cli.io import atomic_write

#: One colour per controller, the same in every figure.
CONTROLLER_COLORS = {
    "pid": "#d62728", "smc": "#1f77b4", "smc_ndo": "#17becf", "smc_ndo_nno": "#000000",
    "smc_ndo_nno_text": "#9467bd", "smc_nno": "#ff7f0e", "open_loop": "#7f7f7f",
}
CONTROLLER_LABELS = {"pid": "PID", "smc": "SMC", "smc_ndo": "SMC-NDO", "smc_ndo_nno": "SMC-NDO-NNO",
                     "smc_ndo_nno_text": "SMC-NDO-NNO (text reading)", "smc_nno": "SMC-NNO",
                     "open_loop": "open loop"}
_FALLBACK = ["#2ca02c", "#8c564b", "#e377c2", "#bcbd22", "#7f7f7f"]


def color_of(controller: str) -> str:
    if controller in CONTROLLER_COLORS:
        return CONTROLLER_COLORS[controller]
    return _FALLBACK[sum(map(ord, controller)) % len(_FALLBACK)]


def label_of(controller: str) -> str:
    return CONTROLLER_LABELS.get(controller, controller)


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: Path, tight: bool = True) -> Path:
    """Save a figure atomically as PNG and close it (laid out once, drawn once)."""
    plt = pyplot()
    if tight:
        fig.tight_layout()
    atomic_write(Path(path), lambda tmp: fig.savefig(tmp, format="png", dpi=100))
    plt.close(fig)
    return Path(path)


def envelope(x: np.ndarray, y: np.ndarray, max_points: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """At most about ``max_points`` points of ``(x, y)`` that keep every bucket's minimum and maximum, so a
    decimated plot of a chattering signal shows its full amplitude."""
    n = len(y)
    if n <= max_points:
        return x, y
    per = int(np.ceil(2 * n / max_points))
    m = n // per * per
    block = y[:m].reshape(-1, per)
    base = np.arange(0, m, per)
    lo, hi = base + block.argmin(axis=1), base + block.argmax(axis=1)
    idx = np.sort(np.concatenate([lo, hi, np.arange(m, n)]))
    return x[idx], y[idx]


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
    paths.append(save_figure(fig, out_dir / "trajectory.png", tight=False))

    fig, axes = plt.subplots(4, 1, figsize=(8, 8), sharex=True)
    for ax, key, label in zip(axes, ("deviation", "e_x", "e_y", "e_theta"),
                              ("deviation [m]", "e_x [m]", "e_y [m]", "e_theta [rad]")):
        ax.plot(*envelope(t, series[key]), color=color, lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"Tracking errors: {title}")
    axes[-1].set_xlabel("t [s]")
    fig.subplots_adjust(left=0.12, right=0.98, bottom=0.07, top=0.95, hspace=0.12)
    paths.append(save_figure(fig, out_dir / "errors.png", tight=False))

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
    paths.append(save_figure(fig, out_dir / "control.png", tight=False))
    return paths
