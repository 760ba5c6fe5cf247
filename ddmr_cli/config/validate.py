"""Validation of a composed config before anything is run or written.

The model parts and controllers check their own values when they are built (their constructors raise
:class:`~ddmr_cli.errors.ConfigError` naming the key) and :meth:`~ddmr_cli.engine.simulation.Simulation.validate`
checks the step against every part's stability bound; this module adds what belongs to the CLI:

- which classes a config may instantiate (a controller node only a controller, a trajectory node only a
  trajectory), and which new keys ``+key=value`` may add (only under a free-form dict such as ``tags.*``);
- the numbers derived from the values (J^-1, the plant's pole, the controller's law parameters, the reference
  and the initial state) are finite, named by the section whose values gave them;
- the ``run`` section (seeds, kept series, memory budget) and the ``cluster`` section.

The CLI prints a ConfigError as one line (:func:`message`), exit 2.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from types import MappingProxyType
from typing import Any, Iterable, Iterator, Sequence

import numpy as np
from omegaconf import DictConfig, ListConfig, OmegaConf

from ddmr_cli.checks import integer, positive
from ddmr_cli.config import budget
from ddmr_cli.config.build import USER_TARGETS, build_simulation, check_targets, plant_module
from ddmr_cli.errors import ConfigError
from ddmr_cli import display

#: the forms of run.keep_series
KEEP_FORMS = "a list of seeds, first:N (the job's first N seeds), all or none"
#: config nodes that instantiate a class -> the base class (module, name) their _target_ must be or extend;
#: a trajectory is any class of ddmr_cli.model.trajectory (a protocol, no base class)
TARGET_BASES = MappingProxyType({
    "controller": USER_TARGETS["controller"],  # the one definition of a controller's base class
    "controller.ndo": ("ddmr_cli.control.ndo", "NonlinearDisturbanceObserver"),
    "controller.nn": ("ddmr_cli.control.rbf", "RBFNetworkObserver"),
    "trajectory": ("ddmr_cli.model.trajectory", None),
})


class DerivedError(ConfigError):
    """A number derived from a section's values (J^-1, a law parameter, the reference) is unusable; the CLI
    names the overrides of that section (:func:`message`)."""

    def __init__(self, section: str, rule: str) -> None:
        super().__init__(section, None, rule)


# --- run and cluster -----------------------------------------------------------------------------------------


def kept_seeds(run: DictConfig) -> list[int]:
    """The seeds whose time series a job keeps, from ``run.keep_series``: a list of seeds (each must be one of
    the job's seeds ``base_seed .. base_seed + n_runs - 1``), ``first:N`` (the job's first N seeds, whatever
    base_seed is), ``all`` or ``none``."""
    seeds = range(int(run.base_seed), int(run.base_seed) + int(run.n_runs))
    spec = run.keep_series
    if isinstance(spec, str):
        text = spec.strip()
        match = re.fullmatch(r"first:(\d+)", text)
        if match:
            return list(seeds[:int(match.group(1))])
        if text in ("all", "none"):
            return list(seeds) if text == "all" else []
        raise ConfigError("run.keep_series", spec, f"must be {KEEP_FORMS}")
    if not isinstance(spec, (list, tuple, ListConfig)):
        raise ConfigError("run.keep_series", spec, f"must be {KEEP_FORMS}")
    kept = []
    for i, seed in enumerate(spec):
        seed = integer(f"run.keep_series[{i}]", seed, 0)
        if seed not in seeds:
            raise ConfigError(f"run.keep_series[{i}]", seed, f"is not a seed of this job (seeds {seeds.start}.."
                                                             f"{seeds.stop - 1}); keep_series lists seeds, "
                                                             "first:N keeps the first N of any base_seed")
        kept.append(seed)
    return list(dict.fromkeys(kept))


def validate_run(run: DictConfig) -> list[int]:
    """The ``run`` section: seeds, kept series, threads, memory budget. Returns the kept seeds."""
    integer("run.n_runs", run.n_runs, 1)
    integer("run.base_seed", run.base_seed, 0)
    integer("run.threads", run.threads, 0)
    if run.get("max_memory_gb") is not None:
        positive("run.max_memory_gb", run.max_memory_gb)
    try:
        return kept_seeds(run)
    except MemoryError:  # run.keep_series=all with a huge run.n_runs: the list of seeds alone does not fit
        raise ConfigError("run.n_runs", run.n_runs, f"with run.keep_series={run.keep_series} the kept seeds alone "
                                                    "do not fit in memory; lower run.n_runs") from None


def _text(key: str, value: Any, optional: bool = True) -> None:
    if value is None and optional:
        return
    if not isinstance(value, str) or not value.strip() or any(c.isspace() for c in value):
        raise ConfigError(key, value, "must be null or a name without spaces" if optional else "must be a name")


def _cpus(key: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or (value != -1 and value < 1):
        raise ConfigError(key, value, "must be -1 (every core) or an integer >= 1")


#: the rule of every documented cluster key (conf/launcher presets; schema.CLUSTER_KEYS documents them)
CLUSTER_RULES = MappingProxyType({
    "cpus": _cpus,
    "partition": _text,
    "time_min": lambda key, value: integer(key, value, 1),
    "mem_gb": positive,
    "jobs": lambda key, value: integer(key, value, 1),
    "address": _text,
})


def validate_cluster(cluster: DictConfig | None) -> None:
    """The ``cluster`` keys the launcher presets set: known keys only, each value by its rule."""
    for key in cluster or {}:
        rule = CLUSTER_RULES.get(str(key))
        if rule is None:
            raise ConfigError(f"cluster.{key}", cluster[key], f"unknown cluster key; known: {', '.join(CLUSTER_RULES)}")
        rule(f"cluster.{key}", cluster[key])


# --- classes and new keys ------------------------------------------------------------------------------------


def _targets(node: DictConfig, path: str) -> Iterator[tuple[str, Any]]:
    """(path, target) of every node with a ``_target_`` (values other than targets are not resolved). Keys are
    looked up in ``keys()``: ``in`` on a structured node raises and catches an error for every absent key."""
    keys = node.keys()
    if "_target_" in keys:
        yield path, node.get("_target_")
    for key in keys:
        child = node._get_node(key)
        if key != "_target_" and isinstance(child, DictConfig) and not child._is_none():
            yield from _targets(node[key], f"{path}.{key}" if path else str(key))


def _study_role(path: str) -> str:
    """The role of a node of a sensitivity study's own configs: ``study.configs.controller.pid.ndo`` is a
    ``controller.ndo`` (the study builds one simulation per controller option, docs/model.md §11)."""
    parts = path.split(".")
    if len(parts) >= 4 and parts[:2] == ["study", "configs"]:
        return ".".join([parts[2], *parts[4:]])
    return path


def check_target_classes(cfg: DictConfig) -> None:
    """Every ``_target_`` sits where the config instantiates a class and names a class of the right kind (a
    controller node a :class:`~ddmr_cli.control.base.WheelController`, ...), not any ``ddmr_cli`` class."""
    import importlib

    from ddmr_cli.compat import locate  # hydra.utils.get_class also logs an error line on failure

    for path, target in ((p, t) for p, t in _targets(cfg, "") if p != "hydra" and not p.startswith("hydra.")):
        if path not in TARGET_BASES and _study_role(path) not in TARGET_BASES:
            raise ConfigError(f"{path}._target_", target, f"no class is instantiated from {path}")
        try:
            cls = locate(str(target))
        except Exception as exc:  # noqa: BLE001  (Hydra wraps import errors of any kind)
            raise ConfigError(f"{path}._target_", target, f"cannot be imported ({type(exc).__name__})") from None
        module, base = TARGET_BASES[path if path in TARGET_BASES else _study_role(path)]
        if not isinstance(cls, type):
            raise ConfigError(f"{path}._target_", target, "must name a class")
        if base is None:
            ok = cls.__module__ == module and callable(getattr(cls, "reference", None))
            kind = f"a trajectory class of {module}"
        else:
            ok = issubclass(cls, getattr(importlib.import_module(module), base))
            kind = f"a {base} ({module}.{base} or a subclass)"
        if not ok:
            raise ConfigError(f"{path}._target_", target, f"must be {kind}")


def _free_form(cfg: DictConfig) -> list[str]:
    """Dict-typed nodes of the composed config (``tags``, ``terrain.zones``, ...), where new keys are welcome."""
    out = []
    for key in cfg:
        node = cfg._get_node(key)
        if key != "hydra" and isinstance(node, DictConfig) and not node._is_none():
            if not dataclasses.is_dataclass(OmegaConf.get_type(node)):
                out.append(f"{key}.*")
            else:
                out.extend(f"{key}.{sub}" for sub in _free_form(cfg[key]))
    return out


def unknown_key(parents: Sequence[str], name: str, fields: Iterable[str]) -> str:
    """``unknown key run.nruns (did you mean run.n_runs?); run has no key 'nruns'``: the key ``parents.name``
    that a schema with ``fields`` does not have, with the closest field when one is close (difflib)."""
    close = difflib.get_close_matches(name, list(fields), n=1)
    hint = f" (did you mean {'.'.join([*parents, close[0]])}?)" if close else ""
    return (f"unknown key {'.'.join([*parents, name])}{hint}; {'.'.join(parents) or 'the config'} has no key "
            f"{name!r}")


def check_additions(cfg: DictConfig, overrides: Iterable[str], groups: Iterable[str] = ()) -> None:
    """Refuse ``+key=value`` (and ``++``) that adds a key a schema does not have (``+run.nruns=5``): new keys
    are accepted only under a free-form dict (``tags.*``, ``terrain.zones.*``, ``scenario.phases.*``)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    groups = set(groups)
    for ov in OverridesParser.create().parse_overrides(list(overrides)):
        if not (ov.is_add() or ov.is_force_add()):
            continue
        key = ov.key_or_group
        if key in groups or "/" in key or key == "hydra" or key.startswith("hydra.") or (
                "." not in key and key not in cfg):  # a config group (+experiment=table4), not a key
            continue
        node: Any = cfg
        parts = key.split(".")
        for i, part in enumerate(parts):
            node_type = OmegaConf.get_type(node) if isinstance(node, DictConfig) else None
            if node_type is None or not dataclasses.is_dataclass(node_type):
                break  # a free-form dict (or a value): anything below it is the user's
            fields = [f.name for f in dataclasses.fields(node_type)]
            if part not in fields:
                raise ConfigError(ov.input_line.partition("=")[0], ov.value(),
                                  f"{unknown_key(parts[:i], part, fields)}. New keys are accepted only under a "
                                  f"free-form dict: {', '.join(_free_form(cfg))}")
            node = node[part]


