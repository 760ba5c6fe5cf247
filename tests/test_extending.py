"""docs/extending.md's worked example, taken from the page and run: a new controller is one module (plus YAML)
and runs compiled through the unchanged engine, with its closed-form behaviour."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from paper import make_simulation, make_terrain
from ddmr_cli import paper_terrain
from ddmr_cli import Simulation, Terrain, TerrainZone, simulate

PAGE = Path(__file__).resolve().parents[1] / "docs" / "extending.md"


@pytest.fixture(scope="module")
def computed_torque(tmp_path_factory):
    text = PAGE.read_text(encoding="utf-8")
    source = re.search(r"<!-- extending:module -->\n```python\n(.*?)```", text, re.S).group(1)
    stated = int(re.search(r"computed_torque\.py` \((\d+) lines\)", text).group(1))
    assert len(source.strip().splitlines()) == stated  # the page's line count is the listing's
    root = tmp_path_factory.mktemp("user_controller")
    (root / "user_computed_torque.py").write_text(source, encoding="utf-8")
    sys.path.insert(0, str(root))
    gains = yaml.safe_load(re.search(r"<!-- extending:yaml -->\n```yaml\n(.*?)```", text, re.S).group(1))
    try:
        module = importlib.import_module("user_computed_torque")
        # the page's YAML is where the gains live: build the controller from it
        module.from_page = lambda **values: module.ComputedTorquePI(
            **{**{k: gains[k] for k in ("kp", "ki")}, **values})
        yield module
    finally:
        sys.path.remove(str(root))


def test_zero_disturbance_and_zero_initial_error_keep_every_error_at_zero(computed_torque):
    sim = make_simulation(controller=computed_torque.from_page(), terrain=paper_terrain("none"), duration=1.0,
                     initial_pose=(0.0, 0.0, 0.0))
    s = simulate(sim, [0], keep_series=[0]).series[0]
    assert np.max(np.abs(s["deviation"])) < 1e-12
    assert np.max(np.abs(s["s_right"])) < 1e-10 and np.max(np.abs(s["s_left"])) < 1e-10


def test_the_integral_removes_a_constant_disturbance(computed_torque):
    sand = make_terrain(TerrainZone("sand", 0.0, 0.0, 0.05))  # constant rolling resistance, no roughness
    sim = make_simulation(controller=computed_torque.from_page(), terrain=sand, duration=2.0,
                     initial_pose=(0.0, 0.0, 0.0))
    s = simulate(sim, [0], keep_series=[0]).series[0]
    early, late = np.max(np.abs(s["s_right"][:200])), np.max(np.abs(s["s_right"][-200:]))
    assert early > 1e-3  # the disturbance does push the wheels off their reference at first
    assert late < early * 1e-3


def test_bad_gain_is_refused_naming_the_key(computed_torque):
    from ddmr_cli import ConfigError

    with pytest.raises(ConfigError, match=r"controller\.kp=-1"):
        computed_torque.from_page(kp=-1)
