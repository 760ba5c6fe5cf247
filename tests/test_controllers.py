"""Wheel controllers and observers (docs/model.md §6) in closed loop, against closed forms.

Constant disturbance used throughout: a single zone with roughness 0 and rolling resistance mu > 0 gives, while
both wheels turn forward, ``d = -J^-1 mu m g R / 2 [1, 1] = -mu m g R / (2 (J11 + J12)) [1, 1]`` (docs/model.md §5).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from paper import make_smc, make_pid, make_rbf, make_robot, make_simulation, make_terrain
from ddmr_cli import (PID, SMC, NonlinearDisturbanceObserver, RBFNetworkObserver, Robot, Simulation, Terrain,
                      TerrainZone, paper_terrain, simulate)
from ddmr_cli.model.robot import GRAVITY

ROBOT = make_robot()
MU = 0.05
CONSTANT_D = make_terrain(TerrainZone("sand", 0.0, 0.0, MU))
QUIET = make_terrain(TerrainZone("quiet", 0.0, 0.0, 0.0))
J = ROBOT.inertia_matrix
D = -MU * ROBOT.mass * GRAVITY * ROBOT.wheel_radius / 2.0 / (J[0, 0] + J[0, 1])  # ~ -7.745 rad/s^2


def run(controller, terrain, duration, dt=1e-3, integrator="euler", initial_pose=(0.0, 0.0, 0.0),
        initial_wheel_speeds="reference", seeds=(0,), keep=(0,), robot=ROBOT):
    sim = make_simulation(controller=controller, robot=robot, terrain=terrain, dt=dt, duration=duration,
                     integrator=integrator, initial_pose=initial_pose, initial_wheel_speeds=initial_wheel_speeds,
                     divergence_bound=1e9)
    return simulate(sim, seeds=list(seeds), keep_series=list(keep))


# --------------------------------------------------------------------------------------------------------------
# NDO: estimation error decays at rate L
# --------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("gain", [50.0, 20.0])
def test_ndo_error_decays_like_exp_minus_L_t(gain):
    """Paper (20): d_tilde' = -L d_tilde for a constant d. The NDO is an Euler discretisation, so with the
    Euler plant the discrete error is exactly d_tilde_k = (1 - L dt)^k d_tilde_0, with d_tilde_0 = d
    (z(0) = -L w(0) gives d_hat(0) = 0). Against the continuous exp(-L t): |(1 - h)^k - e^{-kh}| <= h / (2e)."""
    dt = 1e-3
    res = run(make_smc(ndo=NonlinearDisturbanceObserver(gain)), CONSTANT_D, duration=0.3, dt=dt)
    s = res.series[0]
    assert np.all(s["w_right"] > 0) and np.all(s["w_left"] > 0)  # turning forward: d is constant
    for wheel in ("right", "left"):
        d_true, d_hat = s[f"d_true_{wheel}"], s[f"d_hat_ndo_{wheel}"]
        np.testing.assert_allclose(d_true, D, rtol=1e-10)
        assert d_hat[0] == 0.0
        err = d_true - d_hat
        for k in (1, 10, 40, 100, 200, 299):
            assert err[k] == pytest.approx(D * (1.0 - gain * dt) ** k, rel=1e-8, abs=1e-10)
            assert abs(err[k] - D * math.exp(-gain * k * dt)) <= abs(D) * gain * dt / (2 * math.e) * 1.05
        # and the estimate really converged to the disturbance (the test would catch a wrong sign or rate)
        assert abs(err[-1]) < abs(D) * math.exp(-gain * 0.29)


def test_ndo_rate_differs_between_gains():
    """The rate really is the configured L: at t = 50 ms the error ratio between L = 50 and L = 20 is
    (0.95 / 0.98)^50."""
    errs = {}
    for gain in (50.0, 20.0):
        s = run(make_smc(ndo=NonlinearDisturbanceObserver(gain)), CONSTANT_D, duration=0.06).series[0]
        errs[gain] = s["d_true_right"][50] - s["d_hat_ndo_right"][50]
    assert errs[50.0] / errs[20.0] == pytest.approx((0.95 / 0.98) ** 50, rel=1e-8)


def test_ndo_rk4_plant_still_decays_like_exp():
    """With the RK4 plant the observer's Euler step no longer matches the plant's step exactly.

    The error then obeys d_tilde_{k+1} = (1 - L dt) d_tilde_k + L delta_k, where delta_k = (RK4 increment of w) -
    (Euler increment) = O(dt^2 |A| |w'| / 2). Summed over the decay this adds at most dt |A| max|w'| / 2 to the
    Euler observer's own O(dt) deviation from exp(-L t), which is at most |d| L dt / (2 e)."""
    gain, dt = 50.0, 1e-3
    s = run(make_smc(ndo=NonlinearDisturbanceObserver(gain)), CONSTANT_D, duration=0.15, dt=dt,
            integrator="rk4").series[0]
    err = s["d_true_right"] - s["d_hat_ndo_right"]
    t = s["t"]
    w = np.column_stack([s["w_right"], s["w_left"]])
    max_w_dot = np.max(np.abs(np.diff(w, axis=0))) / dt
    norm_A = np.linalg.norm(ROBOT.drift_matrix, 2)
    bound = abs(D) * gain * dt / (2 * math.e) + dt * norm_A * max_w_dot / 2
    assert np.max(np.abs(err - D * np.exp(-gain * t))) <= 1.05 * bound
    assert abs(err[-1]) < abs(D) * math.exp(-gain * 0.14)


# --------------------------------------------------------------------------------------------------------------
# RBF network: the sign of the update law (25)
# --------------------------------------------------------------------------------------------------------------


def test_smc_alone_steady_error_closed_form():
    """SMC without observers: s' = -lambda s - K sat(s/Phi) - d. Inside the boundary layer the steady state is
    s = -d / (lambda + K / Phi) = 7.745 / 145 = 0.0534 rad/s (< Phi = 0.1, so inside)."""
    s = run(make_smc(), CONSTANT_D, duration=1.0).series[0]
    expected = -D / (25.0 + 12.0 / 0.1)
    assert 0 < expected < 0.1
    np.testing.assert_allclose(s["s_right"][-200:], expected, rtol=1e-4)
    np.testing.assert_allclose(s["s_left"][-200:], expected, rtol=1e-4)


def test_nn_observer_reduces_steady_error():
    """NDO off, constant d: SMC + RBF network ends with a much smaller |s| than SMC alone.

    With W' = -gamma Phi s^T, d_hat_NN' = -gamma |Phi|^2 s acts as an integral action that drives d_hat_NN to d;
    the wrong sign would make it run away from d and increase |s|. The learning rate is raised to 2000 (with
    width 2, |Phi|^2 ~ 0.085 at 33 rad/s) so the adaptation settles within the short run."""
    duration = 2.5
    plain = run(make_smc(), CONSTANT_D, duration=duration).series[0]
    nn = run(make_smc(nn=make_rbf(n_neurons=10, width=2.0, learning_rate=2000.0)), CONSTANT_D,
             duration=duration).series[0]
    late = slice(-500, None)
    for wheel in ("right", "left"):
        s_plain = np.mean(np.abs(plain[f"s_{wheel}"][late]))
        s_nn = np.mean(np.abs(nn[f"s_{wheel}"][late]))
        assert s_nn < 0.2 * s_plain
        # the network's estimate moved towards the true disturbance (same sign, most of it)
        assert nn[f"d_hat_nn_{wheel}"][-1] == pytest.approx(D, rel=0.1)
        assert f"d_hat_nn_{wheel}" not in plain  # a controller without a network records no NN channel


def test_nn_observer_with_default_gains_moves_the_right_way():
    """Default (Table 3) reading: slower, but d_hat_NN already has the sign of d and |s| shrinks over time."""
    s = run(make_smc(nn=make_rbf()), CONSTANT_D, duration=1.5).series[0]
    assert s["d_hat_nn_right"][-1] < 0 and s["d_hat_nn_left"][-1] < 0  # d < 0
    assert np.mean(np.abs(s["s_right"][-200:])) < np.mean(np.abs(s["s_right"][300:500]))


# --------------------------------------------------------------------------------------------------------------
# zero disturbance, zero initial error
# --------------------------------------------------------------------------------------------------------------

ZERO_ERROR_CONTROLLERS = {
    "smc": lambda: make_smc(),
    "smc_ndo": lambda: make_smc(ndo=NonlinearDisturbanceObserver(50.0)),
    "smc_ndo_nno": lambda: make_smc(ndo=NonlinearDisturbanceObserver(50.0), nn=make_rbf()),
    "smc_integral": lambda: make_smc(surface="integral", ndo=NonlinearDisturbanceObserver(50.0)),
}


@pytest.mark.parametrize("name", sorted(ZERO_ERROR_CONTROLLERS))
def test_zero_disturbance_zero_error_stays_zero(name):
    """On the reference line (0, 0, 0) with the reference wheel speeds and no disturbance, the equivalent
    control u = g^-1 (-f(w)) holds w' = 0 exactly: every error stays at rounding level."""
    res = run(ZERO_ERROR_CONTROLLERS[name](), QUIET, duration=1.0)
    s = res.series[0]
    for ch in ("e_x", "e_y", "e_theta", "deviation"):
        assert np.max(np.abs(s[ch])) < 1e-12, ch
    w_ref = 1.0 / ROBOT.wheel_radius
    for wheel in ("right", "left"):
        assert np.max(np.abs(s[f"s_{wheel}"])) < 1e-12 * w_ref
        assert np.max(np.abs(s[f"w_{wheel}"] - w_ref)) < 1e-12 * w_ref
        for channel in (k for k in s if k.startswith("d_hat_") and k.endswith(wheel)):  # each estimate of d
            assert np.max(np.abs(s[channel])) < 1e-9, channel
        # the voltage is the steady-state one, B w / K_u, all the time
        np.testing.assert_allclose(s[f"u_{wheel}"], ROBOT.damping * w_ref / ROBOT.voltage_gain, rtol=1e-12)
    assert res.metric("deviation_max")[0] < 1e-12


def test_pid_drifts_at_zero_error():
    """PID is exempt: it has no feed-forward, so at zero error it applies exactly 0 V, the wheels slow down
    (w' = -A w) and the robot falls behind the reference; the loop then needs a non-zero error to hold speed."""
    res = run(make_pid(), QUIET, duration=0.5)
    s = res.series[0]
    assert s["u_right"][0] == 0.0 and s["u_left"][0] == 0.0
    # first step: w_1 = w_0 - dt A w_0 (Euler, u = 0)
    w0 = np.full(2, 1.0 / ROBOT.wheel_radius)
    np.testing.assert_allclose([s["w_right"][1], s["w_left"][1]], w0 - 1e-3 * ROBOT.drift_matrix @ w0, rtol=1e-12)
    assert res.metric("deviation_final")[0] > 1e-3
    assert np.max(np.abs(s["s_right"])) > 1.0


# --------------------------------------------------------------------------------------------------------------
# saturation
# --------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("make", [
    lambda: make_smc(lam=200.0, switching_gain=100.0, ndo=NonlinearDisturbanceObserver(50.0)),
    lambda: make_pid(kp=20.0, ki=10.0, kd=0.01),
], ids=["smc_big_gains", "pid_big_gains"])
def test_applied_voltage_never_exceeds_u_max(make):
    """Harsh case: from rest, big gains, very rough terrain. The command exceeds U_max, the applied u never."""
    ctrl = make()
    terrain = make_terrain(TerrainZone("very_rough", 0.0, 100.0, 0.10))
    res = run(ctrl, terrain, duration=0.4, initial_pose=(0.0, 0.05, 0.05), initial_wheel_speeds="rest",
              seeds=[0, 1, 2], keep=[0, 1, 2])
    u_max = ROBOT.max_voltage
    for seed in (0, 1, 2):
        s = res.series[seed]
        assert np.max(np.abs(np.concatenate([s["u_command_right"], s["u_command_left"]]))) > 2 * u_max
        u = np.concatenate([s["u_right"], s["u_left"]])
        assert np.max(np.abs(u)) <= u_max
        assert np.max(np.abs(u)) == u_max  # it does saturate, exactly at the rail
    frac = res.metric("saturation_fraction")
    assert np.all(frac > 0) and np.all(frac <= 1)
    # the saturation fraction is the fraction of steps with a wheel at the rail
    s = res.series[0]
    at_rail = (np.abs(s["u_right"]) == u_max) | (np.abs(s["u_left"]) == u_max)
    assert frac[0] == pytest.approx(np.mean(at_rail), abs=1.5 / len(at_rail))


