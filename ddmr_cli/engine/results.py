"""The result of a batch of runs: per-run metrics (whole run, per zone, per phase), divergence, time series; and
:func:`record`, the law that writes a kept run's step (its channels: :mod:`ddmr_cli.engine.series`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterator

import numpy as np

from ddmr_cli.compiled import law

if TYPE_CHECKING:  # pandas is imported only when a table is asked for
    import pandas as pd

@law
def record(row, t, x, y, theta, x_ref, y_ref, theta_ref, e_x, e_y, e_theta, deviation, distance, w_R, w_L,
           wd_R, wd_L, u_R, u_L, uc_R, uc_L, s_R, s_L, d_R, d_L, roughness, damping_scale, zone, diagnostics,
           recorded):
    """Write one step of a kept run into ``row``, in the order of
    :func:`~ddmr_cli.engine.series.series_channels`: the base channels, then rows ``recorded`` of the controller's
    ``diagnostics`` (right, left)."""
    row[0], row[1], row[2], row[3], row[4], row[5], row[6] = t, x, y, theta, x_ref, y_ref, theta_ref
    row[7], row[8], row[9], row[10], row[11] = e_x, e_y, e_theta, deviation, distance
    row[12], row[13], row[14], row[15], row[16], row[17], row[18], row[19] = w_R, w_L, wd_R, wd_L, u_R, u_L, uc_R, uc_L
    row[20], row[21], row[22], row[23] = s_R, s_L, d_R, d_L
    row[24], row[25], row[26] = roughness, damping_scale, zone
    for j in range(recorded.shape[0]):
        row[27 + 2 * j] = diagnostics[recorded[j], 0]
        row[28 + 2 * j] = diagnostics[recorded[j], 1]


#: seeds whose rows :meth:`SimulationResult.table` converts at once (a 10,000-seed batch's rows never all sit in memory)
ROW_BLOCK_SEEDS = 256


@dataclass
class SimulationResult:
    """Outcome of :func:`ddmr_cli.simulate` for one controller, one scenario and a batch of seeds.

    Attributes
    ----------
    seeds : list of int
    controller, scenario : str
    segments : list of str
        ``total``, then ``zone:<name>`` per terrain zone and ``phase:<name>`` per scenario phase.
    metrics : dict of str -> ndarray (n_runs, n_segments)
        Run metrics (:data:`ddmr_cli.engine.catalog.METRICS` and their steady-state twins ``<name>_ss``), NaN for
        diverged runs and empty segments.
    diverged : ndarray of bool (n_runs,)
    divergence_time : ndarray (n_runs,)
        Time of divergence [s], NaN for runs that did not diverge.
    series : dict of seed -> dict of channel -> ndarray (n_steps,)
        Time series of the seeds asked for.
    bands : dict of str -> ndarray
        Across-seed mean and 5-95 % band of a few channels on a grid of steps
        (:meth:`ddmr_cli.engine.bands.BandAccumulator.arrays`; empty when not asked for).
    """

    seeds: list[int]
    controller: str
    scenario: str
    segments: list[str]
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    divergence_time: np.ndarray
    series: dict[int, dict[str, np.ndarray]] = field(default_factory=dict)
    dt: float = 1e-3
    duration: float = 0.0
    wall_time: float = 0.0
    engine: str = "compiled"
    bands: dict[str, np.ndarray] = field(default_factory=dict)

    def metric(self, name: str, segment: str = "total") -> np.ndarray:
        """One metric for every run, in seed order."""
        return self.metrics[name][:, self.segments.index(segment)]

    def to_pandas(self, segments: bool = False) -> "pd.DataFrame":
        """Tidy per-run table: one row per seed (``segments=False``) or per seed and segment (``True``).

        Columns: ``controller, scenario, seed, [segment,] status, divergence_time`` and every metric.
        """
        import pandas as pd

        return pd.DataFrame(self.rows(segments))

    def rows(self, segments: bool = False) -> list[dict]:
        """The rows of :meth:`to_pandas` as dicts (no pandas needed)."""
        return list(self.iter_rows(segments))

    def iter_rows(self, segments: bool = False) -> Iterator[dict]:
        """The rows of :meth:`rows`, one at a time."""
        columns, rows = self.table(segments)
        for values in rows:
            yield dict(zip(columns, values))

    def table(self, segments: bool = False) -> tuple[list[str], Iterator[tuple]]:
        """The columns of :meth:`to_pandas` and its rows as tuples in that order, one at a time (what the CSV writers
        stream). The numbers become Python floats :data:`ROW_BLOCK_SEEDS` seeds at a time, by numpy, not one value
        at a time: a job's ``segments.csv`` 2.8 -> 0.9 us a value (measured), and a block's rows are all that sits
        in memory."""
        names = list(self.metrics)
        columns = ["controller", "scenario", "seed", *(["segment"] if segments else []), "status", "divergence_time",
                   *names]
        segs = list(enumerate(self.segments)) if segments else [(0, "total")]
        picked = [j for j, _ in segs]

        def rows() -> Iterator[tuple]:
            for first in range(0, len(self.seeds), ROW_BLOCK_SEEDS):
                block = slice(first, first + ROW_BLOCK_SEEDS)
                values = np.stack([self.metrics[m][block][:, picked] for m in names], axis=-1).tolist()
                times = self.divergence_time[block].astype(float).tolist()
                statuses = ["diverged" if d else "ok" for d in self.diverged[block].tolist()]
                for seed, per_segment, status, time in zip(self.seeds[block], values, statuses, times):
                    for (_, seg), metric_values in zip(segs, per_segment):
                        head = (self.controller, self.scenario, seed, seg) if segments else \
                            (self.controller, self.scenario, seed)
                        yield (*head, status, time, *metric_values)

        return columns, rows()

    def summary(self) -> dict[str, float]:
        """Across-seed mean and SD of every whole-run metric and its steady-state twin (Table 4's statistic), plus
        run counts."""
        ok = ~self.diverged
        out: dict[str, float] = {"runs": len(self.seeds), "diverged": int(self.diverged.sum())}
        for m in self.metrics:
            vals = self.metric(m)[ok]
            out[f"{m}_mean"] = float(np.mean(vals)) if vals.size else float("nan")
            out[f"{m}_sd"] = float(np.std(vals, ddof=1)) if vals.size > 1 else float("nan")
        return out
