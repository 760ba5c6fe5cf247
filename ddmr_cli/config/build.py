"""From a composed config to the plain model objects (the only place config meets model code)."""

from __future__ import annotations

import hashlib
import json
from types import MappingProxyType
from typing import Any, Mapping

from hydra.errors import InstantiationException
from omegaconf import DictConfig, OmegaConf

from ddmr_cli.checks import one_of
from ddmr_cli.errors import ConfigError
from ddmr_cli.control.outer_loop import Kanayama
from ddmr_cli.model.actuator import Actuator
from ddmr_cli.model.robot import Robot
from ddmr_cli.model.sensor import Sensor
from ddmr_cli.model.scenario import UNCERTAINTY_FORMS, DampingUncertainty, Phase, Scenario
from ddmr_cli.engine.simulation import Simulation
from ddmr_cli.model.terrain import Terrain, TerrainZone
from ddmr_cli.display import DISPLAY

#: Only the project's own classes may be instantiated from a config.
ALLOWED_TARGET_PREFIX = "ddmr_cli."

#: Keys that do not change the numbers (left out of the config hash used to resume sweeps).
NON_RESULT_KEYS = ("run.plots", "run.progress", "run.threads", "run.max_memory_gb", "experiment_name", "cluster",
                   "report", "tags")


#: Where a class of the user's own package may be instantiated (docs/extending.md: a controller in a module on the
#: user's PYTHONPATH, its YAML in a ``--config-dir``): path -> (module, base class) it must subclass.
USER_TARGETS = MappingProxyType({"controller": ("ddmr_cli.control.base", "WheelController")})


def check_targets(node: Any, path: str) -> None:
    """Refuse a ``_target_`` outside the project's classes (ConfigError naming the key), unless it is at a path of
    :data:`USER_TARGETS` and names a subclass of that path's base class (a user's controller)."""
    if isinstance(node, DictConfig):
        target = node.get("_target_") if "_target_" in node.keys() else None
        if target is not None and not str(target).startswith(ALLOWED_TARGET_PREFIX) and not _user_class(path, target):
            raise ConfigError(f"{path}._target_", target, f"only {ALLOWED_TARGET_PREFIX}* classes may be instantiated"
                              + (f", or a subclass of {'.'.join(USER_TARGETS[path])}" if path in USER_TARGETS else ""))
        for key in node:
            check_targets(node[key], f"{path}.{key}")


def _user_class(path: str, target: Any) -> bool:
    """True when ``target`` at ``path`` names a subclass of the base :data:`USER_TARGETS` gives for the path."""
    import importlib

    from ddmr_cli.compat import locate

    if path not in USER_TARGETS:
        return False
    try:
        cls = locate(str(target))
    except Exception as exc:  # noqa: BLE001  (Hydra wraps import errors of any kind)
        raise ConfigError(f"{path}._target_", target, f"cannot be imported ({type(exc).__name__}); is its module on "
                                                      f"PYTHONPATH?") from None
    module, base = USER_TARGETS[path]
    return isinstance(cls, type) and issubclass(cls, getattr(importlib.import_module(module), base))


#: Hydra's instantiation keys other than ``_target_``: a node that uses one is instantiated by Hydra itself
HYDRA_KEYS = frozenset({"_args_", "_partial_", "_recursive_", "_convert_"})


def instantiate_checked(node: DictConfig, path: str):
    """``hydra.utils.instantiate(node, _convert_="all")`` restricted to the project's own classes; a controller's
    ``display`` node (the report's label and style) is not the constructor's.

    The node is resolved to plain values once and each ``_target_`` called on them, innermost first
    (:func:`_construct`): what Hydra's instantiate does for a node that uses no other instantiation key, without
    its copies of the node (a controller: 0.5 ms against 8 ms, measured; every job builds its controller in the
    sweep's plan and again in its worker, every study sample and tuning trial once). A node that uses another of
    Hydra's keys (:data:`HYDRA_KEYS`) or a missing value, and any failure, goes to Hydra's instantiate, so what
    is built and every error are Hydra's (tests/test_instantiate.py holds the two to each other). Hydra is given
    the node's resolved values: its own copy of a part of the config lost the rest, so an interpolation to another
    key (``controller.ndo.gain=${controller.lam}``) failed with no key named."""
    from hydra.utils import instantiate

    check_targets(node, path)
    try:
        plain = OmegaConf.to_container(node, resolve=True, throw_on_missing=True)
    except Exception:  # noqa: BLE001 - Hydra's instantiate below raises its own error for it
        plain = None
    if plain is None:
        keys = [k for k in node.keys() if k != DISPLAY]
        return instantiate(OmegaConf.masked_copy(node, keys) if len(keys) < len(node) else node, _convert_="all")
    plain.pop(DISPLAY, None)
    if not _uses_hydra_keys(plain):
        try:
            return _construct(plain)
        except Exception:  # noqa: BLE001 - Hydra's instantiate below raises its own error for it
            pass
    # the resolved values, not a copy of the node: a copy loses the rest of the config its interpolations name
    return instantiate(OmegaConf.create(plain), _convert_="all")


