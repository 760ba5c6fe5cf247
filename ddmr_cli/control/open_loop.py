"""Open-loop constant voltage: no feedback. Used to check the plant against closed-form solutions."""

from __future__ import annotations

import numpy as np

from ddmr_cli.control.base import WheelController, compact, per_wheel


class OpenLoop(WheelController):
    """Apply a constant voltage ``(u_R, u_L)`` whatever the wheel speeds.

    Parameters
    ----------
    voltage : float or (float, float)
        Voltage per wheel [V].
    """

    name = "open_loop"

    def __init__(self, voltage=0.0) -> None:
        self.voltage = per_wheel(voltage, "controller.voltage")

    def command(self, w, w_d, w_d_dot):
        self.s = w_d - w
        return np.broadcast_to(self.voltage, w.shape).copy()

    def kernel_spec(self, w0):
        """The compiled form (:mod:`ddmr_cli.engine.kernel`)."""
        from ddmr_cli.engine import kernel

        return kernel.OPEN_LOOP, self.voltage.copy(), np.zeros(0), np.zeros((w0.shape[0], 1))

    def parameters(self):
        return {"voltage": compact(self.voltage)}
