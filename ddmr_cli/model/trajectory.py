"""Reference trajectories: pose, v_r and omega_r as functions of time (docs/model.md §3).

A trajectory is any object with ``reference(t) -> (x_r, y_r, theta_r, v_r, omega_r)`` for a scalar time ``t``.
Adding one is a new class here plus a YAML file in ``conf/trajectory``. The engine reads the reference of every
step from :func:`reference_table`; a trajectory may give its own ``table(t)`` for a whole time array when it
computes the same numbers as ``reference`` step by step (the straight line does: elementwise IEEE arithmetic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from ddmr_cli.checks import finite, positive


class Trajectory(Protocol):
    """Reference trajectory protocol."""

    def reference(self, t: float) -> tuple[float, float, float, float, float]:
        """Return ``(x_r, y_r, theta_r, v_r, omega_r)`` at time ``t`` [s]."""
        ...


@dataclass(frozen=True)
class StraightLine:
    """The paper's reference: ``x_r = x0 + v t cos(heading)``, ``y_r = y0 + v t sin(heading)`` (docs/model.md §3)."""

    speed: float
    heading: float
    x0: float
    y0: float

    def __post_init__(self) -> None:
        for name in ("speed", "heading", "x0", "y0"):
            finite(f"trajectory.{name}", getattr(self, name))

    def reference(self, t: float) -> tuple[float, float, float, float, float]:
        d = self.speed * t
        return self.x0 + d * math.cos(self.heading), self.y0 + d * math.sin(self.heading), self.heading, self.speed, 0.0

    def table(self, t: np.ndarray) -> np.ndarray:
        """:meth:`reference` at every time of ``t``, shape ``(len(t), 5)``: the same operations elementwise (the
        cosine and sine of the constant heading by ``math``), so the same bits."""
        d = self.speed * t
        return np.stack([self.x0 + d * math.cos(self.heading), self.y0 + d * math.sin(self.heading),
                         np.full_like(d, self.heading), np.full_like(d, self.speed), np.zeros_like(d)], axis=1)


@dataclass(frozen=True)
class Circle:
    """A circle of ``radius`` driven counter-clockwise at ``speed``, starting at the origin heading along +x."""

    speed: float
    radius: float

    def __post_init__(self) -> None:
        finite("trajectory.speed", self.speed)
        positive("trajectory.radius", self.radius)

    def reference(self, t: float) -> tuple[float, float, float, float, float]:
        omega = self.speed / self.radius
        phi = omega * t
        return self.radius * math.sin(phi), self.radius * (1.0 - math.cos(phi)), phi, self.speed, omega


@dataclass(frozen=True)
class FigureEight:
    """A lemniscate of Gerono, ``x = a sin(w t)``, ``y = a sin(w t) cos(w t)``, started at the origin.

    ``v_r`` and ``omega_r`` are the exact path speed and curvature rate of the curve.
    """

    amplitude: float
    period: float

    def __post_init__(self) -> None:
        positive("trajectory.amplitude", self.amplitude)
        positive("trajectory.period", self.period)

    def reference(self, t: float) -> tuple[float, float, float, float, float]:
        a, w = self.amplitude, 2.0 * math.pi / self.period
        x, y = a * math.sin(w * t), 0.5 * a * math.sin(2.0 * w * t)
        dx, dy = a * w * math.cos(w * t), a * w * math.cos(2.0 * w * t)
        ddx, ddy = -a * w * w * math.sin(w * t), -2.0 * a * w * w * math.sin(2.0 * w * t)
        v = math.hypot(dx, dy)
        omega = (dx * ddy - dy * ddx) / (v * v) if v > 0 else 0.0
        return x, y, math.atan2(dy, dx), v, omega


@dataclass(frozen=True)
class Sinusoid:
    """A lane-change path ``y = A sin(2 pi x / lambda)`` driven at constant path speed ``v`` from the origin.

    The arc length to ``x`` is an incomplete elliptic integral of the second kind, with ``a = A k``,
    ``k = 2 pi / lambda``: ``s(x) = sqrt(1 + a^2) / k E(k x | a^2 / (1 + a^2))``; ``x(t)`` solves
    ``s(x) = v t`` by Newton's method (``s' = sqrt(1 + y'^2) >= 1``, converged to 1e-12 m). Then
    ``theta_r = atan(y'(x))``, ``v_r = v`` and ``omega_r = v kappa(x)``, ``kappa = y'' / (1 + y'^2)^(3/2)``
    (exact, not differenced; docs/model.md §3).
    """

    amplitude: float
    wavelength: float
    speed: float

    def __post_init__(self) -> None:
        finite("trajectory.amplitude", self.amplitude)
        positive("trajectory.wavelength", self.wavelength)
        positive("trajectory.speed", self.speed)

    def arc_length(self, x: float) -> float:
        """``s(x)``, the path length from the origin to abscissa ``x`` [m]."""
        from scipy.special import ellipeinc

        k = 2.0 * math.pi / self.wavelength
        a2 = (self.amplitude * k) ** 2
        return math.sqrt(1.0 + a2) / k * float(ellipeinc(k * x, a2 / (1.0 + a2)))

    def abscissa(self, t: float) -> float:
        """``x(t)``: the root of ``s(x) = v t`` (Newton from ``x = v t / s'_mean``, at most 50 steps)."""
        target = self.speed * t
        x = target * self.wavelength / self.arc_length(self.wavelength) if target else 0.0
        k = 2.0 * math.pi / self.wavelength
        for _ in range(50):
            step = (self.arc_length(x) - target) / math.hypot(1.0, self.amplitude * k * math.cos(k * x))
            x -= step
            if abs(step) <= 1e-12:
                break
        return x

    def reference(self, t: float) -> tuple[float, float, float, float, float]:
        k = 2.0 * math.pi / self.wavelength
        x = self.abscissa(t)
        slope = self.amplitude * k * math.cos(k * x)
        bend = -self.amplitude * k * k * math.sin(k * x)
        curvature = bend / (1.0 + slope * slope) ** 1.5
        return x, self.amplitude * math.sin(k * x), math.atan(slope), self.speed, self.speed * curvature


def reference_table(trajectory: Trajectory, n_steps: int, dt: float) -> np.ndarray:
    """``(x_r, y_r, theta_r, v_r, omega_r)`` at steps ``k = 0 .. n_steps - 1``, ``t = k dt``, shape ``(n_steps, 5)``:
    the trajectory's ``table`` when it has one, else ``reference`` step by step."""
    t = np.arange(n_steps) * float(dt)
    table = getattr(trajectory, "table", None)
    if table is not None:
        return np.ascontiguousarray(table(t), dtype=float)
    return np.array([trajectory.reference(float(x)) for x in t], dtype=float).reshape(n_steps, 5)
