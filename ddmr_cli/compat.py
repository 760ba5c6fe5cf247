"""Every private API of a library the package uses, in one place, behind a version check.

ddmr reaches into Hydra where its public API has no equivalent: composing a sweep's jobs from one composition
(its loader's override application and its repository), naming job dirs exactly as Hydra will, expanding a sweep
as its basic sweeper does, and locating a ``_target_`` class without Hydra's error log line. Each symbol is
wrapped here, with the versions it was written for; ``tests/test_compat.py`` checks each one's behaviour, so an
upgrade of Hydra is this file and that test.

Hydra
    :data:`HYDRA_SUPPORTED`: the ``major.minor`` releases these wrappers are written for (``hydra-core>=1.3.2,<1.4``
    in ``pyproject.toml``). :func:`check_hydra` raises :class:`~ddmr_cli.errors.DDMRError` on another release.
"""

from __future__ import annotations

from typing import Any, Iterable, Sequence

from ddmr_cli.errors import DDMRError

#: Hydra releases (major, minor) the wrappers below are written for
HYDRA_SUPPORTED = ((1, 3),)


def _release(version: str) -> tuple[int, int]:
    major, minor, *_ = (version.split("+")[0].split(".") + ["0", "0"])
    return int(major), int("".join(c for c in minor if c.isdigit()) or 0)


def check_hydra(version: str | None = None) -> None:
    """Raise DDMRError (one line) unless the installed Hydra (or ``version``) is a release the wrappers support."""
    if version is None:
        import hydra

        version = hydra.__version__
    if _release(version) not in HYDRA_SUPPORTED:
        supported = ", ".join(f"{a}.{b}" for a, b in HYDRA_SUPPORTED)
        raise DDMRError(f"hydra-core {version} is installed; ddmr uses private Hydra APIs written for {supported}.x "
                        f"(ddmr_cli/compat.py): pip install 'hydra-core>=1.3.2,<1.4'")


def apply_overrides(overrides: Sequence, cfg) -> None:
    """Apply parsed value overrides to a composed config in place, as Hydra's loader does after composing the
    defaults tree (struct mode on): ``ConfigLoaderImpl._apply_overrides_to_config``."""
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    ConfigLoaderImpl._apply_overrides_to_config(list(overrides), cfg)


def overrides_dirname(parsed: Sequence, exclude_keys: Iterable[str], item_sep: str, kv_sep: str) -> str:
    """``hydra.job.override_dirname`` of parsed overrides, as Hydra computes it for a job."""
    from hydra._internal.config_loader_impl import get_overrides_dirname

    return get_overrides_dirname(list(parsed), exclude_keys=list(exclude_keys), item_sep=item_sep, kv_sep=kv_sep)


def basic_sweeper(max_batch_size: int | None = None, params: dict | None = None):
    """A new instance of Hydra's basic sweeper (the class Hydra's own plugin registry holds)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    return BasicSweeper(max_batch_size=max_batch_size, params=params)


def split_sweep(parsed: Sequence) -> list[list[str]]:
    """The job override lists Hydra's basic sweeper makes of parsed overrides (the cartesian product, in its
    order): ``BasicSweeper.split_arguments`` in one batch."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    return BasicSweeper.split_arguments(list(parsed), None)[0]


def locate(path: str) -> Any:
    """The object a dotted path names (``_target_``), raising on failure without the error line Hydra's public
    ``hydra.utils.get_class`` logs: ``hydra._internal.utils._locate``."""
    from hydra._internal.utils import _locate

    return _locate(path)


def config_repository(loader) -> Any:
    """The config repository of a Hydra config loader (``group_exists``, ``get_group_options``):
    ``ConfigLoaderImpl.repository``."""
    return loader.repository


__all__ = ["HYDRA_SUPPORTED", "check_hydra", "apply_overrides", "overrides_dirname", "basic_sweeper",
           "split_sweep", "locate", "config_repository"]
