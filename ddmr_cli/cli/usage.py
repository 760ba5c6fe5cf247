"""Bad input on the command line: :class:`UsageError`, the one line it prints (exit status 2), and the one-line
reading of a Hydra or OmegaConf composition error (the key, the value and what is wrong)."""

from __future__ import annotations

import sys

EXIT_USAGE = 2
EXIT_FAILED = 1
INTERRUPTED = 130
INTERRUPTED_MESSAGE = "ddmr: interrupted; run the same command again to resume"


class UsageError(Exception):
    """Bad input found before anything ran: printed as one line, exit status 2."""


def fail(message: str) -> int:
    """Print ``ddmr: error: MESSAGE`` and return the usage exit status (2)."""
    print(f"ddmr: error: {message}", file=sys.stderr)
    return EXIT_USAGE


def composition_error(exc: BaseException, overrides: list[str]) -> str:
    """One line for a composition error: the key, the value and what is wrong."""
    from hydra.errors import MissingConfigException, OverrideParseException
    from omegaconf.errors import ConfigAttributeError, ConfigKeyError, OmegaConfBaseException

    from ddmr_cli.config import config_groups, group_options

    if isinstance(exc, OverrideParseException):
        return f"{exc.override}: cannot parse override ({str(exc.message).splitlines()[0]})" if hasattr(
            exc, "override") else f"cannot parse overrides: {str(exc).splitlines()[0]}"
    for ov in overrides:
        key, sep, value = ov.lstrip("+~").partition("=")
        if sep and key in config_groups():
            options = group_options(key)
            for v in value.split(","):
                if v and v not in options:
                    return f"{key}={v}: unknown {key}; available: {', '.join(options)}"
    cause = exc
    while cause.__cause__ is not None and not isinstance(cause, OmegaConfBaseException):
        cause = cause.__cause__
    if isinstance(cause, OmegaConfBaseException):
        key = getattr(cause, "full_key", None) or "?"
        # the value the user typed: the last override of the key (Hydra applies the last one)
        value = next((ov.partition("=")[2] for ov in reversed(overrides) if ov.lstrip("+~").partition("=")[0] == key),
                     None)
        msg = str(getattr(cause, "msg", cause)).splitlines()[0]
        if isinstance(cause, (ConfigKeyError, ConfigAttributeError)) and "not in" in msg:
            return f"{key}={value}: {_unknown(cause, key)}"
        return f"{key}={value}: {msg}" if value is not None else f"{key}: {msg}"
    if isinstance(exc, MissingConfigException):
        return str(exc).splitlines()[0]
    return " ".join(str(exc).split())


def _unknown(cause, key: str) -> str:
    """A key a schema does not have, with the closest key when one is close (as for ``+key=value``)."""
    import dataclasses

    from ddmr_cli.config.validate import unknown_key

    kind = getattr(cause, "object_type", None)
    fields = [f.name for f in dataclasses.fields(kind)] if dataclasses.is_dataclass(kind) else []
    *parents, name = key.split(".")
    return unknown_key(parents, name, fields)


#: Hydra launcher plugins that come with an extra of this package: launcher config name -> extra
_LAUNCHER_EXTRAS = (("ray", "ray"), ("submitit_slurm", "slurm"), ("submitit_local", "slurm"))


def missing_plugin(exc: BaseException, overrides: list[str]) -> str | None:
    """One line naming the pip extra when a launcher preset needs a Hydra plugin that is not installed."""
    from hydra.errors import MissingConfigException

    missing = getattr(exc, "missing_cfg_file", None) if isinstance(exc, MissingConfigException) else None
    if not missing or not str(missing).startswith("hydra/launcher/"):
        return None
    name = str(missing).rsplit("/", 1)[-1]
    extra = dict(_LAUNCHER_EXTRAS).get(name)
    given = next((ov for ov in overrides if ov.lstrip("+").partition("=")[0] in ("launcher", "hydra/launcher")),
                 f"hydra/launcher={name}")
    if extra is None:
        return f"{given}: Hydra's {name} launcher plugin is not installed"
    return (f"{given}: Hydra's {name} launcher plugin is not installed; "
            f"pip install 'ddmr-cli[{extra}]' (or pip install -e '.[{extra}]' in a checkout)")



def one_line(exc: BaseException, overrides: list[str]) -> str:
    """The one line for a composition error: the launcher extra to install, or the key, value and problem."""
    return missing_plugin(exc, overrides) or composition_error(exc, overrides)


__all__ = ["EXIT_USAGE", "EXIT_FAILED", "INTERRUPTED", "INTERRUPTED_MESSAGE", "UsageError", "fail", "one_line",
           "composition_error", "missing_plugin"]
