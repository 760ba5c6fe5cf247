"""A validated config's simulation with some values changed (ddmr_cli/config/variants.py, the study's samples):
the parts rebuilt in place give the simulation the full path gives (the whole config copied, validated and built),
for every parameter of the default study's box at both ends of its range and every option; the same refusals;
the full path wherever a changed value could reach another section; and the study's per-process memo."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from omegaconf import OmegaConf

from ddmr_cli.config import compose_config, validate_config
from ddmr_cli.config.variants import BuiltParts, Variants, with_values
from ddmr_cli.engine.simulation import simulate
from ddmr_cli.errors import ConfigError
from ddmr_cli.study.setup import study_configs, study_models
from ddmr_cli.study.space import Box

#: the two controllers whose configs hold every key of the box (the NN keys: SMC-NDO-NNO's), in both scenarios
KEYS = [("smc_ndo_nno", "paper_1"), ("pid", "paper_2")]


@pytest.fixture(scope="module")
def study_cfg():
    return compose_config(["+experiment=sensitivity_oat", "simulation.duration=1.5", "metrics.settle_time=1.0",
                           "metrics.zone_settle_time=0.2"])


@pytest.fixture(scope="module")
def box(study_cfg):
    return Box.from_config(study_cfg.study)


@pytest.fixture(scope="module")
def variants(study_cfg):
    configs = study_configs(study_cfg)
    return {key: Variants(configs[key]) for key in KEYS}


def _readings(box):
    """For each parameter: its low and high end (each option of a choice), the others faithful."""
    for p in box.parameters:
        for value in (p.options if p.is_choice else (p.low, p.high)):
            yield p.name, value


def _plain(obj):
    """An object's values, recursively: arrays and tuples as lists, objects as their class and attributes."""
    if isinstance(obj, np.ndarray):
        return ["array", obj.dtype.str, obj.tolist()]
    if isinstance(obj, (list, tuple)):
        return [type(obj).__name__, [_plain(v) for v in obj]]
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if hasattr(obj, "__dict__") and not callable(obj):
        return [type(obj).__qualname__, _plain(vars(obj))]
    return obj


def _same_simulation(a, b) -> None:
    """Every field of the same classes and values (built in the same process: equal to the bit), the controllers'
    law parameters too."""
    from ddmr_cli.model.robot import NominalModel

    for field in dataclasses.fields(a):
        assert _plain(getattr(a, field.name)) == _plain(getattr(b, field.name)), field.name
    nominal = NominalModel.from_robot(a.robot)
    assert _plain(a.controller.law_parameters(nominal, a.dt)) == _plain(b.controller.law_parameters(nominal, b.dt))


@pytest.mark.parametrize("key", KEYS, ids=lambda k: "/".join(k))
def test_every_parameter_rebuilt_in_place_is_the_full_paths_simulation(key, box, variants):
    """Same machine, same code: the rebuilt simulation's per-seed metrics equal the full path's bit for bit."""
    base = variants[key]
    faithful = box.faithful_across([variants[KEYS[0]].cfg, base.cfg])
    seen = 0
    for name, value in _readings(box):
        values = box.key_values({name: value}, base.cfg)
        assert box.key_values({name: value}, base.cfg, base.value) == values  # the job's cached lookup
        if not values:  # a key this controller does not have (the NN's of PID)
            continue
        full = validate_config(box.apply({name: value}, base.cfg))
        fast = base.simulation_with(values)
        _same_simulation(fast, full)
        if name in ("dt", "roughness_scale", "nn_learning_rate", "switching", "integrator"):
            a, b = simulate(fast, [3, 4], bands=False, threads=1), simulate(full, [3, 4], bands=False, threads=1)
            for metric in ("deviation_mae", "chattering", "d_est_mae"):
                np.testing.assert_array_equal(a.metric(metric), b.metric(metric))
        seen += 1
    assert seen >= (20 if key[0] == "smc_ndo_nno" else 14)
    # the faithful reading changes nothing: the simulation built once
    assert base.simulation_with(box.key_values(faithful, base.cfg)) is base.simulation


