"""The wheel-controller protocol every controller implements, and shared pieces (switching functions).

A controller acts on both wheels at once, for a batch of runs: every array has shape ``(n_runs, 2)``
with wheels ordered (right, left). Per step the engine calls

1. ``command(w, w_d, w_d_dot)`` -> the unsaturated voltage, having set ``s``, ``d_hat_ndo``, ``d_hat_nn``;
2. ``update(w, u_applied, u_command)`` -> advance internal states (integrators, observers) by one step.

``bind(model, dt)`` gives it the nominal model and the step once, ``reset(w0)`` starts a batch.
Adding a controller is a new module with a subclass of :class:`WheelController` plus a YAML file
in ``conf/controller``.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ddmr_cli.model.robot import NominalModel

SwitchingFunction = Callable[[np.ndarray], np.ndarray]


def _sign(x: np.ndarray) -> np.ndarray:
    return np.sign(x)


def _sat(x: np.ndarray) -> np.ndarray:
    return np.minimum(np.maximum(x, -1.0), 1.0)


SWITCHING_FUNCTIONS: dict[str, SwitchingFunction] = {"sign": _sign, "sat": _sat, "tanh": np.tanh}


def per_wheel(value, name: str) -> np.ndarray:
    """A gain given as a scalar (both wheels) or as a (right, left) pair, as an array of shape (2,)."""
    arr = np.broadcast_to(np.asarray(value, dtype=float), (2,)).copy()
    if not np.all(np.isfinite(arr)):
        from ddmr_cli.errors import ConfigError

        raise ConfigError(name, value, "must be finite")
    return arr


def compact(arr: np.ndarray):
    """A per-wheel gain as a scalar when both wheels share it, else as a [right, left] list."""
    return float(arr[0]) if arr[0] == arr[1] else arr.tolist()


class WheelController:
    """Base class: holds the nominal model, the step and the per-step diagnostics.

    Attributes set by :meth:`command` for the engine's time series and metrics:
    ``s`` (sliding variable; the speed error for controllers without a surface),
    ``d_hat_ndo`` and ``d_hat_nn`` (the observers' parts of the disturbance estimate).
    """

    #: short name used in tables and plots
    name: str = "controller"

    def bind(self, model: NominalModel, dt: float) -> "WheelController":
        """Attach the nominal model the controller believes in and the control step [s]."""
        self.model, self.dt = model, dt
        return self

    def reset(self, w0: np.ndarray) -> None:
        """Start a batch whose wheel speeds are ``w0`` (shape ``(n_runs, 2)``)."""
        zeros = np.zeros_like(w0)
        self.s, self.d_hat_ndo, self.d_hat_nn = zeros, zeros, zeros

    def command(self, w: np.ndarray, w_d: np.ndarray, w_d_dot: np.ndarray) -> np.ndarray:
        """Unsaturated voltage command ``u`` (shape ``(n_runs, 2)``)."""
        raise NotImplementedError

    def update(self, w: np.ndarray, u_applied: np.ndarray, u_command: np.ndarray) -> None:
        """Advance internal states by one step ``dt``, given the voltage actually applied."""

    def parameters(self) -> dict[str, object]:
        """The controller's parameters, for the report's Table 3."""
        return {}
