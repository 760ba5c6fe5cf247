"""The kept time series: their channels, and the controller's estimate of d read from them (docs/model.md §7).

Plain Python on names and arrays (the compiled law that writes a kept run's step is
:func:`ddmr_cli.engine.results.record`), so that what only reads results (the report, the run's plots) names the
channels without loading numba.
"""

from __future__ import annotations

import numpy as np

from ddmr_cli.control.base import ESTIMATE_PREFIX, SURFACE, series_name

#: Time-series channels every kept run has (one array per channel, shape (n_steps,)); ``s_*`` is the controller's
#: SURFACE channel (NaN without one). The controller's other diagnostic channels follow (:func:`series_channels`).
SERIES_CHANNELS = (
    "t", "x", "y", "theta", "x_ref", "y_ref", "theta_ref", "e_x", "e_y", "e_theta", "deviation", "distance",
    "w_right", "w_left", "w_d_right", "w_d_left", "u_right", "u_left", "u_command_right", "u_command_left",
    "s_right", "s_left", "d_true_right", "d_true_left", "roughness", "damping_scale", "zone",
)


def series_channels(channels) -> tuple[str, ...]:
    """Every series channel of a run of a controller with these diagnostic channels
    (:class:`~ddmr_cli.control.base.Diagnostic`): :data:`SERIES_CHANNELS`, then each non-surface channel's
    ``<series name>_right``/``_left`` (``d_hat_ndo_right``, ...) in row order."""
    extra = [f"{series_name(c)}_{wheel}" for c in channels if c.kind != SURFACE for wheel in ("right", "left")]
    return SERIES_CHANNELS + tuple(extra)


def estimate_names(series: dict) -> list[str]:
    """The estimators whose estimate of d a run's series carry (``d_hat_<name>_right``), in the controller's row
    order, upper-case (``NDO``, ``NN``, ``ESO``)."""
    return [k[len(ESTIMATE_PREFIX):-len("_right")].upper() for k in series
            if k.startswith(ESTIMATE_PREFIX) and k.endswith("_right")]


def d_hat(series: dict, wheel: str = "right") -> np.ndarray:
    """The controller's whole estimate of d on one wheel: the sum of its estimate channels
    (``d_hat_<name>_<wheel>``, in row order), zero without one."""
    out = np.zeros(len(series["t"])) if "t" in series else 0.0
    for name in estimate_names(series):
        out = out + series[f"{ESTIMATE_PREFIX}{name.lower()}_{wheel}"]
    return out


__all__ = ["SERIES_CHANNELS", "d_hat", "estimate_names", "series_channels"]