def test_a_variant_shares_the_untouched_parts_and_leaves_them_as_they_were(variants):
    """A variant keeps the base's controller object when no controller key changed; simulating it leaves the
    base's numbers as they were (every simulate call starts the controller afresh)."""
    base = variants[("smc_ndo_nno", "paper_1")]
    first = simulate(base.simulation, [5, 6], bands=False, threads=1)
    other = base.simulation_with({"robot.max_voltage": 18.0, "terrain.correlation_time": 0.01})
    assert other.controller is base.simulation.controller and other.robot != base.simulation.robot
    simulate(other, [5, 6], bands=False, threads=1)
    again = simulate(base.simulation, [5, 6], bands=False, threads=1)
    for metric in ("deviation_mae", "d_est_mae", "chattering"):
        np.testing.assert_array_equal(first.metric(metric), again.metric(metric))


def test_configs_sharing_built_parts_get_each_its_own_simulation(study_cfg, box):
    """Configs that keep their built sections in one :class:`BuiltParts` (a study job's) get, for every reading,
    the simulation each builds alone: a section is reused across configs only where it is the same section with
    the same values (the robot, terrain and step sections of one sample), never another controller's."""
    configs = study_configs(study_cfg)
    keys = [("smc_ndo_nno", "paper_1"), ("smc_ndo", "paper_1"), ("pid", "paper_2"), ("smc_ndo", "paper_2")]
    parts = BuiltParts()
    shared = {key: Variants(configs[key], parts) for key in keys}
    alone = {key: Variants(configs[key]) for key in keys}
    readings = [{name: value} for name, value in _readings(box)]
    readings.append({p.name: (p.options[-1] if p.is_choice else p.high) for p in box.parameters})  # every key
    for reading in readings:
        for key in keys:
            values = box.key_values(reading, configs[key])
            if values:
                _same_simulation(shared[key].simulation_with(values), alone[key].simulation_with(values))
    assert parts.reused >= 20  # the configs' common sections were built once
    values = {"robot.max_voltage": 18.0, "controller.lam": [3.0, 3.0]}
    first = shared[keys[1]].simulation_with(values)
    again = shared[keys[3]].simulation_with(values)  # the same controller section in the other scenario
    assert again.robot is first.robot and again.controller is first.controller


@pytest.mark.parametrize("values", [{"robot.max_voltage": -1.0}, {"controller.nn.width": 0.0},
                                    {"simulation.dt": 0.05}, {"terrain.correlation_time": -0.1},
                                    {"simulation.integrator": "midpoint"}])
def test_a_refused_value_is_the_same_refusal(values, variants):
    base = variants[("smc_ndo_nno", "paper_1")]
    with pytest.raises(ConfigError) as full:
        validate_config(with_values(base.cfg, values))
    with pytest.raises(ConfigError) as fast:
        base.simulation_with(values)
    assert str(fast.value) == str(full.value)


def test_a_changed_value_that_flows_elsewhere_takes_the_full_path(study_cfg):
    """A model value that interpolates another: changing the one changes the other, as the full path does."""
    cfg = study_configs(study_cfg)[("smc_ndo_nno", "paper_1")]
    OmegaConf.update(cfg, "simulation.divergence_bound", "${robot.track_width}", merge=False)
    base = Variants(cfg)
    assert not base.in_place
    sim = base.simulation_with({"robot.track_width": 0.6})
    _same_simulation(sim, validate_config(with_values(cfg, {"robot.track_width": 0.6})))
    assert sim.divergence_bound == pytest.approx(0.6) and base.simulation.divergence_bound == pytest.approx(0.5)