# --- derived numbers -----------------------------------------------------------------------------------------


def _first_not_finite(value: Any, name: str = "") -> str | None:
    """The name of the first non-finite number in a (nested) NamedTuple / tuple / array, or None."""
    fields = getattr(value, "_fields", None)
    if fields is not None:
        return next((bad for f in fields if (bad := _first_not_finite(getattr(value, f), f)) is not None), None)
    if isinstance(value, (tuple, list)):
        return next((bad for i, v in enumerate(value) if (bad := _first_not_finite(v, f"{name}[{i}]")) is not None),
                    None)
    if isinstance(value, (float, np.floating, np.ndarray)) and np.issubdtype(np.asarray(value).dtype, np.floating):
        return None if np.isfinite(value).all() else (name or "value")
    return None


def check_derived(sim) -> None:
    """The numbers derived from the values are finite: J^-1 and the plant's fastest pole (robot), the
    controller's law parameters, the reference over the run (trajectory), the initial wheel speeds and the
    initial deviation (within simulation.divergence_bound, else every run stops at once)."""
    from ddmr_cli.compiled import plain
    from ddmr_cli.model.kinematics import inverse
    from ddmr_cli.model.robot import NominalModel

    try:
        nominal = NominalModel.from_robot(sim.robot)
    except ValueError as exc:
        raise DerivedError("robot", f"gives no usable inertia matrix J ({exc})") from None
    bad = _first_not_finite(nominal)
    if bad is not None or not math.isfinite(sim.robot.step_rate()):
        raise DerivedError("robot", f"the derived nominal model is not finite ({bad or 'the plant pole'})")
    bad = _first_not_finite(sim.controller.law_parameters(nominal, float(sim.dt)))
    if bad is not None:
        raise DerivedError("controller", f"the derived law parameter {bad} is not finite")
    duration = float(sim.duration)
    for t in (0.0, duration / 2, duration):
        if not all(math.isfinite(v) for v in sim.trajectory.reference(t)):
            raise DerivedError("trajectory", f"the reference at t = {t:g} s is not finite")
    x_r, y_r, _, v_r, omega_r = sim.trajectory.reference(0.0)
    if sim.initial_wheel_speeds == "reference":
        wheels = plain(inverse)(v_r, omega_r, sim.robot.wheel_radius, sim.robot.half_track)
        if not all(math.isfinite(w) for w in wheels):
            raise DerivedError("trajectory", "the initial wheel speeds of the reference (v_r / R) are not finite")
    dx, dy = float(sim.initial_pose[0]) - x_r, float(sim.initial_pose[1]) - y_r
    deviation = math.sqrt(dx * dx + dy * dy)
    if not deviation < float(sim.divergence_bound):
        raise ConfigError("simulation.initial_pose", list(sim.initial_pose),
                          f"starts {deviation:.3g} m from the reference, not within simulation.divergence_bound="
                          f"{float(sim.divergence_bound):g} m: every run would stop at once")


