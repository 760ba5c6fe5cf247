"""PID wheel-speed controller, the paper's linear baseline (Table 3; MODEL.md section 6)."""

from __future__ import annotations

import numpy as np

from ddmr_cli.control.base import WheelController, compact, per_wheel


class PID(WheelController):
    """PID on the wheel-speed error ``e = w_d - w`` with no feed-forward (MODEL.md 6).

    ``u = K_p e + K_i int e + K_d e'``; ``e'`` is the backward difference of ``e`` (zero at the first step).
    Anti-windup: the integrator is held while the output is saturated and the error would drive it further
    into saturation (conditional integration).

    Parameters
    ----------
    kp, ki, kd : float or (float, float)
        Gains per wheel (Table 3: 5, 0.1, 0.01).
    anti_windup : bool
        Hold the integrator while saturated (default True).
    """

    name = "pid"

    def __init__(self, kp=5.0, ki=0.1, kd=0.01, anti_windup: bool = True) -> None:
        self.kp = per_wheel(kp, "controller.kp")
        self.ki = per_wheel(ki, "controller.ki")
        self.kd = per_wheel(kd, "controller.kd")
        self.anti_windup = bool(anti_windup)

    def reset(self, w0):
        super().reset(w0)
        self.integral = np.zeros_like(w0)
        self.e_prev = None

    def command(self, w, w_d, w_d_dot):
        e = w_d - w
        e_dot = np.zeros_like(e) if self.e_prev is None else (e - self.e_prev) / self.dt
        self.e_prev = e
        self.s = e
        return self.kp * e + self.ki * self.integral + self.kd * e_dot

    def update(self, w, u_applied, u_command):
        e = self.s
        if self.anti_windup:
            winding_up = (u_applied != u_command) & (np.sign(e) == np.sign(u_command))
            e = np.where(winding_up, 0.0, e)
        self.integral = self.integral + self.dt * e

    def kernel_spec(self, w0):
        """The compiled form (:mod:`ddmr_cli.engine.kernel`): kind, parameters, centres, state (integral, e_prev)."""
        from ddmr_cli.engine import kernel

        params = np.concatenate([self.kp, self.ki, self.kd, [float(self.anti_windup)]])
        return kernel.PID_KIND, params, np.zeros(0), np.zeros((w0.shape[0], 4))

    def parameters(self):
        return {"K_p": compact(self.kp), "K_i": compact(self.ki), "K_d": compact(self.kd),
                "anti_windup": self.anti_windup}
