"""Differential-drive kinematics (MODEL.md section 2; the paper's (1)-(5)).

All functions are vectorised: scalars or arrays with a leading run axis.
"""

from __future__ import annotations

import numpy as np


def wrap_angle(angle: np.ndarray | float) -> np.ndarray | float:
    """Wrap an angle into (-pi, pi] (MODEL.md 2)."""
    wrapped = np.pi - np.mod(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi)
    # np.mod can round up to exactly 2 pi (e.g. just above pi), which would give -pi: map it to pi
    wrapped = np.where(wrapped <= -np.pi, wrapped + 2.0 * np.pi, wrapped)
    return wrapped if np.ndim(wrapped) else float(wrapped)


def forward(w_right, w_left, wheel_radius: float, half_track: float):
    """Body velocities from wheel speeds, the paper's (1).

    Returns
    -------
    v, omega : linear [m/s] and angular [rad/s] velocity.
    """
    v = wheel_radius * (w_right + w_left) / 2.0
    omega = wheel_radius * (w_right - w_left) / (2.0 * half_track)
    return v, omega


def inverse(v, omega, wheel_radius: float, half_track: float):
    """Wheel speeds from body velocities, the paper's (4)-(5).

    Returns
    -------
    w_right, w_left : wheel angular speeds [rad/s].
    """
    w_right = (v + half_track * omega) / wheel_radius
    w_left = (v - half_track * omega) / wheel_radius
    return w_right, w_left


def pose_error(x, y, theta, x_ref, y_ref, theta_ref):
    """Tracking error expressed in the robot frame (MODEL.md 2; Kanayama et al. 1990).

    Returns
    -------
    e_x, e_y, e_theta : longitudinal [m], lateral [m] and heading [rad] error, e_theta wrapped.
    """
    dx, dy = x_ref - x, y_ref - y
    c, s = np.cos(theta), np.sin(theta)
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(theta_ref - theta)


def circle_radius(w_right: float, w_left: float, half_track: float) -> float:
    """Radius of the circle driven by constant wheel speeds, ``L (wR + wL) / (wR - wL)``."""
    return half_track * (w_right + w_left) / (w_right - w_left)
