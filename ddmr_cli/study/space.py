"""The parameter box of the sensitivity study (docs/model.md §11): each parameter, its range and the config keys
it sets; a sample (parameter -> value) <-> Hydra overrides; a sample applied to a composed config.

A parameter is one of

- **set** (``mode: set``): every key gets ``coefficient * value`` (``nn_center_range``: ``center_max = c``,
  ``center_min = -c``);
- **scale** (``mode: scale``): every key gets its configured value times ``value`` (list values element-wise);
  the faithful reading is 1;
- **choice** (``options``, a list): the value is one of the options, set on every key (``integrator: rk4``,
  ``n_neurons: 10``; a few values, as each block of 16 RBF sizes compiles its own kernel).

Samplers work on the unit cube: :meth:`Parameter.from_unit` maps u in [0, 1] onto the box (log or linear axis,
integers rounded, choices by equal shares).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from omegaconf import DictConfig, ListConfig, OmegaConf

from ddmr_cli.errors import ConfigError

SET, SCALE = "set", "scale"
LOG, LINEAR = "log", "linear"


@dataclass(frozen=True)
class Parameter:
    """One parameter of the box.

    Parameters
    ----------
    name : str
        Its name in the study (``nn_learning_rate``).
    keys : mapping of str -> float
        Config key -> coefficient (mode ``set``: key = coefficient * value).
    mode : {'set', 'scale'}
    low, high : float
        The box (numbers only).
    scale : {'log', 'linear'}
        Axis of the samplers' unit interval.
    integer : bool
        Values rounded to integers.
    options : tuple, optional
        A choice's values.
    oat_only : bool
        Only in the one-at-a-time curves (not in Morris, Sobol, calibration).
    """

    name: str
    keys: Mapping[str, float] = field(default_factory=dict)
    mode: str = SET
    low: float = math.nan
    high: float = math.nan
    scale: str = LINEAR
    integer: bool = False
    options: tuple | None = None
    oat_only: bool = False

    @property
    def is_choice(self) -> bool:
        return self.options is not None

    def check(self) -> None:
        """Raise ConfigError (key ``study.parameters.<name>``) on an unusable definition."""
        key = f"study.parameters.{self.name}"
        if self.is_choice:
            if not self.options:
                raise ConfigError(key, list(self.options), "a choice needs at least one option")
            return
        if not self.keys:
            raise ConfigError(key, {}, "names no config key (keys: {key: coefficient})")
        if self.mode not in (SET, SCALE):
            raise ConfigError(f"{key}.mode", self.mode, "must be set or scale")
        if self.scale not in (LOG, LINEAR):
            raise ConfigError(f"{key}.scale", self.scale, "must be log or linear")
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise ConfigError(key, [self.low, self.high], "needs finite low < high")
        if self.scale == LOG and self.low <= 0:
            raise ConfigError(f"{key}.low", self.low, "must be > 0 on a log axis")

    def from_unit(self, u: float) -> Any:
        """The value at position u in [0, 1] of the box (a choice: option ``floor(u n)``)."""
        u = min(max(float(u), 0.0), 1.0)
        if self.is_choice:
            return self.options[min(int(u * len(self.options)), len(self.options) - 1)]
        if self.scale == LOG:
            value = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            value = self.low + u * (self.high - self.low)
        return int(round(value)) if self.integer else value

    def to_unit(self, value: Any) -> float:
        """The inverse of :meth:`from_unit` (a choice: the middle of its option's share)."""
        if self.is_choice:
            return (self.options.index(value) + 0.5) / len(self.options)
        if self.scale == LOG:
            return (math.log(value) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        return (value - self.low) / (self.high - self.low)

    def grid(self, levels: int) -> list:
        """``levels`` values evenly spaced on the axis from low to high (a choice: every option)."""
        if self.is_choice:
            return list(self.options)
        values = [self.from_unit(i / (levels - 1)) for i in range(levels)] if levels > 1 else [self.from_unit(0.5)]
        return list(dict.fromkeys(values))  # integers may repeat


def _plain(node: Any) -> Any:
    return OmegaConf.to_container(node, resolve=True) if isinstance(node, (DictConfig, ListConfig)) else node


@dataclass(frozen=True)
class Box:
    """The study's parameters, in config order."""

    parameters: tuple[Parameter, ...]

    def restricted(self, names: Sequence[str] | None) -> "Box":
        """The box of ``names`` only (None: all)."""
        return self if names is None else Box(tuple(self[n] for n in names))

    @classmethod
    def from_config(cls, study: DictConfig | Mapping) -> "Box":
        """The box of a ``study`` config node (``study.parameters``; all of them, ``study.vary`` does not
        restrict it: see :func:`ddmr_cli.study.design.build`)."""
        params = []
        for name, spec in _plain(study["parameters"]).items():
            spec = dict(spec)
            keys = {str(k): float(c) for k, c in (spec.pop("keys", None) or {}).items()}
            p = Parameter(name=str(name), keys=keys, mode=spec.pop("mode", SET),
                          low=float(spec.pop("low", math.nan)), high=float(spec.pop("high", math.nan)),
                          scale=spec.pop("scale", LINEAR), integer=bool(spec.pop("integer", False)),
                          options=_options(spec.pop("options", None)), oat_only=bool(spec.pop("oat_only", False)))
            if spec:
                raise ConfigError(f"study.parameters.{name}", sorted(spec), "unknown fields (keys, mode, low, high, "
                                  "scale, integer, options, oat_only)")
            p.check()
            params.append(p)
        return cls(tuple(params))

    def __getitem__(self, name: str) -> Parameter:
        for p in self.parameters:
            if p.name == name:
                return p
        raise ConfigError("study.parameters", name, f"unknown parameter; known: {', '.join(self.names)}")

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def global_names(self) -> list[str]:
        """The parameters of the global designs (Morris, Sobol, calibration)."""
        return [p.name for p in self.parameters if not p.oat_only]

    def keys(self) -> list[str]:
        """Every config key the box sets."""
        return list(dict.fromkeys(k for p in self.parameters for k in p.keys))

    def faithful(self, cfg: DictConfig) -> dict[str, Any]:
        """Each parameter's value in ``cfg`` (the faithful reading): scale 1, set keys read back, a choice the
        option matching the config (None when none does)."""
        return {p.name: self._value_in(p, cfg) for p in self.parameters}

    def faithful_across(self, configs: Sequence[DictConfig]) -> dict[str, Any]:
        """:meth:`faithful`, each parameter read from the first of ``configs`` that has its first key."""
        out = {}
        for p in self.parameters:
            key = next(iter(p.keys))
            cfg = next((c for c in configs if _select(c, key) is not None), None)
            if cfg is None:
                raise ConfigError(f"study.parameters.{p.name}", key, "is not a key of any study config")
            out[p.name] = self._value_in(p, cfg)
        return out

    def _value_in(self, p: Parameter, cfg: DictConfig, base: DictConfig | None = None) -> Any:
        """The value of ``p`` that ``cfg`` holds; a scale parameter relative to ``base`` (1 without one)."""
        if p.is_choice:
            current = _plain(_select(cfg, next(iter(p.keys))))
            return next((o for o in p.options if o == current), None)
        key, coefficient = next(iter(p.keys.items()))
        if p.mode == SCALE:
            if base is None:
                return 1.0
            pairs = list(zip(_as_list(_select(base, key)), _as_list(_select(cfg, key))))
            ratios = [float(v) / float(b) for b, v in pairs if abs(float(b)) > 0]
            return ratios[0] if ratios else 1.0
        return float(_select(cfg, key)) / coefficient

    def key_values(self, sample: Mapping[str, Any], cfg: DictConfig,
                   current: Callable[[str], Any] | None = None) -> dict[str, Any]:
        """Config key -> value for a sample, relative to ``cfg`` (scale parameters multiply its values). Keys
        ``cfg`` does not have (``controller.nn.*`` of a controller without network) are left out. ``current``:
        the value ``cfg`` holds at a key, None for none (default: selected from ``cfg``; a study job passes its
        built config's lookup, :meth:`~ddmr_cli.config.variants.Variants.value`)."""
        current_of = current if current is not None else (lambda key: _select(cfg, key))
        out: dict[str, Any] = {}
        for name, value in sample.items():
            p = self[name]
            for key, coefficient in p.keys.items():
                held = current_of(key)
                if held is None:
                    continue
                if p.is_choice:
                    out[key] = value
                elif p.mode == SCALE:
                    held = _plain(held)
                    out[key] = ([float(v) * float(value) for v in held] if isinstance(held, list)
                                else float(held) * float(value))
                else:
                    out[key] = int(round(coefficient * value)) if p.integer else float(coefficient * value)
        return out

    def overrides(self, sample: Mapping[str, Any], cfg: DictConfig) -> list[str]:
        """The sample as Hydra command-line overrides (``robot.max_voltage=18.0``), relative to ``cfg``: the
        reading can be rerun with ``ddmr run <overrides>``."""
        return [f"{key}={_override_value(value)}" for key, value in self.key_values(sample, cfg).items()]

    def apply(self, sample: Mapping[str, Any], cfg: DictConfig) -> DictConfig:
        """A copy of ``cfg`` with the sample's values set (``cfg`` unchanged)."""
        from ddmr_cli.config.variants import with_values

        if not isinstance(cfg, DictConfig):
            cfg = OmegaConf.create(OmegaConf.to_container(cfg, resolve=False))
        return with_values(cfg, self.key_values(sample, cfg))

    def sample_of_overrides(self, overrides: Sequence[str], cfg: DictConfig, names: Sequence[str]) -> dict:
        """The values of ``names`` that ``overrides`` (from :meth:`overrides`) describe, read back from ``cfg``
        with the overrides applied: the inverse of :meth:`overrides`."""
        from ddmr_cli.config.variants import with_values

        out = with_values(cfg, {key: _parse_value(text) for key, _, text in (ov.partition("=") for ov in overrides)})
        return {n: self._value_in(self[n], out, base=cfg) for n in names}


def _select(cfg: DictConfig, key: str) -> Any:
    return OmegaConf.select(cfg, key, default=None, throw_on_missing=False)


def _options(options: Any) -> tuple | None:
    if options is None:
        return None
    options = _plain(options)
    return tuple(options) if isinstance(options, (list, tuple)) else (options,)


def _as_list(value: Any) -> list:
    value = _plain(value)
    return list(value) if isinstance(value, list) else [value]


def _override_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(_override_value(v) for v in value) + "]"
    return str(value)


def _parse_value(text: str) -> Any:
    from hydra.core.override_parser.overrides_parser import OverridesParser

    return OverridesParser.create().parse_override(f"k={text}").value()


#: the config key of a calibration trial's reading
READING = "study.reading"


def reading_of(study: DictConfig, box: Box) -> dict[str, Any]:
    """A trial's reading (``study.reading``), each value checked against the box (ConfigError naming the key)."""
    reading = OmegaConf.to_container(study.get("reading") or OmegaConf.create({}), resolve=True)
    for name, value in reading.items():
        p = box[name]
        ok = value in p.options if p.is_choice else (isinstance(value, (int, float)) and p.low <= value <= p.high)
        if not ok:
            bounds = list(p.options) if p.is_choice else [p.low, p.high]
            raise ConfigError(f"{READING}.{name}", value, f"must be in the box {bounds}")
    return reading



__all__ = ["READING", "reading_of", "Parameter", "Box", "SET", "SCALE", "LOG", "LINEAR"]
