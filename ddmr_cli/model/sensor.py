"""What the controller measures: the wheel speeds and the pose, ideal, from encoders, or noisy (docs/model.md §10).

The controller and the outer loop see only the measured signals; the metrics are always computed on the truth.
The sensor is sampled at the control instants (``control.rate``), every ``T`` seconds:

``ideal``
    The truth, untouched (the paper's assumption, and the default).
``encoder``
    Each wheel's angle ``phi`` (integrated from its speed by the trapezoidal rule) read as a whole number of
    counts of ``q = 2 pi / N`` rad (:func:`quantise`, nearest count); the speed is the finite difference of the
    counts over the control period, ``w_m = (phi_q(t) - phi_q(t - T)) / T`` (:func:`encoder_speed`), optionally
    through a first-order low-pass of time constant ``tau_f`` (:func:`low_pass`); the pose is either dead
    reckoning of the quantised wheel increments (:func:`odometry`, ``pose=odometry``) or the true pose plus
    Gaussian noise (``pose=noisy``).
``noisy``
    The true wheel speeds and pose plus Gaussian noise, stds in physical units (``speed_std`` [rad/s],
    ``position_std`` [m], ``heading_std`` [rad]).

Noise is drawn from the run's sensor stream, a generator of its own derived from the seed
(:class:`ddmr_cli.model.noise.SensorNoise`), only when a std is above zero: the disturbance streams of a seed are
the same with or without sensor noise.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ddmr_cli.checks import integer, non_negative, one_of
from ddmr_cli.compiled import law
from ddmr_cli.errors import ConfigError

KINDS = ("ideal", "encoder", "noisy")
#: where an encoder sensor takes the pose from
POSE_SOURCES = ("odometry", "noisy")
#: sensor noise channels per step (standard normals): speed right, speed left, x, y, theta
NOISE_CHANNELS = ("speed_right", "speed_left", "x", "y", "theta")
#: the per-run sensor state (fields of the engine's run record)
SENSOR_FIELDS = [("wheel_angle", "f8", 2), ("count_prev", "f8", 2), ("w_filtered", "f8", 2), ("odometry", "f8", 3),
                 ("odometry_count", "f8", 2)]


class SensorParameters(NamedTuple):
    """The sensor as its laws take it (built by :meth:`Sensor.law_parameters`)."""

    ideal: bool  # the truth, untouched
    encoder: bool  # wheel speeds from quantised angles
    count: float  # q = 2 pi / N, the angle of one count [rad]
    period: float  # T, the control period [s]
    filtered: bool  # first-order low-pass on the encoder speed
    filter_a: float  # exp(-T / tau_f)
    odometry: bool  # pose by dead reckoning of the quantised wheels (encoder), else true pose + noise
    noisy: bool  # some std > 0: normals are drawn and used
    speed_std: float  # [rad/s]
    position_std: float  # [m], on x and y
    heading_std: float  # [rad]


@law
def quantise(angle, count):
    """An encoder's reading of ``angle`` [rad]: the nearest whole number of counts ``q``, ``q floor(angle/q + 1/2)``."""
    return count * math.floor(angle / count + 0.5)


@law
def encoder_speed(angle, angle_prev, period):
    """The finite difference of the quantised angle over one control period, ``(phi_q - phi_q,prev) / T`` [rad/s]."""
    return (angle - angle_prev) * (1.0 / period)


@law
def low_pass(y_prev, x, a):
    """First-order low-pass, exact for ``x`` held over the period: ``y = x + a (y_prev - x)``, ``a = exp(-T/tau)``."""
    return x + a * (y_prev - x)


@law
def odometry(x, y, theta, d_R, d_L, wheel_radius, half_track):
    """Dead reckoning of wheel increments ``d`` [rad] (the paper's (1) over one period, midpoint heading):
    ``ds = R (d_R + d_L) / 2``, ``dtheta = R (d_R - d_L) / (2 L)``, ``x += ds cos(theta + dtheta/2)``, ..."""
    ds = wheel_radius * 0.5 * (d_R + d_L)
    dth = (wheel_radius / (2.0 * half_track)) * (d_R - d_L)
    mid = theta + 0.5 * dth
    return x + ds * math.cos(mid), y + ds * math.sin(mid), theta + dth


@law
def wheel_angle(angle, w_before, w_after, dt):
    """The true wheel angle over one plant step, by the trapezoidal rule: ``phi + dt (w_k + w_k+1) / 2`` [rad]."""
    return angle + (0.5 * dt) * (w_before + w_after)


@law
def start(p, run, w0_R, w0_L):
    """Before the first reading: the wheel angles are 0; the speed estimate's previous reading is the angle one
    period earlier at the initial speed (the wheels were turning before t = 0, so the first speed estimate is
    ``w(0)`` to within a count), the filter starts at ``w(0)``; the odometry starts at the true initial pose and
    integrates the counts from the reading at t = 0 (0): the wheel turned by nothing before the run began for the
    pose, which is the true pose at t = 0."""
    run["wheel_angle"][0] = 0.0
    run["wheel_angle"][1] = 0.0
    run["count_prev"][0] = quantise(-w0_R * p.period, p.count)
    run["count_prev"][1] = quantise(-w0_L * p.period, p.count)
    run["odometry_count"][0] = 0.0
    run["odometry_count"][1] = 0.0
    run["w_filtered"][0] = w0_R
    run["w_filtered"][1] = w0_L
    run["odometry"][0] = run["x"]
    run["odometry"][1] = run["y"]
    run["odometry"][2] = run["theta"]


