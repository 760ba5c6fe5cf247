"""Each part declares the step its sampled loops need (docs/model.md §4), and the bound sits where the closed form
puts it: accepted just below, refused just above."""

from __future__ import annotations

import pytest

from paper import make_smc, make_pid, make_robot, make_simulation
from ddmr_cli import PID, SMC, ConfigError, NonlinearDisturbanceObserver, Robot, Simulation
from ddmr_cli import paper_scenario


def _validate(controller, dt, scenario=None, integrator="euler"):
    sim = make_simulation(controller=controller, dt=dt, duration=1.0, integrator=integrator,
                     **({"scenario": scenario} if scenario is not None else {}))
    sim.validate()


def test_pid_step_bound_is_where_the_sampled_pd_loop_loses_stability():
    """z^2 - (1 - dt g K_p - g K_d) z - g K_d has a root at z = -1 when dt = 2 (1 - g K_d) / (g K_p)."""
    g = max(make_robot().input_gain.eigenvalues)
    kp, kd = 5.0, 0.01
    boundary = 2.0 * (1.0 - g * kd) / (g * kp)
    assert boundary == pytest.approx(4.81e-3, rel=2e-3)
    _validate(make_pid(kp=kp, kd=kd), 0.99 * boundary)
    with pytest.raises(ConfigError, match=r"simulation\.dt=.*sampled PD loop"):
        _validate(make_pid(kp=kp, kd=kd), 1.01 * boundary)


def test_smc_step_bound_is_two_over_its_fastest_rate():
    lam, k, phi = 25.0, 12.0, 0.1
    boundary = 2.0 / (lam + k / phi)
    _validate(make_smc(lam=lam, switching_gain=k, boundary_layer=phi), 0.99 * boundary)
    with pytest.raises(ConfigError, match=r"simulation\.dt=.*lam \+ switching_gain/boundary_layer"):
        _validate(make_smc(lam=lam, switching_gain=k, boundary_layer=phi), 1.01 * boundary)


def test_ndo_step_bound_is_two_over_its_gain():
    gain = 800.0
    smc = make_smc(lam=1.0, switching_gain=0.0, ndo=NonlinearDisturbanceObserver(gain))
    _validate(smc, 0.99 * 2.0 / gain)
    with pytest.raises(ConfigError, match=r"controller\.ndo\.gain"):
        _validate(make_smc(lam=1.0, switching_gain=0.0, ndo=NonlinearDisturbanceObserver(gain)), 1.01 * 2.0 / gain)


def test_plant_step_bound_counts_scenario_two_damping_and_the_integrator():
    pole = max(make_robot().drift.eigenvalues) * 2.0  # scenario 2: B_true up to 2 B_nom
    weak = make_smc(lam=1.0, switching_gain=0.0)
    _validate(weak, 0.99 * 2.0 / pole, paper_scenario(2))
    with pytest.raises(ConfigError, match="plant's fastest pole"):
        _validate(weak, 1.01 * 2.0 / pole, paper_scenario(2))
    _validate(weak, 1.01 * 2.0 / pole, paper_scenario(1))  # without the uncertainty the pole is half as fast
    _validate(weak, 1.01 * 2.0 / pole, paper_scenario(2), integrator="rk4")  # RK4's region reaches 2.78