def check_plant(cfg: DictConfig, sim) -> None:
    """An external plant's own checks before anything runs: ``ddmr_cli.plant.<name>.check(config, sim)`` where the
    plant's module defines it (``plant=mujoco``: the physics extra installed, the heightfield fine enough for the
    wheel, the zones and the reference on the field, a timestep MuJoCo holds stable; ``plant=wheel_python``: explicit
    Euler); nothing for the wheel plant."""
    plant = cfg.get("plant")
    check = getattr(plant_module(plant), "check", None)
    if check is not None:
        check(OmegaConf.to_container(plant, resolve=True), sim)


def message(exc: ConfigError, overrides: Iterable[str] = ()) -> str:
    """The one line of a ConfigError: ``key=value: rule``; when it names a whole section (a derived number,
    or a model part's check of several values), the overrides of that section stand for it."""
    if not isinstance(exc, DerivedError) and not isinstance(exc.value, (dict, DictConfig)):
        return " ".join(str(exc).split())
    mine = [ov for ov in overrides if ov.lstrip("+~").partition("=")[0] == exc.key
            or ov.lstrip("+~").startswith(exc.key + ".")]
    return " ".join(f"{' '.join(mine) or exc.key}: {exc.rule}".split())


# --- everything ----------------------------------------------------------------------------------------------