@law
def measure(p, run, x, y, theta, w_R, w_L, xi, wheel_radius, half_track):
    """One reading at a control instant: ``(w_R, w_L, x, y, theta)`` as measured (module docstring); ``xi`` are this
    instant's standard normals (:data:`NOISE_CHANNELS`), used when ``p.noisy``."""
    if p.ideal:
        return w_R, w_L, x, y, theta
    m_R, m_L, m_x, m_y, m_th = w_R, w_L, x, y, theta
    if p.encoder:
        q_R = quantise(run["wheel_angle"][0], p.count)
        q_L = quantise(run["wheel_angle"][1], p.count)
        m_R = encoder_speed(q_R, run["count_prev"][0], p.period)
        m_L = encoder_speed(q_L, run["count_prev"][1], p.period)
        if p.filtered:
            m_R = low_pass(run["w_filtered"][0], m_R, p.filter_a)
            m_L = low_pass(run["w_filtered"][1], m_L, p.filter_a)
            run["w_filtered"][0] = m_R
            run["w_filtered"][1] = m_L
        if p.odometry:
            m_x, m_y, m_th = odometry(run["odometry"][0], run["odometry"][1], run["odometry"][2],
                                      q_R - run["odometry_count"][0], q_L - run["odometry_count"][1], wheel_radius,
                                      half_track)
            run["odometry"][0] = m_x
            run["odometry"][1] = m_y
            run["odometry"][2] = m_th
            run["odometry_count"][0] = q_R
            run["odometry_count"][1] = q_L
        run["count_prev"][0] = q_R
        run["count_prev"][1] = q_L
    if p.noisy:
        m_R += p.speed_std * xi[0]
        m_L += p.speed_std * xi[1]
        if not (p.encoder and p.odometry):
            m_x += p.position_std * xi[2]
            m_y += p.position_std * xi[3]
            m_th += p.heading_std * xi[4]
    return m_R, m_L, m_x, m_y, m_th


class Sensor:
    """The wheel-speed and pose sensor (module docstring; docs/model.md §10).

    Parameters
    ----------
    kind : {'ideal', 'encoder', 'noisy'}
    counts_per_rev : int
        Encoder counts per wheel revolution N (``encoder``).
    speed_filter : float
        Time constant tau_f [s] of the low-pass on the encoder speed; 0: none.
    pose : {'odometry', 'noisy'}
        Where an ``encoder`` sensor takes the pose from: dead reckoning of the quantised wheels, or the true pose
        plus noise (``position_std``, ``heading_std``).
    speed_std, position_std, heading_std : float
        Standard deviations of the Gaussian noise on the wheel speeds [rad/s], on x and y [m] and on the heading
        [rad] (``noisy``; with ``encoder``, speed noise is added to the finite difference and pose noise used by
        ``pose=noisy``). Must be 0 for ``ideal``.
    """

    def __init__(self, *, kind: str, counts_per_rev: int, speed_filter: float, pose: str, speed_std: float,
                 position_std: float, heading_std: float) -> None:
        self.kind = one_of("sensor.kind", kind, KINDS)
        self.counts_per_rev = integer("sensor.counts_per_rev", counts_per_rev, 1)
        self.speed_filter = non_negative("sensor.speed_filter", speed_filter)
        self.pose = one_of("sensor.pose", pose, POSE_SOURCES)
        self.speed_std = non_negative("sensor.speed_std", speed_std)
        self.position_std = non_negative("sensor.position_std", position_std)
        self.heading_std = non_negative("sensor.heading_std", heading_std)
        if self.kind == "ideal":
            for key in ("speed_std", "position_std", "heading_std"):
                if getattr(self, key) > 0.0:
                    raise ConfigError(f"sensor.{key}", getattr(self, key),
                                      "must be 0 with sensor.kind=ideal (sensor=noisy adds noise)")

    @property
    def noisy(self) -> bool:
        """Whether the runs draw sensor noise (some std that the kind uses is above zero)."""
        if self.kind == "ideal":
            return False
        pose_noise = self.kind == "noisy" or self.pose == "noisy"
        return self.speed_std > 0.0 or (pose_noise and (self.position_std > 0.0 or self.heading_std > 0.0))

    def law_parameters(self, period: float) -> SensorParameters:
        """The parameters at control period ``period`` [s]."""
        encoder = self.kind == "encoder"
        filtered = encoder and self.speed_filter > 0.0
        return SensorParameters(
            ideal=self.kind == "ideal", encoder=encoder, count=2.0 * math.pi / self.counts_per_rev, period=float(period),
            filtered=filtered, filter_a=math.exp(-period / self.speed_filter) if filtered else 0.0,
            odometry=encoder and self.pose == "odometry", noisy=self.noisy, speed_std=self.speed_std,
            position_std=self.position_std, heading_std=self.heading_std)

    def describe(self) -> dict[str, object]:
        """The settings that matter for this kind (for summaries)."""
        if self.kind == "ideal":
            return {"kind": "ideal"}
        if self.kind == "noisy":
            return {"kind": "noisy", "speed_std": self.speed_std, "position_std": self.position_std,
                    "heading_std": self.heading_std}
        return {"kind": "encoder", "counts_per_rev": self.counts_per_rev, "speed_filter": self.speed_filter,
                "pose": self.pose, "speed_std": self.speed_std}


__all__ = ["Sensor", "SensorParameters", "KINDS", "POSE_SOURCES", "NOISE_CHANNELS", "SENSOR_FIELDS", "quantise",
           "encoder_speed", "low_pass", "odometry", "wheel_angle", "start", "measure"]
