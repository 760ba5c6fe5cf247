"""Outer-loop kinematic controller: Kanayama et al. (1990) (MODEL.md section 3, Resolution).

The paper only says "an outer-loop kinematic controller"; MODEL.md fixes Kanayama's law
``v_d = v_r cos e_th + k_x e_x``, ``omega_d = omega_r + v_r (k_y e_y + k_th sin e_th)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Kanayama:
    """Kanayama tracking law (MODEL.md 3).

    Parameters
    ----------
    k_x : float
        Longitudinal gain [1/s] (default 10).
    k_y : float
        Lateral gain [1/m^2] (default 25).
    k_theta : float
        Heading gain [1/m] (default 10, critically damped: ``2 sqrt(k_y)``).
    """

    k_x: float = 10.0
    k_y: float = 25.0
    k_theta: float = 10.0

    def command(self, e_x, e_y, e_theta, v_r: float, omega_r: float):
        """Desired body velocities ``(v_d, omega_d)`` from the robot-frame errors."""
        v_d = v_r * np.cos(e_theta) + self.k_x * e_x
        omega_d = omega_r + v_r * (self.k_y * e_y + self.k_theta * np.sin(e_theta))
        return v_d, omega_d
