"""The wheel-space dynamics (8) as the engine and the controllers run them (docs/model.md §1, §4 and §5).

``w' = f(w) + g u + d``: the true plant's acceleration and lumped disturbance, the nominal model's acceleration and
the voltage it needs for a given acceleration, and the motor driver's limit. Each is a compiled law
(:mod:`ddmr_cli.compiled`) on the constants of :class:`~ddmr_cli.model.robot.Plant` or
:class:`~ddmr_cli.model.robot.NominalModel`. Wheel vectors are ordered (right, left).
"""

from __future__ import annotations

from ddmr_cli.compiled import law


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


__all__ = ["acceleration", "disturbance", "nominal_acceleration", "saturate", "sign", "voltage_for", "wheel_acceleration"]
