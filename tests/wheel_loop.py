"""A bare wheel-speed loop for the controllers' laws: a controller's ``start``/``command``/``update`` laws (the very
functions the engine compiles) on a plant the test chooses, constant references ``w_d`` and ``w_d' = 0``, the
driver's saturation and explicit Euler, with the controller's state record readable after every step. For the
closed forms that need a disturbance the terrain model does not produce (a sinusoid with a bounded derivative) or
a plant reduced to ``w' = b0 u + f``."""

from __future__ import annotations

import numpy as np

from ddmr_cli import NominalModel
from ddmr_cli.model.dynamics import nominal_acceleration, saturate
from ddmr_cli.control.base import ESTIMATE, SURFACE


def nominal_plant(nominal: NominalModel, disturbance):
    """The nominal plant (8) plus ``disturbance(t) -> (d_R, d_L)``: ``w' = f(w) + g u + d(t)``."""
    def acceleration(t, w_R, w_L, u_R, u_L):
        a_R, a_L = nominal_acceleration(nominal, w_R, w_L, u_R, u_L)
        d_R, d_L = disturbance(t)
        return a_R + d_R, a_L + d_L
    return acceleration


def wheel_loop(controller, nominal: NominalModel, acceleration, w0, w_d, duration: float, dt: float = 1e-3,
               max_voltage: float = 24.0, state: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Run the loop for ``duration``; returns per-step arrays ``t``, ``w``, ``u``, ``s`` (shape (n, 2) for the
    wheel pairs), ``d_hat`` and the state fields named in ``state`` (after each step's update)."""
    laws = controller.laws
    p = controller.law_parameters(nominal, dt)
    records = controller.initial_state(1)
    n = int(round(duration / dt))
    out = {name: np.zeros((n, 2)) for name in ("w", "u", "u_command", "s", "d_hat") + tuple(state)}
    out["t"] = np.arange(n) * dt
    w_R, w_L = float(w0[0]), float(w0[1])
    laws.start(p, records[0], w_R, w_L)
    for k in range(n):
        uc_R, uc_L = laws.command(p, records[0], k, w_R, w_L, w_d[0], w_d[1], 0.0, 0.0)
        u_R, sat_R = saturate(uc_R, max_voltage)
        u_L, sat_L = saturate(uc_L, max_voltage)
        if hasattr(laws, "estimates"):  # estimates reported under the applied voltage (ADRC's)
            laws.estimates(p, records[0], w_R, w_L, u_R, u_L)
        a_R, a_L = acceleration(k * dt, w_R, w_L, u_R, u_L)
        laws.update(p, records[0], w_R, w_L, w_d[0], w_d[1], u_R, u_L, uc_R, uc_L, sat_R, sat_L)
        out["w"][k], out["u"][k], out["u_command"][k] = (w_R, w_L), (u_R, u_L), (uc_R, uc_L)
        # the controller's diagnostic channels: the surface, and the sum of its estimates of d
        diagnostics, channels = records[0]["diagnostics"], controller.diagnostics()
        surface = [c for c, ch in enumerate(channels) if ch.kind == SURFACE]
        out["s"][k] = diagnostics[surface[0]] if surface else (np.nan, np.nan)
        out["d_hat"][k] = sum((diagnostics[c] for c, ch in enumerate(channels) if ch.kind == ESTIMATE), np.zeros(2))
        for name in state:
            out[name][k] = records[0][name]
        w_R, w_L = w_R + dt * a_R, w_L + dt * a_L
    return out
