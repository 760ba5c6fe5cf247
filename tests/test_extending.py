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


def _user_package(root: Path, target_class: str = "ComputedTorquePI") -> tuple[Path, Path]:
    """The page's module in a package of the user's own (not under ddmr_cli) and its YAML in the user's config dir,
    as the page's "In your own package" paragraph says: returns (PYTHONPATH entry, config dir)."""
    text = PAGE.read_text(encoding="utf-8")
    package = root / "src" / "mylab"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("", encoding="utf-8")
    (package / "ct.py").write_text(re.search(r"<!-- extending:module -->\n```python\n(.*?)```", text, re.S).group(1),
                                   encoding="utf-8")
    conf = root / "myconf" / "controller"
    conf.mkdir(parents=True)
    page_yaml = re.search(r"<!-- extending:yaml -->\n```yaml\n(.*?)```", text, re.S).group(1)
    (conf / "computed_torque.yaml").write_text(
        page_yaml.replace("ddmr_cli.control.computed_torque.ComputedTorquePI", f"mylab.ct.{target_class}"),
        encoding="utf-8")
    return root / "src", root / "myconf"


def test_the_page_s_controller_runs_through_the_cli_from_the_user_s_own_package(tmp_path):
    """docs/extending.md's path, on the command line: the module outside ddmr_cli on PYTHONPATH, its YAML (the
    page's, unchanged but for the target) in a --config-dir; the run completes and its gains are the YAML's."""
    from conftest import run_ddmr

    src, conf = _user_package(tmp_path)
    out = tmp_path / "run"
    proc = run_ddmr(["run", "--config-dir", str(conf), "controller=computed_torque", "run.n_runs=2",
                     "simulation.duration=0.05", "run.plots=false", f"hydra.run.dir={out}"], cwd=tmp_path,
                    env={"PYTHONPATH": str(src)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    saved = yaml.safe_load((out / "config.yaml").read_text())
    assert saved["controller"]["_target_"] == "mylab.ct.ComputedTorquePI"
    assert (saved["controller"]["kp"], saved["controller"]["ki"]) == (40.0, 400.0)
    import pandas as pd

    metrics = pd.read_csv(out / "metrics.csv")
    assert len(metrics) == 2 and np.isfinite(metrics.deviation_mae).all()


def test_a_user_target_that_is_not_a_controller_is_refused_naming_the_key(tmp_path):
    from conftest import run_ddmr

    src, conf = _user_package(tmp_path, target_class="ComputedTorqueParameters")
    proc = run_ddmr(["run", "--config-dir", str(conf), "controller=computed_torque", f"hydra.run.dir={tmp_path / 'r'}"],
                    cwd=tmp_path, env={"PYTHONPATH": str(src)})
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1].startswith(
        "ddmr: error: controller._target_='mylab.ct.ComputedTorqueParameters': only ddmr_cli.* classes")
    assert not (tmp_path / "r").exists()


def test_a_users_module_importing_the_plants_laws_from_their_old_module_still_runs_them():
    """The plant's laws moved from model/robot.py to model/dynamics.py (robot.py then loads no numba, for the
    report): a user's controller written against the old page imports them from robot still, gets the same law,
    and is told where it went; a name robot never had is an AttributeError."""
    import importlib

    from ddmr_cli.model import dynamics, robot

    for name in robot.MOVED_TO_DYNAMICS:
        with pytest.warns(DeprecationWarning, match=f"ddmr_cli.model.robot.{name} has moved"):
            assert getattr(importlib.import_module("ddmr_cli.model.robot"), name) is getattr(dynamics, name)
    with pytest.raises(AttributeError):
        robot.no_such_law
