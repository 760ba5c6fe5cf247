"""Disturbance observers that plug into the SMC: the NDO (paper 3.2) and the RBF network observer (paper 3.3).

An observer has ``reset(w0)``, ``estimate(w) -> d_hat`` (called once per step, before the control law) and
``update(w, u_applied, s)`` (advance its state by one step ``dt``). Arrays have shape ``(n_runs, 2)``.
"""

from __future__ import annotations

import numpy as np

from ddmr_cli.model.robot import NominalModel
from ddmr_cli.control.base import compact, per_wheel


class NonlinearDisturbanceObserver:
    """Nonlinear disturbance observer, the paper's (21)-(22) with ``Gamma = L I`` (MODEL.md 6).

    ``d_hat = z + Gamma w``, ``z' = -Gamma (d_hat + f(w) + g u)``, fed with the applied (saturated) ``u``,
    ``z(0) = -Gamma w(0)`` so that ``d_hat(0) = 0``. The estimation error obeys ``d_tilde' = -Gamma d_tilde``
    for a constant disturbance (the paper's (20)): it converges at rate ``L``.

    Parameters
    ----------
    gain : float or (float, float)
        Observer gain L per wheel [1/s] (Table 3: 50).
    """

    def __init__(self, gain=50.0) -> None:
        self.gain = per_wheel(gain, "controller.ndo.gain")

    def bind(self, model: NominalModel, dt: float) -> None:
        self.model, self.dt = model, dt
        self.dt_gain = dt * self.gain

    def reset(self, w0: np.ndarray) -> None:
        self.z = -self.gain * w0

    def estimate(self, w: np.ndarray) -> np.ndarray:
        self.d_hat = self.z + self.gain * w
        return self.d_hat

    def update(self, w: np.ndarray, u_applied: np.ndarray, s: np.ndarray) -> None:
        self.z = self.z - self.dt_gain * (self.d_hat + self.model.f_plus_g_u(w, u_applied))

    def parameters(self) -> dict[str, object]:
        return {"L": compact(self.gain)}


class RBFNetworkObserver:
    """RBF neural-network observer, the paper's (24)-(27) with the update law (25) (MODEL.md 6).

    ``d_hat_NN = W^T Phi(x)`` with ``x = w``, ``phi_j = exp(-||x - c_j||^2 / (2 sigma^2))``, centres
    ``c_j = (c, c)`` evenly spaced on ``[center_min, center_max]``, ``W`` (n x 2 per run, stored transposed) starting at 0 and
    adapting by ``W' = -gamma Phi(x) s^T`` (25), the sign that makes (28)'s ``V' <= 0`` for ``s = w_d - w``
    with ``d_hat`` subtracted in (17).

    Parameters
    ----------
    n_neurons : int
        Hidden neurons n (Table 3: 10).
    width : float
        RBF width sigma [rad/s] (eq. 25 / Table 3 reading: 2; text reading: 50).
    learning_rate : float or (float, float)
        gamma per wheel (eq. 25 / Table 3 reading: 50; text reading: 2).
    center_min, center_max : float
        Range of the centres [rad/s] (MODEL.md: -40, 40).
    """

    def __init__(self, n_neurons: int = 10, width: float = 2.0, learning_rate=50.0,
                 center_min: float = -40.0, center_max: float = 40.0) -> None:
        self.n_neurons, self.width = int(n_neurons), float(width)
        self.learning_rate = per_wheel(learning_rate, "controller.nn.learning_rate")
        self.center_min, self.center_max = float(center_min), float(center_max)
        self.centers = np.linspace(self.center_min, self.center_max, self.n_neurons)

    def bind(self, model: NominalModel, dt: float) -> None:
        self.model, self.dt = model, dt

    def reset(self, w0: np.ndarray) -> None:
        # W^T, one row of n weights per wheel: shape (n_runs, 2, n)
        self.weights = np.zeros((w0.shape[0], 2, self.n_neurons))

    def basis(self, w: np.ndarray) -> np.ndarray:
        """Phi(x) of (27) for a batch: shape ``(n_runs, n_neurons)``."""
        dist2 = (w[:, :1] - self.centers) ** 2 + (w[:, 1:] - self.centers) ** 2
        return np.exp(dist2 * (-0.5 / self.width**2))

    def estimate(self, w: np.ndarray) -> np.ndarray:
        """``d_hat_NN = W^T Phi(x)`` (24), summed along the contiguous neuron axis (batch-invariant rounding)."""
        self.phi = self.basis(w)[:, None, :]
        self.d_hat = (self.weights * self.phi).sum(axis=-1)
        return self.d_hat

    def update(self, w: np.ndarray, u_applied: np.ndarray, s: np.ndarray) -> None:
        """One Euler step of (25): ``W' = -gamma Phi(x) s^T``."""
        step = (self.dt * self.learning_rate) * s
        self.weights = self.weights - step[:, :, None] * self.phi

    def parameters(self) -> dict[str, object]:
        return {"n": self.n_neurons, "sigma": self.width, "gamma": compact(self.learning_rate),
                "centres": f"[{self.center_min:g}, {self.center_max:g}]"}
