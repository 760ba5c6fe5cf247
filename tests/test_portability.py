"""The model's numbers must not depend on which BLAS/LAPACK kernel a CPU gets (issue: crash on AVX-512).

The wheel-space matrices of a symmetric robot are built in closed form; a computed matrix that is symmetric
only to rounding is accepted within a stated tolerance; every robot in a grid of plausible parameters builds,
validates and runs; and the validator's stability verdicts use closed-form roots, not LAPACK.
"""

from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest

from paper import make_smc, make_robot, make_simulation
from ddmr_cli import SMC, NonlinearDisturbanceObserver, Robot, Simulation, compose_config, simulate
from ddmr_cli.config import build_simulation, validate_config
from ddmr_cli.control.pid import _pd_spectral_radius
from ddmr_cli import paper_scenario, paper_terrain
from ddmr_cli.model.robot import SYMMETRY_RTOL, WheelMatrix

#: A model built from a matrix one ulp away from the exact one agrees with it to this relative tolerance.
ULP_RTOL = 1e-9


def test_closed_form_inverse_and_eigenvalues_match_linear_algebra():
    for robot in (make_robot(), make_robot(mass=20.0), make_robot(mass=5.0, track_width=0.4), make_robot(yaw_inertia=2.0)):
        J = robot.inertia
        np.testing.assert_allclose(J.inverse().to_array() @ J.to_array(), np.eye(2), atol=1e-14)
        np.testing.assert_allclose(sorted(J.eigenvalues), np.linalg.eigvalsh(J.to_array()), rtol=1e-13)
        np.testing.assert_allclose(robot.inverse_inertia.to_array(), np.linalg.inv(J.to_array()), rtol=1e-13)


def test_the_papers_plant_poles_are_9_72_and_14_67_per_second():
    common, differential = make_robot().drift.eigenvalues
    assert abs(common - 9.72) < 0.01 and abs(differential - 14.67) < 0.01


def test_a_matrix_symmetric_to_one_ulp_is_accepted_and_a_clearly_asymmetric_one_refused():
    exact = make_robot().inverse_inertia.to_array()
    off = exact.copy()
    off[0, 0] = np.nextafter(off[0, 0], 0.0)  # what an AVX-512 LAPACK kernel gives
    m = WheelMatrix.of(off)
    assert abs(m.p - exact[0, 0]) <= 2 * np.spacing(exact[0, 0])
    skewed = exact.copy()
    skewed[0, 0] *= 1.0 + 1e3 * SYMMETRY_RTOL
    with pytest.raises(ValueError, match="not a symmetric wheel matrix"):
        WheelMatrix.of(skewed)


@pytest.fixture(scope="module")
def short_nno_config():
    return compose_config(["simulation.duration=0.05", "run.n_runs=2", "controller=smc_ndo_nno"])


@pytest.mark.parametrize("mass,track_width,yaw_inertia,wheel_inertia", list(itertools.product(
    (5.0, 15.0, 20.0, 60.0), (0.3, 0.4, 0.5), (0.27, 1.5), (0.0075, 0.02))))
def test_a_grid_of_robots_builds_validates_and_runs(short_nno_config, mass, track_width, yaw_inertia, wheel_inertia):
    cfg = copy.deepcopy(short_nno_config)  # the same as the overrides robot.mass=... (composed once: 0.1 s each)
    cfg.robot.mass, cfg.robot.track_width, cfg.robot.yaw_inertia, cfg.robot.wheel_inertia = (
        mass, track_width, yaw_inertia, wheel_inertia)
    validate_config(cfg)
    result = simulate(build_simulation(cfg), seeds=[0, 1])
    assert not result.diverged.any()
    assert np.all(np.isfinite(result.metric("deviation_mae")))


def test_a_model_from_a_matrix_perturbed_by_one_ulp_runs_within_tolerance(monkeypatch):
    def scenario_2():
        return make_simulation(controller=make_smc(ndo=NonlinearDisturbanceObserver(50.0)), terrain=paper_terrain(),
                               scenario=paper_scenario(2), duration=2.0)

    exact = simulate(scenario_2(), seeds=[0, 1, 2])

    def perturbed_inverse(self):
        m = self.to_array()
        inv = np.array([[m[0, 0], -m[0, 1]], [-m[1, 0], m[1, 1]]]) / (m[0, 0] ** 2 - m[0, 1] ** 2)
        inv[0, 0] = np.nextafter(inv[0, 0], np.inf)  # one and two ulps off, as a CPU-specific kernel gives
        inv[1, 1] = np.nextafter(np.nextafter(inv[1, 1], np.inf), np.inf)
        return WheelMatrix.of(inv)

    exact_p = make_robot().inverse_inertia.p
    monkeypatch.setattr(WheelMatrix, "inverse", perturbed_inverse)
    assert make_robot().inverse_inertia.p > exact_p  # the perturbation reaches the model
    perturbed = simulate(scenario_2(), seeds=[0, 1, 2])
    for name in ("deviation_mae", "e_x_mae", "e_y_mae", "chattering", "d_est_mae", "electrical_energy"):
        np.testing.assert_allclose(perturbed.metric(name), exact.metric(name), rtol=ULP_RTOL, err_msg=name)


@pytest.mark.parametrize("a_target", [0.2, 0.9, 0.999, 1.0, 1.2])
def test_pd_spectral_radius_closed_form_matches_polynomial_roots(a_target):
    for dt_g_kp in np.linspace(0.0, 2.5, 11):
        for g_kd in (0.0, 0.05, 0.3, a_target):
            expected = np.max(np.abs(np.roots([1.0, -(1.0 - dt_g_kp - g_kd), -g_kd])))
            assert _pd_spectral_radius(dt_g_kp, g_kd) == pytest.approx(expected, rel=1e-9, abs=1e-12)
