"""Linear ADRC with an extended state observer (ddmr_cli/control/adrc.py; docs/model.md §6, "ADRC")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine_checks import assert_seed_alone_equals_seed_in_batch, assert_zero_error_stays_zero
from paper import make_simulation, make_terrain
from wheel_loop import wheel_loop
from ddmr_cli import ADRC, ConfigError, NominalModel, TerrainZone, paper_controller, paper_robot, simulate
from ddmr_cli.model.robot import GRAVITY

ROBOT = paper_robot()
NOMINAL = NominalModel.from_robot(ROBOT)
W_REF = 1.0 / ROBOT.wheel_radius
DT = 1e-3
F = -7.745  # a constant total disturbance [rad/s^2]


@pytest.fixture(scope="module")
def adrc():
    return paper_controller("adrc")


@pytest.fixture(scope="module")
def eso_run(adrc):
    """The plant the ESO assumes, w' = b0 u + F per wheel with F constant, under the ADRC's own (saturated) u."""
    b0 = adrc.input_gain(NOMINAL)
    return wheel_loop(adrc, NOMINAL, lambda t, w_R, w_L, u_R, u_L: (b0 * u_R + F, b0 * u_L + F),
                      (W_REF, W_REF), (W_REF + 2.0, W_REF + 2.0), 0.1, dt=DT, state=("z1", "z2"))


def test_eso_error_is_the_double_pole_response(adrc, eso_run):
    """With F constant, e1 = w - z1 and e2 = F - z2 obey e_k+1 = M e_k, M = [[1 - 2 w_o dt, dt], [-w_o^2 dt, 1]] (whatever u: plant and ESO get the same u). M = lambda I + N with lambda = 1 - w_o dt and N nilpotent, so
    e2_k = e2_0 lambda^(k-1) (lambda + k w_o dt) and e1_k = e2_0 k dt lambda^(k-1) (e1_0 = 0): exactly the
    sampled double pole (checked to 1e-9 relative); against the continuous e2_0 e^(-w_o t)(1 + w_o t) the
    difference is O(w_o dt) (below 0.07 |e2_0| at w_o dt = 0.25)."""
    w_o = adrc.observer_bandwidth
    lam = 1.0 - w_o * DT
    # state after the update of step k is z_{k+1}; z_0 from start: e1_0 = 0, e2_0 = F - z2(0)
    w, z1, z2 = eso_run["w"][:, 0], eso_run["z1"][:, 0], eso_run["z2"][:, 0]
    w_next = np.append(w[1:], np.nan)
    e1, e2 = (w_next - z1)[:-1], (F - z2)[:-1]  # e_{k+1}, k = 0 .. n-2
    k = np.arange(1, len(e2) + 1)
    e2_0 = e2[0]  # e2_1 = e2_0: with e1_0 = 0 the first step leaves e2 unchanged
    assert abs(e2_0) > 100.0  # the ESO does start far off (its nominal z2(0) is not this plant's F)
    np.testing.assert_allclose(e2, e2_0 * lam ** (k - 1) * (lam + k * w_o * DT), rtol=1e-9, atol=1e-9 * abs(e2_0))
    np.testing.assert_allclose(e1, e2_0 * k * DT * lam ** (k - 1), rtol=1e-9, atol=1e-12 * abs(e2_0))
    t = k * DT
    continuous = e2_0 * np.exp(-w_o * t) * (1.0 + w_o * t)
    assert np.max(np.abs(e2 - continuous)) < 0.07 * abs(e2_0)
    assert abs(e2[-1]) < 1e-6 * abs(e2_0)  # and it did converge


def test_with_the_estimate_converged_the_speed_error_decays_at_w_c(adrc, eso_run):
    """Once z2 = F, the loop is w' = w_c (w_d - w) (separation holds exactly for the sampled loop: the error
    dynamics are triangular): from 40 ms on, e_k+1 = (1 - w_c dt) e_k to 1e-6 relative."""
    e = (W_REF + 2.0) - eso_run["w"][:, 0]
    k0 = 40
    ratio = e[k0 + 1:] / e[k0:-1]
    np.testing.assert_allclose(ratio[50:], 1.0 - adrc.bandwidth * DT, rtol=1e-6)


def test_eso_estimate_of_d_converges_in_the_robot_loop(adrc):
    """On the engine's robot with a constant rolling resistance (d = -mu m g R / (2 (J11 + J12)) per wheel,
    both wheels forward), the reported estimate z2 - (f(w) + (g - b0) u) converges to d, and the speed error to 0
    (the ESO's z2 acts as an integral)."""
    mu = 0.05
    J = ROBOT.inertia_matrix
    d = -mu * ROBOT.mass * GRAVITY * ROBOT.wheel_radius / 2.0 / (J[0, 0] + J[0, 1])
    sim = make_simulation(controller=adrc, terrain=make_terrain(TerrainZone("sand", 0.0, 0.0, mu)), duration=0.5,
                          initial_pose=(0.0, 0.0, 0.0))
    s = simulate(sim, [0], keep_series=[0]).series[0]
    for wheel in ("right", "left"):
        np.testing.assert_allclose(s[f"d_true_{wheel}"], d, rtol=1e-10)
        assert abs(s[f"d_hat_eso_{wheel}"][0]) < 1e-9  # no kick at the rolling start
        np.testing.assert_allclose(s[f"d_hat_eso_{wheel}"][-100:], d, rtol=1e-4)
        assert np.max(np.abs(s[f"s_{wheel}"][-100:])) < 1e-5 < np.max(np.abs(s[f"s_{wheel}"]))


def test_the_estimate_of_d_is_taken_under_the_applied_voltage_while_saturated(adrc):
    """With U_max = 11 V the cruise (about 11 V plus the rolling resistance's share) saturates for the whole run:
    the ESO, fed the applied u, still converges, so the reported z2 - (f(w) + (g - b0) u) with u the *applied*
    voltage converges to d. Taken with the command before the limit (the old code) it was off by
    (g - b0) (u_c - u), several times d."""
    mu = 0.05
    J = ROBOT.inertia_matrix
    d = -mu * ROBOT.mass * GRAVITY * ROBOT.wheel_radius / 2.0 / (J[0, 0] + J[0, 1])
    sim = make_simulation(controller=adrc, terrain=make_terrain(TerrainZone("sand", 0.0, 0.0, mu)), duration=0.5,
                          initial_pose=(0.0, 0.0, 0.0), robot=paper_robot("robot.max_voltage=11.0"))
    s = simulate(sim, [0], keep_series=[0]).series[0]
    for wheel in ("right", "left"):
        late = slice(-100, None)
        assert np.all(np.abs(s[f"u_command_{wheel}"][late]) > 11.0)  # saturated to the end
        np.testing.assert_allclose(s[f"d_hat_eso_{wheel}"][late], d, rtol=1e-3)


def test_zero_disturbance_and_zero_initial_error_keep_every_error_at_zero(adrc):
    assert_zero_error_stays_zero(adrc)


def test_seed_alone_equals_seed_in_batch(adrc):
    assert_seed_alone_equals_seed_in_batch(adrc)


def test_eso_step_bound_holds_for_rk4_too():
    """The ESO is Euler whatever the plant's integrator: w_o dt < 2 is required even with rk4 (limit 2.78)."""
    adrc = ADRC(bandwidth=50.0, observer_bandwidth=2100.0)
    adrc.check_step(NOMINAL, 0.0009, "rk4")  # 1.89 < 2
    with pytest.raises(ConfigError, match=r"simulation\.dt=0\.001: must be < 0\.000952 s for the Euler ESO"):
        adrc.check_step(NOMINAL, 0.001, "rk4")  # 2.1


@pytest.mark.parametrize("key", ["bandwidth", "observer_bandwidth"])
def test_bad_bandwidth_is_refused_naming_the_key(key):
    with pytest.raises(ConfigError, match=rf"controller\.{key}=0"):
        ADRC(**{"bandwidth": 50.0, "observer_bandwidth": 250.0, key: 0.0})
