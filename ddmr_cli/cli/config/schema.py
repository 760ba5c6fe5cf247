"""Typed config schemas (dataclasses registered in Hydra's ConfigStore); the values live in ``conf/`` YAML.

Each YAML file of a group starts from its schema (``defaults: [/schema_<name>@_here_]``), so a
misspelt key or a wrong type is refused when the config is composed. Per-wheel gains accept a number or a
``[right, left]`` pair, hence ``Any``; :mod:`ddmr_cli.cli.config.validate` checks the values.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING


@dataclass
class RobotConfig:
    """Paper Table 2 plus motor constants (MODEL.md 1). Fields as :class:`ddmr_cli.model.robot.Robot`."""

    mass: float = MISSING
    wheel_radius: float = MISSING
    track_width: float = MISSING
    yaw_inertia: float = MISSING
    wheel_inertia: float = MISSING
    torque_constant: float = MISSING
    back_emf_constant: float = MISSING
    armature_resistance: float = MISSING
    viscous_friction: float = MISSING
    max_voltage: float = MISSING


@dataclass
class ZoneConfig:
    start: float = MISSING  # m of distance travelled
    roughness: float = MISSING  # rad/s^2, scales the unit OU process
    mu: float = MISSING  # rolling-resistance coefficient


@dataclass
class TerrainConfig:
    name: str = MISSING
    correlation_time: float = 0.02
    zones: Dict[str, ZoneConfig] = field(default_factory=dict)


@dataclass
class PhaseConfig:
    start: float = MISSING  # s
    roughness: bool = True
    uncertainty: bool = False


@dataclass
class UncertaintyConfig:
    correlation_time: float = 0.5
    std: float = 0.4
    low: float = -0.5
    high: float = 1.0


@dataclass
class ScenarioConfig:
    name: str = MISSING
    phases: Dict[str, PhaseConfig] = field(default_factory=dict)
    uncertainty: UncertaintyConfig = field(default_factory=UncertaintyConfig)


@dataclass
class NDOConfig:
    _target_: str = "ddmr_cli.control.NonlinearDisturbanceObserver"
    gain: Any = 50.0


@dataclass
class NNConfig:
    _target_: str = "ddmr_cli.control.RBFNetworkObserver"
    n_neurons: int = 10
    width: float = 2.0
    learning_rate: Any = 50.0
    center_min: float = -40.0
    center_max: float = 40.0


@dataclass
class PIDConfig:
    _target_: str = "ddmr_cli.control.PID"
    kp: Any = 5.0
    ki: Any = 0.1
    kd: Any = 0.01
    anti_windup: bool = True


@dataclass
class SMCConfig:
    _target_: str = "ddmr_cli.control.SMC"
    name: str = "smc"
    lam: Any = 25.0
    switching_gain: Any = 12.0
    boundary_layer: float = 0.1
    surface: str = "proportional"
    switching: str = "sat"
    ndo: Optional[NDOConfig] = None
    nn: Optional[NNConfig] = None


@dataclass
class OpenLoopConfig:
    _target_: str = "ddmr_cli.control.OpenLoop"
    voltage: Any = 0.0


@dataclass
class LineConfig:
    _target_: str = "ddmr_cli.model.trajectory.StraightLine"
    speed: float = 1.0
    heading: float = 0.0
    x0: float = 0.0
    y0: float = 0.0


@dataclass
class CircleConfig:
    _target_: str = "ddmr_cli.model.trajectory.Circle"
    speed: float = 1.0
    radius: float = 2.0


@dataclass
class FigureEightConfig:
    _target_: str = "ddmr_cli.model.trajectory.FigureEight"
    amplitude: float = 3.0
    period: float = 30.0


@dataclass
class OuterLoopConfig:
    """Kanayama gains (MODEL.md 3)."""

    k_x: float = 10.0
    k_y: float = 25.0
    k_theta: float = 10.0


@dataclass
class SimulationConfig:
    dt: float = 1e-3
    duration: float = 15.0
    integrator: str = "euler"
    initial_pose: List[float] = field(default_factory=lambda: [0.0, 0.05, 0.05])
    initial_wheel_speeds: Any = "reference"
    divergence_bound: float = 1.0


@dataclass
class RunConfig:
    n_runs: int = 50
    base_seed: int = 0
    keep_series: List[int] = field(default_factory=lambda: [0])
    plots: bool = True
    progress: bool = True
    threads: int = 0


@dataclass
class DDMRConfig:
    robot: RobotConfig = MISSING
    terrain: TerrainConfig = MISSING
    controller: Any = MISSING
    scenario: ScenarioConfig = MISSING
    trajectory: Any = MISSING
    outer_loop: OuterLoopConfig = field(default_factory=OuterLoopConfig)
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    run: RunConfig = field(default_factory=RunConfig)
    experiment_name: str = "run"
    #: launcher settings set by conf/launcher presets (partition, time_min, cpus, mem_gb, ...)
    cluster: Dict[str, Any] = field(default_factory=dict)


def register_configs() -> None:
    """Register the schemas; idempotent."""
    cs = ConfigStore.instance()
    cs.store(name="ddmr_schema", node=DDMRConfig)
    for name, node in [
        ("robot", RobotConfig), ("terrain", TerrainConfig), ("scenario", ScenarioConfig),
        ("controller_pid", PIDConfig), ("controller_smc", SMCConfig), ("controller_open_loop", OpenLoopConfig),
        ("trajectory_line", LineConfig), ("trajectory_circle", CircleConfig),
        ("trajectory_figure_eight", FigureEightConfig),
    ]:
        # root-level names (not groups), so `ddmr run --help` lists only the real options
        cs.store(name=f"schema_{name}", node=node)


register_configs()
