"""The seed bands' compiled windowed reduction (ddmr_cli.engine.band_windows) against numpy's sort: the same bits.

The windows decide only how fast each grid point's order statistics come, never what they are; these tests hold
the windowed pass to numpy's reduction (BandAccumulator's transpose, sort or partition, and mean) to the bit, on
drifting runs like the engine's, on ties, on jumps that make every window miss, with windows that are wrong, and
through the engine itself.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ddmr_cli.compiled import jit_enabled
from ddmr_cli.engine import bands
from ddmr_cli.engine.band_windows import reduce_points
from ddmr_cli.engine.bands import BAND_CHANNELS, BandAccumulator

pytestmark = pytest.mark.skipif(not jit_enabled(), reason="the windowed pass runs compiled only (numba installed)")

FAST = settings(max_examples=25, deadline=None, database=None)
C = len(BAND_CHANNELS)


def drifting_runs(n_runs: int, n_points: int, seed: int, jumps: float = 0.0) -> np.ndarray:
    """``(runs, points, channels)``: every run a smooth random path plus a drift common to all runs, much larger
    than their spread (as the engine's deviations and voltages are); ``jumps``: the fraction of (point, channel)
    where every run jumps by a random multiple of the spread (windows carried from the point before then miss)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n_points)
    drift = 50.0 * np.sin(2 * np.pi * rng.random(C) + 3.0 * t[:, None])  # (points, channels)
    spread = rng.standard_normal((n_runs, 1, C)) * (1.0 + t[None, :, None])
    wiggle = 0.05 * np.cumsum(rng.standard_normal((n_runs, n_points, C)), axis=1) / math.sqrt(n_points)
    out = drift[None] + spread + wiggle
    if jumps:
        hit = rng.random((n_points, C)) < jumps
        out += (hit * rng.standard_normal((n_points, C)) * 20.0)[None] * rng.random((n_runs, 1, 1))
    return out


def reduced(buffer: np.ndarray, min_runs: int, chunk: int | None = None, monkeypatch=None) -> BandAccumulator:
    """The bands of ``buffer`` reduced with the windowed pass from ``min_runs`` runs on, ``chunk`` points a call."""
    monkeypatch.setattr(bands, "WINDOW_MIN_RUNS", min_runs)
    acc = BandAccumulator(buffer.shape[1], 1e-3)
    step = chunk or buffer.shape[1]
    for a in range(0, buffer.shape[1], step):
        acc.add_chunk(np.ascontiguousarray(buffer[:, a:a + step]), a)
    return acc


