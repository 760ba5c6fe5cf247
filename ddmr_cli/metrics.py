"""Metrics of one run, computed as the run goes (MODEL.md section 7).

The engine hands over the per-step signals in chunks (time-major arrays with the run axis second); the
accumulator keeps only running sums per run, so memory does not grow with the duration. Every metric is
reported for the whole run, for each terrain zone and for each scenario phase.

Chattering: total variation of the applied voltage per second (V/s), and the fraction of the variance of
``u`` that passes a 2nd-order Butterworth high-pass at ``hf_cutoff`` Hz (the "power above 10 Hz" of
MODEL.md 7, computed online with the filter started at steady state for the first voltage).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi

#: Per-step sums kept per run and segment; the metrics are built from them in :meth:`finalize`.
SUMS = ("count", "dev", "dev2", "tdev", "abs_ex", "abs_ey", "abs_eth", "saturated",
        "abs_du", "u2", "power", "abs_dtilde", "abs_dtilde_ndo", "abs_s", "u", "u_hp2", "abs_u")
_PER_WHEEL = {"abs_du", "u2", "power", "abs_dtilde", "abs_dtilde_ndo", "abs_s", "u", "u_hp2", "abs_u"}

#: Run metrics, in the order of the tables: name -> (unit, description).
METRICS: dict[str, tuple[str, str]] = {
    "deviation_mae": ("m", "mean of ||(x_r - x, y_r - y)|| (Table 4 'Deviation')"),
    "deviation_rmse": ("m", "RMS deviation"),
    "deviation_max": ("m", "largest deviation"),
    "deviation_final": ("m", "deviation at the last step"),
    "e_x_mae": ("m", "mean |e_x| (longitudinal)"),
    "e_y_mae": ("m", "mean |e_y| (lateral)"),
    "e_theta_mae": ("rad", "mean |e_theta| (heading; the paper prints it in m)"),
    "iae": ("m s", "integral of |deviation|"),
    "ise": ("m^2 s", "integral of deviation^2"),
    "itae": ("m s^2", "integral of t |deviation|"),
    "chattering": ("V/s", "total variation of applied u per second, mean of both wheels"),
    "chattering_right": ("V/s", "total variation of applied u_R per second"),
    "chattering_left": ("V/s", "total variation of applied u_L per second"),
    "hf_fraction": ("1", "fraction of var(u) above the high-pass cutoff, mean of both wheels"),
    "mean_voltage": ("V", "mean |u| of both wheels"),
    "energy_u2": ("V^2 s", "integral of u_R^2 + u_L^2"),
    "electrical_energy": ("J", "integral of u i over both motors"),
    "saturation_fraction": ("1", "fraction of steps with a wheel at +-U_max"),
    "d_est_mae": ("rad/s^2", "mean |d_true - d_hat| of both wheels"),
    "d_est_mae_ndo": ("rad/s^2", "mean |d_true - d_hat_NDO| of both wheels (the NDO part alone)"),
    "s_mae": ("rad/s", "mean |s| of both wheels"),
}
SEGMENT_METRICS = tuple(m for m in METRICS if m not in ("deviation_max", "deviation_final"))


#: Sums over time are taken in blocks of this many steps, aligned to the run's first step, then added in
#: order: the rounding is then the same whatever the batch size and chunk size (chunks are whole blocks).
BLOCK_STEPS = 256

#: Column layout of the per-step quantities: name -> (first column, width).
_COLUMNS: dict[str, tuple[int, int]] = {}
for _name in SUMS:
    _COLUMNS[_name] = (sum(w for _, w in _COLUMNS.values()), 2 if _name in _PER_WHEEL else 1)
N_COLUMNS = sum(w for _, w in _COLUMNS.values())


@dataclass
class StepSignals:
    """One chunk of per-step signals: time-major arrays, shape ``(steps, runs[, 2])``."""

    t: np.ndarray
    dev: np.ndarray
    e_x: np.ndarray
    e_y: np.ndarray
    e_theta: np.ndarray
    u: np.ndarray
    u_command: np.ndarray
    w: np.ndarray
    s: np.ndarray
    d_true: np.ndarray
    d_hat_ndo: np.ndarray
    d_hat_nn: np.ndarray
    zone: np.ndarray
    phase: np.ndarray


class MetricAccumulator:
    """Running sums per run for the whole run (segment 0), each zone and each phase.

    Parameters
    ----------
    n_runs : int
    dt : float
        Step [s].
    zone_names, phase_names : list of str
    back_emf_constant, armature_resistance : float
        For the electrical power ``u i``, ``i = (u - k_e w) / R_a``.
    hf_cutoff : float
        High-pass cutoff for the chattering spectrum fraction [Hz].
    """

    def __init__(self, n_runs: int, dt: float, zone_names, phase_names, back_emf_constant: float,
                 armature_resistance: float, hf_cutoff: float = 10.0) -> None:
        self.n_runs, self.dt = n_runs, dt
        self.zone_names, self.phase_names = list(zone_names), list(phase_names)
        self.segments = ["total"] + [f"zone:{z}" for z in self.zone_names] + [f"phase:{p}" for p in self.phase_names]
        self.k_e, self.r_a = back_emf_constant, armature_resistance
        n_seg = len(self.segments)
        self.n_zones, self.n_phases = len(self.zone_names), len(self.phase_names)
        self.sums = np.zeros((n_runs, n_seg, N_COLUMNS))  # [run, segment, column]
        self.dev_max = np.zeros(n_runs)
        self.dev_final = np.full(n_runs, np.nan)
        self.u_prev: np.ndarray | None = None
        nyquist = 0.5 / dt
        self.hf_cutoff = hf_cutoff
        self.sos = butter(2, hf_cutoff, btype="highpass", fs=1.0 / dt, output="sos") if hf_cutoff < nyquist else None
        self.hp_state: np.ndarray | None = None

    def _high_pass(self, u: np.ndarray) -> np.ndarray:
        if self.sos is None:
            return np.zeros_like(u)
        if self.hp_state is None:  # steady state for the first voltage: no start-up transient
            zi = sosfilt_zi(self.sos)  # (sections, 2)
            self.hp_state = zi[:, :, None, None] * u[0][None, None, :, :]
        y, self.hp_state = sosfilt(self.sos, u, axis=0, zi=self.hp_state)
        return y

    def consume(self, sig: StepSignals) -> None:
        """Add one chunk of steps."""
        u = sig.u
        prev = u[:1] if self.u_prev is None else self.u_prev[None]
        du = np.diff(u, axis=0, prepend=prev)
        self.u_prev = u[-1].copy()
        current = (u - self.k_e * sig.w) / self.r_a
        d_hat = sig.d_hat_ndo + sig.d_hat_nn
        quantities = {
            "count": np.ones_like(sig.dev),
            "dev": sig.dev,
            "dev2": sig.dev**2,
            "tdev": sig.t[:, None] * sig.dev,
            "abs_ex": np.abs(sig.e_x),
            "abs_ey": np.abs(sig.e_y),
            "abs_eth": np.abs(sig.e_theta),
            "saturated": np.any(u != sig.u_command, axis=-1),
            "abs_du": np.abs(du),
            "u2": u**2,
            "power": u * current,
            "abs_dtilde": np.abs(sig.d_true - d_hat),
            "abs_dtilde_ndo": np.abs(sig.d_true - sig.d_hat_ndo),
            "abs_s": np.abs(sig.s),
            "u": u,
            "u_hp2": self._high_pass(u) ** 2,
            "abs_u": np.abs(u),
        }
        n, n_runs = sig.dev.shape
        q = np.empty((n, n_runs, N_COLUMNS))
        for key, value in quantities.items():
            start, width = _COLUMNS[key]
            q[:, :, start:start + width] = value if width == 2 else value[:, :, None]
        for start in range(0, n, BLOCK_STEPS):
            block = slice(start, start + BLOCK_STEPS)
            self._add_block(q[block], sig.zone[block], sig.phase[block])
        self.dev_max = np.fmax(self.dev_max, np.max(sig.dev, axis=0))
        self.dev_final = sig.dev[-1].copy()

    def _add_block(self, q: np.ndarray, zone: np.ndarray, phase: np.ndarray) -> None:
        """Add one block of steps to the whole-run, zone and phase sums.

        Each run's block is summed along its own contiguous time axis (the same rounding in any batch). Zones
        follow the distance travelled, which never decreases, so a run's zone changes at most a few times: a
        block inside one zone adds its sum to that zone; the rare block that crosses an edge is split by mask.
        """
        runs = np.arange(q.shape[1])
        qt = np.ascontiguousarray(np.moveaxis(q, 0, -1))  # (runs, columns, steps)
        block_sum = qt.sum(axis=-1)
        self.sums[:, 0] += block_sum
        z_first, z_last = zone.min(axis=0), zone.max(axis=0)
        inside = z_first == z_last
        self.sums[runs[inside], 1 + z_first[inside]] += block_sum[inside]
        for r in runs[~inside]:
            for z in range(z_first[r], z_last[r] + 1):
                self.sums[r, 1 + z] += (qt[r] * (zone[:, r] == z)).sum(axis=-1)
        base = 1 + self.n_zones
        if phase[0] == phase[-1]:
            self.sums[:, base + phase[0]] += block_sum
        else:
            for p in np.unique(phase):
                self.sums[:, base + p] += (qt * (phase == p)).sum(axis=-1)

    def finalize(self) -> dict[str, np.ndarray]:
        """Metrics per run and segment: ``{name: array (n_runs, n_segments)}`` (NaN where a segment is empty)."""
        S = {key: self.sums[:, :, a:a + w] if w == 2 else self.sums[:, :, a] for key, (a, w) in _COLUMNS.items()}
        dt = self.dt
        with np.errstate(invalid="ignore", divide="ignore"):
            n = np.where(S["count"] > 0, S["count"], np.nan)
            nw = n[:, :, None]
            mean_u = S["u"] / nw
            var_u = S["u2"] / nw - mean_u**2
            hf = np.where(var_u > 1e-12 * np.maximum(S["u2"] / nw, 1e-300), S["u_hp2"] / nw / var_u, 0.0)
            chat = S["abs_du"] / nw / dt
            out = {
                "deviation_mae": S["dev"] / n,
                "deviation_rmse": np.sqrt(S["dev2"] / n),
                "e_x_mae": S["abs_ex"] / n,
                "e_y_mae": S["abs_ey"] / n,
                "e_theta_mae": S["abs_eth"] / n,
                "iae": S["dev"] * dt,
                "ise": S["dev2"] * dt,
                "itae": S["tdev"] * dt,
                "chattering": chat.mean(axis=-1),
                "chattering_right": chat[..., 0],
                "chattering_left": chat[..., 1],
                "hf_fraction": hf.mean(axis=-1),
                "mean_voltage": (S["abs_u"] / nw).mean(axis=-1),
                "energy_u2": S["u2"].sum(axis=-1) * dt,
                "electrical_energy": S["power"].sum(axis=-1) * dt,
                "saturation_fraction": S["saturated"] / n,
                "d_est_mae": (S["abs_dtilde"] / nw).mean(axis=-1),
                "d_est_mae_ndo": (S["abs_dtilde_ndo"] / nw).mean(axis=-1),
                "s_mae": (S["abs_s"] / nw).mean(axis=-1),
            }
        total_only = {"deviation_max": self.dev_max, "deviation_final": self.dev_final}
        for key, val in total_only.items():
            arr = np.full((self.n_runs, len(self.segments)), np.nan)
            arr[:, 0] = val
            out[key] = arr
        return {k: out[k] for k in METRICS}
