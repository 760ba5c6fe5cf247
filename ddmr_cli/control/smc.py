"""Sliding-mode wheel-speed controller with optional disturbance observers (paper 3.1-3.3; MODEL.md 6).

SMC, SMC-NDO and SMC-NDO-NNO are this one class with zero, one or two observers.
"""

from __future__ import annotations

import numpy as np

from ddmr_cli.errors import ConfigError
from ddmr_cli.control.base import SWITCHING_FUNCTIONS, WheelController, compact, per_wheel
from ddmr_cli.control.observers import NonlinearDisturbanceObserver, RBFNetworkObserver

SURFACES = ("proportional", "integral")


class SMC(WheelController):
    """Sliding-mode control law (17) with the observers' estimate subtracted.

    Surface ``proportional`` (the paper's (10)): ``s = e = w_d - w`` and
    ``u = g^-1 (w_d' - f(w) + lambda s + K sw(s/Phi) - d_hat)`` (17), lambda read as the linear term of an
    exponential reaching law and Phi as the boundary layer (MODEL.md 6, Resolution).
    Surface ``integral``: ``s = e + lambda int e`` and ``u = g^-1 (w_d' - f(w) + lambda e + K sw(s/Phi) - d_hat)``,
    the equivalent control of that surface plus the switching term.
    ``d_hat`` is the sum of the observers' estimates (NDO (21), NN (24)); zero without observers.

    Parameters
    ----------
    lam : float or (float, float)
        lambda per wheel [1/s] (Table 3: 25).
    switching_gain : float or (float, float)
        K per wheel [rad/s^2] (Table 3: 12).
    boundary_layer : float
        Phi [rad/s] (Table 3: 0.1); unused by ``switching='sign'``.
    surface : {'proportional', 'integral'}
    switching : {'sign', 'sat', 'tanh'}
        The switching function ``sw`` of (15): ``sgn`` as printed, or its boundary-layer ``sat``/``tanh``.
    ndo : NonlinearDisturbanceObserver, optional
        The NDO of 3.2 (SMC-NDO); None for none.
    nn : RBFNetworkObserver, optional
        The RBF network observer of 3.3 (SMC-NDO-NNO with ``ndo``); None for none.
    name : str
        Label in tables and plots.
    """

    def __init__(self, lam=25.0, switching_gain=12.0, boundary_layer: float = 0.1,
                 surface: str = "proportional", switching: str = "sat",
                 ndo: NonlinearDisturbanceObserver | None = None, nn: RBFNetworkObserver | None = None,
                 name: str = "smc") -> None:
        self.lam = per_wheel(lam, "controller.lam")
        self.switching_gain = per_wheel(switching_gain, "controller.switching_gain")
        self.boundary_layer = float(boundary_layer)
        if surface not in SURFACES:
            raise ConfigError("controller.surface", surface, f"must be one of {', '.join(SURFACES)}")
        if switching not in SWITCHING_FUNCTIONS:
            raise ConfigError("controller.switching", switching,
                              f"must be one of {', '.join(SWITCHING_FUNCTIONS)}")
        self.surface, self.switching = surface, switching
        self._sw = SWITCHING_FUNCTIONS[switching]
        self.ndo, self.nn = ndo, nn
        self.observers = [obs for obs in (ndo, nn) if obs is not None]
        self.name = name

    def bind(self, model, dt):
        super().bind(model, dt)
        for obs in self.observers:
            obs.bind(model, dt)
        return self

    def reset(self, w0):
        super().reset(w0)
        self.error_integral = np.zeros_like(w0)
        for obs in self.observers:
            obs.reset(w0)

    def command(self, w, w_d, w_d_dot):
        e = w_d - w
        self.e = e
        if self.surface == "integral":
            s = e + self.lam * self.error_integral
            linear = self.lam * e
        else:
            s = e
            linear = self.lam * s
        self.s = s
        d_hat = None
        if self.ndo is not None:
            self.d_hat_ndo = d_hat = self.ndo.estimate(w)
        if self.nn is not None:
            self.d_hat_nn = self.nn.estimate(w)
            d_hat = self.d_hat_nn if d_hat is None else d_hat + self.d_hat_nn
        x = s if self.switching == "sign" else s * (1.0 / self.boundary_layer)
        # (17): u = g^-1 (w_d' - f(w) + lambda s + K sw(s/Phi) - d_hat)
        a = w_d_dot + linear + self.switching_gain * self._sw(x)
        if d_hat is not None:
            a = a - d_hat
        return self.model.voltage_for(a, w)

    def update(self, w, u_applied, u_command):
        if self.surface == "integral":
            self.error_integral = self.error_integral + self.dt * self.e
        for obs in self.observers:
            obs.update(w, u_applied, self.s)

    def kernel_spec(self, w0):
        """The compiled form (:mod:`ddmr_cli.engine.kernel`): kind, parameters, RBF centres, and the state
        ``[int e (2), z (2), W^T (2 n)]`` with ``z(0) = -Gamma w(0)`` and ``W(0) = 0``."""
        from ddmr_cli.engine import kernel

        if (self.ndo is not None and type(self.ndo) is not NonlinearDisturbanceObserver) or (
                self.nn is not None and type(self.nn) is not RBFNetworkObserver):
            return None  # a custom observer: the numpy engine runs it
        switching = {"sign": kernel.SWITCH_SIGN, "sat": kernel.SWITCH_SAT, "tanh": kernel.SWITCH_TANH}[self.switching]
        ndo_gain = self.ndo.gain if self.ndo is not None else np.zeros(2)
        nn = self.nn
        params = np.concatenate([
            self.lam, self.switching_gain, [self.boundary_layer, float(self.surface == "integral"), switching,
                                            float(self.ndo is not None)], ndo_gain,
            [float(nn is not None), nn.n_neurons if nn else 0, nn.width if nn else 1.0],
            nn.learning_rate if nn else np.zeros(2)])
        centers = nn.centers.copy() if nn is not None else np.zeros(0)
        state = np.zeros((w0.shape[0], 4 + 2 * centers.size))
        state[:, 2:4] = -ndo_gain * w0
        return kernel.SMC_KIND, params, centers, state

    def parameters(self):
        params = {"lambda": compact(self.lam), "K": compact(self.switching_gain),
                  "Phi": self.boundary_layer, "surface": self.surface, "switching": self.switching}
        for obs in self.observers:
            params.update(obs.parameters())
        return params
