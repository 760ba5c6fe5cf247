"""Typed exceptions of ddmr.

Every error a user can cause carries the offending key, its value and the rule it broke, so the CLI
can print it as one line (``error: <key>=<value>: <rule>``) and exit with status 2.
"""

from __future__ import annotations

from typing import Any


class DDMRError(Exception):
    """Base class of every error raised by ddmr."""


class EngineUnavailable(DDMRError, RuntimeError):
    """The compiled engine cannot run with the installed numba: it lacks the parts the step loop draws its runs' noise
    through (:mod:`ddmr_cli.bit_generators`)."""


class ConfigError(DDMRError, ValueError):
    """A configuration value breaks a rule.

    Parameters
    ----------
    key : str
        Dotted config key, e.g. ``robot.mass``.
    value : Any
        The offending value.
    rule : str
        The rule it broke, e.g. ``must be > 0``.
    """

    def __init__(self, key: str, value: Any, rule: str) -> None:
        self.key, self.value, self.rule = key, value, rule
        super().__init__(f"{key}={value!r}: {rule}")
