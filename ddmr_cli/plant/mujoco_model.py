"""The MuJoCo model of the paper's robot and terrain, generated from the configs (docs/model.md §13, "Physics
plant (MuJoCo)"). Plain Python and numpy: this module writes the MJCF text and the heightfield; it never imports mujoco.

The robot: a chassis on a free joint whose origin is the axle midpoint, two hinge-driven wheels on the axle
(right at ``y = -L``, left at ``y = +L``; positive speed drives forward) and two frictionless ball casters on the
centre line, each on a vertical spring (a slide joint) that carries no load at rest, so the wheels carry the
weight and the springs hold the chassis's pitch. Mass and inertia are placed so that the model's wheel-space inertia equals the paper's J
(:attr:`ddmr_cli.model.robot.Robot.inertia`): total mass ``m``, total yaw inertia ``I_z`` about the axle
midpoint, centre of mass on the axle, each wheel's spin inertia ``I_w`` (the wheel body's thin-disc inertia plus
the joint armature, the reflected motor and gearbox inertia). Each motor is a pair of MuJoCo ``general`` actuators
that together apply the DC-motor law ``tau = K_u u - b B w`` (:func:`motor_gains`); a touch sensor on each wheel
tells whether it is on the ground.

The terrain: a Gaussian-correlated random heightfield along x with the terrain config's zones, one heightfield
geom per zone so each zone has its own rolling friction (:func:`zone_friction`), heights drawn from the run's seed
(:func:`heightfield`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping, Sequence

import numpy as np

from ddmr_cli.checks import finite, integer, non_negative, one_of, positive
from ddmr_cli.errors import ConfigError
from ddmr_cli.model.robot import GRAVITY, Robot
from ddmr_cli.model.scenario import Scenario
from ddmr_cli.model.terrain import Terrain

__all__ = ["HeightfieldConfig", "WheelConfig", "CasterConfig", "ChassisConfig", "ContactConfig", "DivergenceConfig",
           "PhysicsConfig", "FieldLayout", "field_layout", "check_robot", "check_reference", "substeps", "slope_gain",
           "height_sd", "zone_friction", "motor_gains", "heightfield", "rough_phases", "amplitude", "normalised",
           "mjcf", "TERRAIN_STREAM", "WHEEL_SHAPES"]

#: the spawn key that derives a run's heightfield from its seed (child 2 of ``SeedSequence(seed)``; child 1 is
#: the sensor's stream, :data:`ddmr_cli.model.noise.SENSOR_STREAM`)
TERRAIN_STREAM = 2

WHEEL_SHAPES = ("sphere", "cylinder")


def _section(cls, key: str, values: Any):
    """``cls`` from the mapping ``values`` at config key ``key``: every field present, no other key."""
    if not isinstance(values, Mapping) and type(values).__name__ != "DictConfig":
        raise ConfigError(key, values, "must be a mapping")
    names = [f.name for f in fields(cls)]
    for k in values:
        if k not in names:
            raise ConfigError(f"{key}.{k}", values[k], f"unknown key (known: {', '.join(names)})")
    for name in names:
        if name not in values:
            raise ConfigError(f"{key}.{name}", None, "is missing")
    return cls(**{name: values[name] for name in names})


@dataclass(frozen=True)
class HeightfieldConfig:
    """The heightfield's extent and the roughness-to-height mapping (docs/model.md §13)."""

    resolution: float          # m
    x_min: float               # m
    x_max: float               # m
    half_width: float          # m
    origin: float              # m
    correlation_length: float  # m
    truncation: float          # unitless
    ramp: float                # m

    def __post_init__(self) -> None:
        k = "plant.heightfield"
        positive(f"{k}.resolution", self.resolution)
        finite(f"{k}.x_min", self.x_min)
        finite(f"{k}.x_max", self.x_max)
        positive(f"{k}.half_width", self.half_width)
        finite(f"{k}.origin", self.origin)
        positive(f"{k}.correlation_length", self.correlation_length)
        positive(f"{k}.truncation", self.truncation)
        non_negative(f"{k}.ramp", self.ramp)
        if self.x_max <= self.x_min:
            raise ConfigError(f"{k}.x_max", self.x_max, f"must be > plant.heightfield.x_min ({self.x_min:g})")
        if not self.x_min < self.origin < self.x_max:
            raise ConfigError(f"{k}.origin", self.origin,
                              f"must lie inside the field ({self.x_min:g}, {self.x_max:g}) m")
        if self.resolution > self.correlation_length / 2:
            raise ConfigError(f"{k}.resolution", self.resolution,
                              f"too coarse for the correlation length: must be <= correlation_length / 2 = "
                              f"{self.correlation_length / 2:g} m")


