"""The search space of ``hydra/sweeper=ddmr_optuna``: Hydra's sweep overrides as Optuna suggestions.

A module whose name starts with ``_``: Hydra's plugin scan skips it (the scan executes each module of
``hydra_plugins`` outside ``sys.modules``, where a dataclass cannot be defined).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Sequence

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import ChoiceSweep, IntervalSweep, Override, RangeSweep, Transformer

from .config import DIRECTIONS


@dataclass(frozen=True)
class Dimension:
    """One searched key: how a trial suggests its value (``kind``: float, int or categorical)."""

    name: str
    kind: str
    low: Any = None
    high: Any = None
    log: bool = False
    step: Any = None
    choices: tuple = ()

    def suggest(self, trial) -> Any:
        """The trial's value of this key, by Optuna's public ``suggest_*`` API."""
        if self.kind == "categorical":
            return trial.suggest_categorical(self.name, list(self.choices))
        if self.kind == "int":
            return trial.suggest_int(self.name, self.low, self.high, step=self.step or 1, log=self.log)
        return trial.suggest_float(self.name, self.low, self.high, step=self.step, log=self.log)

    def grid(self) -> list:
        """The values of this key on a grid (GridSampler): a choice's, or a range's."""
        if self.kind == "categorical":
            return list(self.choices)
        if self.step is None:
            raise ValueError(f"{self.name}: the grid sampler needs choice(...) or range(...), not an interval")
        n = int(round((self.high - self.low) / self.step)) + 1
        return [self.low + i * self.step for i in range(n)]


def _encoded(override: Override) -> tuple:
    values = tuple(override.sweep_iterator(transformer=Transformer.encode))
    for v in values:
        if not isinstance(v, (str, int, float, bool, type(None))):
            raise ValueError(f"{override.input_line}: a choice holds str, int, float, bool or null, not {v!r}")
    return values


def dimension(override: Override) -> Optional[Dimension]:
    """The searched dimension of a sweep override, or None for a plain (fixed) override."""
    if not override.is_sweep_override():
        return None
    name, value = override.get_key_element(), override.value()
    if isinstance(value, ChoiceSweep):
        return Dimension(name, "categorical", choices=_encoded(override))
    if isinstance(value, RangeSweep):
        values = _encoded(override)
        if value.shuffle or not values:
            return Dimension(name, "categorical", choices=values)
        if all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            step = int(value.step)
            return Dimension(name, "int", values[0], values[-1], step=abs(step)) if step > 0 else \
                Dimension(name, "int", values[-1], values[0], step=abs(step))
        return Dimension(name, "float", float(min(values)), float(max(values)), step=abs(float(value.step)))
    if isinstance(value, IntervalSweep):
        ints = isinstance(value.start, int) and isinstance(value.end, int)
        low, high = (int(value.start), int(value.end)) if ints else (float(value.start), float(value.end))
        return Dimension(name, "int" if ints else "float", low, high, log="log" in value.tags)
    raise ValueError(f"{override.input_line}: not supported by the Optuna sweeper (interval, tag(log, interval), "
                     f"choice, range)")


def search_space(arguments: Sequence[str]) -> tuple[Dict[str, Dimension], List[str]]:
    """The searched dimensions and the fixed overrides of a list of overrides (later keys replace earlier ones)."""
    dims: Dict[str, Dimension] = {}
    fixed: Dict[str, str] = {}
    for override in OverridesParser.create().parse_overrides(list(arguments)):
        dim = dimension(override)
        key = override.get_key_element()
        dims.pop(key, None), fixed.pop(key, None)
        if dim is None:
            fixed[key] = str(override.input_line)
        else:
            dims[key] = dim
    return dims, list(fixed.values())


def directions(direction: Any) -> List[str]:
    """The study's directions: ``direction`` as one name or a list of them (``minimize`` | ``maximize``)."""
    names = [direction] if isinstance(direction, str) or not isinstance(direction, Sequence) else list(direction)
    out = [str(getattr(d, "name", d)) for d in names]
    bad = [d for d in out if d not in DIRECTIONS]
    if not out or bad:
        raise ValueError(f"hydra.sweeper.direction={direction!r}: each direction must be one of {', '.join(DIRECTIONS)}")
    return out


def objective_values(value: Any, n: int) -> List[float]:
    """A job's return value as ``n`` floats (one objective: a float; several: a sequence)."""
    items = [value] if n == 1 and not isinstance(value, (list, tuple)) else list(value)
    values = [float(v) for v in items]
    if len(values) != n:
        raise ValueError(f"the task returned {len(values)} values for {n} objectives")
    return values


__all__ = ["Dimension", "dimension", "search_space", "directions", "objective_values"]
