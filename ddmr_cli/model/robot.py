"""The paper's robot: physical constants and the wheel-space dynamics they imply (MODEL.md section 1).

Wheel vectors are ordered (right, left). The wheel-space dynamics are the paper's (6),
``J w' + B w + tau_d = K_u u`` with ``u`` the motor voltage, written in the form (8)
``w' = f(w) + g u + d`` with ``f(w) = -J^-1 B w``, ``g = J^-1 K_u`` and ``d = -J^-1 tau_d``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

GRAVITY = 9.81  # m/s^2


#: relative tolerance within which a computed 2x2 matrix counts as the symmetric form [[p, q], [q, p]]
SYMMETRY_RTOL = 1e-12


@dataclass(frozen=True)
class WheelMatrix:
    """A 2x2 wheel-space matrix ``[[p, q], [q, p]]`` (the form of J, J^-1, J^-1 B, g for a symmetric robot).

    Its inverse and eigenvalues have closed forms, so the model's numbers never depend on which LAPACK kernel
    a CPU gets: ``[[p, q], [q, p]]^-1 = [[p, -q], [-q, p]] / (p^2 - q^2)``, eigenvalues ``p + q`` (common
    mode, eigenvector ``[1, 1]``) and ``p - q`` (differential mode, ``[1, -1]``).

    Calling it on a batch of wheel vectors ``v`` (shape ``(n_runs, 2)``) returns ``(M v^T)^T`` computed
    elementwise, ``p v + q v_swapped``: BLAS matrix products round differently for different batch sizes,
    and a run must give bit-identical numbers alone or inside any batch.
    """

    p: float
    q: float

    @classmethod
    def of(cls, m: np.ndarray, rtol: float = SYMMETRY_RTOL) -> "WheelMatrix":
        """The symmetric form of ``m``: ``p``, ``q`` are the means of its diagonal and off-diagonal entries.

        A computed matrix is symmetric only to rounding (a LAPACK inverse can differ in the last digit between
        its diagonal entries), so entries that agree to ``rtol`` relative to the matrix's largest entry count as
        equal; a matrix further from the form is refused.
        """
        m = np.asarray(m, dtype=float)
        if m.shape != (2, 2) or not np.all(np.isfinite(m)):
            raise ValueError(f"not a finite 2x2 wheel matrix: {m.tolist()}")
        scale = float(np.max(np.abs(m)))
        if abs(m[0, 0] - m[1, 1]) > rtol * scale or abs(m[0, 1] - m[1, 0]) > rtol * scale:
            raise ValueError(f"not a symmetric wheel matrix [[p, q], [q, p]] (to rtol {rtol:g}): {m.tolist()}")
        return cls(0.5 * (float(m[0, 0]) + float(m[1, 1])), 0.5 * (float(m[0, 1]) + float(m[1, 0])))

    def inverse(self) -> "WheelMatrix":
        """``[[p, -q], [-q, p]] / (p^2 - q^2)``, the exact inverse (no LAPACK)."""
        det = self.p * self.p - self.q * self.q
        if not det > 0.0 or not np.isfinite(det):
            raise ValueError(f"wheel matrix [[{self.p!r}, {self.q!r}], [{self.q!r}, {self.p!r}]] is not "
                             "positive definite (p^2 - q^2 must be > 0)")
        return WheelMatrix(self.p / det, -self.q / det)

    def scaled(self, factor: float) -> "WheelMatrix":
        """``factor M``."""
        return WheelMatrix(self.p * factor, self.q * factor)

    @property
    def eigenvalues(self) -> tuple[float, float]:
        """``(p + q, p - q)``: common mode (both wheels alike) and differential mode (turning)."""
        return self.p + self.q, self.p - self.q

    def to_array(self) -> np.ndarray:
        return np.array([[self.p, self.q], [self.q, self.p]])

    def __call__(self, v: np.ndarray) -> np.ndarray:
        return self.p * v + self.q * v[:, ::-1]


@dataclass(frozen=True)
class Robot:
    """Physical parameters of a differential-drive robot (paper Table 2 plus motor constants).

    Parameters
    ----------
    mass : float
        Robot mass m [kg] (Table 2: 15).
    wheel_radius : float
        Wheel radius R [m] (Table 2: 0.03).
    track_width : float
        Distance between the wheels 2L [m] (Table 2: 0.5).
    yaw_inertia : float
        Robot yaw moment of inertia I_z [kg m^2] (Table 2: 0.27).
    wheel_inertia : float
        Wheel moment of inertia I_w [kg m^2] (Table 2: 0.0075).
    torque_constant, back_emf_constant : float
        Motor constants k_t [N m/A] and k_e [V s/rad], referred to the wheel (MODEL.md: 0.3, 0.3).
    armature_resistance : float
        R_a [ohm] (MODEL.md: 0.7).
    viscous_friction : float
        b_v per wheel [N m s/rad] (MODEL.md: 0.01).
    max_voltage : float
        Supply voltage U_max [V]; the applied voltage is saturated to +-U_max (paper 4.1: 24).
    """

    mass: float = 15.0
    wheel_radius: float = 0.03
    track_width: float = 0.5
    yaw_inertia: float = 0.27
    wheel_inertia: float = 0.0075
    torque_constant: float = 0.3
    back_emf_constant: float = 0.3
    armature_resistance: float = 0.7
    viscous_friction: float = 0.01
    max_voltage: float = 24.0

    @property
    def half_track(self) -> float:
        """L, half the distance between the wheels [m]."""
        return self.track_width / 2.0

    @cached_property
    def inertia(self) -> WheelMatrix:
        """J, from the kinetic energy of body plus wheels (MODEL.md 1, the paper's (6))."""
        r2, L = self.wheel_radius**2, self.half_track
        translational = self.mass * r2 / 4.0
        rotational = self.yaw_inertia * r2 / (4.0 * L**2)
        return WheelMatrix(self.wheel_inertia + translational + rotational, translational - rotational)

    @property
    def inertia_matrix(self) -> np.ndarray:
        """J as a 2x2 array."""
        return self.inertia.to_array()

    @property
    def damping(self) -> float:
        """B = b_v + k_t k_e / R_a [N m s/rad], the same on both wheels (MODEL.md 1)."""
        return self.viscous_friction + self.torque_constant * self.back_emf_constant / self.armature_resistance

    @property
    def voltage_gain(self) -> float:
        """K_u = k_t / R_a [N m/V] (MODEL.md 1)."""
        return self.torque_constant / self.armature_resistance

    @cached_property
    def inverse_inertia(self) -> WheelMatrix:
        """J^-1, in closed form."""
        return self.inertia.inverse()

    @property
    def drift(self) -> WheelMatrix:
        """A = J^-1 B, so that f(w) = -A w in the paper's (8); its eigenvalues are the plant's poles."""
        return self.inverse_inertia.scaled(self.damping)

    @property
    def input_gain(self) -> WheelMatrix:
        """g = J^-1 K_u, the paper's (8) with u in volts."""
        return self.inverse_inertia.scaled(self.voltage_gain)

    @property
    def drift_matrix(self) -> np.ndarray:
        """A as a 2x2 array."""
        return self.drift.to_array()

    @property
    def input_matrix(self) -> np.ndarray:
        """g as a 2x2 array."""
        return self.input_gain.to_array()

    def rolling_resistance_torque(self, mu: float | np.ndarray) -> float | np.ndarray:
        """Rolling-resistance torque per wheel, ``mu m g R / 2`` [N m] (MODEL.md 5)."""
        return mu * self.mass * GRAVITY * self.wheel_radius / 2.0

    def current(self, u: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Armature current ``i = (u - k_e w) / R_a`` [A] (MODEL.md 7)."""
        return (u - self.back_emf_constant * w) / self.armature_resistance


@dataclass(frozen=True)
class NominalModel:
    """The model a controller believes in: ``w' = -A w + g u + d`` with nominal J, B, K_u (MODEL.md 1).

    Controllers use this; the true plant may differ (scenario 2's time-varying damping).
    """

    inertia: WheelMatrix
    damping: float
    voltage_gain: float

    @classmethod
    def from_robot(cls, robot: Robot) -> "NominalModel":
        return cls(robot.inertia, robot.damping, robot.voltage_gain)

    @cached_property
    def inertia_over_gain(self) -> WheelMatrix:
        """J / K_u, so that ``g^-1 a = (J / K_u) a``."""
        J = self.inertia
        return WheelMatrix(J.p / self.voltage_gain, J.q / self.voltage_gain)

    @cached_property
    def inverse_inertia(self) -> WheelMatrix:
        """J^-1, in closed form."""
        return self.inertia.inverse()

    def f_plus_g_u(self, w: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The nominal acceleration ``f(w) + g u = J^-1 (K_u u - B w)`` (the paper's (8) without d)."""
        return self.inverse_inertia(self.voltage_gain * u - self.damping * w)

    def voltage_for(self, a: np.ndarray, w: np.ndarray) -> np.ndarray:
        """``u = g^-1 (a - f(w)) = (J a + B w) / K_u``: the voltage that gives acceleration ``a`` at speed ``w``."""
        return self.inertia_over_gain(a) + (self.damping / self.voltage_gain) * w
