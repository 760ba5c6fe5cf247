"""The physics plant's speed (``plant=mujoco``, docs/model.md §13) for ``ddmr bench`` and
``benchmarks/physics_plant.py speed``: a batch of runs on the paper terrain under a proportional wheel-speed loop with
the nominal feed-forward, timed in the MuJoCo steps, in the rest of the plant's step and in the loop around it.
Needs the physics extra."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

__all__ = ["PlantSpeed", "plant_config", "plant_throughput"]

#: the wheel-speed loop's gain [V s/rad] and the runs' cruise speed [m/s]
GAIN, SPEED = 2.0, 1.0


@dataclass(frozen=True)
class PlantSpeed:
    """One timed batch: ``runs`` x ``steps`` plant steps in ``wall`` seconds, of which ``mujoco`` in the MuJoCo steps
    and ``plant`` in the rest of the plant's step (its own Python: the true d, divergence); the rest is the loop."""

    runs: int
    steps: int
    threads: int
    reset: float
    wall: float
    mujoco: float
    plant: float
    diverged: int

    @property
    def rate(self) -> float:
        """Plant steps per second (runs x steps / wall)."""
        return self.runs * self.steps / self.wall


def plant_config(**overrides) -> dict:
    """The packaged ``plant=mujoco`` config as composed (``conf/plant/mujoco.yaml`` on its schema), top-level keys
    replaced by ``overrides``."""
    from omegaconf import OmegaConf

    from ddmr_cli.config.presets import paper_config

    return {**OmegaConf.to_container(paper_config("plant=mujoco").plant, resolve=True), **overrides}


def plant_throughput(runs: int, seconds: float, threads: int = 0) -> PlantSpeed:
    """Time ``runs`` runs of ``seconds`` each at dt = 1 ms on the paper terrain, started in turn in the flat, the very
    rough and the slightly rough zone (the packaged robot, terrain and plant configs; ``threads`` as
    ``plant.threads``)."""
    from ddmr_cli.config.presets import paper_robot, paper_terrain
    from ddmr_cli.plant.mujoco import MujocoPlant

    rob = paper_robot()
    plant = MujocoPlant(rob, paper_terrain("paper"), plant_config(threads=threads), 0.001)
    started = time.perf_counter()
    x0 = np.array([1.0, 6.0, 11.0])[np.arange(runs) % 3]
    w_d = np.full((runs, 2), SPEED / rob.wheel_radius)
    plant.reset(np.arange(runs), np.column_stack([x0, np.zeros(runs), np.zeros(runs)]), w_d)
    reset = time.perf_counter() - started
    steps = int(round(seconds / plant.dt))
    feed, limit, scale = rob.damping / rob.voltage_gain * w_d, rob.max_voltage, np.ones(runs)
    started = time.perf_counter()
    for _ in range(steps):
        plant.step(np.clip(feed + GAIN * (w_d - plant.state()["w"]), -limit, limit), scale)
    wall = time.perf_counter() - started
    seconds_in = plant.timing()
    speed = PlantSpeed(runs, steps, plant.threads, reset, wall, seconds_in["mujoco"],
                       seconds_in["step"] - seconds_in["mujoco"], int(plant.diverged().sum()))
    plant.close()
    return speed
