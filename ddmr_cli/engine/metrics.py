"""Metrics of one run, computed as the run goes (MODEL.md section 7).

The engine hands over the per-step signals in chunks (run-major buffers); :func:`accumulate` adds them, run by
run and step by step in time order, to running sums per run for the whole run, each terrain zone and each
scenario phase. Memory does not grow with the duration, and the rounding is the same whatever the batch size
and chunk size. The metrics are built from the sums in :meth:`MetricAccumulator.finalize`.

Chattering: total variation of the applied voltage per second (V/s), and the fraction of the variance of
``u`` that passes a 2nd-order Butterworth high-pass at ``hf_cutoff`` Hz (the "power above 10 Hz" of
MODEL.md 7, computed online with the filter started at steady state for the first voltage).
"""

from __future__ import annotations

from dataclasses import dataclass

import math

import numpy as np

from ddmr_cli.engine.kernel import _jit

#: Per-step sums kept per run and segment (column order of :func:`accumulate`); ``_R``/``_L`` per wheel.
SUMS = ("count", "dev", "dev2", "tdev", "abs_ex", "abs_ey", "abs_eth", "saturated",
        "abs_du_R", "abs_du_L", "u2_R", "u2_L", "power_R", "power_L", "abs_dtilde_R", "abs_dtilde_L",
        "abs_dtilde_ndo_R", "abs_dtilde_ndo_L", "abs_s_R", "abs_s_L", "u_R", "u_L", "u_hp2_R", "u_hp2_L",
        "abs_u_R", "abs_u_L")
N_SUMS = len(SUMS)

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


@dataclass
class StepSignals:
    """One chunk of per-step signals: run-major arrays, shape ``(runs, steps[, 2])``; ``t`` and ``phase`` (steps,)."""

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


def butterworth_highpass(cutoff: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """2nd-order Butterworth high-pass by the bilinear transform with pre-warping, as one biquad
    ``[b0, b1, b2, 1, a1, a2]`` (what ``scipy.signal.butter(2, cutoff, 'highpass', fs=1/dt, output='sos')``
    gives), and the direct-form-II-transposed state per unit input at steady state (DC gain 0: ``[-b0, b2]``).
    A cutoff at or above Nyquist passes nothing."""
    if cutoff >= 0.5 / dt:
        return np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0]), np.zeros(2)
    k = math.tan(math.pi * cutoff * dt)
    norm = 1.0 / (1.0 + math.sqrt(2.0) * k + k * k)
    b0 = norm
    sos = np.array([b0, -2.0 * b0, b0, 1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - math.sqrt(2.0) * k + k * k) * norm])
    return sos, np.array([-b0, b0])


@_jit
def accumulate(sums, t, dev, e_x, e_y, e_th, u, u_cmd, w, s, d_true, d_ndo, d_nn, zone, phase, phase_base,
               k_e, r_a, hp, hp_zi, hp_state, u_prev, started, dev_max, dev_final):
    """Add a chunk of steps to ``sums[run, segment, column]`` (columns: :data:`SUMS`), run by run in time order.

    ``hp`` is one biquad ``[b0, b1, b2, a0, a1, a2]`` (direct form II transposed, as ``scipy.signal.sosfilt``),
    ``hp_state[run, wheel, 2]`` its state, started at ``hp_zi * u`` on the first step (no transient);
    ``u_prev`` the last voltage of the previous chunk for the total variation.
    """
    n_runs, n_steps = dev.shape[0], dev.shape[1]
    q = np.empty(sums.shape[2])
    for r in range(n_runs):
        for j in range(n_steps):
            if not started[r]:
                for k in range(2):
                    u_prev[r, k] = u[r, j, k]
                    hp_state[r, k, 0] = hp_zi[0] * u[r, j, k]
                    hp_state[r, k, 1] = hp_zi[1] * u[r, j, k]
                started[r] = True
            d = dev[r, j]
            q[0] = 1.0
            q[1] = d
            q[2] = d * d
            q[3] = t[j] * d
            q[4] = abs(e_x[r, j])
            q[5] = abs(e_y[r, j])
            q[6] = abs(e_th[r, j])
            q[7] = 1.0 if (u[r, j, 0] != u_cmd[r, j, 0] or u[r, j, 1] != u_cmd[r, j, 1]) else 0.0
            for k in range(2):
                uk = u[r, j, k]
                q[8 + k] = abs(uk - u_prev[r, k])
                u_prev[r, k] = uk
                q[10 + k] = uk * uk
                q[12 + k] = uk * (uk - k_e * w[r, j, k]) / r_a
                q[14 + k] = abs(d_true[r, j, k] - d_ndo[r, j, k] - d_nn[r, j, k])
                q[16 + k] = abs(d_true[r, j, k] - d_ndo[r, j, k])
                q[18 + k] = abs(s[r, j, k])
                q[20 + k] = uk
                y = hp[0] * uk + hp_state[r, k, 0]
                hp_state[r, k, 0] = hp[1] * uk - hp[4] * y + hp_state[r, k, 1]
                hp_state[r, k, 1] = hp[2] * uk - hp[5] * y
                q[22 + k] = y * y
                q[24 + k] = abs(uk)
            z = 1 + zone[r, j]
            p = phase_base + phase[j]
            for c in range(q.shape[0]):
                sums[r, 0, c] += q[c]
                sums[r, z, c] += q[c]
                sums[r, p, c] += q[c]
            if d > dev_max[r]:
                dev_max[r] = d
            dev_final[r] = d


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
        self.k_e, self.r_a = float(back_emf_constant), float(armature_resistance)
        self.sums = np.zeros((n_runs, len(self.segments), N_SUMS))
        self.dev_max = np.full(n_runs, -np.inf)
        self.dev_final = np.full(n_runs, np.nan)
        self.u_prev = np.zeros((n_runs, 2))
        self.started = np.zeros(n_runs, dtype=np.bool_)
        self.hf_cutoff = hf_cutoff
        self.hp, self.hp_zi = butterworth_highpass(hf_cutoff, dt)
        self.hp_state = np.zeros((n_runs, 2, 2))

    def consume(self, sig: StepSignals) -> None:
        """Add one chunk of steps."""
        accumulate(self.sums, np.ascontiguousarray(sig.t), sig.dev, sig.e_x, sig.e_y, sig.e_theta, sig.u,
                   sig.u_command, sig.w, sig.s, sig.d_true, sig.d_hat_ndo, sig.d_hat_nn, sig.zone,
                   np.ascontiguousarray(sig.phase.astype(np.int64)), 1 + len(self.zone_names), self.k_e, self.r_a,
                   self.hp, self.hp_zi, self.hp_state, self.u_prev, self.started, self.dev_max, self.dev_final)

    def finalize(self) -> dict[str, np.ndarray]:
        """Metrics per run and segment: ``{name: array (n_runs, n_segments)}`` (NaN where a segment is empty)."""
        col = {name: self.sums[:, :, i] for i, name in enumerate(SUMS)}
        S = {name: col[name] for name in SUMS if not name.endswith(("_R", "_L"))}
        for name in SUMS:
            if name.endswith("_R"):
                S[name[:-2]] = np.stack([col[name], col[name[:-2] + "_L"]], axis=-1)
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
        total_only = {"deviation_max": np.where(np.isfinite(self.dev_max), self.dev_max, np.nan),
                      "deviation_final": self.dev_final}
        for key, val in total_only.items():
            arr = np.full((self.n_runs, len(self.segments)), np.nan)
            arr[:, 0] = val
            out[key] = arr
        return {k: out[k] for k in METRICS}
