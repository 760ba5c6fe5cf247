"""Accepted nonsense (issue 26, class 7): every float value of the robot, terrain, trajectory, outer loop and
controller, pushed to the extremes a float can hold, is either refused with a ConfigError naming its key (one line,
exit 2 at the command line), or gives a run whose whole-run metrics are finite or a recorded divergence (a
diverging run is a result). Never NaN metrics from a run that did not diverge."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ddmr_cli import ConfigError, compose_config, paper_simulation, simulate
from ddmr_cli.checks import first_non_finite

EXTREMES = (5e-324, 1e-300, 1e300, 1.7e308)
GROUPS = ("robot", "terrain", "trajectory", "outer_loop", "controller")


def _float_keys(node, prefix):
    from omegaconf import DictConfig

    for key in node:
        value = node[key]
        path = f"{prefix}.{key}"
        if isinstance(value, DictConfig):
            yield from _float_keys(value, path)
        elif isinstance(value, float):
            yield path


def _keys(controller):
    cfg = compose_config([f"controller={controller}"])
    return [k for g in GROUPS if g in cfg for k in _float_keys(cfg[g], g)]


def _outcome(overrides):
    try:
        sim = paper_simulation(*overrides, "simulation.duration=0.05")
    except ConfigError as exc:
        return "refused", exc
    try:
        result = simulate(sim, [0])
    except ConfigError as exc:
        return "refused", exc
    return "ran", result


@pytest.mark.slow
@pytest.mark.parametrize("controller", ["smc_ndo_nno", "pid", "adrc"])
def test_every_extreme_float_is_refused_or_runs_to_a_result(controller):
    keys = _keys(controller)
    assert len(keys) > 15, keys  # the sweep reaches the groups' values
    checked = 0
    for key in keys:
        for value in EXTREMES:
            kind, out = _outcome([f"controller={controller}", f"{key}={value!r}"])
            checked += 1
            if kind == "refused":
                assert str(out).count("\n") == 0 and str(out), key  # one line, naming a key
                continue
            finite = np.isfinite(out.metric("deviation_mae"))  # the whole run (zones not reached are NaN)
            assert np.all(finite | out.diverged), (key, value, out.metric("deviation_mae"), out.diverged)
    assert checked == len(keys) * len(EXTREMES)


@pytest.mark.parametrize("overrides, key", [
    (["terrain.zones.very_rough.mu=1.7e308"], "terrain.zones.very_rough.mu"),
    (["terrain.zones.flat.mu=1e300", "robot.mass=1e10"], "terrain.zones.flat.mu"),
    (["controller=pid", "controller.kp=1e300"], "simulation.dt"),
    (["controller=pid", "controller.kd=1e300"], "simulation.dt"),
])
def test_an_overflowing_value_is_refused_by_name_without_a_warning(overrides, key):
    """Found by the sweep above: a rolling-resistance coefficient whose torque overflows was refused as
    ``terrain='[0]'`` after numpy's overflow warning, and an extreme PD gain warned on its way to the refusal. The
    refusal is one line: the zone's own key and value, and no RuntimeWarning before it."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        kind, out = _outcome(overrides)
    assert kind == "refused" and out.key == key, out


@pytest.mark.parametrize("width", [5e-324, 1e-300])
def test_a_width_whose_inverse_square_overflows_is_refused(width):
    """Found by the sweep above: nn.width = 1e-300 passed '> 0' and the compiled basis divided by zero."""
    kind, out = _outcome(["controller=smc_ndo_nno", f"controller.nn.width={width!r}"])
    assert kind == "refused" and out.key == "controller.nn.width" and "overflows" in out.rule


def test_a_non_finite_derived_quantity_is_refused_before_the_first_step():
    """The class check at the end of Simulation.validate: law parameters that are not finite (here a controller
    whose parameters a user's code computed as inf) are refused naming the group and the quantity."""
    from ddmr_cli import OpenLoop, paper_simulation

    class Broken(OpenLoop):
        def law_parameters(self, nominal, dt):
            return type(super().law_parameters(nominal, dt))((math.inf, 1.0))

    sim = paper_simulation(controller=Broken(1.0), duration=0.05)
    with pytest.raises(ConfigError) as info:
        simulate(sim, [0])
    assert info.value.key == "controller" and info.value.value == "voltage[0]"


def test_first_non_finite_names_the_quantity():
    from typing import NamedTuple

    class P(NamedTuple):
        a: float
        b: tuple
        c: np.ndarray

    assert first_non_finite(P(1.0, (2.0, 3.0), np.ones(3))) is None
    assert first_non_finite(P(1.0, (2.0, math.inf), np.ones(3))) == "b[1]"
    assert first_non_finite(P(1.0, (2.0, 3.0), np.array([1.0, np.nan]))) == "c[1]"
    assert first_non_finite(P(math.nan, (), np.ones(1)), "params") == "params.a"
