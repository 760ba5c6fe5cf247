"""A package's public names imported on first use (PEP 562), so that importing the package, or one of its modules,
does not import every module behind those names (``ddmr --help`` starts fast; the report reads the controllers'
channel kinds without loading numba)."""

from __future__ import annotations

import sys
from importlib import import_module


def lazy_exports(package: str, exports: dict[str, str]):
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` for ``exports`` (public name -> the module,
    relative to the package, that defines it): a name is imported when first read, then kept in the package."""

    def __getattr__(name: str):
        if name in exports:
            value = getattr(import_module(f".{exports[name]}", package), name)
            setattr(sys.modules[package], name, value)
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(exports))

    return __getattr__, __dir__


__all__ = ["lazy_exports"]