def test_smaller_supply_voltage_is_respected():
    robot = make_robot(max_voltage=12.0)
    res = run(make_smc(), paper_terrain(), duration=0.2, initial_wheel_speeds="rest", robot=robot)
    u = np.concatenate([res.series[0]["u_right"], res.series[0]["u_left"]])
    assert np.max(np.abs(res.series[0]["u_command_right"])) > 12.0
    assert np.max(np.abs(u)) == 12.0


def test_ndo_is_fed_the_applied_voltage():
    """docs/model.md §6: the NDO uses the applied (saturated) u. Under saturation from rest with a constant d, the
    Euler estimation error still obeys d_tilde_k = (1 - L dt)^k d exactly; fed with the unsaturated command it
    would not."""
    gain, dt = 50.0, 1e-3
    ctrl = make_smc(lam=200.0, switching_gain=100.0, ndo=NonlinearDisturbanceObserver(gain))
    # start slowly rolling forward so that sign(w) = +1 and the rolling resistance is constant
    res = run(ctrl, CONSTANT_D, duration=0.1, dt=dt, initial_wheel_speeds=(1.0, 1.0))
    s = res.series[0]
    assert np.max(s["u_command_right"]) > ROBOT.max_voltage and res.metric("saturation_fraction")[0] > 0
    assert np.all(s["w_right"] > 0) and np.all(s["w_left"] > 0)
    err = s["d_true_right"] - s["d_hat_ndo_right"]
    k = np.arange(len(err))
    np.testing.assert_allclose(err, D * (1.0 - gain * dt) ** k, rtol=1e-7, atol=1e-9)


def test_each_controller_declares_the_estimators_it_reports():
    """What the report's estimation table rests on: a controller without an estimator reports d-hat = 0, so its
    'estimation MAE' would be the mean |d| (issue 25: it was printed for PID and SMC)."""
    from ddmr_cli import paper_controller

    expected = {"pid": (), "smc": (), "sta": (), "adaptive_smc": (), "smc_ndo": ("NDO",), "sta_ndo": ("NDO",),
                "adaptive_smc_ndo": ("NDO",), "smc_ndo_nno": ("NDO", "NN"), "smc_nno": ("NN",), "adrc": ("ESO",)}
    assert {name: paper_controller(name).estimators() for name in expected} == expected
