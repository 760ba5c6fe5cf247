"""Numbers the report computes from the kept time series (for the NN-share table, the spectra and the figures'
captions), as plain functions of arrays so each can be tested with constructed signals."""

from __future__ import annotations

import math

import numpy as np

from ddmr_cli.engine.catalog import HF_CUTOFF


def hf_cutoff(config_flat: dict | None = None) -> float:
    """The cutoff [Hz] the engine's ``hf_fraction`` metric uses: a ``*hf_cutoff`` config value when the job has
    one, else the engine's (:data:`ddmr_cli.engine.catalog.HF_CUTOFF`)."""
    for key, value in (config_flat or {}).items():
        if key.endswith("hf_cutoff"):
            try:
                return float(value)
            except (TypeError, ValueError):
                break
    return HF_CUTOFF


def mean_abs(*arrays: np.ndarray) -> float:
    vals = np.concatenate([np.abs(np.asarray(a, float)).ravel() for a in arrays])
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else math.nan


def nominal_input_inverse(robot_cfg: dict | None):
    """``a -> g^-1 a`` of the controllers' nominal model (docs/model.md §1) for the job's robot config, or None."""
    try:
        from ddmr_cli.model.robot import NominalModel, Robot

        n = NominalModel.from_robot(Robot(**{k: float(v) for k, v in (robot_cfg or {}).items()}))
        # g^-1 a = (J / K_u) a, the acceleration part of voltage_for, over a (steps, 2) array
        return lambda a: n.j_over_ku_p * a + n.j_over_ku_q * a[:, ::-1]
    except Exception:  # noqa: BLE001 - a robot config this version does not know: no voltage share
        return None




def _channel(series: dict, name: str) -> np.ndarray:
    """A series channel, zero when the run's controller does not have it."""
    return np.asarray(series[name]) if name in series else np.zeros(len(series["u_right"]))


def nn_share(series_list: list[dict], g_inv=None) -> dict:
    """The NN's share of a job's disturbance estimate and of its voltage, over the given kept seeds and both
    wheels: ``mean |d̂_NN| / mean |d̂_NDO + d̂_NN|``, and the voltage the NN term adds, ``g^-1 d̂_NN`` (eq. 17
    subtracts ``d̂``), against the mean |u| applied."""
    ndo, nn, u, u_nn = [], [], [], []
    for s in series_list:
        d_ndo = np.column_stack([_channel(s, "d_hat_ndo_right"), _channel(s, "d_hat_ndo_left")])
        d_nn = np.column_stack([_channel(s, "d_hat_nn_right"), _channel(s, "d_hat_nn_left")])
        ndo.append(d_ndo)
        nn.append(d_nn)
        u.append(np.column_stack([s["u_right"], s["u_left"]]))
        if g_inv is not None:
            u_nn.append(g_inv(d_nn))
    total = [a + b for a, b in zip(ndo, nn)]
    out = {"mean_abs_d_ndo": mean_abs(*ndo), "mean_abs_d_nn": mean_abs(*nn), "mean_abs_d_hat": mean_abs(*total),
           "mean_abs_u": mean_abs(*u), "mean_abs_u_nn": mean_abs(*u_nn) if u_nn else math.nan}
    out["share_of_estimate"] = (out["mean_abs_d_nn"] / out["mean_abs_d_hat"] if out["mean_abs_d_hat"] > 0
                                else math.nan)
    out["share_of_u"] = out["mean_abs_u_nn"] / out["mean_abs_u"] if out["mean_abs_u"] > 0 else math.nan
    return out


def has_nn(series: dict) -> bool:
    """Whether a run's series carry a non-zero NN estimate."""
    return bool(np.any(np.asarray(series.get("d_hat_nn_right", 0.0)) != 0)
                or np.any(np.asarray(series.get("d_hat_nn_left", 0.0)) != 0))


def welch(x: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch's power spectral density of ``x`` [unit²/Hz]: the mean of the one-sided periodograms of its segments
    of ``nperseg`` samples with half overlap, each less its mean and under a periodic Hann window, density
    scaling. What ``scipy.signal.welch(x, fs, nperseg=nperseg)`` returns with its defaults (tests hold the two to
    1e-12): written out here because importing ``scipy.signal`` costs about a second, on the report's serial path
    before its figure processes start. Returns the frequencies [Hz] and the density."""
    x = np.asarray(x, dtype=float)
    step = nperseg - nperseg // 2
    count = (x.size - nperseg // 2) // step
    starts = step * np.arange(count)
    segments = x[starts[:, None] + np.arange(nperseg)]
    segments = segments - segments.mean(axis=1, keepdims=True)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(nperseg) / nperseg)  # Hann, periodic
    power = np.abs(np.fft.rfft(segments * window, axis=1)) ** 2 / (fs * (window * window).sum())
    power[:, 1:power.shape[1] - (1 - nperseg % 2)] *= 2.0  # one-sided: every bin but 0 and (even nperseg) Nyquist
    return np.fft.rfftfreq(nperseg, 1.0 / fs), power.mean(axis=0)


def welch_u(series: dict, dt: float, window: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Welch power spectral density of the applied voltage, mean of both wheels [V²/Hz], over the whole run
    (as the hf_fraction metric), Hann windows of ``window`` seconds with half overlap, mean removed
    (:func:`welch`)."""
    fs = 1.0 / dt
    n = len(series["u_right"])
    nperseg = int(min(n, max(16, round(window * fs))))
    f, p_r = welch(series["u_right"], fs, nperseg)
    _, p_l = welch(series["u_left"], fs, nperseg)
    return f, 0.5 * (p_r + p_l)


def window_mask(t: np.ndarray, start: float, end: float) -> np.ndarray:
    return (np.asarray(t) >= start) & (np.asarray(t) < end)


def mean_in(t: np.ndarray, y: np.ndarray, start: float, end: float = math.inf) -> float:
    m = window_mask(t, start, end)
    vals = np.asarray(y, float)[m]
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else math.nan


def range_in(t: np.ndarray, y: np.ndarray, start: float, end: float = math.inf,
             q: tuple[float, float] = (1.0, 99.0)) -> tuple[float, float]:
    """The ``q`` percentiles of ``y`` over ``start <= t < end``."""
    vals = np.asarray(y, float)[window_mask(t, start, end)]
    vals = vals[np.isfinite(vals)]
    if not vals.size:
        return math.nan, math.nan
    lo, hi = np.percentile(vals, q)
    return float(lo), float(hi)
