"""Every controller YAML runs (issue 27): each ``conf/controller/*.yaml`` that exists, composed with Hydra's
``initialize_config_module``/``compose`` as the command line does, builds the class its ``_target_`` names and
runs 2 seeds for 0.05 s with finite metrics. Parametrised over the files, so a new controller YAML is tested
without editing this file.

The runs go through the numba JIT here (the loop every user runs). A controller's first run compiles its step
loop (about 10 s, once per machine and source version: the loop is cached on disk); most of the loops are
compiled by the rest of the fast tier anyway.
"""

from __future__ import annotations

import math
from importlib.resources import files

import numpy as np
import pytest
from hydra import compose, initialize_config_module
from hydra.utils import get_class

from ddmr_cli import run_config
from ddmr_cli.config import build_simulation  # also registers the schemas and the sweeper plugin

CONFIG_MODULE = "ddmr_cli.conf"
CONTROLLERS = files(CONFIG_MODULE) / "controller"
YAMLS = sorted(p.name[:-len(".yaml")] for p in CONTROLLERS.iterdir() if p.name.endswith(".yaml"))
SHORT = ["run.n_runs=2", "simulation.duration=0.05", "run.keep_series=none", "run.bands=false"]


def _compose(overrides):
    with initialize_config_module(config_module=CONFIG_MODULE, version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def test_the_yamls_are_found_and_subdirectories_are_observer_groups():
    assert {"pid", "smc", "smc_ndo", "smc_ndo_nno", "open_loop"} <= set(YAMLS)
    # a subdirectory is a group nested in a controller (conf/controller/ndo: the NDO of the SMC family), not a
    # controller: the controller that selects its option carries it as a node of that name
    for sub in (p for p in CONTROLLERS.iterdir() if p.is_dir() and not p.name.startswith("__")):
        users = [name for name in YAMLS if _compose([f"controller={name}"]).controller.get(sub.name) is not None]
        assert users, f"conf/controller/{sub.name}/ is neither a controller nor a group any controller uses"


@pytest.mark.parametrize("name", YAMLS)
def test_every_controller_yaml_composes_builds_its_class_and_runs(name):
    cfg = _compose([f"controller={name}", *SHORT])
    node = cfg.controller
    result = run_config(cfg)
    # the class the YAML names (its _target_, with its observers' own), built as run_config builds it
    controller = build_simulation(cfg).controller
    assert type(controller) is get_class(node._target_)
    for part in ("ndo", "nn"):
        sub = node.get(part) if part in node else None
        built = getattr(controller, part, None)
        assert (built is None) == (sub is None), part
        if sub is not None:
            assert type(built) is get_class(sub._target_), part
    if "name" in node:  # the label in tables and plots is the file's name
        assert node.name == name and result.controller == name
    assert result.seeds == [0, 1] and not result.diverged.any()
    assert result.duration == pytest.approx(0.05)
    metrics = {k: v for k, v in result.metrics.items()}
    assert len(metrics) > 20
    for key in ("deviation_mae", "e_y_mae", "chattering", "mean_voltage", "saturation_fraction", "energy_u2"):
        values = result.metric(key)
        assert values.shape == (2,) and np.all(np.isfinite(values)), (key, values)
    assert all(math.isfinite(v) for v in result.metric("deviation_max")) and result.metric("deviation_max").max() < 1.0
