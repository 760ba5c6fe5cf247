"""Kinematics (docs/model.md §2): the pure functions, and constant wheel speeds driven through the engine.

Closed forms used here:

* forward kinematics (1): ``v = R (wR + wL) / 2``, ``omega = R (wR - wL) / (2 L)``;
* constant equal wheel speeds: a straight line at ``v = R w`` along the initial heading;
* constant unequal wheel speeds: a circle of radius ``r = L (wR + wL) / (wR - wL)`` whose centre is at distance
  ``r`` to the left of the start pose, travelled at ``omega = v / r``.

To hold the wheel speeds constant inside the engine, the open-loop voltage ``u`` is applied with the wheels
started at the plant's steady state ``w_ss = K_u u / B`` on terrain without any disturbance (roughness 0, mu 0):
then ``J w' = K_u u - B w = 0`` and the wheels never change speed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from paper import make_robot, make_simulation, make_terrain
from ddmr_cli import OpenLoop, Robot, Simulation, Terrain, TerrainZone, simulate
from ddmr_cli.model import kinematics

ROBOT = make_robot()
R, L = ROBOT.wheel_radius, ROBOT.half_track
QUIET = make_terrain(TerrainZone("quiet", 0.0, 0.0, 0.0))


# --------------------------------------------------------------------------------------------------------------
# pure functions
# --------------------------------------------------------------------------------------------------------------


def test_forward_matches_paper_eq_1():
    v, omega = kinematics.forward(40.0, 20.0, 0.03, 0.25)
    assert v == pytest.approx(0.03 * 60.0 / 2.0, rel=1e-15)  # 0.9 m/s
    assert omega == pytest.approx(0.03 * 20.0 / 0.5, rel=1e-15)  # 1.2 rad/s


def test_forward_vectorised_over_runs():
    wr, wl = np.array([10.0, 0.0, -5.0]), np.array([10.0, 4.0, 5.0])
    v, omega = kinematics.forward(wr, wl, R, L)
    np.testing.assert_allclose(v, [10.0 * R, 2.0 * R, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(omega, [0.0, -4.0 * R / (2 * L), -10.0 * R / (2 * L)], rtol=1e-14)


def test_inverse_matches_paper_eq_4_5():
    wr, wl = kinematics.inverse(1.0, 2.0, 0.03, 0.25)
    assert wr == pytest.approx((1.0 + 0.25 * 2.0) / 0.03, rel=1e-15)  # 50 rad/s
    assert wl == pytest.approx((1.0 - 0.25 * 2.0) / 0.03, rel=1e-15)  # 16.67 rad/s


def test_the_plain_law_set_up_code_calls_agrees_with_the_compiled_one():
    """Set-up and validation call ``plain(inverse)`` (no compilation per process); the step loop runs the compiled
    law. Both must give the wheel speeds the same numbers, to 1 ulp (compiled, numba may fuse ``L omega + v`` into
    an FMA, which rounds once less; on these draws the two are bit-equal on the AVX-512 development machine)."""
    from ddmr_cli.compiled import jit_enabled, plain

    rng = np.random.default_rng(7)
    for v, omega, radius, half_track in zip(rng.uniform(-3, 3, 200), rng.uniform(-5, 5, 200),
                                            rng.uniform(0.01, 0.2, 200), rng.uniform(0.05, 0.5, 200)):
        compiled = kinematics.inverse(v, omega, radius, half_track)
        python = plain(kinematics.inverse)(v, omega, radius, half_track)
        np.testing.assert_array_max_ulp(np.array(python), np.array(compiled), maxulp=1)
    if jit_enabled():
        assert plain(kinematics.inverse) is kinematics.inverse.py_func


def test_inverse_then_forward_roundtrip():
    v, omega = kinematics.forward(*kinematics.inverse(0.7, -0.4, R, L), R, L)
    assert v == pytest.approx(0.7, rel=1e-14)
    assert omega == pytest.approx(-0.4, rel=1e-14)


def test_circle_radius_closed_form():
    assert kinematics.circle_radius(30.0, 10.0, 0.25) == pytest.approx(0.25 * 40.0 / 20.0, rel=1e-15)
    # turning right (wR < wL) gives a negative (clockwise) radius; spinning on the spot gives 0
    assert kinematics.circle_radius(10.0, 30.0, 0.25) == pytest.approx(-0.5, rel=1e-15)
    assert kinematics.circle_radius(5.0, -5.0, 0.25) == 0.0
    # the radius is v / omega of the forward kinematics
    v, omega = kinematics.forward(31.0, 17.0, R, L)
    assert kinematics.circle_radius(31.0, 17.0, L) == pytest.approx(v / omega, rel=1e-14)


def test_pose_error_in_robot_frame():
    # robot at (1, 0) facing +y: a reference 2 m ahead (at (1, 2)) is pure longitudinal error;
    # a reference at (0, 0) is 1 m to the robot's left (-x is on the left when facing +y)
    e_x, e_y, e_th = kinematics.pose_error(1.0, 0.0, math.pi / 2, 1.0, 2.0, math.pi / 2)
    assert (e_x, e_y, e_th) == (pytest.approx(2.0), pytest.approx(0.0, abs=1e-15), pytest.approx(0.0))
    e_x, e_y, e_th = kinematics.pose_error(1.0, 0.0, math.pi / 2, 0.0, 0.0, 0.0)
    assert e_x == pytest.approx(0.0, abs=1e-15)
    assert e_y == pytest.approx(1.0)  # -x is to the left of a robot facing +y: positive lateral error
    assert e_th == pytest.approx(-math.pi / 2)


def test_pose_error_heading_is_wrapped():
    _, _, e_th = kinematics.pose_error(0.0, 0.0, -3.0, 0.0, 0.0, 3.0)  # 6 rad apart = -0.283 rad
    assert e_th == pytest.approx(6.0 - 2 * math.pi, abs=1e-14)


def test_wrap_angle_examples():
    assert kinematics.wrap_angle(0.0) == 0.0
    assert kinematics.wrap_angle(math.pi) == pytest.approx(math.pi)
    assert kinematics.wrap_angle(-math.pi) == pytest.approx(math.pi)  # (-pi, pi]: -pi maps to +pi
    assert kinematics.wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert kinematics.wrap_angle(-7.0) == pytest.approx(-7.0 + 2 * math.pi)
    np.testing.assert_allclose(np.vectorize(kinematics.wrap_angle)(np.array([0.5, 2 * math.pi + 0.5, -2 * math.pi + 0.5])),
                               0.5, atol=1e-14)


# --------------------------------------------------------------------------------------------------------------
# constant wheel speeds through the engine
# --------------------------------------------------------------------------------------------------------------


def steady_wheel_speeds(u):
    """w_ss = K_u u / B: the plant's equilibrium for a constant voltage (J w' = K_u u - B w)."""
    return ROBOT.voltage_gain * np.asarray(u, dtype=float) / ROBOT.damping


def drive(u, integrator, dt, duration, initial_pose=(0.0, 0.0, 0.0)):
    sim = make_simulation(controller=OpenLoop(list(u)), robot=ROBOT, terrain=QUIET, dt=dt, duration=duration,
                     integrator=integrator, initial_pose=initial_pose,
                     initial_wheel_speeds=tuple(steady_wheel_speeds(u)), divergence_bound=1e9)
    res = simulate(sim, seeds=[0], keep_series=[0])
    assert not res.diverged[0]
    return res.series[0]


@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_equal_wheel_speeds_drive_straight_line(integrator):
    u, th0 = 8.0, 0.3
    w = steady_wheel_speeds(u)
    v = R * w  # closed form: v = R w
    s = drive((u, u), integrator, dt=1e-3, duration=1.0, initial_pose=(0.5, -0.2, th0))
    # the wheels really are held at the steady state
    np.testing.assert_allclose(s["w_right"], w, rtol=1e-12)
    np.testing.assert_allclose(s["w_left"], w, rtol=1e-12)
    t = s["t"]
    # a straight line is integrated exactly by both schemes (constant velocity): only rounding remains
    np.testing.assert_allclose(s["x"], 0.5 + v * t * math.cos(th0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["y"], -0.2 + v * t * math.sin(th0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["theta"], th0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(s["distance"], v * t, rtol=0, atol=1e-12)


def _circle_case():
    u = (10.0, 6.0)
    w_r, w_l = steady_wheel_speeds(u)
    r = L * (w_r + w_l) / (w_r - w_l)  # closed form: 0.25 * 16 / 4 = 1 m
    v = R * (w_r + w_l) / 2.0
    return u, r, v, v / r


def test_circle_case_closed_form_numbers():
    _, r, v, omega = _circle_case()
    assert r == pytest.approx(1.0, rel=1e-12)  # L (uR + uL) / (uR - uL) since w is proportional to u
    assert omega == pytest.approx(R * (10.0 - 6.0) * ROBOT.voltage_gain / ROBOT.damping / (2 * L), rel=1e-12)


def _fit_circle(x, y):
    """Algebraic least-squares circle fit (Kasa): returns centre (a, b) and radius."""
    M = np.column_stack([x, y, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(M, x**2 + y**2, rcond=None)
    a, b = sol[0] / 2.0, sol[1] / 2.0
    return a, b, math.sqrt(sol[2] + a * a + b * b)


def test_unequal_wheel_speeds_drive_circle_rk4():
    u, r, v, omega = _circle_case()
    dt = 1e-3
    s = drive(u, "rk4", dt=dt, duration=3.0)
    # closed form from (0, 0, 0) turning left: centre (0, r), x = r sin(omega t), y = r (1 - cos(omega t))
    dist_from_centre = np.hypot(s["x"] - 0.0, s["y"] - r)
    assert np.max(np.abs(dist_from_centre - r)) < 1e-10
    t = s["t"]
    np.testing.assert_allclose(s["theta"], omega * t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(s["x"], r * np.sin(omega * t), rtol=0, atol=1e-10)
    np.testing.assert_allclose(s["y"], r * (1.0 - np.cos(omega * t)), rtol=0, atol=1e-10)
    a, b, r_fit = _fit_circle(s["x"], s["y"])
    assert r_fit == pytest.approx(r, abs=1e-10)
    assert (a, b) == (pytest.approx(0.0, abs=1e-10), pytest.approx(r, abs=1e-10))


def test_unequal_wheel_speeds_drive_circle_euler():
    """Explicit Euler on the unicycle with constant (v, omega).

    theta_k = omega k dt exactly, and the positions are the vertices of a regular polygon with side ``v dt`` and
    exterior angle ``omega dt``: they lie on a circle of radius ``rho = v dt / (2 sin(omega dt / 2))`` (so
    ``rho - r ~ r (omega dt)^2 / 24``) whose centre ``(v dt / 2, rho cos(omega dt / 2))`` is displaced by
    ``v dt / 2`` from the true centre. Bound used against the continuous closed form: every point is within
    ``v dt`` (one step of arc, i.e. the O(dt) Euler drift) of the true circle.
    """
    u, r, v, omega = _circle_case()
    dt = 1e-3
    s = drive(u, "euler", dt=dt, duration=3.0)
    t = s["t"]
    np.testing.assert_allclose(s["theta"], omega * t, rtol=0, atol=1e-12)
    # O(dt) bound against the continuous circle
    dist_from_centre = np.hypot(s["x"], s["y"] - r)
    err = np.max(np.abs(dist_from_centre - r))
    assert err <= v * dt
    # and it is really Euler (a first-order method would not be this close to the exact circle otherwise)
    assert err > 1e-2 * v * dt
    # the Euler polygon's own closed form
    half = omega * dt / 2.0
    rho = v * dt / (2.0 * math.sin(half))
    centre = (v * dt / 2.0, rho * math.cos(half))
    np.testing.assert_allclose(np.hypot(s["x"] - centre[0], s["y"] - centre[1]), rho, rtol=0, atol=1e-10)
    _, _, r_fit = _fit_circle(s["x"], s["y"])
    assert r_fit == pytest.approx(rho, abs=1e-9)
    assert abs(r_fit - r) <= 1.01 * r * (omega * dt) ** 2 / 24.0 + 1e-9