@dataclass(frozen=True)
class WheelConfig:
    shape: str
    mass: float                # kg
    width: float               # m
    friction: float            # unitless
    torsional_friction: float  # m

    def __post_init__(self) -> None:
        one_of("plant.wheel.shape", self.shape, WHEEL_SHAPES)
        positive("plant.wheel.mass", self.mass)
        positive("plant.wheel.width", self.width)
        positive("plant.wheel.friction", self.friction)
        non_negative("plant.wheel.torsional_friction", self.torsional_friction)


@dataclass(frozen=True)
class CasterConfig:
    radius: float     # m
    offset: float     # m
    mass: float       # kg
    stiffness: float  # N/m
    damping: float    # N s/m

    def __post_init__(self) -> None:
        for name in ("radius", "offset", "mass", "stiffness", "damping"):
            positive(f"plant.caster.{name}", getattr(self, name))


@dataclass(frozen=True)
class ChassisConfig:
    length: float     # m
    width: float      # m
    height: float     # m
    clearance: float  # m

    def __post_init__(self) -> None:
        for name in ("length", "width", "height", "clearance"):
            positive(f"plant.chassis.{name}", getattr(self, name))


@dataclass(frozen=True)
class ContactConfig:
    timeconst: float  # s
    dampratio: float  # unitless

    def __post_init__(self) -> None:
        positive("plant.contact.timeconst", self.timeconst)
        positive("plant.contact.dampratio", self.dampratio)


@dataclass(frozen=True)
class DivergenceConfig:
    tip_angle: float      # rad
    airborne_time: float  # s

    def __post_init__(self) -> None:
        positive("plant.divergence.tip_angle", self.tip_angle)
        if self.tip_angle >= math.pi:
            raise ConfigError("plant.divergence.tip_angle", self.tip_angle, "must be < pi rad")
        positive("plant.divergence.airborne_time", self.airborne_time)


