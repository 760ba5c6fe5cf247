"""The rules a configured value must follow, each raising :class:`~ddmr_cli.errors.ConfigError` with the value's
config key (``robot.mass``, ``controller.nn.width``, ...), so the CLI can print one line and exit 2.

The model's and the controllers' own constructors apply them: validation lives with what it validates.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ddmr_cli.errors import ConfigError


def _number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ConfigError(key, value, "must be a number")
    if not math.isfinite(value):
        raise ConfigError(key, value, "must be finite")
    return float(value)


def finite(key: str, value: Any) -> float:
    """A finite number."""
    return _number(key, value)


def positive(key: str, value: Any) -> float:
    """A finite number > 0."""
    v = _number(key, value)
    if v <= 0:
        raise ConfigError(key, value, "must be > 0")
    return v


def non_negative(key: str, value: Any) -> float:
    """A finite number >= 0."""
    v = _number(key, value)
    if v < 0:
        raise ConfigError(key, value, "must be >= 0")
    return v


def integer(key: str, value: Any, minimum: int) -> int:
    """An integer >= ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(key, value, "must be an integer")
    if value < minimum:
        raise ConfigError(key, value, f"must be >= {minimum}")
    return int(value)


def boolean(key: str, value: Any) -> bool:
    """true or false (not a number or a string)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(key, value, "must be true or false")
    return bool(value)


def one_of(key: str, value: Any, options: Sequence[str]) -> str:
    """One of ``options``."""
    if value not in options:
        raise ConfigError(key, value, f"must be one of {', '.join(options)}")
    return value


def per_wheel(key: str, value: Any, rule=non_negative) -> tuple[float, float]:
    """A gain given as a number (both wheels) or a ``[right, left]`` pair, each checked by ``rule``."""
    if isinstance(value, (list, tuple, np.ndarray)) or type(value).__name__ == "ListConfig":
        items = list(value)
        if len(items) != 2:
            raise ConfigError(key, list(items), "must be a number or a [right, left] pair")
        return rule(f"{key}[0]", items[0]), rule(f"{key}[1]", items[1])
    v = rule(key, value)
    return v, v


def compact(pair: tuple[float, float]):
    """A per-wheel gain as a number when both wheels share it, else as a [right, left] list (config values)."""
    return pair[0] if pair[0] == pair[1] else list(pair)



def starts_increasing_from_zero(key: str, items: Sequence[tuple[str, float]], what: str) -> None:
    """Named segments whose starts begin at 0 and increase strictly (terrain zones, scenario phases)."""
    if len(items) == 0:
        raise ConfigError(key, {}, f"needs at least one {what}")
    previous = None
    for name, start in items:
        start = non_negative(f"{key}.{name}.start", start)
        if previous is None and start != 0:
            raise ConfigError(f"{key}.{name}.start", start, f"the first {what} must start at 0")
        if previous is not None and start <= previous:
            raise ConfigError(f"{key}.{name}.start", start,
                              f"{what} starts must be increasing (previous one starts at {previous:g})")
        previous = start


__all__ = ["first_non_finite", "finite", "positive", "non_negative", "integer", "boolean", "one_of", "per_wheel", "compact",
           "starts_increasing_from_zero"]


def first_non_finite(value: Any, path: str = "") -> str | None:
    """The path (``ginv[0]``, ``nominal.jinv_p``) of the first NaN or inf number in a derived model quantity:
    a float, a named tuple, a tuple or list, or a float array, nested; None when every number is finite."""
    if hasattr(value, "_fields"):
        items = ((f"{path}.{name}" if path else name, getattr(value, name)) for name in value._fields)
    elif isinstance(value, (tuple, list)):
        items = ((f"{path}[{i}]", v) for i, v in enumerate(value))
    elif isinstance(value, np.ndarray):
        if value.dtype.kind in "fc" and not np.all(np.isfinite(value)):
            return f"{path}[{np.flatnonzero(~np.isfinite(value.ravel()))[0]}]"
        return None
    elif isinstance(value, (float, np.floating)) and not isinstance(value, bool):
        return None if math.isfinite(value) else path
    else:
        return None
    for sub_path, sub in items:
        found = first_non_finite(sub, sub_path)
        if found is not None:
            return found
    return None

