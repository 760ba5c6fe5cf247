"""The words of ``ddmr run``'s command line: overrides apart from Hydra's flags, config dirs made absolute,
``report=true`` as short for ``report.auto=true``, and a value quoted as an override value."""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType
from typing import Sequence

# Hydra flags after which no job runs (nothing to validate)
INFO_FLAGS = frozenset({"--help", "-h", "--hydra-help", "--version", "--info", "-i", "--cfg", "-c",
                        "--shell-completion", "-sc"})
_VALUE_FLAGS = frozenset({"--cfg", "-c", "--package", "-p", "--info", "-i", "--config-path", "-cp", "--config-name",
                          "-cn", "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc"})


def split_args(argv: Sequence[str]) -> tuple[list[str], dict[str, str | bool]]:
    """The overrides and the flags (name -> value, or True) of ``ddmr run ARGV``."""
    overrides, flags = [], {}
    it = iter(argv)
    for arg in it:
        if arg.startswith("-"):
            name, _, value = arg.partition("=")
            if name in _VALUE_FLAGS and not value and name not in ("--info", "-i", "--cfg", "-c",
                                                                   "--shell-completion", "-sc"):
                value = next(it, "")
            flags[name] = value or True
        else:
            overrides.append(arg)
    return overrides, flags


def override_value(value: str | Path) -> str:
    """A value as a Hydra override value: quoted when it has characters the override grammar would read."""
    text = str(value)
    if all(c.isalnum() or c in "/._-:+@" for c in text) and text:
        return text
    return "'" + text.replace("'", "\\'") + "'"


#: flags naming config dirs: the primary config's (``--config-path``) and an extra one (``--config-dir``)
_DIR_FLAGS = MappingProxyType({"--config-path": "path", "-cp": "path", "--config-dir": "dir", "-cd": "dir"})


def config_dirs(argv: list[str]) -> tuple[list[str], str | None, str | None]:
    """``argv`` with the ``--config-path`` / ``--config-dir`` values made absolute against the current dir (Hydra
    would read a relative --config-path against its own module's dir), and those two dirs (or None)."""
    out, dirs = [], {"path": None, "dir": None}
    it = iter(argv)
    for arg in it:
        name, sep, value = arg.partition("=")
        if name not in _DIR_FLAGS:
            out.append(arg)
            continue
        value = value if sep else next(it, "")
        if not value.startswith("pkg://"):
            value = str(Path(value.removeprefix("file://")).expanduser().resolve())
            dirs[_DIR_FLAGS[name]] = value
        out.append(f"{name}={value}")
    return out, dirs["path"], dirs["dir"]


def normalise(argv: list[str]) -> list[str]:
    """``report=true`` is short for ``report.auto=true`` (``report`` is a node: auto, margin)."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if sep and key == "report" and value.lower() in ("true", "false"):
            arg = f"report.auto={value.lower()}"
        out.append(arg)
    return out



__all__ = ["INFO_FLAGS", "split_args", "override_value", "config_dirs", "normalise"]
