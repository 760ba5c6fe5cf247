"""The compiled kernel against the numpy engine (the specification), and the engine choice."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from ddmr_cli import (PID, SMC, ConfigError, NonlinearDisturbanceObserver, OpenLoop, RBFNetworkObserver, Simulation,
                      paper_scenario, paper_terrain, simulate)
from ddmr_cli.engine.kernel import AVAILABLE

pytestmark = pytest.mark.skipif(not AVAILABLE, reason="numba is a dependency; this only runs where it is missing")

CONTROLLERS = {
    "open_loop": lambda: OpenLoop([11.0, 10.5]),
    "pid": lambda: PID(),
    "pid_per_wheel": lambda: PID(kp=[5.0, 4.0], ki=[0.1, 0.3], kd=[0.01, 0.0], anti_windup=False),
    "smc_sat": lambda: SMC(),
    "smc_sign": lambda: SMC(switching="sign", switching_gain=4.0),
    "smc_tanh_integral": lambda: SMC(switching="tanh", surface="integral", lam=[20.0, 30.0]),
    "smc_ndo": lambda: SMC(ndo=NonlinearDisturbanceObserver([50.0, 40.0])),
    "smc_nno": lambda: SMC(nn=RBFNetworkObserver(10, 2.0, 50.0)),
    "smc_ndo_nno": lambda: SMC(ndo=NonlinearDisturbanceObserver(50.0), nn=RBFNetworkObserver(10, 2.0, 50.0)),
    "smc_ndo_nno_text": lambda: SMC(ndo=NonlinearDisturbanceObserver(50.0), nn=RBFNetworkObserver(10, 50.0, 2.0)),
}


def _pair(make, scenario, integrator, **extra):
    sim = Simulation(controller=make(), terrain=paper_terrain(), scenario=paper_scenario(scenario), duration=1.5,
                     integrator=integrator, initial_pose=(0.0, 0.05, 0.05), **extra)
    # zones shrunk so 1.5 s crosses all three; phases too, so scenario 2 reaches every phase
    terrain = dataclasses.replace(sim.terrain, zones=tuple(
        dataclasses.replace(z, start=z.start / 10.0) for z in sim.terrain.zones))
    phases = tuple(dataclasses.replace(p, start=p.start / 10.0) for p in sim.scenario.phases)
    sim = dataclasses.replace(sim, terrain=terrain, scenario=dataclasses.replace(sim.scenario, phases=phases))
    seeds = [3, 4, 5]
    compiled = simulate(dataclasses.replace(sim, engine="compiled", controller=make()), seeds, keep_series=[4])
    reference = simulate(dataclasses.replace(sim, engine="numpy", controller=make()), seeds, keep_series=[4])
    return compiled, reference


@pytest.mark.parametrize("name", sorted(CONTROLLERS))
@pytest.mark.parametrize("scenario", [1, 2])
@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_compiled_kernel_matches_the_numpy_engine(name, scenario, integrator):
    compiled, reference = _pair(CONTROLLERS[name], scenario, integrator)
    assert compiled.engine == "compiled" and reference.engine == "numpy"
    for metric, values in reference.metrics.items():
        np.testing.assert_allclose(compiled.metrics[metric], values, rtol=1e-9, atol=1e-12, err_msg=metric)
    for channel, values in reference.series[4].items():
        np.testing.assert_allclose(compiled.series[4][channel], values, rtol=1e-9, atol=1e-9, err_msg=channel)
    assert np.array_equal(compiled.diverged, reference.diverged)


def test_both_engines_saturate_and_diverge_alike():
    make = lambda: PID(kp=40.0, kd=0.0)  # noqa: E731  (saturates hard at the start)
    compiled, reference = _pair(make, 1, "euler", initial_wheel_speeds="rest", divergence_bound=0.06)
    assert reference.metric("saturation_fraction").max() > 0
    np.testing.assert_allclose(compiled.metric("saturation_fraction"), reference.metric("saturation_fraction"))
    assert np.array_equal(compiled.diverged, reference.diverged)
    np.testing.assert_array_equal(compiled.divergence_time, reference.divergence_time)


def test_numpy_engine_is_batch_invariant_too():
    sim = Simulation(controller=SMC(ndo=NonlinearDisturbanceObserver(50.0), nn=RBFNetworkObserver()),
                     terrain=paper_terrain(), scenario=paper_scenario(2), duration=0.6, engine="numpy")
    alone = simulate(sim, [7])
    batch = simulate(sim, [1, 7, 2, 9])
    for metric, values in alone.metrics.items():
        assert np.array_equal(values[0], batch.metrics[metric][1], equal_nan=True), metric


def test_a_subclass_that_overrides_the_law_runs_on_numpy():
    class Tweaked(SMC):
        def command(self, w, w_d, w_d_dot):
            return super().command(w, w_d, w_d_dot) * 0.5

    sim = Simulation(controller=Tweaked(), duration=0.05)
    assert simulate(sim, [0]).engine == "numpy"
    with pytest.raises(ConfigError, match="simulation.engine"):
        simulate(dataclasses.replace(sim, engine="compiled"), [0])
    assert simulate(Simulation(controller=SMC(), duration=0.05), [0]).engine == "compiled"


def test_thread_count_does_not_change_the_numbers():
    from ddmr_cli.engine.kernel import set_threads

    sim = Simulation(controller=SMC(ndo=NonlinearDisturbanceObserver(50.0), nn=RBFNetworkObserver()),
                     terrain=paper_terrain(), scenario=paper_scenario(1), duration=0.5)
    set_threads(1)
    one = simulate(sim, range(6))
    set_threads(0)
    many = simulate(sim, range(6))
    for metric, values in one.metrics.items():
        assert np.array_equal(values, many.metrics[metric], equal_nan=True), metric
