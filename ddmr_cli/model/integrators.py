"""One step of the plant and the pose, with ``u`` and the disturbances held over it (docs/model.md §4).

The state is the pose ``(x, y, theta)``, the distance travelled and the wheel speeds ``w``; its derivative is
the forward kinematics (1)-(2) and the plant (8) (:func:`ddmr_cli.model.dynamics.wheel_acceleration`).
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import law
from ddmr_cli.model.kinematics import forward
from ddmr_cli.model.dynamics import wheel_acceleration


@law
def euler(plant, dt, x, y, theta, distance, w_R, w_L, cos_theta, sin_theta, a_R, a_L):
    """Explicit Euler, from the step's derivatives (``a`` = w', and ``cos``, ``sin`` of theta already known)."""
    v, omega = forward(w_R, w_L, plant.wheel_radius, plant.half_track)
    return (x + dt * (v * cos_theta), y + dt * (v * sin_theta), theta + dt * omega, distance + dt * abs(v),
            w_R + dt * a_R, w_L + dt * a_L)


@law
def rk4(plant, dt, x, y, theta, distance, w_R, w_L, cos_theta, sin_theta, a_R, a_L,
        u_R, u_L, damping_scale, uncertain, roughness_R, roughness_L, roll_torque):
    """Classic 4th-order Runge-Kutta, the plant's inputs held over the step."""
    R, L, h = plant.wheel_radius, plant.half_track, 0.5 * dt
    v, omega = forward(w_R, w_L, R, L)
    th2, w2_R, w2_L = theta + h * omega, w_R + h * a_R, w_L + h * a_L
    v2, omega2 = forward(w2_R, w2_L, R, L)
    a2_R, a2_L, _, _ = wheel_acceleration(plant, w2_R, w2_L, u_R, u_L, damping_scale, uncertain, roughness_R,
                                          roughness_L, roll_torque)
    th3, w3_R, w3_L = theta + h * omega2, w_R + h * a2_R, w_L + h * a2_L
    v3, omega3 = forward(w3_R, w3_L, R, L)
    a3_R, a3_L, _, _ = wheel_acceleration(plant, w3_R, w3_L, u_R, u_L, damping_scale, uncertain, roughness_R,
                                          roughness_L, roll_torque)
    th4, w4_R, w4_L = theta + dt * omega3, w_R + dt * a3_R, w_L + dt * a3_L
    v4, omega4 = forward(w4_R, w4_L, R, L)
    a4_R, a4_L, _, _ = wheel_acceleration(plant, w4_R, w4_L, u_R, u_L, damping_scale, uncertain, roughness_R,
                                          roughness_L, roll_torque)
    sixth = dt / 6.0
    return (x + sixth * (v * cos_theta + 2.0 * v2 * math.cos(th2) + 2.0 * v3 * math.cos(th3) + v4 * math.cos(th4)),
            y + sixth * (v * sin_theta + 2.0 * v2 * math.sin(th2) + 2.0 * v3 * math.sin(th3) + v4 * math.sin(th4)),
            theta + sixth * (omega + 2.0 * omega2 + 2.0 * omega3 + omega4),
            distance + sixth * (abs(v) + 2.0 * abs(v2) + 2.0 * abs(v3) + abs(v4)),
            w_R + sixth * (a_R + 2.0 * a2_R + 2.0 * a3_R + a4_R),
            w_L + sixth * (a_L + 2.0 * a2_L + 2.0 * a3_L + a4_L))
