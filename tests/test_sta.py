"""Super-twisting SMC (ddmr_cli/control/sta.py; docs/model.md §6, "Super-twisting")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine_checks import assert_seed_alone_equals_seed_in_batch, zero_error_run
from paper import make_smc
from wheel_loop import nominal_plant, wheel_loop
from ddmr_cli import ConfigError, NominalModel, SuperTwisting, paper_config, paper_controller, paper_robot

ROBOT = paper_robot()
NOMINAL = NominalModel.from_robot(ROBOT)
W_REF = 1.0 / ROBOT.wheel_radius  # 1 m/s on both wheels
# d(t) = D sin(Omega t) on both wheels: |d'| <= L = D Omega
D, OMEGA = 10.0, 4.0 * math.pi
L = D * OMEGA  # 125.7 rad/s^3
# gains meeting the sufficient condition k2 > L, k1^2 >= 4 L (k2 + L) / (k2 - L) (docs/model.md §6)
K1, K2 = 40.0, 260.0
EPS = 1e-3      # the neighbourhood of s = 0 [rad/s]
T_REACH = 0.2   # [s]
DT = 1e-3


def sinusoid(t):
    d = D * math.sin(OMEGA * t)
    return d, d


def loop(controller, duration=1.0):
    return wheel_loop(controller, NOMINAL, nominal_plant(NOMINAL, sinusoid), (W_REF - 1.0, W_REF - 1.0),
                      (W_REF, W_REF), duration, dt=DT, state=("v",) if isinstance(controller, SuperTwisting) else ())


@pytest.fixture(scope="module")
def sta_run():
    return loop(SuperTwisting(k1=K1, k2=K2, anti_windup=True))


def test_the_test_gains_meet_the_sufficient_condition():
    assert K2 > L and K1**2 >= 4 * L * (K2 + L) / (K2 - L)


def test_s_reaches_a_small_neighbourhood_in_finite_time_and_stays(sta_run):
    """From s(0) = 1 rad/s under a disturbance with |d'| <= L: |s| < EPS from T_REACH on (sampled at 1 ms the
    super-twisting keeps |s| = O(dt^2); measured about 2e-4 rad/s), and v takes over -d (the integral of the
    discontinuity is what rejects the disturbance): from the Euler step s_k+1 - s_k = -dt (k1 |s_k|^(1/2) sign(s_k)
    + v_k + d_k), |v + d| < 2 EPS / dt + k1 sqrt(EPS) = 3.3 rad/s^2 once |s| < EPS (measured 0.53)."""
    s = np.abs(sta_run["s"])
    k_reach = int(T_REACH / DT)
    assert s[0, 0] == pytest.approx(1.0)
    assert np.max(s[k_reach:]) < EPS
    assert np.max(s[: k_reach // 4]) > 10 * EPS  # it did start outside
    d = np.array([sinusoid(t)[0] for t in sta_run["t"]])
    assert np.max(np.abs(sta_run["v"][k_reach:, 0] + d[k_reach:])) < 2 * EPS / DT + K1 * math.sqrt(EPS) < D


def test_u_is_continuous_its_step_jump_is_bounded_unlike_sign_smc(sta_run):
    """After reaching, |s| < EPS, so |s_k - s_k-1| < 2 EPS, and sqrt|x| sign(x) is 1/2-Hoelder with constant
    sqrt(2): the commanded acceleration a = k1 |s|^(1/2) sign(s) + v moves by at most 2 k1 sqrt(EPS) + dt k2 per
    step, and u = (J a + B w) / K_u by at most (j_p + |j_q|)(2 k1 sqrt(EPS) + dt k2) + (B/K_u) 2 EPS
    (0.093 V here). Sign-SMC with K = 12 > D jumps by 2 K (j_p + j_q) = 0.80 V whenever s changes sign."""
    j_p, j_q, b = NOMINAL.j_over_ku_p, NOMINAL.j_over_ku_q, NOMINAL.damping_over_gain
    bound = (j_p + abs(j_q)) * (2 * K1 * math.sqrt(EPS) + DT * K2) + b * 2 * EPS
    k_reach = int(T_REACH / DT)
    jump_sta = np.max(np.abs(np.diff(sta_run["u"][k_reach:], axis=0)))
    assert jump_sta <= bound
    K = 12.0
    sign_smc = loop(make_smc(switching="sign", switching_gain=K))
    jump_smc = np.max(np.abs(np.diff(sign_smc["u"][k_reach:], axis=0)))
    assert jump_smc >= 0.95 * 2 * K * (j_p + j_q)
    assert bound < 0.2 * jump_smc


def test_default_gains_are_the_common_choice_for_the_terrain_bound():
    """docs/model.md §6: L = (largest roughness) / tau_c + (common-mode pole) w_cruise sigma_delta / tau_delta
    (5000 + 259 = 5259 rad/s^3, taken as 5300) and k1 = 1.5 sqrt(L), k2 = 1.1 L."""
    cfg = paper_config()
    rough = max(z.roughness for z in cfg.terrain.zones.values())
    unc = cfg.scenario.uncertainty
    common_pole = max(ROBOT.drift.eigenvalues[0], 0.0)
    bound = rough / cfg.terrain.correlation_time + common_pole * W_REF * unc.std / unc.correlation_time
    assert bound == pytest.approx(5259, abs=1)
    for name in ("sta", "sta_ndo"):
        sta = paper_controller(name)
        assert sta.k1[0] == pytest.approx(1.5 * math.sqrt(5300), rel=2e-3)
        assert sta.k2[0] == pytest.approx(1.1 * 5300, rel=1e-3)
    assert paper_controller("sta_ndo").ndo.gain == paper_controller("smc_ndo").ndo.gain


@pytest.mark.parametrize("name", ["sta", "sta_ndo"])
def test_zero_disturbance_and_zero_initial_error_stay_within_the_sampled_band(name):
    """Zero stays zero only until rounding: the plant's K_u (B/K_u) w - B w leaves w' ~ 1e-14 rad/s^2, s turns
    ~3e-14 (step 15), sign(s) = 1 and v jumps by dt k2 (a discontinuous law cannot tell rounding from error).
    From then on the sampled super-twisting holds its limit cycle |s| <= 2 k2 dt^2 (measured k2 dt^2 =
    5.8e-3 rad/s), the deviation stays below 1e-6 m (measured 1.9e-7 m), and y and theta stay exactly on the
    line (both wheels alike)."""
    sta = paper_controller(name)
    _, s = zero_error_run(sta)
    k_first = int(np.flatnonzero(np.abs(s["s_right"]) > 0)[0])
    assert k_first > 0 and abs(s["s_right"][k_first]) < 1e-12  # exactly 0 until rounding
    for wheel in ("right", "left"):
        assert np.max(np.abs(s[f"s_{wheel}"])) <= 2 * sta.k2[0] * DT**2
    assert np.max(s["deviation"]) < 1e-6
    assert np.max(np.abs(s["e_y"])) < 1e-12 and np.max(np.abs(s["e_theta"])) < 1e-12


def test_seed_alone_equals_seed_in_batch():
    assert_seed_alone_equals_seed_in_batch(paper_controller("sta_ndo"))


@pytest.mark.parametrize("key", ["k1", "k2"])
def test_bad_gain_is_refused_naming_the_key(key):
    with pytest.raises(ConfigError, match=rf"controller\.{key}=-1"):
        SuperTwisting(**{"k1": K1, "k2": K2, "anti_windup": True, key: -1.0})


@pytest.mark.parametrize("anti_windup", [True, False])
def test_v_winds_up_under_saturation_only_without_anti_windup(anti_windup):
    """A 12 V supply cannot hold 1 m/s against d = -60 rad/s^2 (it needs (B w - J d) / K_u = 12.8 V): the wheels
    stay saturated and slow. v integrates k2 sign(s) = k2 per step without anti-windup (v = k2 t), and is held
    with it (it stops as soon as the wheel saturates with s > 0)."""
    sta = SuperTwisting(k1=K1, k2=K2, anti_windup=anti_windup)
    out = wheel_loop(sta, NOMINAL, nominal_plant(NOMINAL, lambda t: (-60.0, -60.0)), (W_REF, W_REF), (W_REF, W_REF),
                     0.5, dt=DT, max_voltage=12.0, state=("v",))
    assert np.all(out["u_command"][100:] > 12.0) and np.all(out["s"][100:] > 0)  # saturated, slower than wanted
    v_end = out["v"][-1, 0]
    if anti_windup:
        assert np.ptp(out["v"][100:, 0]) < 1e-12 and v_end < 0.1 * K2 * 0.5  # held from saturation on
    else:
        assert v_end == pytest.approx(K2 * 0.5, rel=0.02)
