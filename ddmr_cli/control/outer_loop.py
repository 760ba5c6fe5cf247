"""Outer-loop kinematic controller: Kanayama et al. (1990) (docs/model.md §3).

The paper only says "an outer-loop kinematic controller"; the model doc fixes Kanayama's law
``v_d = v_r cos e_th + k_x e_x``, ``omega_d = omega_r + v_r (k_y e_y + k_th sin e_th)``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ddmr_cli.checks import non_negative
from ddmr_cli.compiled import law


class Kanayama(NamedTuple):
    """Kanayama tracking gains (docs/model.md §3).

    Parameters
    ----------
    k_x : float
        Longitudinal gain [1/s] (``outer_loop.k_x``).
    k_y : float
        Lateral gain [1/m^2] (``outer_loop.k_y``).
    k_theta : float
        Heading gain [1/m] (``outer_loop.k_theta``; the defaults are critically damped, ``2 sqrt(k_y)``).
    """

    k_x: float
    k_y: float
    k_theta: float

    def validate(self) -> None:
        """Every gain finite and >= 0 (ConfigError on ``outer_loop.<gain>``)."""
        for name, value in zip(self._fields, self):
            non_negative(f"outer_loop.{name}", value)

    def command(self, e_x, e_y, e_theta, v_r, omega_r):
        """Desired body velocities ``(v_d, omega_d)`` from the robot-frame errors (the law below)."""
        return kanayama(self, e_x, e_y, e_theta, v_r, omega_r)


@law
def kanayama(gains, e_x, e_y, e_theta, v_r, omega_r):
    """Kanayama's law (docs/model.md §3): ``v_d = v_r cos e_th + k_x e_x`` [m/s],
    ``omega_d = omega_r + v_r (k_y e_y + k_th sin e_th)`` [rad/s] (:func:`kanayama_of` with libm's cosine and sine)."""
    return kanayama_of(gains, e_x, e_y, math.cos(e_theta), math.sin(e_theta), v_r, omega_r)


@law
def kanayama_of(gains, e_x, e_y, cos_e_theta, sin_e_theta, v_r, omega_r):
    """Kanayama's law given the heading error's cosine and sine (:mod:`ddmr_cli.model.kinematics` says whose)."""
    v_d = v_r * cos_e_theta + gains.k_x * e_x
    omega_d = omega_r + v_r * (gains.k_y * e_y + gains.k_theta * sin_e_theta)
    return v_d, omega_d
