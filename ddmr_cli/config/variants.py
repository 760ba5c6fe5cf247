"""One validated config, its built simulation, and the simulation of that config with some values changed.

A sensitivity study (docs/model.md §11) simulates thousands of readings of the same few configs (a controller
in a scenario, 8 of them by default). Setting a reading on a copy of the whole config, then validating and
building it anew, took about 7.7 ms a config, most of a sample's time (issue 28). :class:`Variants` validates and
builds its config once. For a reading it copies only the sections the changed keys belong to, sets the values
there (with the config's types and struct checks), rebuilds the model parts built from those sections
(:data:`~ddmr_cli.config.build.SECTION_BUILDERS`) and runs the checks of a built simulation
(:func:`~ddmr_cli.config.validate.check_simulation`). The result is the simulation the full path would give,
with the same refusals (tests/test_variants.py compares both for every parameter of the default study).

The model parts a section builds with a reading's values are kept (:class:`BuiltParts`, shared by a study job's
configs): the configs of one sample share their robot, terrain and step sections, and a Morris trajectory or a
Sobol matrix moves one parameter at a time, so most sections of a sample were built before with the same values.
A part is reused only for the same section (its schema type and content) and the same values, by type and bits
(:func:`values_key`).

The full path (the whole config copied, validated and built: :func:`with_values` then
:func:`~ddmr_cli.config.validate.validate_config`) is taken for a key outside those sections (``run.*``,
``plant.*``), a key naming a class (``_target_``) or a controller's ``display``, and for a config whose model
sections hold an interpolation (a changed value could flow into another section).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from typing import Any, Mapping

from omegaconf import DictConfig, ListConfig, OmegaConf

from ddmr_cli.config.build import SECTION_BUILDERS, build_parts
from ddmr_cli.display import DISPLAY
from ddmr_cli.config.validate import check_simulation, validate_config
from ddmr_cli.keyed import Kept


#: the sections :func:`~ddmr_cli.config.validate.check_simulation` reads besides the model's (kept as they are)
CHECKED = ("run", "cluster", "plant")


def with_values(cfg: DictConfig, values: Mapping[str, Any]) -> DictConfig:
    """A copy of ``cfg`` with ``values`` (dotted key -> value) set, in their order (``cfg`` unchanged)."""
    out = cfg.copy()
    for key, value in values.items():
        OmegaConf.update(out, key, value, merge=False)
    return out


def _interpolated(node: Any) -> bool:
    """True when a node's unresolved values hold an interpolation (``${...}``) anywhere."""
    container = OmegaConf.to_container(node, resolve=False) if isinstance(node, DictConfig) else node
    if isinstance(container, dict):
        return any(_interpolated(v) for v in container.values())
    if isinstance(container, list):
        return any(_interpolated(v) for v in container)
    return isinstance(container, str) and "${" in container