def validate_config(cfg: DictConfig):
    """Check every value of a composed config; raise ConfigError on the first bad one. Returns the built
    :class:`~ddmr_cli.engine.simulation.Simulation`."""
    check_targets(cfg.get("controller"), "controller")
    check_targets(cfg.get("trajectory"), "trajectory")
    check_target_classes(cfg)
    display.check(OmegaConf.to_container(cfg.controller, resolve=True).get(display.DISPLAY))
    validate_cluster(cfg.get("cluster"))
    kept = validate_run(cfg.run)
    sim = build_simulation(cfg)
    check_simulation(cfg, sim, kept)
    return sim


def check_simulation(cfg: DictConfig, sim, kept: list[int] | None = None) -> None:
    """The checks of a built :class:`~ddmr_cli.engine.simulation.Simulation` of ``cfg`` (the run of
    :func:`validate_config` after the build): the step against every part's stability bound, the derived numbers,
    the plant's own checks and the job's memory budget (``kept``: the kept seeds, read from ``cfg.run`` if None)."""
    sim.validate()
    check_derived(sim)
    check_plant(cfg, sim)
    budget.check(job_estimate(cfg, sim, kept), cfg.run.get("max_memory_gb"),
                 cluster_mem_gb=(cfg.get("cluster") or {}).get("mem_gb"))


def steady_state_warning(sim) -> str | None:
    """One line when the steady-state window of a built
    :class:`~ddmr_cli.engine.simulation.Simulation` is empty (no step at or after ``metrics.settle_time``):
    every ``<metric>_ss`` is then NaN, and so are the report's steady-state tables, verdicts and realism figures.
    None when the window has steps."""
    if int(round(sim.settle_time / sim.dt)) < sim.n_steps:
        return None
    return (f"metrics.settle_time={sim.settle_time:g} s is not below simulation.duration={sim.duration:g} s: "
            f"the steady-state window is empty and every <metric>_ss will be NaN (lower metrics.settle_time or "
            f"run longer)")


def job_estimate(cfg: DictConfig, sim, kept: list[int] | None = None) -> budget.Estimate:
    """The memory estimate of a composed config's job (:mod:`ddmr_cli.config.budget`)."""
    kept = kept_seeds(cfg.run) if kept is None else kept
    return budget.estimate(sim, int(cfg.run.n_runs), len(kept))


__all__ = ["validate_config", "check_simulation", "validate_run", "validate_cluster", "kept_seeds", "check_additions", "unknown_key",
           "check_target_classes", "check_derived", "check_plant", "message", "job_estimate", "steady_state_warning",
           "DerivedError", "KEEP_FORMS"]
