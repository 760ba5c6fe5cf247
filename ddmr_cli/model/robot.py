"""The paper's robot: physical constants and the wheel-space plant they imply (docs/model.md §1 and §5).

Wheel vectors are ordered (right, left). The wheel-space dynamics are the paper's (6),
``J w' + B w + tau_d = K_u u`` with ``u`` the motor voltage, written in the form (8)
``w' = f(w) + g u + d`` with ``f(w) = -J^-1 B w``, ``g = J^-1 K_u`` and ``d = -J^-1 tau_d``.
The plant's equations as the engine and the controllers run them (its acceleration, its disturbance, the nominal
model's acceleration and voltage) are compiled laws in :mod:`ddmr_cli.model.dynamics`: this module holds plain
classes only and does not load numba, so what only reads results (the report, its figures) can build a robot.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, fields
from functools import cached_property
from typing import NamedTuple

import numpy as np

from ddmr_cli.checks import non_negative, positive
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


#: the plant's laws this module held until they moved to :mod:`ddmr_cli.model.dynamics` (so that this one loads no
#: numba); a user's module that imports one from here still gets it, with a DeprecationWarning
MOVED_TO_DYNAMICS = ("sign", "acceleration", "disturbance", "wheel_acceleration", "saturate", "nominal_acceleration",
                     "voltage_for")


def __getattr__(name: str):
    if name in MOVED_TO_DYNAMICS:
        from ddmr_cli.model import dynamics

        warnings.warn(f"ddmr_cli.model.robot.{name} has moved: import it from ddmr_cli.model.dynamics",
                      DeprecationWarning, stacklevel=2)
        return getattr(dynamics, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