def _same(a: Any, b: Any) -> bool:
    """``a`` and ``b`` are equal and of the same types, element by element in lists and tuples."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def values_key(values: Mapping[str, Any]) -> tuple:
    """``values`` (dotted key -> value) as a hashable record, equal for two mappings only when they hold the same
    keys in the same order with values of the same types and the same bits (floats by :meth:`float.hex`: -0.0 is
    not 0.0): a memo key for what a deterministic function of the values computed."""
    def frozen(value: Any) -> Any:
        if isinstance(value, (list, tuple)):
            return tuple(frozen(v) for v in value)
        if isinstance(value, Mapping):
            return tuple((k, frozen(v)) for k, v in value.items())
        return (type(value).__name__, value.hex() if isinstance(value, float) else value)

    return tuple((key, frozen(value)) for key, value in values.items())


class BuiltParts(Kept):
    """The Simulation fields built from config sections with some values set, kept by (section, its schema type and
    content, the values): shared by the :class:`Variants` of a study job, at most ``size`` of them (the oldest go
    first; ``reused`` counts the sections not built again). A section builds from its own node alone
    (:data:`~ddmr_cli.config.build.SECTION_BUILDERS`), and its parts are not changed after they are built (the
    base simulation's are shared the same way), so equal keys give equal parts."""

    def __init__(self, size: int = 1024) -> None:
        super().__init__(size)


class Variants:
    """A config validated and built once (:attr:`simulation`), and :meth:`simulation_with` changed values.

    Parameters
    ----------
    cfg : DictConfig
        A composed config (as :func:`~ddmr_cli.config.validate.validate_config` takes it; not changed).
    parts : BuiltParts, optional
        Where sections built with a reading's values are kept (shared by the configs of a study job); none: every
        changed section is built for every reading.
    """

    def __init__(self, cfg: DictConfig, parts: BuiltParts | None = None) -> None:
        self.cfg = cfg
        self.simulation = validate_config(cfg)
        self.parts = parts
        self._values: dict[str, Any] = {}
        self._sections: dict[str, str] = {}
        #: False when a value the simulation is built or checked from is an interpolation: a changed value could
        #: flow into another section, and every change takes the full path
        self.in_place = not any(_interpolated(cfg.get(name)) for name in (*SECTION_BUILDERS, *CHECKED))

    def _in_place(self, key: str) -> bool:
        section, _, rest = key.partition(".")
        return (self.in_place and section in SECTION_BUILDERS and bool(rest) and "_target_" not in key.split(".")
                and not (section == "controller" and rest.split(".")[0] == DISPLAY))

    def value(self, key: str) -> Any:
        """The config's resolved value at ``key`` (lists and dicts plain), None where it has none; each key
        looked up once (a study reads the same keys for every sample)."""
        if key not in self._values:
            found = OmegaConf.select(self.cfg, key, default=None, throw_on_missing=False)
            self._values[key] = OmegaConf.to_container(found, resolve=True) \
                if isinstance(found, (DictConfig, ListConfig)) else found
        return self._values[key]

    def _holds(self, key: str, value: Any) -> bool:
        """True when the config holds ``value`` at ``key`` already, of the same type (setting it would change
        nothing: an exact comparison that only skips a no-op)."""
        return _same(value, self.value(key))

    def changes(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """The ``values`` the config does not hold already: what :meth:`simulation_with` sets."""
        return {key: value for key, value in values.items() if not self._holds(key, value)}

    def simulation_with(self, values: Mapping[str, Any]):
        """The :class:`~ddmr_cli.engine.simulation.Simulation` of the config with ``values`` (dotted key -> value)
        set, checked as :func:`~ddmr_cli.config.validate.validate_config` checks it (ConfigError naming the key
        of a refused value). No values: :attr:`simulation` itself."""
        values = self.changes(values)
        if not all(self._in_place(key) for key in values):
            return validate_config(with_values(self.cfg, values))
        by_section: dict[str, dict[str, Any]] = {}
        for key, value in values.items():
            name, _, rest = key.partition(".")
            by_section.setdefault(name, {})[rest] = value
        if not by_section:
            return self.simulation
        parts: dict[str, Any] = {}
        for name in SECTION_BUILDERS:  # in the builders' order, as validate_config refuses
            if name in by_section:
                parts.update(self._built(name, by_section[name]))
        sim = dataclasses.replace(self.simulation, **parts)
        check_simulation(self.cfg, sim)
        return sim

    def _section(self, name: str) -> str:
        """What section ``name`` builds from: its schema type and its content (each section read once)."""
        if name not in self._sections:
            node = self.cfg[name]
            content = f"{OmegaConf.get_type(node)!r}\n{OmegaConf.to_yaml(node)}"
            self._sections[name] = hashlib.sha256(content.encode()).hexdigest()
        return self._sections[name]

    def _built(self, name: str, values: dict[str, Any]) -> dict[str, Any]:
        """The Simulation fields section ``name`` builds with ``values`` (key within the section -> value) set, in
        their order, on a copy of it (:attr:`parts` keeps them)."""
        key = (name, self._section(name), values_key(values)) if self.parts is not None else None
        found = self.parts.get(key) if key is not None else None
        if found is None:
            node = copy.deepcopy(self.cfg[name])  # keeps its schema's types and struct flag
            for rest, value in values.items():
                OmegaConf.update(node, rest, value, merge=False)
            found = build_parts({name: node})
            if key is not None:
                self.parts.put(key, found)
        return found


__all__ = ["BuiltParts", "Variants", "values_key", "with_values"]