def _uses_hydra_keys(value: Any) -> bool:
    """Whether a plain container holds one of :data:`HYDRA_KEYS` at any depth."""
    if isinstance(value, dict):
        return any(k in HYDRA_KEYS for k in value) or any(_uses_hydra_keys(v) for v in value.values())
    if isinstance(value, list):
        return any(_uses_hydra_keys(v) for v in value)
    return False


def _construct(value: Any) -> Any:
    """A resolved plain value with every ``_target_`` dict called on its other keys, innermost first (Hydra's
    recursive instantiation with ``_convert_="all"``: what is not a target stays a plain dict or list)."""
    from ddmr_cli.compat import locate

    if isinstance(value, dict):
        kwargs = {k: _construct(v) for k, v in value.items() if k != "_target_"}
        return locate(value["_target_"])(**kwargs) if "_target_" in value else kwargs
    if isinstance(value, list):
        return [_construct(v) for v in value]
    return value


def build_robot(cfg: DictConfig) -> Robot:
    return Robot(**OmegaConf.to_container(cfg, resolve=True))


def build_terrain(cfg: DictConfig) -> Terrain:
    zones = list(cfg.zones.items())  # in config order: Terrain refuses starts that do not increase
    return Terrain(zones=tuple(TerrainZone(str(name), float(z.start), float(z.roughness), float(z.mu))
                               for name, z in zones), correlation_time=float(cfg.correlation_time))


def build_scenario(cfg: DictConfig) -> Scenario:
    phases = list(cfg.phases.items())  # in config order: Scenario refuses starts that do not increase
    u = cfg.uncertainty
    return Scenario(
        name=str(cfg.name),
        phases=tuple(Phase(str(name), float(p.start), bool(p.roughness), bool(p.uncertainty)) for name, p in phases),
        uncertainty=DampingUncertainty(float(u.correlation_time), float(u.std), float(u.low), float(u.high),
                                       one_of("scenario.uncertainty.form", str(u.form), UNCERTAINTY_FORMS) == "constant"),
        phase_clock=str(cfg.phase_clock),
    )


def controller_name(cfg: DictConfig) -> str:
    """The label of a controller config: its ``name`` or the last part of its target."""
    return str(cfg.get("name") or str(cfg._target_).rsplit(".", 1)[-1].lower())


def _instantiated(node: DictConfig, path: str):
    """:func:`instantiate_checked`, a constructor's ConfigError unwrapped from Hydra's InstantiationException."""
    try:
        return instantiate_checked(node, path)
    except InstantiationException as exc:
        cause = exc.__cause__ or exc.__context__
        if isinstance(cause, ConfigError):
            raise cause from None
        raise


def _simulation_values(node: DictConfig) -> dict[str, Any]:
    wheel = node.initial_wheel_speeds
    return {
        "dt": float(node.dt),
        "duration": float(node.duration),
        "integrator": str(node.integrator),
        "initial_pose": tuple(float(v) for v in node.initial_pose),
        "initial_wheel_speeds": wheel if isinstance(wheel, str) else tuple(float(v) for v in wheel),
        "divergence_bound": float(node.divergence_bound),
    }