def assert_same_bits(a: BandAccumulator, b: BandAccumulator) -> None:
    for name in ("mean", "low", "high"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name


@pytest.mark.parametrize("n_runs", [400, 457, 1000, 2501])
def test_the_windowed_bands_are_numpys_to_the_bit(n_runs, monkeypatch):
    """Drifting runs at run counts whose percentile indices fall on an order statistic (401: g = 0), below the
    middle (457: g = 0.8 of the 95th) and above it, and past the partition's threshold (2501): the mean, the 5th and
    the 95th percentile are numpy's reduction's, bit for bit, chunked as the engine chunks."""
    buffer = drifting_runs(n_runs, 120, seed=n_runs)
    numpys = reduced(buffer, 10**9, chunk=50, monkeypatch=monkeypatch)
    windowed = reduced(buffer, 0, chunk=50, monkeypatch=monkeypatch)
    assert_same_bits(windowed, numpys)
    assert np.isfinite(windowed.low).all() and (windowed.low < windowed.high).all()


@FAST
@given(n_runs=st.integers(2, 700), points=st.integers(1, 30), jumps=st.sampled_from([0.0, 0.3, 1.0]),
       ties=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_any_runs_jumps_and_ties_give_numpys_bands(n_runs, points, jumps, ties, seed):
    """Any run count (down to 2), jumps that make the carried windows miss (then widened, then the row sorted
    whole), and ties (values rounded: many runs equal at the order statistics): numpy's bands, bit for bit."""
    buffer = drifting_runs(n_runs, points, seed, jumps)
    if ties:
        buffer = np.round(buffer, 0)
    with pytest.MonkeyPatch.context() as patch:
        assert_same_bits(reduced(buffer, 0, chunk=7, monkeypatch=patch), reduced(buffer, 10**9, monkeypatch=patch))


def test_every_run_equal_and_a_single_run(monkeypatch):
    """Every run at one value (the start of a batch: every seed starts at the same pose), then spreading; and one
    run alone: numpy's bands."""
    buffer = drifting_runs(600, 40, seed=3)
    buffer[:, :5] = 1.25
    assert_same_bits(reduced(buffer, 0, monkeypatch=monkeypatch), reduced(buffer, 10**9, monkeypatch=monkeypatch))
    one = drifting_runs(1, 10, seed=4)
    assert_same_bits(reduced(one, 0, monkeypatch=monkeypatch), reduced(one, 10**9, monkeypatch=monkeypatch))


def work(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The pass's working memory for n runs: one row per channel, and three rows of scratch."""
    return np.empty((C, n)), np.empty((3, n))


def _order_statistics(n: int) -> np.ndarray:
    ks = []
    for p in (bands.LOW, bands.HIGH):
        k = math.floor((n - 1) * (p / 100.0))
        ks += [k, min(k + 1, n - 1)]
    return np.array(ks, dtype=np.int64)


@pytest.mark.parametrize("windows", ["nan", "inverted", "far", "random"])
def test_wrong_windows_change_only_the_speed(windows):
    """The windows are a hint: none (NaN), inverted, far from the values or random, the order statistics and sums
    are those of a sort of each row."""
    rng = np.random.default_rng(7)
    buffer = drifting_runs(800, 12, seed=5)
    start = {"nan": np.full((C, 4), np.nan), "inverted": np.tile([1.0, -1.0, 2.0, -2.0], (C, 1)),
             "far": np.tile([1e6, 2e6, 3e6, 4e6], (C, 1)), "random": rng.standard_normal((C, 4))}[windows]
    ks = _order_statistics(800)
    sums, stats = np.empty((12, C)), np.empty((4, 12, C))
    assert reduce_points(buffer, 0, 12, ks, sums, stats, start.copy(), *work(800)) >= 0
    ordered = np.sort(buffer, axis=0)
    for q, k in enumerate(ks):
        assert stats[q].tobytes() == ordered[k].tobytes()
    assert sums.tobytes() == np.add.reduce(buffer, axis=0).tobytes()


def test_windows_carried_relative_to_the_mean_hit_on_drifting_runs():
    """What makes the pass fast: on runs whose common drift is far larger than their spread, the windows carried
    from the grid point before (relative to the mean) hold the wanted ranks at nearly every point (here: at most
    1 % of the windows miss). Windows carried as absolute values would miss at nearly every point."""
    n_runs, points = 1000, 300
    buffer, ks, windows = drifting_runs(n_runs, points, seed=11), _order_statistics(n_runs), np.full((C, 4), np.nan)
    assert reduce_points(buffer, 0, 1, ks, np.empty((1, C)), np.empty((4, 1, C)), windows, *work(n_runs)) >= 0
    missed = reduce_points(buffer, 1, points, ks, np.empty((points - 1, C)), np.empty((4, points - 1, C)), windows,
                           *work(n_runs))
    assert 0 <= missed <= 0.01 * points * C


def test_a_diverged_run_leaves_the_block_to_numpy(monkeypatch):
    """A non-finite value anywhere in the block: the pass writes nothing and reports it; the accumulator reduces the
    block by numpy's rules for diverged runs (they drop out), the same bands as the numpy path."""
    buffer = drifting_runs(500, 20, seed=9)
    buffer[17, 5:, :] = np.nan
    buffer[3, 12:, 2] = np.inf
    windows = np.full((C, 4), np.nan)
    assert reduce_points(buffer, 0, 20, _order_statistics(500), np.empty((20, C)), np.empty((4, 20, C)),
                         windows, *work(500)) == -1
    windowed = reduced(buffer, 0, chunk=8, monkeypatch=monkeypatch)
    assert_same_bits(windowed, reduced(buffer, 10**9, chunk=8, monkeypatch=monkeypatch))
    assert np.isfinite(windowed.mean).all()


@pytest.mark.parametrize("threads", [1, 2])
def test_the_engines_bands_are_the_same_with_the_windowed_pass(threads, monkeypatch):
    """Through the engine (its chunks; two threads reducing disjoint grid points at once and sharing the carried
    windows): the bands of 450 seeds on the paper's terrain are those of numpy's reduction, bit for bit."""
    from ddmr_cli.config.presets import paper_simulation
    from ddmr_cli.engine.simulation import simulate

    sim = paper_simulation("controller=smc_ndo", "simulation.duration=0.3")
    results = {}
    for name, min_runs in (("numpy", 10**9), ("windowed", 0)):
        monkeypatch.setattr(bands, "WINDOW_MIN_RUNS", min_runs)
        results[name] = simulate(sim, range(450), threads=threads).bands
    assert results["numpy"].keys() == results["windowed"].keys()
    for key, values in results["numpy"].items():
        assert values.tobytes() == results["windowed"][key].tobytes(), key


def test_windows_from_a_sample_hold_the_ranks_without_a_window_carried():
    """The first grid point of a call (no windows carried yet, or stale ones from another thread's range): windows
    from a sample of 64 runs hold both percentiles' ranks at the first try in most rows (here: at least 80 % of 300
    rows of 1,000 runs), so a row is seldom sorted whole."""
    from ddmr_cli.engine.band_windows import _sample_windows, _search

    rng = np.random.default_rng(2)
    ks = _order_statistics(1000)
    inside1, inside2, sample = np.empty(1000), np.empty(1000), np.empty(1000)
    hits = 0
    for _ in range(300):
        column = rng.standard_normal(1000) * rng.uniform(0.1, 10.0) + rng.uniform(-5.0, 5.0)
        lo1, hi1, lo2, hi2 = _sample_windows(column, 1000, ks, sample)
        hits += _search(column, 1000, ks, lo1, hi1, lo2, hi2, 1, inside1, inside2)[0]
    assert hits >= 0.8 * 300