@dataclass(frozen=True)
class PhysicsConfig:
    """The MuJoCo plant's own parameters (conf/plant/mujoco.yaml, each with its unit there)."""

    timestep: float  # s
    threads: int
    settle_time: float  # s
    heightfield: HeightfieldConfig
    wheel: WheelConfig
    caster: CasterConfig
    chassis: ChassisConfig
    contact: ContactConfig
    divergence: DivergenceConfig

    def __post_init__(self) -> None:
        positive("plant.timestep", self.timestep)
        integer("plant.threads", self.threads, 0)
        non_negative("plant.settle_time", self.settle_time)
        # MuJoCo's soft contacts are stable only when the contact time constant spans at least two steps
        # (MuJoCo documentation, solref); it would silently stiffen them otherwise
        if self.contact.timeconst < 2 * self.timestep:
            raise ConfigError("plant.timestep", self.timestep,
                              f"MuJoCo cannot hold the contacts stable: must be <= plant.contact.timeconst / 2 = "
                              f"{self.contact.timeconst / 2:g} s")
        # MuJoCo integrates a joint's spring explicitly: a caster (mass m_c on stiffness k, the chassis far heavier)
        # oscillates at w = sqrt(k / m_c) and the step is stable only while w h < 2
        spring = 2.0 * math.sqrt(self.caster.mass / self.caster.stiffness)
        if not self.timestep < spring:
            raise ConfigError("plant.timestep", self.timestep,
                              f"MuJoCo cannot hold the caster springs stable: must be < 2 sqrt(plant.caster.mass / "
                              f"plant.caster.stiffness) = {spring:.3g} s")

    @classmethod
    def from_mapping(cls, values: Mapping) -> "PhysicsConfig":
        """From the plant config (conf/plant/mujoco.yaml, as a dict or a DictConfig); ``name`` is ignored."""
        values = {k: v for k, v in values.items() if k != "name"}
        sections = {"heightfield": HeightfieldConfig, "wheel": WheelConfig, "caster": CasterConfig,
                    "chassis": ChassisConfig, "contact": ContactConfig, "divergence": DivergenceConfig}
        known = [f.name for f in fields(cls)]
        for k in values:
            if k not in known:
                raise ConfigError(f"plant.{k}", values[k], f"unknown key (known: {', '.join(known)})")
        for name in known:
            if name not in values:
                raise ConfigError(f"plant.{name}", None, "is missing")
        parsed = {k: (_section(sections[k], f"plant.{k}", v) if k in sections else v) for k, v in values.items()}
        return cls(**parsed)


def substeps(config: PhysicsConfig, dt: float) -> int:
    """MuJoCo steps per plant step: ``dt / timestep``, which must be a whole number."""
    n = round(dt / config.timestep)
    if n < 1 or abs(n * config.timestep - dt) > 1e-9 * dt:
        raise ConfigError("plant.timestep", config.timestep,
                          f"must divide simulation.dt ({dt:g} s) into a whole number of steps")
    return n


def check_robot(robot: Robot, config: PhysicsConfig) -> None:
    """The robot and the plant config fit together: a wheel too coarse for the grid, wheel mass and inertia that
    leave a chassis, casters and chassis clear of the wheels."""
    R, L, hf = robot.wheel_radius, robot.half_track, config.heightfield
    if hf.resolution > R / 2:
        raise ConfigError("plant.heightfield.resolution", hf.resolution,
                          f"too coarse for the wheel radius: must be <= robot.wheel_radius / 2 = {R / 2:g} m")
    mw = config.wheel.mass
    if 2 * (mw + config.caster.mass) >= robot.mass:
        raise ConfigError("plant.wheel.mass", mw, f"two wheels and two casters must weigh less than robot.mass "
                                                  f"({robot.mass:g} kg)")
    if disc_inertia(mw, R)[0] > robot.wheel_inertia:
        raise ConfigError("plant.wheel.mass", mw, f"a disc of radius {R:g} m of this mass has more spin inertia "
                                                  f"than robot.wheel_inertia ({robot.wheel_inertia:g} kg m^2)")
    if chassis_yaw_inertia(robot, config) <= 0:
        raise ConfigError("plant.wheel.mass", mw, f"the wheels alone exceed robot.yaw_inertia ({robot.yaw_inertia:g} "
                                                  "kg m^2) about the axle midpoint")
    if config.caster.offset <= R + config.caster.radius:
        raise ConfigError("plant.caster.offset", config.caster.offset,
                          f"casters must clear the wheels: must be > {R + config.caster.radius:g} m")
    if config.chassis.width / 2 >= L - config.wheel.width / 2:
        raise ConfigError("plant.chassis.width", config.chassis.width,
                          f"the chassis must fit between the wheels: must be < {2 * L - config.wheel.width:g} m")


