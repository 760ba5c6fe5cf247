"""What a batch of runs shares (:class:`World`) and what each run holds (:data:`RUN_FIELDS`) in the step loop."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

#: the fields of one run's engine state (a structured record)
RUN_FIELDS = [("x", "f8"), ("y", "f8"), ("theta", "f8"), ("distance", "f8"), ("w", "f8", 2), ("w_d_prev", "f8", 2),
              ("noise", "f8", 3), ("divergence_step", "i8")]
#: what the zero-order hold keeps between control instants (docs/model.md §10): the controller's command, the
#: voltage it sent (saturated, PWM-quantised), whether it saturated (1/0: numba has no nested bool arrays) and the
#: wheel-speed references (the controller's diagnostic channels are held in its own state record)
HOLD_FIELDS = [("u_command", "f8", 2), ("u_sent", "f8", 2), ("saturated", "i8", 2), ("w_d", "f8", 2)]


class World(NamedTuple):
    """What every run of a batch shares: the reference, the scenario and terrain tables, the noise filters."""

    reference: np.ndarray  # (n_steps, 5): x_r [m], y_r [m], theta_r [rad], v_r [m/s], omega_r [rad/s]
    phase: np.ndarray  # (n_steps,) scenario phase of each step by time (phase_by_distance false)
    phase_by_distance: bool  # phases by the distance travelled (phase_edges), else by time (phase)
    phase_edges: np.ndarray  # starts of every phase but the first [m of distance travelled]
    roughness_on: np.ndarray  # (n_phases,) 1.0 where the phase has terrain roughness, else 0.0
    uncertainty_on: np.ndarray  # (n_phases,) True where the phase has damping uncertainty
    zone_edges: np.ndarray  # starts of every terrain zone but the first [m of distance travelled]
    roughness: np.ndarray  # (n_zones,) roughness per zone [rad/s^2]
    roll_torque: np.ndarray  # (n_zones,) rolling-resistance torque per wheel [N m]
    ou_a: np.ndarray  # (3,) OU coefficients per noise channel (roughness right, left, uncertainty)
    ou_b: np.ndarray
    uncertainty: object  # the scenario's DampingUncertainty
    gains: object  # the outer loop's Kanayama gains
    dt: float  # [s]
    rk4: bool  # RK4, else explicit Euler
    divergence_bound: float  # [m]
    hp: np.ndarray  # the chattering high-pass biquad [b0, b1, b2, a0, a1, a2]
    hp_zi: np.ndarray  # its state per unit input at steady state
    phase_base: int  # metric segment index of the first phase
    settle_steps: int  # steps from the start before a step is steady (the start-up transient)
    zone_settle_steps: int  # steps after a zone's or phase's entry before its steps are steady there
    bands: bool  # record every run's band channels on the band grid
    band_stride: int  # steps between band grid points
    control_steps: int  # plant steps per control period (control.rate; 1: control at every step)
    control_dt: float  # the control period [s]
    sensor: object  # the sensor's SensorParameters (docs/model.md §10)
    actuator: object  # the actuator's ActuatorParameters
    surface: int  # the row of the controller's SURFACE diagnostic channel (-1: none, s is NaN)
    recorded: np.ndarray  # (n,) int64: the rows of the other diagnostic channels, recorded after the base series
    estimation: np.ndarray  # (n_estimation_metrics, n_rows) int64: the channels whose estimates count in a metric, then -1