@pytest.mark.parametrize("values", [{"controller.display.label": "other"}, {"run.n_runs": 3}])
def test_keys_outside_the_model_sections_take_the_full_path(values, variants, monkeypatch):
    import ddmr_cli.config.variants as module

    base = variants[("smc_ndo_nno", "paper_1")]
    calls = []
    monkeypatch.setattr(module, "validate_config", lambda cfg: calls.append(cfg) or validate_config(cfg))
    base.simulation_with(values)
    assert len(calls) == 1 and OmegaConf.select(calls[0], next(iter(values))) == next(iter(values.values()))


def test_the_study_builds_its_configs_once_per_process_and_config(study_cfg):
    """Jobs of one stage differ in their chunk (a calibration's trials in their reading): the same built configs;
    another study config: built anew."""
    first = study_models(study_cfg)
    again = study_models(with_values(study_cfg, {"study.chunk": 1}))
    other = study_models(with_values(study_cfg, {"run.n_runs": 5}))
    assert again[1] is first[1] and other[1] is not first[1]
    assert set(first[1]) == set(study_configs(study_cfg))


def test_values_key_tells_apart_what_a_simulation_could_tell_apart():
    """Two sets of values share a memo key only when they hold the same keys, in order, with values of the same
    types and bits."""
    from ddmr_cli.config.variants import values_key

    base = values_key({"robot.max_voltage": 24.0, "simulation.initial_pose": [0.1, -0.2, 0.0]})
    assert base == values_key({"robot.max_voltage": 24.0, "simulation.initial_pose": [0.1, -0.2, 0.0]})
    hash(base)
    for other in ({"robot.max_voltage": 24}, {"robot.max_voltage": True}, {"robot.max_voltage": 24.000000000000004},
                  {"robot.max_voltage": -0.0}, {"simulation.initial_pose": [0.1, -0.2, -0.0]},
                  {"simulation.initial_pose": [0.1, -0.2, 0.0], "robot.max_voltage": 24.0}):
        assert values_key(other) != base, other
    assert values_key({"a": 0.0}) != values_key({"a": -0.0})
    assert values_key({"controller.switching": "sign"}) != values_key({"controller.switching": "sat"})


def test_a_job_takes_an_identical_earlier_runs_numbers_to_the_bit(study_cfg, box):
    """A study job's memo (ddmr_cli/study/task.py RunMemo): samples that leave a config as an earlier sample left it
    (the network's parameters, for the controllers without one) take that config's numbers, equal to the bit to
    simulating it again; every config a sample changes is simulated. The kept arrays are read-only."""
    from ddmr_cli.study.task import RunMemo, simulate_sample

    _, configs, _ = study_models(study_cfg)
    seeds = [0, 1]
    samples = [{"nn_width": 2.0}, {"nn_width": 20.0}, {"nn_width": 2.0, "k_y": 30.0}, {"nn_learning_rate": 5.0}]
    memo = RunMemo(seeds)
    with_memo = [simulate_sample(box, configs, s, seeds, 1, memo) for s in samples]
    alone = [simulate_sample(box, configs, s, seeds, 1) for s in samples]
    nn = [key for key in configs if key[0] == "smc_ndo_nno"]
    others = [key for key in configs if key[0] != "smc_ndo_nno"]
    # sample 1 and 3 change only the network: the three other controllers' runs of sample 0 again
    assert memo.reused == 2 * len(others) * len(seeds)
    for (runs, n, diverged), (runs0, n0, diverged0) in zip(with_memo, alone):
        assert (n, diverged) == (n0, diverged0)
        for key in configs:
            for metric, values in runs[key].items():
                np.testing.assert_array_equal(values, runs0[key][metric], err_msg=f"{key} {metric}")
                assert not values.flags.writeable
    # the network's configs differ between the samples, and so do their numbers
    metric = next(iter(with_memo[0][0][nn[0]]))
    assert not np.array_equal(with_memo[0][0][nn[0]][metric], with_memo[1][0][nn[0]][metric])
    assert with_memo[0][0][others[0]][metric] is with_memo[1][0][others[0]][metric]
    assert not np.array_equal(with_memo[0][0][others[0]][metric], with_memo[2][0][others[0]][metric])
