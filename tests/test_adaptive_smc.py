"""Adaptive-gain SMC (ddmr_cli/control/adaptive_smc.py; docs/model.md §6, "Adaptive-gain SMC")."""

from __future__ import annotations

import math

import numpy as np
import pytest

from engine_checks import assert_seed_alone_equals_seed_in_batch, assert_zero_error_stays_zero
from wheel_loop import nominal_plant, wheel_loop
from ddmr_cli import AdaptiveSMC, ConfigError, NominalModel, paper_config, paper_controller, paper_robot
from omegaconf import OmegaConf

ROBOT = paper_robot()
NOMINAL = NominalModel.from_robot(ROBOT)
W_REF = 1.0 / ROBOT.wheel_radius
DT = 1e-3


def make(**values) -> AdaptiveSMC:
    """conf/controller/adaptive_smc.yaml with ``values`` replaced."""
    cfg = OmegaConf.to_container(paper_config("controller=adaptive_smc").controller, resolve=True)
    cfg.pop("_target_")
    cfg.pop("display")
    return AdaptiveSMC(**{**cfg, **values})


def gains(controller, disturbance, duration=1.0):
    """K per step (after each update) on the nominal plant plus ``disturbance(t)``, from zero error."""
    out = wheel_loop(controller, NOMINAL, nominal_plant(NOMINAL, disturbance), (W_REF, W_REF), (W_REF, W_REF),
                     duration, dt=DT, state=("gain",))
    return out["gain"], out["s"]


def rough(amplitude):
    """A disturbance the fixed K = 12 cannot hold inside the dead zone: amplitude * sin(2 pi 5 t) on both wheels."""
    return lambda t: (amplitude * math.sin(10 * math.pi * t),) * 2


def test_gain_stays_in_its_range_and_reaches_the_top_under_a_large_disturbance():
    ctrl = make(gain_min=6.0, gain_max=30.0)
    K, _ = gains(ctrl, rough(300.0))
    assert np.all(K >= 6.0) and np.all(K <= 30.0)
    assert np.max(K) == pytest.approx(30.0, abs=1e-12)  # clipped at K_max


def test_gain_falls_to_the_bottom_when_leakage_wins():
    """|s| outside the dead zone but small: gamma |s| < sigma K, so K decays to K_min and is clipped there."""
    ctrl = make(adaptation_rate=1.0, leakage=20.0, dead_zone=0.0, gain_min=6.0, gain_max=30.0)
    K, _ = gains(ctrl, rough(50.0))
    assert np.all(K >= 6.0) and K[-1] == pytest.approx(6.0, abs=1e-12)


def test_gain_rises_under_a_larger_disturbance():
    K_small, _ = gains(make(), rough(20.0))
    K_large, _ = gains(make(), rough(80.0))
    assert np.mean(K_large) > 1.5 * np.mean(K_small)
    assert np.max(K_small) > 12.0  # both do adapt upwards from K(0)


def test_gain_holds_still_inside_the_dead_zone():
    """A constant d = -7.745 rad/s^2: SMC's steady s = -d / (lambda + K/Phi) = 0.053 rad/s at K = 12. With the
    dead zone eps = 0.1 it lies inside: K stays at K(0) = 12 throughout; with eps = 0.01 outside: K adapts."""
    d = lambda t: (-7.745, -7.745)  # noqa: E731
    K_inside, s_inside = gains(make(dead_zone=0.1), d, duration=0.5)
    assert np.max(np.abs(s_inside)) < 0.1
    assert np.max(np.abs(K_inside - 12.0)) < 1e-12
    K_outside, _ = gains(make(dead_zone=0.01), d, duration=0.5)
    assert np.max(K_outside) > 13.0


@pytest.mark.parametrize("name", ["adaptive_smc", "adaptive_smc_ndo"])
def test_zero_disturbance_and_zero_initial_error_keep_every_error_at_zero(name):
    assert_zero_error_stays_zero(paper_controller(name))


def test_seed_alone_equals_seed_in_batch():
    assert_seed_alone_equals_seed_in_batch(paper_controller("adaptive_smc_ndo"))


def test_step_bound_uses_k_max():
    """The boundary layer's fastest rate is lambda + K_max / Phi (K can grow to K_max)."""
    ctrl = make(gain_max=300.0)  # 25 + 3000 = 3025 1/s: dt must be < 2 / 3025 = 0.661 ms
    with pytest.raises(ConfigError, match=r"simulation\.dt=0\.001: must be < 0\.000661 s .*gain_max/boundary_layer"):
        ctrl.check_step(NOMINAL, 1e-3, "euler")


@pytest.mark.parametrize("values, key", [
    ({"switching_gain": 100.0}, "switching_gain"), ({"gain_min": 50.0, "gain_max": 40.0}, "gain_max"),
    ({"adaptation_rate": 0.0}, "adaptation_rate"), ({"leakage": -1.0}, "leakage"), ({"dead_zone": -1.0}, "dead_zone"),
])
def test_bad_values_are_refused_naming_the_key(values, key):
    with pytest.raises(ConfigError, match=rf"controller\.{key}="):
        make(**values)
