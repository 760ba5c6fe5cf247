"""A result's per-seed rows (ddmr_cli/engine/results.py, ``SimulationResult.table``), as the job's ``metrics.csv``
and ``segments.csv`` stream them: every value where its seed, segment and metric say, Python numbers, diverged runs
marked, and the same bytes as the rows written one dict at a time."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from ddmr_cli.engine import results
from ddmr_cli.engine.results import SimulationResult
from ddmr_cli.storage import io

SEGMENTS = ["total", "zone:flat", "zone:gravel", "phase:cruise"]


@pytest.fixture
def result(monkeypatch):
    """Seeds in an order of their own, two diverged, values of every magnitude; blocks of 3 seeds, so the 7 seeds
    cross block boundaries."""
    monkeypatch.setattr(results, "ROW_BLOCK_SEEDS", 3)
    rng = np.random.default_rng(7)
    seeds = [11, 3, 40, 5, 8, 1, 2]
    names = ["deviation_mae", "chattering", "deviation_mae_ss"]
    metrics = {m: rng.standard_normal((len(seeds), len(SEGMENTS))) * 10.0 ** rng.integers(-7, 5, (len(seeds), 1))
               for m in names}
    diverged = np.array([False, True, False, False, False, True, False])
    for values in metrics.values():
        values[diverged] = np.nan
    metrics["chattering"][2, 3] = np.nan  # an empty segment
    return SimulationResult(seeds=seeds, controller="smc", scenario="paper_1", segments=SEGMENTS, metrics=metrics,
                            diverged=diverged,
                            divergence_time=np.where(diverged, 0.5 * np.arange(1, len(seeds) + 1), np.nan))


@pytest.mark.parametrize("segments", [False, True])
def test_every_value_sits_under_its_seed_segment_and_metric(result, segments):
    columns, rows = result.table(segments)
    rows = list(rows)
    picked = list(enumerate(SEGMENTS)) if segments else [(0, "total")]
    assert len(rows) == len(result.seeds) * len(picked)
    assert columns[:3] == ["controller", "scenario", "seed"] and columns[-3:] == list(result.metrics)
    for n, row in enumerate(rows):
        i, (j, segment) = divmod(n, len(picked))[0], picked[n % len(picked)]
        cell = dict(zip(columns, row))
        assert cell["seed"] == result.seeds[i] and type(cell["seed"]) is int
        assert cell.get("segment", "total") == segment
        assert cell["status"] == ("diverged" if result.diverged[i] else "ok")
        for name, values in result.metrics.items():
            assert type(cell[name]) is float
            assert cell[name] == values[i, j] or (math.isnan(cell[name]) and math.isnan(values[i, j]))
        time = result.divergence_time[i]
        assert cell["divergence_time"] == time or (math.isnan(cell["divergence_time"]) and math.isnan(time))


@pytest.mark.parametrize("segments", [False, True])
def test_the_streamed_csv_is_the_csv_of_the_rows_as_dicts(result, segments, tmp_path):
    """The same bytes as the rows written one dict at a time (csv.DictWriter, each float by repr)."""
    columns, rows = result.table(segments)
    streamed = io.write_csv(tmp_path / "streamed.csv", rows, columns=columns)
    dicts = result.rows(segments)
    with open(tmp_path / "dicts.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(dicts[0]))
        writer.writeheader()
        writer.writerows({k: repr(v) if isinstance(v, float) else v for k, v in row.items()} for row in dicts)
    assert streamed.read_bytes() == (tmp_path / "dicts.csv").read_bytes()
    assert b"nan" in streamed.read_bytes()  # a diverged run's values


def test_to_pandas_reads_what_the_csv_holds(result, tmp_path):
    import pandas as pd

    columns, rows = result.table(True)
    path = io.write_csv(tmp_path / "segments.csv", rows, columns=columns)
    read, made = pd.read_csv(path), result.to_pandas(segments=True)
    assert list(read.columns) == list(made.columns)
    pd.testing.assert_frame_equal(read, made, check_dtype=False)
