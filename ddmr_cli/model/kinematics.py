"""Differential-drive kinematics (docs/model.md §2; the paper's (1)-(5)).

Each function is a law on scalars: the engine runs these very definitions, compiled.
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import law


@law
def wrap_angle(angle):
    """Wrap an angle into (-pi, pi] (docs/model.md §2)."""
    turned = math.pi - angle
    # x % 2 pi is x itself for x in [0, 2 pi): skip the (slow, out-of-line) floating modulo then, same bits
    wrapped = math.pi - (turned if 0.0 <= turned < 2.0 * math.pi else turned % (2.0 * math.pi))
    # the modulo can round up to exactly 2 pi (e.g. just above pi), which would give -pi: map it to pi
    return wrapped + 2.0 * math.pi if wrapped <= -math.pi else wrapped


@law
def forward(w_right, w_left, wheel_radius, half_track):
    """Body velocities from wheel speeds, the paper's (1): ``v = R (w_R + w_L) / 2``,
    ``omega = R (w_R - w_L) / (2 L)``.

    Returns
    -------
    v, omega : linear [m/s] and angular [rad/s] velocity.
    """
    return wheel_radius * 0.5 * (w_right + w_left), (wheel_radius / (2.0 * half_track)) * (w_right - w_left)


@law
def inverse(v, omega, wheel_radius, half_track):
    """Wheel speeds from body velocities, the paper's (4)-(5): ``w_R,L = (v +- L omega) / R``.

    Returns
    -------
    w_right, w_left : wheel angular speeds [rad/s].
    """
    return (v + half_track * omega) * (1.0 / wheel_radius), (v - half_track * omega) * (1.0 / wheel_radius)


@law
def pose_error(x, y, theta, x_ref, y_ref, theta_ref):
    """Tracking error expressed in the robot frame (docs/model.md §2; Kanayama et al. 1990).

    Returns
    -------
    e_x, e_y, e_theta : longitudinal [m], lateral [m] and heading [rad] error, e_theta wrapped.
    """
    dx, dy = x_ref - x, y_ref - y
    c, s = math.cos(theta), math.sin(theta)
    return c * dx + s * dy, c * dy - s * dx, wrap_angle(theta_ref - theta)


@law
def deviation(x, y, x_ref, y_ref):
    """Distance from the reference position [m] (Table 4's 'Deviation', docs/model.md §2 and §7).

    The square root of the sum of squares, not ``math.hypot``: the same distance to within 2 ulp, and glibc's
    hypot (rounded correctly, with scaling) took 7.5 % of the step loop's samples under perf (smc_ndo, 50 runs:
    164 -> 150 ns per run and step, the fastest of 6 process pairs). hypot's scaling matters only beyond 1e154 m,
    where a run has long diverged (the deviation is then inf, above any finite divergence bound), and below
    1e-154 m, where the squares underflow and the deviation is 0."""
    dx, dy = x_ref - x, y_ref - y
    return math.sqrt(dx * dx + dy * dy)


def circle_radius(w_right: float, w_left: float, half_track: float) -> float:
    """Radius of the circle driven by constant wheel speeds, ``L (wR + wL) / (wR - wL)`` [m]."""
    return half_track * (w_right + w_left) / (w_right - w_left)