def check_reference(robot: Robot, config: HeightfieldConfig, xy: np.ndarray) -> None:
    """The reference path ``xy`` ``(K, 2)`` [m] keeps both wheels on the heightfield: ``x_min + L + R <= x <= x_max -
    L - R`` and ``|y| <= half_width - L - R`` (a robot that follows it would otherwise drive off the ground)."""
    reach = robot.half_track + robot.wheel_radius
    x, y = xy[:, 0], xy[:, 1]
    if x.min() < config.x_min + reach:
        raise ConfigError("plant.heightfield.x_min", config.x_min,
                          f"the reference leaves the field: it reaches x = {x.min():.3g} m, the wheels need x_min <= "
                          f"{x.min() - reach:.3g} m")
    if x.max() > config.x_max - reach:
        raise ConfigError("plant.heightfield.x_max", config.x_max,
                          f"the reference leaves the field: it reaches x = {x.max():.3g} m, the wheels need x_max >= "
                          f"{x.max() + reach:.3g} m")
    if np.abs(y).max() > config.half_width - reach:
        raise ConfigError("plant.heightfield.half_width", config.half_width,
                          f"the reference leaves the field: it reaches |y| = {np.abs(y).max():.3g} m, the wheels need "
                          f"half_width >= {np.abs(y).max() + reach:.3g} m")


def disc_inertia(mass: float, radius: float) -> tuple[float, float]:
    """A thin disc's ``(spin, diametral)`` moments of inertia ``(m r^2 / 2, m r^2 / 4)`` [kg m^2]."""
    return mass * radius**2 / 2, mass * radius**2 / 4


def chassis_yaw_inertia(robot: Robot, config: PhysicsConfig) -> float:
    """The chassis's own yaw inertia [kg m^2]: ``I_z`` minus both wheels' (diametral inertia plus ``m_w L^2``) and
    both casters' (point masses at the caster offset)."""
    return robot.yaw_inertia - 2 * (disc_inertia(config.wheel.mass, robot.wheel_radius)[1]
                                    + config.wheel.mass * robot.half_track**2
                                    + config.caster.mass * config.caster.offset**2)


def motor_gains(robot: Robot) -> tuple[float, float]:
    """The DC-motor law ``tau = K_u u - b B w`` (docs/model.md [13a], [1b]; b of [5d]) as two MuJoCo actuators
    per wheel: a motor of gain ``K_u = k_t / R_a`` [N m/V] on the voltage ``u`` and a damper whose gain is affine in the wheel
    speed, ``-B w`` [N m s/rad] with ``B = b_v + k_t k_e / R_a``, on the control ``b`` (scenario 2's damping
    scale, 1 when none), which multiplies the whole of B as in :func:`ddmr_cli.model.dynamics.disturbance`. Returns
    ``(K_u, -B)``."""
    return robot.voltage_gain, -robot.damping


def slope_gain(robot: Robot) -> float:
    """The wheel acceleration one unit of ground slope under one wheel gives [rad/s^2]: that wheel carries
    ``N = m g / 2`` and feels the torque ``N R s``, and ``d = -J^-1 tau``, so the wheel's own d has RMS
    ``N R s |(J^-1_p, J^-1_q)|`` when the two wheels meet independent slopes (docs/model.md [13b])."""
    jinv = robot.inverse_inertia
    return robot.mass * GRAVITY / 2 * robot.wheel_radius * math.hypot(jinv.p, jinv.q)


def height_sd(robot: Robot, terrain: Terrain, config: HeightfieldConfig) -> np.ndarray:
    """Each zone's height SD [m], docs/model.md [13c]-[13d]: the slope SD ``roughness / slope_gain`` times
    ``l / sqrt(2)`` (the slope SD of a Gaussian-correlated surface of correlation length ``l`` is
    ``sqrt(2) sigma_h / l``)."""
    return terrain.roughness / slope_gain(robot) * config.correlation_length / math.sqrt(2)


def zone_friction(robot: Robot, terrain: Terrain) -> np.ndarray:
    """Each zone's MuJoCo rolling-friction coefficient [m], docs/model.md [13f]: ``mu R``, so that a wheel carrying
    ``N = m g / 2`` meets at most ``mu R N = mu m g R / 2``, the wheel plant's rolling-resistance torque (docs/model.md §5)."""
    return terrain.mu * robot.wheel_radius


