"""Reference trajectories: pose, v_r and omega_r as functions of time (docs/model.md §3).

A trajectory is any object with ``reference(t) -> (x_r, y_r, theta_r, v_r, omega_r)`` for a scalar time ``t``.
Adding one is a new class here plus a YAML file in ``conf/trajectory``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

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
