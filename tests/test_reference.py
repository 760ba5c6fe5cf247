"""The benchmark's reference kernel (ddmr_cli/bench/reference.py) computes the engine's numbers.

``ddmr bench`` prints the engine's throughput as a ratio to this hand-fused kernel's, so the kernel must run the
same loop on the same noise: per seed, its whole-run metrics equal the engine's to 1e-12 relative, in each of its
layouts. It refuses, naming the key, every configuration it does not run.
"""

from __future__ import annotations

import numpy as np
import pytest

from ddmr_cli.bench.reference import LAYOUTS, METRICS, exp_neg, reference_metrics, sincos
from ddmr_cli.config.presets import paper_simulation
from ddmr_cli.compiled import jit_enabled
from ddmr_cli.engine.simulation import simulate
from ddmr_cli.errors import ConfigError

pytestmark = pytest.mark.skipif(not jit_enabled(), reason="the reference kernel is a numba kernel")

SEEDS = (0, 1, 7)


@pytest.fixture(scope="module", params=["smc_ndo", "smc_ndo_nno"])
def engine_run(request):
    sim = paper_simulation(f"controller={request.param}", "simulation.duration=1.5")
    return sim, simulate(sim, SEEDS, threads=1, bands=False)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_the_reference_computes_the_engines_metrics(engine_run, layout):
    sim, result = engine_run
    ref = reference_metrics(sim, SEEDS, layout)
    np.testing.assert_array_equal(ref["diverged"], result.diverged)
    for name in METRICS:
        np.testing.assert_allclose(ref[name], result.metric(name), rtol=1e-12, atol=0, err_msg=name)


def test_the_exact_layout_is_the_scalar_loop_in_lanes():
    """The exact layout (the bench's yardstick at equal work) does the scalar layout's operations in its order, a
    lane at a time: the same metrics to the bit here (1e-15 relative); the lanes layout's fdlibm sine and cosine and
    fused multiply-adds move them by about 1e-13 over 15 s."""
    sim = paper_simulation("controller=smc_ndo_nno", "simulation.duration=15")
    seeds = range(35)  # a full block of lanes and a partial one
    exact, scalar = reference_metrics(sim, seeds, "exact"), reference_metrics(sim, seeds, "scalar")
    np.testing.assert_array_equal(exact["diverged"], scalar["diverged"])
    for name in METRICS:
        np.testing.assert_allclose(exact[name], scalar[name], rtol=1e-15, atol=0, err_msg=name)


def test_a_seed_gives_the_same_numbers_alone_or_in_a_block_of_runs():
    sim = paper_simulation("controller=smc_ndo_nno", "simulation.duration=0.5")
    batch = reference_metrics(sim, range(40))  # a full block of lanes and a partial one
    for seed in (0, 35):
        alone = reference_metrics(sim, [seed])
        for name in METRICS:
            np.testing.assert_allclose(alone[name][0], batch[name][seed], rtol=1e-15, atol=0, err_msg=name)


def test_the_lanes_layouts_sin_cos_and_exp_are_within_an_ulp_of_numpys():
    rng = np.random.default_rng(3)
    angles = np.concatenate([rng.uniform(-np.pi, np.pi, 2000), rng.uniform(-0.2, 0.2, 500),
                             rng.uniform(-1e4, 1e4, 500), [0.0, np.pi / 2, np.pi, -np.pi, 1e-300]])
    for a in angles:  # compiled, with the kernel's flags
        s, c = sincos(a)
        assert abs(s - np.sin(a)) <= np.spacing(abs(np.sin(a))), a
        assert abs(c - np.cos(a)) <= np.spacing(abs(np.cos(a))), a
    exponents = np.concatenate([-rng.uniform(0, 708, 2000), -rng.uniform(0, 1, 500), [0.0, -1e-300]])
    for x in exponents:
        assert abs(exp_neg(x) - np.exp(x)) <= np.spacing(np.exp(x)), x
    for x in (-746.0, -800.0, -1e308):  # below exp's underflow: exactly 0, as the engine's basis
        assert exp_neg(x) == 0.0
    assert np.isnan(exp_neg(np.nan))


@pytest.mark.parametrize("overrides, key", [
    (("controller=pid",), "controller"),
    (("controller=smc",), "controller.ndo"),
    (("controller=smc_ndo", "controller.switching=tanh"), "controller.switching"),
    (("controller=smc_ndo", "controller.surface=integral"), "controller.surface"),
    (("sensor=noisy",), "sensor.kind"),
    (("actuator=realistic",), "actuator.delay"),
    (("simulation.integrator=rk4",), "simulation.integrator"),
    (("control.rate=500",), "control.rate"),
    (("scenario=paper_2",), "scenario.phases.uncertainty.uncertainty"),
])
def test_the_reference_refuses_what_it_does_not_run_naming_the_key(overrides, key):
    sim = paper_simulation(*overrides, "simulation.duration=0.1")
    with pytest.raises(ConfigError) as refused:
        reference_metrics(sim, [0])
    assert refused.value.key == key
    assert isinstance(refused.value, ValueError)


def test_an_unknown_layout_is_refused():
    with pytest.raises(ValueError, match="layout"):
        reference_metrics(paper_simulation("controller=smc_ndo", "simulation.duration=0.1"), [0], "simd")
