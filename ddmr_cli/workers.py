"""The joblib launcher's worker processes, stopped when a sweep ends or is interrupted.

Hydra's joblib launcher keeps loky's reusable workers alive after a multirun (until loky's idle timeout); a
sweep, a tuning session or a study stage stops them when it ends, and ``ddmr run`` kills them after Ctrl-C.
"""

from __future__ import annotations

import sys


def shutdown_joblib_workers(kill: bool = False) -> None:
    """Stop the joblib launcher's worker processes now rather than after loky's idle timeout: wait for them to
    end, or (``kill``, after Ctrl-C, when they may still be running jobs) kill them without waiting."""
    if "joblib" in sys.modules:
        from joblib.externals.loky import get_reusable_executor

        if kill:
            get_reusable_executor().shutdown(wait=False, kill_workers=True)
        else:
            get_reusable_executor().shutdown(wait=True)


__all__ = ["shutdown_joblib_workers"]
