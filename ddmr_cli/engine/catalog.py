"""The run metrics the engine computes: the name, unit and meaning of each (docs/model.md §7), and the suffix of their
steady-state twins.

Apart from :mod:`.metrics`, which computes them (compiled), so that what only reads results (the report, the
storage, the studies) names them without loading numba: this module imports nothing.
"""

from __future__ import annotations

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

#: Cutoff of the chattering spectrum's high-pass [Hz] (docs/model.md §7: "power above 10 Hz"), for ``hf_fraction``.
HF_CUTOFF = 10.0

#: Suffix of a metric's steady-state twin (``deviation_mae_ss``): the same metric over the steps after settling.
STEADY = "_ss"

__all__ = ["HF_CUTOFF", "METRICS", "STEADY"]
