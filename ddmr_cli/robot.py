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


@dataclass(frozen=True)
class WheelMatrix:
    """A 2x2 wheel-space matrix ``[[p, q], [q, p]]`` (the form of J, J^-1, J^-1 B, g for a symmetric robot).

    Calling it on a batch of wheel vectors ``v`` (shape ``(n_runs, 2)``) returns ``(M v^T)^T`` computed
    elementwise, ``p v + q v_swapped``: BLAS matrix products round differently for different batch sizes,
    and a run must give bit-identical numbers alone or inside any batch.
    """

    p: float
    q: float

    @classmethod
    def of(cls, m: np.ndarray) -> "WheelMatrix":
        m = np.asarray(m, dtype=float)
        if m.shape != (2, 2) or m[0, 0] != m[1, 1] or m[0, 1] != m[1, 0]:
            raise ValueError(f"not a symmetric wheel matrix [[p, q], [q, p]]: {m.tolist()}")
        return cls(float(m[0, 0]), float(m[0, 1]))

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
    def inertia_matrix(self) -> np.ndarray:
        """J (2x2), from the kinetic energy of body plus wheels (MODEL.md 1, the paper's (6))."""
        r2, L = self.wheel_radius**2, self.half_track
        translational = self.mass * r2 / 4.0
        rotational = self.yaw_inertia * r2 / (4.0 * L**2)
        j11 = self.wheel_inertia + translational + rotational
        j12 = translational - rotational
        return np.array([[j11, j12], [j12, j11]])

    @property
    def damping(self) -> float:
        """B = b_v + k_t k_e / R_a [N m s/rad], the same on both wheels (MODEL.md 1)."""
        return self.viscous_friction + self.torque_constant * self.back_emf_constant / self.armature_resistance

    @property
    def voltage_gain(self) -> float:
        """K_u = k_t / R_a [N m/V] (MODEL.md 1)."""
        return self.torque_constant / self.armature_resistance

    @cached_property
    def inverse_inertia(self) -> np.ndarray:
        """J^-1 (2x2)."""
        return np.linalg.inv(self.inertia_matrix)

    @property
    def drift_matrix(self) -> np.ndarray:
        """A = J^-1 B, so that f(w) = -A w in the paper's (8)."""
        return self.inverse_inertia * self.damping

    @property
    def input_matrix(self) -> np.ndarray:
        """g = J^-1 K_u (2x2), the paper's (8) with u in volts."""
        return self.inverse_inertia * self.voltage_gain

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

    inertia: np.ndarray
    damping: float
    voltage_gain: float

    @classmethod
    def from_robot(cls, robot: Robot) -> "NominalModel":
        return cls(robot.inertia_matrix, robot.damping, robot.voltage_gain)

    @cached_property
    def inertia_over_gain(self) -> WheelMatrix:
        """J / K_u, so that ``g^-1 a = (J / K_u) a``."""
        return WheelMatrix.of(self.inertia / self.voltage_gain)

    @cached_property
    def inverse_inertia(self) -> WheelMatrix:
        """J^-1."""
        return WheelMatrix.of(np.linalg.inv(self.inertia))

    def f_plus_g_u(self, w: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The nominal acceleration ``f(w) + g u = J^-1 (K_u u - B w)`` (the paper's (8) without d)."""
        return self.inverse_inertia(self.voltage_gain * u - self.damping * w)

    def voltage_for(self, a: np.ndarray, w: np.ndarray) -> np.ndarray:
        """``u = g^-1 (a - f(w)) = (J a + B w) / K_u``: the voltage that gives acceleration ``a`` at speed ``w``."""
        return self.inertia_over_gain(a) + (self.damping / self.voltage_gain) * w
