"""The external-plant path of the engine (ddmr_cli.plant.base; engine/stepper.py's external_control and
external_account, driven by engine/simulation.py): the same laws in the same order as the compiled wheel loop,
split where a plant stepped from Python advances.

The check that holds the two orchestrations to one another: ``plant=wheel_python``, the paper's wheel plant
written as an external plant from the model's own laws (ddmr_cli/plant/wheel_python.py), gives ``plant=wheel``'s
metrics, bands and series to 1e-9 (Python rounds every operation, compiled code may fuse a multiply-add, so not
bit for bit), on terrain with every zone and phase, roughness included.
"""

from __future__ import annotations

import numpy as np
import pytest

from ddmr_cli import paper_simulation, simulate
from ddmr_cli.errors import ConfigError
from ddmr_cli.plant.base import ExternalPlant, check_state
from ddmr_cli.plant.wheel_python import PythonWheelPlant
from test_determinism import SCENARIO, TERRAIN

SEEDS = [0, 1, 2, 3]


def _sim(*overrides, **fields):
    return paper_simulation("controller=smc_ndo_nno", "simulation.duration=0.5", *overrides, terrain=TERRAIN,
                            scenario=SCENARIO, **fields)


def test_the_python_wheel_plant_keeps_the_contract():
    plant = PythonWheelPlant(_sim())
    assert isinstance(plant, ExternalPlant)
    plant.reset(np.array(SEEDS), np.zeros((4, 3)), np.ones((4, 2)))
    check_state(plant.state(), 4)
    plant.step(np.full((4, 2), 6.0), np.ones(4))
    check_state(plant.state(), 4)
    assert plant.true_disturbance().shape == (4, 2) and not plant.diverged().any()


@pytest.mark.parametrize("overrides", [(), ("sensor=encoder", "actuator=realistic", "control.rate=250"),
                                       ("sensor=noisy", "actuator=pwm8", "scenario.phase_clock=time")],
                         ids=["ideal", "encoder-realistic-250Hz", "noisy-pwm8-time-phases"])
def test_the_wheel_plant_stepped_from_python_gives_the_compiled_loops_numbers(overrides):
    """Every metric of every seed, the bands and the kept series agree to 1e-9 (relative) with the compiled wheel
    loop, with rough zones, scenario 2's uncertainty, and the sensor, actuator and control-rate holds in play."""
    compiled = simulate(_sim(*overrides), SEEDS, keep_series=[1])
    external = simulate(_sim(*overrides, "plant=wheel_python"), SEEDS, keep_series=[1])
    assert compiled.segments == external.segments
    assert not external.diverged.any()
    checked = 0
    for name, values in compiled.metrics.items():
        np.testing.assert_allclose(external.metrics[name], values, rtol=1e-9, atol=1e-12, err_msg=name)
        checked += np.isfinite(values).sum()
    assert checked > 100  # the comparison saw numbers, not only NaN
    for channel, values in compiled.series[1].items():
        np.testing.assert_allclose(external.series[1][channel], values, rtol=1e-9, atol=1e-12, err_msg=channel)
    assert np.abs(compiled.series[1]["roughness"]).max() > 50.0  # the very rough zone was crossed
    for name, values in compiled.bands.items():
        np.testing.assert_allclose(external.bands[name], values, rtol=1e-9, atol=1e-12, err_msg=name)


class _TipsOver(PythonWheelPlant):
    """Run 2 is flagged diverged after step 123 (a robot that tipped over)."""

    def diverged(self):
        out = super().diverged()
        out[2] |= self._k > 123
        return out


def test_a_run_the_plant_calls_diverged_is_a_diverged_result_at_that_step():
    result = simulate(_sim(plant=_TipsOver), SEEDS)
    assert list(result.diverged) == [False, False, True, False]
    assert result.divergence_time[2] == pytest.approx(123 * 0.001)
    mae = np.asarray(result.metrics["deviation_mae"])
    assert np.isnan(mae[2]).all() and np.isfinite(mae[[0, 1, 3]]).all()


def test_a_plant_name_without_a_module_and_a_key_the_plant_lacks_are_one_line_errors():
    from ddmr_cli.config.build import build_plant

    with pytest.raises(ConfigError, match="plant.name"):
        build_plant({"name": "no_such_plant"})
    with pytest.raises(ConfigError, match="plant.timestep"):
        build_plant({"name": "wheel_python", "timestep": 0.001})
