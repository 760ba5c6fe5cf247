"""How often the garbage collector runs in ddmr's own processes: the ``ddmr`` program and a sweep's workers.

CPython collects its youngest generation after every 700 net allocations of container objects. What a command
allocates most is short-lived and free of cycles (Hydra's and OmegaConf's config copies for every job, the objects
of the modules it imports, matplotlib's artists): reference counting frees it, and most collections find nothing.
Collecting the youngest generation after :data:`YOUNGEST` allocations instead (the older ones after as many of
theirs as before) was measured on the 2-core machine against the program without it, in alternating pairs:
``-m +experiment=table4`` (its 8 jobs in one process) 0.94x the wall and the CPU (5 pairs, 0.89-0.99x), a 60-job
joblib sweep of one-seed jobs 0.93-0.94x (2 pairs); ``ddmr run`` and ``ddmr report`` unchanged within the
machine's noise (6 pairs of runs: 0.93-1.08x; 3 pairs of reports: 0.99-1.06x), their time being the numba loop,
numpy and matplotlib's drawing. What the rarer collections leave longer: 3-4 MB of table4's peak memory (the
10,000-seed run: 194 MB against 195). The Python API leaves the interpreter's setting alone: this is the program's
choice, made at its entry points.
"""

from __future__ import annotations

import gc

#: net allocations between two collections of the youngest generation (CPython's default: 700)
YOUNGEST = 50_000


def collect_less_often() -> None:
    """Collect the youngest generation after :data:`YOUNGEST` allocations (never more often than now); the older
    generations' thresholds are left as they are."""
    youngest, middle, oldest = gc.get_threshold()
    if youngest < YOUNGEST:
        gc.set_threshold(YOUNGEST, middle, oldest)


__all__ = ["YOUNGEST", "collect_less_often"]