@dataclass(frozen=True)
class FieldLayout:
    """The heightfield grid: ``ncol`` samples along x from ``x_min`` at spacing ``dx``, ``nrow`` along y from
    ``-half_width``; zone ``i`` covers columns ``columns[i] .. columns[i + 1]`` (a shared boundary column)."""

    x_min: float
    dx: float
    ncol: int
    half_width: float
    dy: float
    nrow: int
    columns: tuple[int, ...]

    @property
    def x(self) -> np.ndarray:
        return self.x_min + self.dx * np.arange(self.ncol)

    @property
    def y(self) -> np.ndarray:
        return -self.half_width + self.dy * np.arange(self.nrow)


def field_layout(terrain: Terrain, config: HeightfieldConfig) -> FieldLayout:
    """The grid and each zone's columns; a zone start outside the field is refused (edges snap to the grid)."""
    ncol = int(round((config.x_max - config.x_min) / config.resolution)) + 1
    nrow = int(round(2 * config.half_width / config.resolution)) + 1
    dx = (config.x_max - config.x_min) / (ncol - 1)
    dy = 2 * config.half_width / (nrow - 1)
    columns = [0]
    for zone in terrain.zones[1:]:
        x = config.origin + zone.start
        c = int(round((x - config.x_min) / dx))
        if not c < ncol - 1:
            raise ConfigError(f"terrain.zones.{zone.name}.start", zone.start,
                              f"zone outside the heightfield: starts at x = {x:g} m, the field ends at "
                              f"plant.heightfield.x_max = {config.x_max:g} m")
        if c <= columns[-1]:
            raise ConfigError(f"terrain.zones.{zone.name}.start", zone.start,
                              f"zone narrower than one heightfield cell ({dx:g} m) after the previous one")
        columns.append(c)
    columns.append(ncol - 1)
    return FieldLayout(config.x_min, dx, ncol, config.half_width, dy, nrow, tuple(columns))


def heightfield(seed: int, robot: Robot, terrain: Terrain, config: HeightfieldConfig, layout: FieldLayout,
                rough: Sequence[tuple[float, bool]] = ()) -> np.ndarray:
    """A run's ground heights [m], shape ``(nrow, ncol)`` (rows along y, columns along x), docs/model.md [13e].

    A unit-variance Gaussian-correlated field ``n`` (white noise from the run's terrain stream,
    ``default_rng(SeedSequence(seed, spawn_key=(TERRAIN_STREAM,)))``, smoothed by a Gaussian kernel of SD ``l / 2``
    so its correlation is ``exp(-r^2 / l^2)``, rescaled to unit sample variance) times the height SD of each
    stretch of ground (:func:`amplitude`; ``rough``: the scenario's phases, :func:`rough_phases`), clipped at
    ``truncation`` SDs. Same seed, same ground.
    """
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(TERRAIN_STREAM,)))
    white = rng.standard_normal((layout.nrow, layout.ncol))
    unit = gaussian_filter(white, sigma=(config.correlation_length / 2 / layout.dy,
                                         config.correlation_length / 2 / layout.dx), mode="wrap")
    sd = unit.std()
    unit = unit / sd if sd > 0 else unit
    np.clip(unit, -config.truncation, config.truncation, out=unit)
    return unit * amplitude(robot, terrain, config, layout, rough)[None, :]


