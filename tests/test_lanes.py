"""The step loop by blocks of runs (ddmr_cli.engine.lanes) against the run-at-a-time loop (ddmr_cli.engine.stepper).

The two loops run the same laws in the same order, one run at a time or a block of runs at a time, so every metric,
kept series, seed band and divergence of a run must agree. On one machine they agree to the bit (libm's sine and
cosine in both, no fast-math flags); the tolerance below is the regression test's (a last-bit difference on another
CPU grows through the sliding mode's switching to about 1e-12-1e-10 over these short runs), far below any wiring
mistake (a misplaced row moves a metric by percent).
"""

from __future__ import annotations

import numpy as np
import pytest

from ddmr_cli import paper_simulation, simulate
from ddmr_cli.compiled import jit_enabled
from ddmr_cli.control.base import LANES
from ddmr_cli.engine.bands import BAND_CHANNELS
from ddmr_cli.engine.simulation import in_lanes

pytestmark = pytest.mark.skipif(not jit_enabled(), reason="the lanes loop runs compiled only (numba missing or "
                                                          "NUMBA_DISABLE_JIT set)")

RTOL, ATOL = 1e-9, 1e-12
SETTLE = ["metrics.settle_time=0.5", "metrics.zone_settle_time=0.2"]


def _both(sim, seeds, **kwargs):
    return (simulate(sim, seeds, threads=1, lanes=False, **kwargs),
            simulate(sim, seeds, threads=1, lanes=True, **kwargs))


def _assert_same(a, b):
    assert a.metrics.keys() == b.metrics.keys()
    for name in a.metrics:
        np.testing.assert_allclose(b.metrics[name], a.metrics[name], rtol=RTOL, atol=ATOL, err_msg=name)
    np.testing.assert_array_equal(b.diverged, a.diverged)
    np.testing.assert_allclose(b.divergence_time, a.divergence_time, rtol=RTOL, atol=ATOL)
    assert a.series.keys() == b.series.keys()
    for seed in a.series:
        for channel in a.series[seed]:
            np.testing.assert_allclose(b.series[seed][channel], a.series[seed][channel], rtol=RTOL, atol=ATOL,
                                       err_msg=f"seed {seed}, {channel}")
    assert a.bands.keys() == b.bands.keys()
    for name in a.bands:
        np.testing.assert_allclose(np.asarray(b.bands[name]), np.asarray(a.bands[name]), rtol=RTOL, atol=ATOL,
                                   err_msg=name)


@pytest.mark.parametrize("overrides", [
    ["controller=smc_ndo"],
    ["controller=smc_ndo_nno"],
    ["controller=smc"],
    ["controller=smc_ndo", "scenario=paper_2"],  # phases by distance, damping uncertainty
    ["controller=smc_ndo_nno", "scenario=paper_2", "scenario.phase_clock=time"],
    ["controller=smc", "controller.switching=tanh", "controller.surface=integral"],
    ["controller=smc_ndo", "controller.switching=sign"],
    ["controller=open_loop"],
    ["controller=pid"],
    ["controller=pid", "controller.kp=20.0", "controller.ki=300.0"],  # saturated more often: the anti-windup
    ["controller=sta"],
    ["controller=sta_ndo", "scenario=paper_2"],
    ["controller=adrc", "controller.bandwidth=150.0"],  # saturated at the start: the ESO takes the applied u
    ["controller=adaptive_smc"],
    ["controller=adaptive_smc_ndo", "scenario=paper_2"],
    # beyond the paper's loop: the sensor, the actuator, the control rate, the integrator (docs/model.md §10)
    ["controller=smc_ndo", "sensor=noisy"],
    ["controller=smc_ndo_nno", "sensor=encoder"],  # odometry: the sensor's state in the run records
    ["controller=pid", "sensor=encoder", "sensor.speed_filter=0.005", "sensor.pose=noisy", "sensor.speed_std=0.2"],
    ["controller=sta_ndo", "actuator=realistic"],  # delay, driver lag, PWM
    ["controller=adrc", "actuator.pwm_bits=8"],  # the ESO takes the PWM'd voltage
    ["controller=smc_ndo", "control.rate=250"],  # held between control instants
    ["controller=smc_ndo", "+realism=realistic_driver", "scenario=paper_2"],  # all of it at 250 Hz
    ["controller=smc", "simulation.integrator=rk4", "scenario=paper_2"],
    ["controller=pid", "simulation.integrator=rk4", "sensor=noisy", "actuator.delay=0.003", "control.rate=500"],
], ids=lambda o: " ".join(o))
def test_lanes_give_the_run_at_a_time_numbers(overrides):
    # settling early, so that the steady-state metrics (and their segments' entries) count steps in 2.5 s
    sim = paper_simulation(*overrides, "simulation.duration=2.5", *SETTLE)
    assert in_lanes(sim)
    a, b = _both(sim, range(LANES + 7), keep_series=[0, LANES + 3])  # a full block and a partial one
    assert np.isfinite(a.metrics["deviation_max_ss"][:, 0]).all() and np.isfinite(a.metrics["chattering_ss"][:, 1:]).any()
    _assert_same(a, b)


