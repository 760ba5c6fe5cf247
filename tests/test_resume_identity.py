"""Resume identity (issue 27, "tests that cannot fail"): a job dir holding complete results is skipped only when the
config asks for the same numbers; any value that changes them forces a rerun.

``ddmr run`` (here its console-script function, in process) into a dir with a complete job compares the config's hash (every key except the display keys,
:data:`DISPLAY_KEYS`) with the one the job recorded, and skips the job only when they agree and every file is
verified. Before this file only the slow tier changed a value and resumed (tests/test_cli.py), and the fast tier
checked the hash for two keys, so dropping the hash comparison, or a whole group from the hash, survived it.
"""

from __future__ import annotations

import copy
import json
from importlib.metadata import entry_points
from pathlib import Path

import pandas as pd
import pytest
from omegaconf import OmegaConf

from ddmr_cli import compose_config
from ddmr_cli.config import config_hash

#: a job of 2 seeds and 0.05 s (50 steps)
TINY = ["controller=pid", "run.n_runs=2", "simulation.duration=0.05", "run.plots=false", "run.progress=false"]

#: the keys documented as not changing the numbers (display, resources, labels): the only ones outside the hash
DISPLAY_KEYS = ("run.plots", "run.progress", "run.threads", "run.max_memory_gb", "experiment_name", "cluster",
                "report", "tags", "controller.display")


def _ddmr():
    """The ``ddmr`` console script's function, in this process (found by its entry point, wherever it lives)."""
    return next(iter(entry_points(group="console_scripts", name="ddmr"))).load()


def _run(job: Path, *overrides: str) -> tuple[bool, pd.DataFrame]:
    """``ddmr run`` into ``job``: whether it kept the complete job there (its summary untouched), and the table."""
    summary = job / "summary.json"
    before = summary.read_bytes() if summary.exists() else None
    assert _ddmr()(["run", *TINY, *overrides, f"hydra.run.dir={job}"]) in (0, None)
    return summary.read_bytes() == before, pd.read_csv(job / "metrics.csv")


def test_resuming_a_job_reruns_it_exactly_when_a_value_changes(tmp_path):
    job = tmp_path / "job"
    kept, first = _run(job)
    assert not kept
    kept, same = _run(job)
    assert kept  # the control: an unchanged config is not rerun
    pd.testing.assert_frame_equal(same, first, check_exact=True)
    previous = first
    for change, differs in [("controller.kp=6.0", "deviation_mae"), ("run.n_runs=3", "seed"),
                            ("simulation.duration=0.06", "deviation_mae")]:
        kept, table = _run(job, change)
        assert not kept, f"{change}: the complete job of another config was kept"
        assert len(table) != len(previous) or not table[differs].equals(previous[differs]), change
        assert json.loads((job / "summary.json").read_text())["overrides"][-1] == change
        previous = table
    kept, again = _run(job, change)  # the changed config, complete now, is skipped in turn
    assert kept
    pd.testing.assert_frame_equal(again, previous, check_exact=True)


# --- the hash: every key but the display keys ----------------------------------------------------------------


def _leaves(node, path=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _leaves(value, (*path, str(key)))
    else:
        yield path, node


def _changed(value):
    """Another value of the same kind."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, (int, float)):
        return value * 2 + 1
    if isinstance(value, str):
        return value + "_x"
    if isinstance(value, list):
        return [*value, 1]
    return 1  # None


def _display(path: tuple) -> bool:
    dotted = ".".join(path)
    return any(dotted == key or dotted.startswith(key + ".") for key in DISPLAY_KEYS)


@pytest.mark.parametrize("overrides", [[], ["+tune=smc_ndo_nno"], ["controller=sta_ndo", "scenario=paper_2",
                                                                   "sensor=noisy", "actuator=realistic"]],
                         ids=["default", "tuning-study", "sta-noisy"])
def test_every_value_outside_the_display_keys_changes_the_config_hash(overrides):
    """Walk every leaf of the composed config (hydra's node aside): changing it changes the hash unless it is a
    display key, and changing a display key leaves the hash alone."""
    cfg = compose_config(overrides)
    base = OmegaConf.to_container(cfg, resolve=True)
    digest = config_hash(cfg)
    leaves = list(_leaves(base))
    assert len(leaves) > 60
    missed, leaked = [], []
    for path, value in leaves:
        edited = copy.deepcopy(base)
        node = edited
        for part in path[:-1]:
            node = node[part]
        node[path[-1]] = _changed(value)
        same = config_hash(OmegaConf.create(edited)) == digest
        if _display(path) and not same:
            leaked.append(".".join(path))
        if not _display(path) and same:
            missed.append(".".join(path))
    assert missed == [], f"values that change the numbers but not the hash (a resume would keep old results): {missed}"
    assert leaked == [], f"display keys that change the hash (a resume would rerun for nothing): {leaked}"


@pytest.mark.parametrize("override", [
    "controller.switching_gain=11", "controller.nn.width=3", "controller.ndo.gain=40", "run.n_runs=49",
    "run.base_seed=1", "run.keep_series=all", "run.bands=false", "simulation.duration=14", "simulation.dt=0.0005",
    "simulation.integrator=rk4", "simulation.initial_pose=[0.0,0.0,0.0]", "simulation.divergence_bound=2",
    "robot.mass=16", "terrain.zones.flat.roughness=0.2", "terrain.correlation_time=0.03", "scenario=paper_2",
    "trajectory=circle", "outer_loop.k_y=20", "sensor=encoder", "actuator=pwm8", "control.rate=500",
    "metrics.settle_time=2", "metrics.zone_settle_time=0.5",
])
def test_a_value_of_every_group_is_in_the_hash(override):
    """One documented key per config group, composed as on the command line (so a group dropped from the hash
    fails here by name, whatever the list of display keys says)."""
    assert config_hash(compose_config([override])) != config_hash(compose_config())