def rough_phases(scenario: Scenario | None) -> tuple[tuple[float, bool], ...]:
    """The scenario's phases as ``(start [m from the origin], roughness on)`` for the ground (docs/model.md §13):
    empty when every phase has roughness on (or no scenario). The ground is a place, so phases that turn the
    roughness off must go by distance (``scenario.phase_clock=distance``, the default): on the paper's line the
    distance travelled is x to a few millimetres."""
    if scenario is None or all(p.roughness for p in scenario.phases):
        return ()
    if scenario.phase_clock != "distance":
        raise ConfigError("scenario.phase_clock", scenario.phase_clock,
                          "plant=mujoco's ground is a place, not a clock: phases that turn the roughness off must go "
                          "by distance (scenario.phase_clock=distance)")
    return tuple((float(p.start), bool(p.roughness)) for p in scenario.phases)


def amplitude(robot: Robot, terrain: Terrain, config: HeightfieldConfig, layout: FieldLayout,
              rough: Sequence[tuple[float, bool]] = ()) -> np.ndarray:
    """The height SD at each column [m]: the ground in stretches that start at every zone start and every phase
    start of ``rough`` (:func:`rough_phases`), each of its zone's :func:`height_sd` (0 where the phase has the
    roughness off), ramped linearly from the previous stretch's over ``ramp`` metres; a stretch starting past the
    field's end is not on it."""
    sd = height_sd(robot, terrain, config)
    zone_starts = [z.start for z in terrain.zones]
    starts = sorted(set(zone_starts) | {start for start, _ in rough})

    def stretch_sd(start: float) -> float:
        zone = sd[max(i for i, z in enumerate(zone_starts) if z <= start)]
        on = [flag for s0, flag in rough if s0 <= start]
        return zone if not on or on[-1] else 0.0

    x = layout.x
    previous = stretch_sd(starts[0])
    out = np.full(layout.ncol, previous)
    for start in starts[1:]:
        column = int(round((config.origin + start - layout.x_min) / layout.dx))
        if column >= layout.ncol - 1:
            break
        current = stretch_sd(start)
        x0 = layout.x_min + layout.dx * column
        frac = np.ones_like(x) if config.ramp == 0 else np.clip((x - x0) / config.ramp, 0.0, 1.0)
        inside = x >= x0 - 1e-12
        out[inside] = previous + (current - previous) * frac[inside]
        previous = current
    return out


def elevation_range(robot: Robot, terrain: Terrain, config: HeightfieldConfig) -> float:
    """The heightfield's fixed elevation span [m]: ``2 truncation`` times the roughest zone's height SD (1 mm when
    the ground is flat everywhere, MuJoCo needs a span > 0)."""
    return max(2 * config.truncation * float(np.max(height_sd(robot, terrain, config))), 1e-3)


def normalised(heights: np.ndarray, span: float) -> np.ndarray:
    """Heights [m] as MuJoCo's heightfield data in [0, 1] for a geom at ``z = -span / 2`` of elevation ``span``."""
    return np.clip(heights / span + 0.5, 0.0, 1.0)


