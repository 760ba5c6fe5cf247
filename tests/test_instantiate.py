"""A config node built into model objects (ddmr_cli/config/build.py, ``instantiate_checked``): the direct
construction from the resolved node builds what Hydra's ``instantiate(node, _convert_="all")`` builds, for every
packaged controller and trajectory; a node that uses Hydra's other instantiation keys, and every failure, are
Hydra's own."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from omegaconf import OmegaConf

from ddmr_cli.config import compose_config
from ddmr_cli.config import build
from ddmr_cli.errors import ConfigError

CONF = Path(build.__file__).resolve().parents[2] / "conf"
CONTROLLERS = sorted(p.stem for p in (CONF / "controller").glob("*.yaml"))
TRAJECTORIES = sorted(p.stem for p in (CONF / "trajectory").glob("*.yaml"))


def _by_hydra(node):
    """What Hydra's instantiate builds of the node, its interpolations resolved in the whole config first (a copy
    of a part loses the rest) and its ``display`` node left out, as ``instantiate_checked`` leaves it out."""
    root = node._get_root()
    resolved = OmegaConf.create(OmegaConf.to_container(root, resolve=True))
    node = OmegaConf.select(resolved, node._get_full_key(None))
    keys = [k for k in node.keys() if k != "display"]
    return instantiate(OmegaConf.masked_copy(node, keys) if len(keys) < len(node) else node, _convert_="all")


def _same(a, b, where="object") -> None:
    """``a`` and ``b`` are the same build: the same class and, attribute by attribute, the same values (both made by
    the same constructors from the same numbers in this process, so equal to the bit)."""
    assert type(a) is type(b), f"{where}: {type(a).__name__} != {type(b).__name__}"
    if isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), where
    elif isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            _same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif hasattr(a, "__dict__") and not isinstance(a, type):
        _same(vars(a), vars(b), f"{where}.__dict__")
    elif isinstance(a, float) and a != a:
        assert b != b, where
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


@pytest.mark.parametrize("name", CONTROLLERS)
def test_every_packaged_controller_is_built_as_hydra_builds_it(name):
    node = compose_config([f"controller={name}"]).controller
    _same(build.instantiate_checked(node, "controller"), _by_hydra(node), name)


@pytest.mark.parametrize("name", TRAJECTORIES)
def test_every_packaged_trajectory_is_built_as_hydra_builds_it(name):
    node = compose_config([f"trajectory={name}"]).trajectory
    _same(build.instantiate_checked(node, "trajectory"), _by_hydra(node), name)


def test_overridden_and_interpolated_values_are_built_as_hydra_builds_them():
    cfg = compose_config(["controller=smc_ndo_nno", "controller.switching_gain=7.5", "controller.nn.n_neurons=4",
                          "controller.ndo.gain=${controller.lam}"])
    built = build.instantiate_checked(cfg.controller, "controller")
    _same(built, _by_hydra(cfg.controller))
    assert built.parameters()["K"] == 7.5
    # an interpolation to another key of the config resolves (Hydra's instantiate of the controller's copy without
    # its display node lost the rest of the config: the run stopped with "ddmr: error: ?: None")
    assert built.parameters()["L"] == 25.0


def test_the_direct_construction_is_what_runs(monkeypatch):
    """The packaged controllers never reach Hydra's instantiate (the direct construction is not a dead path)."""
    import hydra.utils

    def refuse(*args, **kwargs):
        raise AssertionError("Hydra's instantiate was called")

    monkeypatch.setattr(hydra.utils, "instantiate", refuse)
    node = compose_config(["controller=smc_ndo_nno"]).controller
    assert type(build.instantiate_checked(node, "controller")).__name__ == "SMC"


def test_a_node_with_another_instantiation_key_is_hydras():
    node = OmegaConf.create({"_target_": "ddmr_cli.model.trajectory.StraightLine", "_partial_": True,
                             "speed": 0.5, "heading": 0.0, "x0": 0.0, "y0": 0.0})
    built = build.instantiate_checked(node, "trajectory")
    assert isinstance(built, functools.partial) and built.keywords["speed"] == 0.5


def test_a_constructor_that_refuses_its_arguments_fails_as_in_hydra():
    node = OmegaConf.create({"_target_": "ddmr_cli.model.trajectory.StraightLine", "speed": 0.5, "bogus": 1.0})
    with pytest.raises(InstantiationException) as ours:
        build.instantiate_checked(node, "trajectory")
    with pytest.raises(InstantiationException) as hydras:
        instantiate(node, _convert_="all")
    assert str(ours.value) == str(hydras.value)


def test_a_constructors_config_error_still_names_the_key():
    cfg = compose_config(["controller=smc_ndo_nno", "controller.nn.n_neurons=0"])
    with pytest.raises(ConfigError) as refused:
        build.build_simulation(cfg)
    assert "n_neurons" in str(refused.value)


def test_a_target_outside_the_project_is_still_refused():
    node = OmegaConf.create({"_target_": "os.system", "command": "true"})
    with pytest.raises(ConfigError, match="only ddmr_cli"):
        build.instantiate_checked(node, "trajectory")


def test_a_refused_value_reached_through_an_interpolation_names_its_key():
    """A constructor's refusal of a value that an interpolation gave is the key's one-line error (before, Hydra's
    instantiate of the node's copy could not resolve the interpolation: "ddmr: error: ?: None")."""
    cfg = compose_config(["controller=smc_ndo_nno", "controller.ndo.gain=${controller.lam}", "controller.lam=-1"])
    with pytest.raises(ConfigError) as refused:
        build.build_simulation(cfg)
    assert refused.value.key == "controller.ndo.gain" and "must be > 0" in str(refused.value)
