"""What every figure shares: the controllers' colours and names, matplotlib on Agg, decimation and saving.

Used by the report's figures (:mod:`.figures`) and by the per-job plots (:mod:`.run_plots`): one decimation
helper, one saver.
"""

from __future__ import annotations

import math
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

DPI = 110
MAX_POINTS = 5000


def color_of(controller: str) -> str:
    if controller in CONTROLLER_COLORS:
        return CONTROLLER_COLORS[controller]
    return _FALLBACK[sum(map(ord, controller)) % len(_FALLBACK)]


def label_of(controller: str) -> str:
    return CONTROLLER_LABELS.get(controller, controller)


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend, with the report's font sizes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 9, "axes.titlesize": 10, "legend.fontsize": 8,
                         "path.simplify": True, "agg.path.chunksize": 10000})
    return plt


def save(fig, path: Path, tight: bool = True, dpi: int = DPI) -> Path:
    """Save a figure atomically as PNG and close it: one layout pass (``tight_layout`` unless the figure placed
    its axes itself), then a single draw (``bbox_inches="tight"`` would draw twice)."""
    if tight:
        fig.tight_layout()
    atomic_write(Path(path), lambda tmp: fig.savefig(tmp, format="png", dpi=dpi))
    pyplot().close(fig)
    return Path(path)


def thin(y: np.ndarray, max_points: int = MAX_POINTS) -> np.ndarray:
    """Indices of at most about ``max_points`` samples of ``y`` keeping each bin's minimum and maximum (and the
    first and last sample), so a decimated plot of a chattering signal keeps its full envelope; NaN-safe."""
    n = len(y)
    if n <= max_points:
        return np.arange(n)
    k = int(math.ceil(n / (max_points // 2)))
    m = n // k * k
    bins = np.nan_to_num(np.asarray(y[:m], float), nan=0.0).reshape(-1, k)
    base = np.arange(0, m, k)
    idx = np.concatenate([base + bins.argmin(axis=1), base + bins.argmax(axis=1), np.arange(m, n), [0, n - 1]])
    return np.unique(idx)
