"""Differential-drive kinematics (docs/model.md §2; the paper's (1)-(5)).

Each function is a law on scalars: the engine runs these very definitions, compiled. :func:`frame_error` takes the
heading's cosine and sine: the run-at-a-time loop gets them from libm (:func:`pose_error`), the loop over blocks of
runs (:mod:`ddmr_cli.engine.lanes`) from :func:`~ddmr_cli.model.elementary.sincos` (fdlibm's kernels, within 1 ulp
of libm's: arithmetic LLVM vectorises, where a call of libm's keeps a loop one run at a time; one at a time, libm's
is faster).
"""

from __future__ import annotations

import math

from ddmr_cli.compiled import law


@law
def wrap_in_range(angle):
    """:func:`wrap_angle`'s fast path: ``(wrapped, True)`` for an angle it wraps without a modulo (``pi - angle`` in
    ``[0, 2 pi)``: the angle within a rounding of ``(-pi, pi]``), else ``(anything, False)``. Branch-free (a loop over
    runs vectorises it, :mod:`ddmr_cli.engine.lanes`)."""
    turned = math.pi - angle
    wrapped = math.pi - turned
    # pi - turned can round to exactly -pi: map it to pi
    return wrapped + 2.0 * math.pi if wrapped <= -math.pi else wrapped, 0.0 <= turned < 2.0 * math.pi


@law
def wrap_angle(angle):
    """Wrap an angle into (-pi, pi] (docs/model.md §2)."""
    wrapped, inside = wrap_in_range(angle)
    if inside:  # x % 2 pi is x itself for x in [0, 2 pi): the (slow, out-of-line) floating modulo only outside
        return wrapped
    wrapped = math.pi - (math.pi - angle) % (2.0 * math.pi)
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
def frame_error(x, y, cos_theta, sin_theta, x_ref, y_ref):
    """The position error in the robot frame, (2)'s first two rows: ``e_x = cos th dx + sin th dy``,
    ``e_y = cos th dy - sin th dx`` for ``(dx, dy) = (x_ref - x, y_ref - y)`` [m]."""
    dx, dy = x_ref - x, y_ref - y
    return cos_theta * dx + sin_theta * dy, cos_theta * dy - sin_theta * dx


@law
def pose_error(x, y, theta, x_ref, y_ref, theta_ref):
    """Tracking error expressed in the robot frame (docs/model.md §2; Kanayama et al. 1990): :func:`frame_error`
    and the heading error ``theta_ref - theta`` wrapped.

    Returns
    -------
    e_x, e_y, e_theta : longitudinal [m], lateral [m] and heading [rad] error, e_theta wrapped.
    """
    e_x, e_y = frame_error(x, y, math.cos(theta), math.sin(theta), x_ref, y_ref)
    return e_x, e_y, wrap_angle(theta_ref - theta)


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