@pytest.mark.parametrize("overrides", [["control.rate=250"], ["+realism=realistic_driver"]], ids=" ".join)
def test_chunks_cut_between_control_instants_start_from_the_runs_holds(monkeypatch, overrides):
    """Chunks of 67 steps (no multiple of the control period of 4 steps), two blocks of runs: a chunk that starts
    between control instants starts its lanes from what each run's record holds (the command, the applied voltage,
    the saturation flags, the wheel-speed reference), not from what the block's rows held before, and gives the
    run-at-a-time loop's numbers."""
    from ddmr_cli.engine import simulation as simulation_module

    sim = paper_simulation("controller=smc_ndo", *overrides, "simulation.duration=3.5", *SETTLE)
    seeds, kept = range(LANES + 7), [0, LANES + 3]
    a = simulate(sim, seeds, threads=1, lanes=False, keep_series=kept)
    assert a.bands["t"][1] == pytest.approx(2 * sim.dt)  # a band grid point every other step
    per_run_step = 8 * len(BAND_CHANNELS) // 2  # bytes of the band channels, every other step
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 67 * len(seeds) * per_run_step)
    monkeypatch.setattr(simulation_module, "MIN_CHUNK_STEPS", 1)
    done = []
    b = simulate(sim, seeds, threads=1, lanes=True, keep_series=kept, progress=lambda k, n: done.append(k))
    assert done[:2] == [67, 134]
    _assert_same(a, b)


def test_lanes_agree_on_diverging_runs():
    free = simulate(paper_simulation("controller=smc_ndo", "simulation.duration=1.0"), range(12), threads=1)
    bound = float(np.median(free.metric("deviation_max")))  # some runs, not all, go past it
    sim = paper_simulation("controller=smc_ndo", "simulation.duration=1.0", f"simulation.divergence_bound={bound}")
    a, b = _both(sim, range(12))
    assert 0 < a.diverged.sum() < 12
    _assert_same(a, b)


def test_a_seed_is_the_same_alone_and_in_any_lane():
    sim = paper_simulation("controller=smc_ndo_nno", "simulation.duration=1.0")
    batch = simulate(sim, range(2 * LANES + 5), threads=2)
    for position in (0, LANES - 1, LANES, 2 * LANES + 4):
        alone = simulate(sim, [position], threads=1)
        for name in batch.metrics:
            np.testing.assert_allclose(alone.metrics[name][0], batch.metrics[name][position], rtol=1e-15, atol=0,
                                       err_msg=f"{name}, seed {position}")


def test_runs_step_one_at_a_time_when_the_controller_has_no_lanes_laws_that_fit():
    sim = paper_simulation("controller=smc_ndo_nno", "controller.nn.n_neurons=40", "simulation.duration=0.05")
    assert not in_lanes(sim)  # more neurons than the lanes rows hold
    with pytest.raises(ValueError, match="lanes=True"):
        simulate(sim, range(2), lanes=True)
