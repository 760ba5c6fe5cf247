"""How many threads OpenBLAS starts in ddmr's own processes: one.

numpy's OpenBLAS starts a pool of threads as it loads (one per core) that spin before they sleep: about 60 ms of
CPU on the other core of a 2-core machine in every ``ddmr`` process, while the program imports, composes and loads
its compiled loop on the first core and overlaps its warm-up and the plots on the second. ddmr does no linear
algebra where threads pay (its statistics are small), and one thread also fixes the order of BLAS's sums, so no
number can depend on the thread count. Measured on the 2-core machine against the program without it, 10
alternating pairs of ``ddmr run`` (farm-bench): 0.93x the wall (0.85-1.09x), 0.93x the CPU. A value the user set
is kept; the Python API leaves the environment alone (this is the program's choice, made at its entry point, as
:mod:`ddmr_cli.cli.collector`'s)."""

from __future__ import annotations

import os

#: the variable OpenBLAS reads as it loads (numpy's and scipy's wheels bundle OpenBLAS)
VARIABLE = "OPENBLAS_NUM_THREADS"


def single_threaded_blas() -> None:
    """Set :data:`VARIABLE` to 1 unless the user set it; only effective before numpy is first imported."""
    os.environ.setdefault(VARIABLE, "1")


__all__ = ["VARIABLE", "single_threaded_blas"]