#: config section -> the :class:`~ddmr_cli.engine.simulation.Simulation` fields built from it (the plant's section:
#: :func:`build_plant`), in the order :func:`build_simulation` builds them (the first refusal is the one reported)
SECTION_BUILDERS = MappingProxyType({
    "controller": lambda node: {"controller": _instantiated(node, "controller")},
    "trajectory": lambda node: {"trajectory": _instantiated(node, "trajectory")},
    "robot": lambda node: {"robot": build_robot(node)},
    "terrain": lambda node: {"terrain": build_terrain(node)},
    "scenario": lambda node: {"scenario": build_scenario(node)},
    "outer_loop": lambda node: {"outer_loop": Kanayama(**OmegaConf.to_container(node, resolve=True))},
    "simulation": _simulation_values,
    "metrics": lambda node: {"settle_time": float(node.settle_time), "zone_settle_time": float(node.zone_settle_time)},
    "sensor": lambda node: {"sensor": Sensor(**OmegaConf.to_container(node, resolve=True))},
    "actuator": lambda node: {"actuator": Actuator(**OmegaConf.to_container(node, resolve=True))},
    "control": lambda node: {"control_rate": None if node.rate is None else float(node.rate)},
})


def build_parts(sections: Mapping[str, DictConfig]) -> dict[str, Any]:
    """The Simulation fields built from the config sections ``sections`` holds (section name -> its node, names
    of :data:`SECTION_BUILDERS`), in :data:`SECTION_BUILDERS`' order."""
    fields: dict[str, Any] = {}
    for name, build in SECTION_BUILDERS.items():
        if name in sections:
            fields.update(build(sections[name]))
    return fields


def build_simulation(cfg: DictConfig) -> Simulation:
    """The :class:`~ddmr_cli.engine.simulation.Simulation` a composed (and validated) config describes."""
    return Simulation(**build_parts({name: cfg[name] for name in SECTION_BUILDERS}),
                      plant=build_plant(cfg.get("plant")))


def plant_module(node) -> Any:
    """The module of the plant ``node`` names (``ddmr_cli.plant.<plant.name>``, with its ``factory`` and optional
    ``check``), or None for the wheel plant (no node, or ``plant.name: wheel``). ConfigError on ``plant.name`` for
    a name without such a module."""
    import importlib

    from ddmr_cli.plant.wheel import NAME as WHEEL

    name = WHEEL if node is None else str(node.get("name", WHEEL))
    if name == WHEEL:
        return None
    try:
        module = importlib.import_module(f"ddmr_cli.plant.{name}")
    except ImportError:
        module = None
    if not hasattr(module, "factory"):
        raise ConfigError("plant.name", name, "must name a plant of ddmr_cli.plant with a factory (the "
                          "conf/plant options: wheel, wheel_python, mujoco)")
    return module


def build_plant(node) -> Any:
    """The plant factory of ``plant`` (:attr:`~ddmr_cli.engine.simulation.Simulation.plant`): None for the wheel
    plant, else its module's ``factory(node)`` (:func:`plant_module`)."""
    module = plant_module(node)
    if module is None:
        return None
    return module.factory(OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else dict(node))


def seeds_of(cfg: DictConfig) -> list[int]:
    """The seeds of a job: ``base_seed .. base_seed + n_runs - 1``."""
    return list(range(int(cfg.run.base_seed), int(cfg.run.base_seed) + int(cfg.run.n_runs)))


def result_config(cfg: DictConfig, display: bool = False) -> dict:
    """The part of the resolved config that determines the numbers (no hydra node, no display keys; with
    ``display`` the controllers' ``display`` nodes are kept, for the job's saved config the report reads)."""
    container = OmegaConf.to_container(cfg, resolve=True)
    container.pop("hydra", None)
    if not display:
        _drop_display(container)
    for dotted in NON_RESULT_KEYS:
        node, *rest = dotted.split(".")
        if rest:
            container.get(node, {}).pop(rest[0], None)
        else:
            container.pop(node, None)
    return container


def _drop_display(node) -> None:
    """Remove every controller's ``display`` node (label and style only: not the numbers), at any depth (the
    sensitivity study's ``study.configs.controller.*``)."""
    if isinstance(node, dict):
        if "_target_" in node:
            node.pop(DISPLAY, None)
        for value in node.values():
            _drop_display(value)


def container_digest(container: Any) -> str:
    """SHA-256 (hex) of a plain config container: its JSON, keys sorted (a value JSON cannot spell, as its str)."""
    return hashlib.sha256(json.dumps(container, sort_keys=True, default=str).encode()).hexdigest()


def config_hash(cfg: DictConfig) -> str:
    """SHA-256 of :func:`result_config` (16 hex digits): equal hashes mean equal numbers."""
    return container_digest(result_config(cfg))[:16]
