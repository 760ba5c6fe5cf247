"""The memory a job will need, estimated before it starts, against ``run.max_memory_gb``.

A job holds, besides a fixed base (interpreter, numpy/numba, the compiled kernels, the noise buffer):

- per step: the reference and phase arrays (built from a list of tuples) and the across-seed bands;
- per kept series and step: the 31 channels of :data:`ddmr_cli.engine.series.SERIES_CHANNELS` (8 bytes each),
  copied into the result and again while written to ``series.npz`` and plotted;
- per run: the run and metric records and their per-segment metrics, and twice the controller's state record
  (state and parameters; an RBF network of n neurons holds 3 n numbers per run).

The coefficients are peak RSS measured on the development machine above a warmed-up process (180 MB), with 15-25 %
to spare: 20,000 runs of SMC-NDO-NNO over 0.2 s, +317 MB (16 KB per run); one run over 200 s (200,000 steps),
+40 MB (200 B per step); one kept series over 30 s (15,000 steps), +19 MB (about 1.1 KB per kept step).
The budget refuses a job whose estimate exceeds it, with one line naming what to change.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ddmr_cli.errors import ConfigError

BASE_BYTES = 200 * 2**20
BYTES_PER_STEP = 300
BYTES_PER_KEPT_STEP = 1100
BYTES_PER_RUN = 20 * 2**10
#: share of the machine's available memory a job (or the jobs of a sweep running at once) may use by default
DEFAULT_SHARE = 0.8
GB = 1e9


@dataclass(frozen=True)
class Estimate:
    """The memory of one job, by term [bytes]."""

    n_runs: int
    n_steps: int
    n_kept: int
    state_bytes: int

    @property
    def per_run(self) -> int:
        return BYTES_PER_RUN + 2 * self.state_bytes

    @property
    def terms(self) -> dict[str, int]:
        return {"runs": self.n_runs * self.per_run, "steps": self.n_steps * BYTES_PER_STEP,
                "series": self.n_kept * self.n_steps * BYTES_PER_KEPT_STEP}

    @property
    def total(self) -> int:
        return BASE_BYTES + sum(self.terms.values())


def state_bytes(fields: list[tuple]) -> int:
    """Bytes of one record of a structured dtype's field list, in Python integers (numpy's own itemsize
    overflows for huge shapes, e.g. 10^8 RBF neurons)."""
    total = 0
    for name, fmt, *shape in fields:
        count = math.prod(int(n) for n in (shape[0] if shape and isinstance(shape[0], tuple) else shape))
        total += np.dtype(fmt).itemsize * count
    return total


def estimate(sim, n_runs: int, n_kept: int) -> Estimate:
    """The :class:`Estimate` of a job of ``n_runs`` runs of ``sim`` keeping ``n_kept`` series."""
    n_steps = int(round(float(sim.duration) / float(sim.dt)))
    return Estimate(int(n_runs), n_steps, int(n_kept), state_bytes(sim.controller.state_fields()))


def available_bytes() -> int:
    """Memory available to new processes: psutil's ``virtual_memory().available`` (on Linux ``MemAvailable`` of
    /proc/meminfo; an estimate of the same on macOS and Windows)."""
    import psutil

    return int(psutil.virtual_memory().available)


def budget_bytes(max_memory_gb, cluster_mem_gb=None) -> tuple[int, str]:
    """The budget and where it comes from: ``run.max_memory_gb`` when set, else the memory a cluster job is
    given (``cluster.mem_gb`` of the submitit presets), else :data:`DEFAULT_SHARE` of the available memory."""
    if max_memory_gb is None and cluster_mem_gb is not None:
        return int(float(cluster_mem_gb) * GB), f"cluster.mem_gb={cluster_mem_gb}"
    if max_memory_gb is None:
        avail = available_bytes()
        return int(DEFAULT_SHARE * avail), f"{DEFAULT_SHARE:.0%} of the {avail / GB:.1f} GB available"
    return int(float(max_memory_gb) * GB), "run.max_memory_gb"


def _gb(n: float) -> str:
    return f"{n / GB:.3g} GB"


def check(est: Estimate, max_memory_gb, at_once: int = 1, cluster_mem_gb=None) -> None:
    """Raise ConfigError (one line: the estimate, its largest term and what to change) when ``at_once`` jobs of
    estimate ``est`` exceed the budget (:func:`budget_bytes`)."""
    limit, source = budget_bytes(max_memory_gb, cluster_mem_gb)
    need = est.total * at_once
    if need <= limit:
        return
    per_job = limit // at_once - BASE_BYTES
    terms = est.terms
    if terms["runs"] >= terms["steps"] + terms["series"]:
        fit = max(0, per_job - terms["steps"] - terms["series"]) // est.per_run
        hint = (f"lower run.n_runs (about {fit} fit)" if est.state_bytes < BYTES_PER_RUN else
                f"the controller's state takes {_gb(est.state_bytes)} per run (controller.nn.n_neurons?)")
    else:
        hint = "raise simulation.dt or lower simulation.duration"
        if est.n_kept > 1:
            hint += ", or keep fewer series (run.keep_series=first:1 or none)"
    jobs = f"{at_once} jobs at once x " if at_once > 1 else ""
    raise BudgetError(max_memory_gb,
                      f"the {'sweep' if at_once > 1 else 'job'} needs about {_gb(need)} ({jobs}{est.n_runs} runs x "
                      f"{est.n_steps} steps, {est.n_kept} kept series), over the budget of {_gb(limit)} "
                      f"({source}): {hint}; or raise run.max_memory_gb")


class BudgetError(ConfigError):
    """A job (or the jobs of a sweep at once) would need more memory than ``run.max_memory_gb``."""

    def __init__(self, value, rule: str) -> None:
        super().__init__("run.max_memory_gb", value, rule)
        self.args = (f"run.max_memory_gb={'null' if value is None else value}: {rule}",)


def at_once(launcher_target: str, n_jobs, n_planned: int) -> int:
    """How many jobs of a sweep run at once on this machine: joblib's ``n_jobs`` (-1: every core), every core
    for submitit's local executor, one for the basic launcher and for jobs sent elsewhere (SLURM, Ray)."""
    cores = os.cpu_count() or 1
    if "joblib" in launcher_target:
        n = int(n_jobs) if n_jobs is not None else 1
        n = cores + 1 + n if n < 0 else n
    elif "LocalLauncher" in launcher_target:
        n = cores
    else:
        n = 1
    return max(1, min(n, n_planned))


__all__ = ["at_once", "BudgetError", "Estimate", "estimate", "check", "available_bytes", "budget_bytes", "state_bytes"]
