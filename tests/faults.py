"""File-system faults injected into a ``ddmr`` process, for tests that cannot fill a disk or mount one read-only.

:func:`fault_env` writes a ``sitecustomize.py`` into a dir and returns the environment that loads it: in that
process (and its workers), opening for writing a file whose path contains ``marker`` raises
``OSError(errno)``, as a full disk (ENOSPC) or a read-only file system (EROFS) would. Markers such as
``"/.controller=smc,scenario=paper_1."`` hit only one job's staging dir.
"""

from __future__ import annotations

import os
from pathlib import Path

_SITE = '''
import builtins, errno as _errno, io, os
_SPEC = os.environ.get("DDMR_TEST_FAULT", "")
if _SPEC:
    _code, _, _marker = _SPEC.partition(":")
    _open = builtins.open

    def _faulty_open(file, mode="r", *args, **kwargs):
        if any(c in mode for c in "wax+") and isinstance(file, (str, os.PathLike)) and _marker in os.fspath(file):
            raise OSError(int(_code), os.strerror(int(_code)), os.fspath(file))
        return _open(file, mode, *args, **kwargs)

    builtins.open = _faulty_open
    io.open = _faulty_open
'''


def fault_env(directory: Path, errno: int, marker: str) -> dict[str, str]:
    """Environment variables that make writes to paths containing ``marker`` fail with ``errno``."""
    directory.mkdir(parents=True, exist_ok=True)
    (directory / "sitecustomize.py").write_text(_SITE)
    return {"PYTHONPATH": os.pathsep.join([str(directory), os.environ.get("PYTHONPATH", "")]),
            "DDMR_TEST_FAULT": f"{errno}:{marker}"}
