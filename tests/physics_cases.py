"""The physics plant's validation cases (issue 30), shared by tests/test_physics_plant.py and
benchmarks/physics_plant.py: the configs as shipped, and the flat-ground step response against the nominal 2x2 model.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from scipy.linalg import expm

from ddmr_cli.model.robot import Robot
from ddmr_cli.model.terrain import Terrain, TerrainZone

CONF = Path(__file__).parents[1] / "conf"

#: the step response's voltages (right, left) [V]: unequal, so both the common and the differential mode (the
#: off-diagonal J_q, hence m and I_z separately) are excited
STEP_VOLTAGE = (6.0, 3.0)


def load(group: str, name: str) -> dict:
    """A config file of ``conf/<group>/<name>.yaml`` as a dict (without Hydra's ``defaults``)."""
    return {k: v for k, v in yaml.safe_load((CONF / group / f"{name}.yaml").read_text()).items() if k != "defaults"}


def robot() -> Robot:
    return Robot(**load("robot", "paper"))


def terrain(name: str = "paper") -> Terrain:
    t = load("terrain", name)
    return Terrain([TerrainZone(str(k), float(z["start"]), float(z["roughness"]), float(z["mu"]))
                    for k, z in t["zones"].items()], float(t["correlation_time"]))


def plant_config(**overrides) -> dict:
    """conf/plant/mujoco.yaml with dotted overrides (``heightfield__resolution=0.02`` sets heightfield.resolution)."""
    cfg = load("plant", "mujoco")
    for key, value in overrides.items():
        *path, last = key.split("__")
        node = cfg
        for k in path:
            node = node[k]
        node[last] = value
    return cfg


def nominal_step_response(rob: Robot, u, t: np.ndarray) -> np.ndarray:
    """The nominal model's wheel speeds ``(len(t), 2)`` from rest under the constant voltage ``u``: the exact
    solution of ``w' = -A w + g u``, ``w(t) = (I - e^{-A t}) A^-1 g u``."""
    A, g = rob.drift_matrix, rob.input_matrix
    w_ss = np.linalg.solve(A, g @ np.asarray(u, dtype=float))
    return np.array([w_ss - expm(-A * tk) @ w_ss for tk in t])


def physics_step_response(plant, u, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The plant's ``(t, w, d)`` from rest under the constant voltage ``u`` (one run, seed 0, at the origin):
    times ``(K + 1,)``, wheel speeds ``(K + 1, 2)`` and the true disturbance of each step ``(K, 2)``."""
    plant.reset(np.array([0]), np.zeros((1, 3)), np.zeros((1, 2)))
    steps = int(round(duration / plant.dt))
    w, d = np.zeros((steps + 1, 2)), np.zeros((steps, 2))
    for k in range(steps):
        plant.step(np.array([u], dtype=float), np.ones(1))
        w[k + 1], d[k] = plant.state()["w"][0], plant.true_disturbance()[0]
    return np.arange(steps + 1) * plant.dt, w, d
