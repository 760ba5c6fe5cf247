"""The paper's robot: physical constants and the wheel-space plant they imply (docs/model.md §1 and §5).

Wheel vectors are ordered (right, left). The wheel-space dynamics are the paper's (6),
``J w' + B w + tau_d = K_u u`` with ``u`` the motor voltage, written in the form (8)
``w' = f(w) + g u + d`` with ``f(w) = -J^-1 B w``, ``g = J^-1 K_u`` and ``d = -J^-1 tau_d``.
The laws at the end of this module (:func:`acceleration`, :func:`disturbance`, :func:`nominal_acceleration`,
:func:`voltage_for`) are the plant's equations as the engine and the controllers run them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from functools import cached_property
from typing import NamedTuple

import numpy as np

from ddmr_cli.checks import non_negative, positive
from ddmr_cli.compiled import law
from ddmr_cli.errors import ConfigError

GRAVITY = 9.81  # m/s^2


#: relative tolerance within which a computed 2x2 matrix counts as the symmetric form [[p, q], [q, p]]
SYMMETRY_RTOL = 1e-12


@dataclass(frozen=True)
class WheelMatrix:
    """A 2x2 wheel-space matrix ``[[p, q], [q, p]]`` (the form of J, J^-1, J^-1 B, g for a symmetric robot).

    Its inverse and eigenvalues have closed forms, so the model's numbers never depend on which LAPACK kernel
    a CPU gets: ``[[p, q], [q, p]]^-1 = [[p, -q], [-q, p]] / (p^2 - q^2)``, eigenvalues ``p + q`` (common
    mode, eigenvector ``[1, 1]``) and ``p - q`` (differential mode, ``[1, -1]``).
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
        Motor constants k_t [N m/A] and k_e [V s/rad], referred to the wheel (docs/model.md: 0.3, 0.3).
    armature_resistance : float
        R_a [ohm] (docs/model.md: 0.7).
    viscous_friction : float
        b_v per wheel [N m s/rad] (docs/model.md: 0.01).
    max_voltage : float
        Supply voltage U_max [V]; the applied voltage is saturated to +-U_max (paper 4.1: 24).
    """

    mass: float
    wheel_radius: float
    track_width: float
    yaw_inertia: float
    wheel_inertia: float
    torque_constant: float
    back_emf_constant: float
    armature_resistance: float
    viscous_friction: float
    max_voltage: float

    def __post_init__(self) -> None:
        for name in ("mass", "wheel_radius", "track_width", "yaw_inertia", "wheel_inertia", "torque_constant",
                     "back_emf_constant", "armature_resistance", "max_voltage"):
            positive(f"robot.{name}", getattr(self, name))
        non_negative("robot.viscous_friction", self.viscous_friction)
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        try:
            derived = (*self.inverse_inertia.eigenvalues, self.damping, self.voltage_gain)
        except (ValueError, ArithmeticError) as exc:
            raise ConfigError("robot", values, f"gives no usable inertia matrix J ({' '.join(str(exc).split())})") from None
        if not all(math.isfinite(v) for v in derived):
            raise ConfigError("robot", values, "gives a non-finite J^-1, damping B or voltage gain K_u (too extreme)")

    def step_rate(self, damping_scale_max: float = 1.0) -> float:
        """The plant's fastest pole [1/s], the largest eigenvalue of ``J^-1 B`` times the largest damping ratio
        ``B_true / B_nom`` (docs/model.md §4): the step must resolve it."""
        return max(self.drift.eigenvalues) * damping_scale_max

    @property
    def half_track(self) -> float:
        """L, half the distance between the wheels [m]."""
        return self.track_width / 2.0

    @cached_property
    def inertia(self) -> WheelMatrix:
        """J, from the kinetic energy of body plus wheels (docs/model.md §1, the paper's (6))."""
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
        """B = b_v + k_t k_e / R_a [N m s/rad], the same on both wheels (docs/model.md §1)."""
        return self.viscous_friction + self.torque_constant * self.back_emf_constant / self.armature_resistance

    @property
    def voltage_gain(self) -> float:
        """K_u = k_t / R_a [N m/V] (docs/model.md §1)."""
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
        """Rolling-resistance torque per wheel, ``mu m g R / 2`` [N m] (docs/model.md §5)."""
        return mu * self.mass * GRAVITY * self.wheel_radius / 2.0

    def plant(self) -> "Plant":
        """The constants of the true plant as the engine's laws take them."""
        jinv = self.inverse_inertia
        return Plant(jinv.p, jinv.q, self.damping, self.voltage_gain, self.max_voltage, self.wheel_radius,
                     self.half_track, self.back_emf_constant, self.armature_resistance)


class Plant(NamedTuple):
    """Constants of the true plant (docs/model.md §1): ``J^-1 = [[jinv_p, jinv_q], [jinv_q, jinv_p]]`` [1/(kg m^2)],
    ``B`` [N m s/rad], ``K_u`` [N m/V], ``U_max`` [V], ``R``, ``L`` [m], ``k_e`` [V s/rad], ``R_a`` [ohm]."""

    jinv_p: float
    jinv_q: float
    damping: float
    voltage_gain: float
    max_voltage: float
    wheel_radius: float
    half_track: float
    back_emf_constant: float
    armature_resistance: float


class NominalModel(NamedTuple):
    """The model a controller believes in: ``w' = -A w + g u + d`` with nominal J, B, K_u (docs/model.md §1).

    Controllers use this; the true plant may differ (scenario 2's time-varying damping). Fields:
    ``J^-1`` (``jinv_p``, ``jinv_q``), ``J / K_u`` (``j_over_ku_p``, ``j_over_ku_q``), ``B``, ``K_u`` and ``B / K_u``.
    """

    jinv_p: float
    jinv_q: float
    j_over_ku_p: float
    j_over_ku_q: float
    damping: float
    voltage_gain: float
    damping_over_gain: float

    @classmethod
    def from_robot(cls, robot: Robot) -> "NominalModel":
        J, ku, B = robot.inertia, robot.voltage_gain, robot.damping
        jinv = J.inverse()
        return cls(jinv.p, jinv.q, J.p / ku, J.q / ku, B, ku, B / ku)


@law
def sign(x):
    """sign(x) in {-1, 0, 1} (an int; 0 for 0 and NaN)."""
    return 1 if x > 0.0 else (-1 if x < 0.0 else 0)


@law
def acceleration(plant, w_R, w_L, u_R, u_L, d_R, d_L):
    """The paper's (8): ``w' = J^-1 (K_u u - B w) + d`` [rad/s^2], ``B`` the nominal damping."""
    m_R = plant.voltage_gain * u_R - plant.damping * w_R
    m_L = plant.voltage_gain * u_L - plant.damping * w_L
    return (plant.jinv_p * m_R + plant.jinv_q * m_L + d_R,
            plant.jinv_q * m_R + plant.jinv_p * m_L + d_L)


@law
def disturbance(plant, w_R, w_L, damping_scale, uncertain, roughness_R, roughness_L, roll_torque):
    """The lumped disturbance ``d = w' - f_nom(w) - g_nom u`` of the true plant (docs/model.md §5) [rad/s^2]:
    ``d = -J^-1 (B_nom (b - 1) w + tau_roll sign(w)) + d_rough``, with rolling resistance opposing each wheel's
    rotation, ``b = B_true / B_nom`` the damping uncertainty (scenario 2, when ``uncertain``) and ``d_rough`` the
    terrain roughness part."""
    t_R = sign(w_R) * roll_torque
    t_L = sign(w_L) * roll_torque
    if uncertain:
        t_R += (plant.damping * (damping_scale - 1.0)) * w_R
        t_L += (plant.damping * (damping_scale - 1.0)) * w_L
    return (roughness_R - (plant.jinv_p * t_R + plant.jinv_q * t_L),
            roughness_L - (plant.jinv_q * t_R + plant.jinv_p * t_L))


@law
def wheel_acceleration(plant, w_R, w_L, u_R, u_L, damping_scale, uncertain, roughness_R, roughness_L, roll_torque):
    """The true plant's ``(w'_R, w'_L, d_R, d_L)``: :func:`disturbance` at ``w``, then :func:`acceleration` (8)."""
    d_R, d_L = disturbance(plant, w_R, w_L, damping_scale, uncertain, roughness_R, roughness_L, roll_torque)
    a_R, a_L = acceleration(plant, w_R, w_L, u_R, u_L, d_R, d_L)
    return a_R, a_L, d_R, d_L


@law
def saturate(u_command, max_voltage):
    """The motor driver's limit (docs/model.md §4): ``u = clip(u_c, -U_max, U_max)`` [V], and whether it clipped."""
    return min(max(u_command, -max_voltage), max_voltage), abs(u_command) > max_voltage


@law
def nominal_acceleration(nominal, w_R, w_L, u_R, u_L):
    """``f(w) + g u = J^-1 (K_u u - B w)``: the paper's (8) without d, in the nominal model [rad/s^2]."""
    m_R = nominal.voltage_gain * u_R - nominal.damping * w_R
    m_L = nominal.voltage_gain * u_L - nominal.damping * w_L
    return nominal.jinv_p * m_R + nominal.jinv_q * m_L, nominal.jinv_q * m_R + nominal.jinv_p * m_L


@law
def voltage_for(nominal, a_R, a_L, w_R, w_L):
    """``u = g^-1 (a - f(w)) = (J a + B w) / K_u`` [V]: the voltage that gives acceleration ``a`` at speed ``w``."""
    return (nominal.j_over_ku_p * a_R + nominal.j_over_ku_q * a_L + nominal.damping_over_gain * w_R,
            nominal.j_over_ku_q * a_R + nominal.j_over_ku_p * a_L + nominal.damping_over_gain * w_L)