def mjcf(robot: Robot, terrain: Terrain, config: PhysicsConfig, layout: FieldLayout) -> str:
    """The MJCF text of robot and ground; the heightfields' data are left empty (set per run)."""
    R, L = robot.wheel_radius, robot.half_track
    w, c, ch, ct = config.wheel, config.caster, config.chassis, config.contact
    spin, diam = disc_inertia(w.mass, R)
    m_c = robot.mass - 2 * w.mass - 2 * c.mass
    point = c.mass * c.radius**2 * 2 / 5  # a caster ball's own inertia
    I_cz = chassis_yaw_inertia(robot, config)
    # roll and pitch of the chassis as a flat plate of its height (only the triangle inequality matters here)
    I_cxy = I_cz / 2 + m_c * ch.height**2 / 12
    armature = robot.wheel_inertia - spin
    gain, damping = motor_gains(robot)
    span = elevation_range(robot, terrain, config.heightfield)
    base = max(0.05, span)
    solref = f'{ct.timeconst!r} {ct.dampratio!r}'
    roll = zone_friction(robot, terrain)

    assets, ground = [], []
    for i, zone in enumerate(terrain.zones):
        c0, c1 = layout.columns[i], layout.columns[i + 1]
        hx = layout.dx * (c1 - c0) / 2
        cx = layout.x_min + layout.dx * (c0 + c1) / 2
        assets.append(f'<hfield name="zone{i}" nrow="{layout.nrow}" ncol="{c1 - c0 + 1}" '
                      f'size="{hx!r} {layout.half_width!r} {span!r} {base!r}"/>')
        ground.append(f'<geom name="ground{i}" type="hfield" hfield="zone{i}" pos="{cx!r} 0 {-span / 2!r}" '
                      f'contype="0" conaffinity="1" condim="6" solref="{solref}" '
                      f'friction="{w.friction!r} {w.torsional_friction!r} {float(roll[i])!r}"/>')

    if w.shape == "sphere":
        wheel_geom = f'type="sphere" size="{R!r}"'
    else:
        wheel_geom = f'type="cylinder" size="{R!r} {w.width / 2!r}" euler="1.5707963267948966 0 0"'
    wheels = []
    for side, y in (("R", -L), ("L", L)):
        wheels.append(f'''
      <body name="wheel_{side}" pos="0 {y!r} 0">
        <joint name="wheel_{side}" type="hinge" axis="0 1 0" armature="{armature!r}"/>
        <inertial pos="0 0 0" mass="{w.mass!r}" diaginertia="{diam!r} {spin!r} {diam!r}"/>
        <geom name="wheel_{side}" {wheel_geom} contype="1" conaffinity="0" condim="6" solref="{solref}"
              friction="{w.friction!r} {w.torsional_friction!r} 0"/>
        <site name="touch_{side}" type="sphere" size="{1.5 * R!r}"/>
      </body>''')
    z_box = ch.clearance + ch.height / 2 - R
    casters = "".join(
        f'''
      <body name="caster_{name}" pos="{x!r} 0 {c.radius - R!r}">
        <joint name="caster_{name}" type="slide" axis="0 0 1" stiffness="{c.stiffness!r}" damping="{c.damping!r}"/>
        <inertial pos="0 0 0" mass="{c.mass!r}" diaginertia="{point!r} {point!r} {point!r}"/>
        <geom name="caster_{name}" type="sphere" size="{c.radius!r}" contype="1" conaffinity="0" condim="1"
              priority="1" solref="{solref}"/>
      </body>'''
        for name, x in (("front", c.offset), ("rear", -c.offset)))
    return f'''<mujoco model="ddmr">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{config.timestep!r}" integrator="implicitfast" gravity="0 0 {-GRAVITY!r}"/>
  <asset>
    {"".join(assets)}
  </asset>
  <worldbody>
    {"".join(ground)}
    <body name="chassis" pos="0 0 {R!r}">
      <freejoint name="chassis"/>
      <inertial pos="0 0 0" mass="{m_c!r}" diaginertia="{I_cxy!r} {I_cxy!r} {I_cz!r}"/>
      <geom name="chassis" type="box" size="{ch.length / 2!r} {ch.width / 2!r} {ch.height / 2!r}"
            pos="0 0 {z_box!r}" contype="1" conaffinity="0" condim="3" solref="{solref}"
            friction="{w.friction!r} 0 0"/>{casters}{"".join(wheels)}
    </body>
  </worldbody>
  <actuator>
    <general name="motor_R" joint="wheel_R" gainprm="{gain!r}"/>
    <general name="motor_L" joint="wheel_L" gainprm="{gain!r}"/>
    <general name="damping_R" joint="wheel_R" gaintype="affine" gainprm="0 0 {damping!r}"/>
    <general name="damping_L" joint="wheel_L" gaintype="affine" gainprm="0 0 {damping!r}"/>
  </actuator>
  <sensor>
    <touch name="touch_R" site="touch_R"/>
    <touch name="touch_L" site="touch_L"/>
  </sensor>
</mujoco>
'''
