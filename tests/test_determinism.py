"""Determinism, batch independence and divergence handling of the engine (simulation.py docstring).

The engine promises: each run draws its noise from its own generator and nothing couples runs, so seed k gives
bit-identical numbers alone or inside any batch, in any order, whatever the chunking of the time axis; a run
whose deviation exceeds ``divergence_bound`` is marked diverged with the time it happened, and the others carry
on unaffected.
"""

from __future__ import annotations

import numpy as np
import pytest

from paper import make_smc, make_pid, make_rbf, make_simulation
import ddmr_cli.engine.simulation as simulation_module
from ddmr_cli import paper_terrain
from ddmr_cli import (PID, SMC, NonlinearDisturbanceObserver, Phase, RBFNetworkObserver, Scenario, Simulation,
                      Terrain, TerrainZone, WheelController, simulate)
from ddmr_cli.model.scenario import DampingUncertainty
from nan_after import NaNAfter

# short zones and phases, so that a 0.5 s run crosses every zone and phase and uses every noise channel
TERRAIN = Terrain(zones=(TerrainZone("flat", 0.0, 0.1, 0.02), TerrainZone("very_rough", 0.15, 100.0, 0.10),
                         TerrainZone("slightly_rough", 0.3, 5.0, 0.05)), correlation_time=0.02)
SCENARIO = Scenario("short_2", (Phase("terrain", 0.0, True, False), Phase("uncertainty", 0.1, False, True),
                                Phase("both", 0.25, True, True)), DampingUncertainty(0.5, 0.4, -0.5, 1.0, False),
                    phase_clock="distance")
SEEDS = list(range(8))
K = 5


def make_sim(duration=0.5, **kw):
    ctrl = make_smc(ndo=NonlinearDisturbanceObserver(50.0), nn=make_rbf())
    return make_simulation(controller=ctrl, terrain=TERRAIN, scenario=SCENARIO, dt=1e-3, duration=duration, **kw)


def assert_metrics_equal(a, ia, b, ib):
    assert a.segments == b.segments
    for name in a.metrics:
        np.testing.assert_array_equal(a.metrics[name][ia], b.metrics[name][ib], err_msg=name)
        assert np.array_equal(a.metrics[name][ia], b.metrics[name][ib], equal_nan=True), name


def assert_series_equal(sa, sb):
    assert sa.keys() == sb.keys()
    for ch in sa:
        assert np.array_equal(sa[ch], sb[ch], equal_nan=True), ch


@pytest.fixture(scope="module")
def batch():
    return simulate(make_sim(), seeds=SEEDS, keep_series=[K])


def test_same_seeds_twice_bit_identical(batch):
    again = simulate(make_sim(), seeds=SEEDS, keep_series=[K])
    for name in batch.metrics:
        assert np.array_equal(batch.metrics[name], again.metrics[name], equal_nan=True), name
    assert_series_equal(batch.series[K], again.series[K])
    assert np.array_equal(batch.diverged, again.diverged)


def test_the_run_really_uses_every_zone_phase_and_noise_channel(batch):
    s = batch.series[K]
    assert set(np.unique(s["zone"])) == {0.0, 1.0, 2.0}
    assert np.any(s["damping_scale"] != 1.0) and np.any(s["roughness"] == 100.0)
    assert not batch.diverged.any()


def test_different_seeds_give_different_numbers(batch):
    dev = batch.metric("deviation_mae")
    assert len(np.unique(dev)) == len(SEEDS)
    for name in ("chattering", "d_est_mae", "energy_u2"):
        assert len(np.unique(batch.metric(name))) == len(SEEDS), name


def test_seed_alone_equals_seed_in_batch_metrics(batch):
    alone = simulate(make_sim(), seeds=[K], keep_series=[K])
    assert_metrics_equal(alone, 0, batch, SEEDS.index(K))


def test_seed_alone_equals_seed_in_batch_series(batch):
    alone = simulate(make_sim(), seeds=[K], keep_series=[K])
    assert_series_equal(alone.series[K], batch.series[K])


def test_seed_in_shuffled_batch_equals_seed_in_batch(batch):
    order = [7, 3, 5, 0, 6, 2, 4, 1]
    shuffled = simulate(make_sim(), seeds=order, keep_series=[K, 2])
    for i, seed in enumerate(order):
        assert_metrics_equal(shuffled, i, batch, SEEDS.index(seed))
    assert_series_equal(shuffled.series[K], batch.series[K])


def test_seed_in_a_bigger_batch_equals_seed_in_batch(batch):
    bigger = simulate(make_sim(), seeds=list(range(20, 30)) + SEEDS, keep_series=[K])
    for i, seed in enumerate(SEEDS):
        assert_metrics_equal(bigger, 10 + i, batch, i)
    assert_series_equal(bigger.series[K], batch.series[K])


def run_counting_chunks(**kw):
    calls = []
    res = simulate(make_sim(), seeds=SEEDS, keep_series=[K], progress=lambda done, total: calls.append(done), **kw)
    return res, len(calls)


@pytest.fixture(scope="module")
def default_chunks():
    return run_counting_chunks()


def test_chunk_size_does_not_change_series(default_chunks, monkeypatch):
    default, n_default = default_chunks
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 1)  # the smallest chunks the engine allows
    chunked, n_chunked = run_counting_chunks()
    assert n_chunked > n_default  # the time axis really is cut differently
    assert_series_equal(chunked.series[K], default.series[K])
    assert np.array_equal(chunked.diverged, default.diverged)


def test_chunk_size_does_not_change_metrics(default_chunks, monkeypatch):
    default, n_default = default_chunks
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 1)  # the smallest chunks the engine allows
    chunked, n_chunked = run_counting_chunks()
    assert n_chunked > n_default
    for i in range(len(SEEDS)):
        assert_metrics_equal(chunked, i, default, i)


@pytest.mark.parametrize("rate", [None, 250.0, 333.3333333333333])
def test_chunks_cut_between_control_instants_and_band_points_change_nothing(monkeypatch, rate):
    """Chunks of 67 steps (no multiple of the control period of 3 or 4 steps nor of the bands' grid stride of 2)
    give the numbers, bands and series of the default chunks: the step loop finds the control instants and the band
    grid points of a chunk from its first step."""
    from ddmr_cli import paper_simulation

    overrides = ["controller=smc_ndo", "simulation.duration=3.5"] + ([f"control.rate={rate}"] if rate else [])
    sim = paper_simulation(*overrides)
    default = simulate(sim, seeds=[0, 1, 2], keep_series=[1], threads=1)
    assert default.bands["t"][1] == pytest.approx(2 * sim.dt)  # a grid point every other step
    per_run_step = 8 * 8 // 2  # eight band channels every other step (the runs draw their normals as they step)
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 67 * 3 * per_run_step)
    monkeypatch.setattr(simulation_module, "MIN_CHUNK_STEPS", 1)
    done = []
    chunked = simulate(sim, seeds=[0, 1, 2], keep_series=[1], threads=1, progress=lambda k, n: done.append(k))
    assert done[:2] == [67, 134]
    for name, values in default.metrics.items():
        assert np.array_equal(values, chunked.metrics[name], equal_nan=True), name
    for name, values in default.bands.items():
        assert np.array_equal(values, chunked.bands[name], equal_nan=True), name
    assert_series_equal(chunked.series[1], default.series[1])


def test_progress_reports_every_chunk(monkeypatch):
    monkeypatch.setattr(simulation_module, "CHUNK_BUDGET", 1)  # the smallest chunks the engine allows
    calls = []
    simulate(make_sim(duration=0.6), seeds=[0, 1], progress=lambda done, total: calls.append((done, total)))
    assert len(calls) >= 2
    assert all(total == 600 for _, total in calls)
    done = [d for d, _ in calls]
    assert done == sorted(set(done)) and done[-1] == 600 and done[0] > 0


# --------------------------------------------------------------------------------------------------------------
# divergence
# --------------------------------------------------------------------------------------------------------------

DIV_SEEDS = list(range(10))
HARSH = Terrain(zones=(TerrainZone("very_rough", 0.0, 300.0, 0.10),), correlation_time=0.02)


def harsh_sim(bound):
    """PID on very rough terrain, started on the reference so the deviation is all due to the terrain."""
    return make_simulation(controller=make_pid(), terrain=HARSH, dt=1e-3, duration=0.4, initial_pose=(0.0, 0.0, 0.0),
                      divergence_bound=bound)


@pytest.fixture(scope="module")
def divergence_pair():
    free = simulate(harsh_sim(1e9), seeds=DIV_SEEDS, keep_series=DIV_SEEDS)
    max_dev = free.metric("deviation_max")
    bound = float(np.median(max_dev))  # between per-seed maxima: some runs, not all, exceed it
    bounded = simulate(harsh_sim(bound), seeds=DIV_SEEDS, keep_series=DIV_SEEDS)
    return free, bounded, bound


def test_divergence_marks_exactly_the_runs_over_the_bound(divergence_pair):
    free, bounded, bound = divergence_pair
    assert not free.diverged.any()
    expected = free.metric("deviation_max") > bound
    assert 0 < expected.sum() < len(DIV_SEEDS)
    np.testing.assert_array_equal(bounded.diverged, expected)


def test_divergence_time_is_first_step_over_the_bound(divergence_pair):
    free, bounded, bound = divergence_pair
    for i, seed in enumerate(DIV_SEEDS):
        s = free.series[seed]
        if bounded.diverged[i]:
            first = np.flatnonzero(s["deviation"] > bound)[0]
            assert bounded.divergence_time[i] == pytest.approx(s["t"][first], abs=1e-12)
        else:
            assert np.isnan(bounded.divergence_time[i])
    assert np.all(np.isnan(free.divergence_time))


def test_diverged_runs_do_not_touch_the_others(divergence_pair):
    free, bounded, _ = divergence_pair
    ok = ~bounded.diverged
    for name in free.metrics:
        assert np.array_equal(bounded.metrics[name][ok], free.metrics[name][ok], equal_nan=True), name
    for i, seed in enumerate(DIV_SEEDS):
        if ok[i]:
            assert_series_equal(bounded.series[seed], free.series[seed])


def test_diverged_runs_metrics_are_nan(divergence_pair):
    _, bounded, _ = divergence_pair
    for name, arr in bounded.metrics.items():
        assert np.all(np.isnan(arr[bounded.diverged])), name


def test_summary_counts_diverged_and_averages_the_rest(divergence_pair):
    free, bounded, _ = divergence_pair
    summ = bounded.summary()
    ok = ~bounded.diverged
    assert summ["runs"] == len(DIV_SEEDS)
    assert summ["diverged"] == int(bounded.diverged.sum())
    assert summ["deviation_mae_mean"] == pytest.approx(np.mean(free.metric("deviation_mae")[ok]), rel=1e-12)
    assert summ["deviation_mae_sd"] == pytest.approx(np.std(free.metric("deviation_mae")[ok], ddof=1), rel=1e-10)
    table = bounded.to_pandas()
    assert list(table["status"] == "diverged") == list(bounded.diverged)
    assert table.loc[bounded.diverged, "deviation_mae"].isna().all()


def test_non_finite_deviation_counts_as_divergence():
    """A run whose state turns NaN is diverged even with an infinite bound, at the first step whose deviation is
    NaN; the other run is unaffected. A NaN voltage at step 30 makes w_31 NaN (Euler), hence the pose x_32: the
    deviation is first NaN at t = 32 dt."""
    def sim(ctrl):
        return make_simulation(controller=ctrl, terrain=paper_terrain("none"), dt=1e-3, duration=0.1, initial_pose=(0.0, 0.0, 0.0),
                          divergence_bound=float("inf"))
    res = simulate(sim(NaNAfter(30)), seeds=[0, 1], keep_series=[1])
    ref = simulate(sim(NaNAfter(10**9)), seeds=[0, 1], keep_series=[1])
    np.testing.assert_array_equal(res.diverged, [True, False])
    assert res.divergence_time[0] == pytest.approx(0.032, abs=1e-12)
    assert np.isnan(res.metric("deviation_mae")[0])
    assert not ref.diverged.any()
    for name in ref.metrics:
        assert np.array_equal(res.metrics[name][1], ref.metrics[name][1], equal_nan=True), name
    assert_series_equal(res.series[1], ref.series[1])


def test_noise_drawn_by_blocks_of_runs_is_the_noise_drawn_at_once():
    """Worker threads each draw their own runs' normals: the same numbers as one draw for all runs."""
    from ddmr_cli.model.noise import NoiseStreams

    whole = NoiseStreams([5, 6, 7, 8, 9]).next_chunk(40)
    streams = NoiseStreams([5, 6, 7, 8, 9])
    blocks = np.empty_like(whole)
    for block in ((3, 5), (0, 3)):  # any order
        streams.next_chunk(40, blocks, block)
    assert np.array_equal(blocks, whole)
    with pytest.raises(ValueError, match="shape"):
        streams.next_chunk(40, np.empty((5, 39, 3)), (0, 2))


def test_the_step_loops_draws_one_at_a_time_are_numpys_stream():
    """The step loop draws each run's normals one at a time as it steps (``stream_of``, ``next_normal``, ``keep``),
    compiled (numpy's ziggurat on the run's PCG64 words) and as plain Python (the generator's own
    ``standard_normal()``): the numbers numpy's ``standard_normal(size)`` gives the run's generator at once, and the
    generator's state after them, in two chunks as in the loop."""
    from ddmr_cli import bit_generators
    from ddmr_cli.compiled import law

    def draw_each(streams, out, first, end):
        for r in range(out.shape[0]):
            stream = bit_generators.stream_of(streams, r)
            for i in range(first, end):
                x, stream = bit_generators.next_normal(stream)
                out[r, i] = x
            bit_generators.keep(streams, r, stream)

    seeds = (3, 11, 2**32 - 1)
    compiled, plain = bit_generators.states(seeds), bit_generators.generators(seeds)
    for drawn_by, streams in ((law(draw_each), compiled), (draw_each, plain)):
        drawn = np.empty((len(seeds), 50_000))
        drawn_by(streams, drawn, 0, 20_000)
        drawn_by(streams, drawn, 20_000, 50_000)
        for run, seed in enumerate(seeds):
            numpys = np.random.default_rng(seed)
            np.testing.assert_allclose(drawn[run], numpys.standard_normal(50_000), rtol=1e-15, atol=0,
                                       err_msg=f"{drawn_by} {seed}")
    for run, seed in enumerate(seeds):  # both left where numpy's own draw leaves the generator
        numpys = np.random.default_rng(seed)
        numpys.standard_normal(50_000)
        assert bit_generators.state_of(compiled[run]) == numpys.bit_generator.state == plain[run].bit_generator.state


def test_the_compiled_draw_is_numpys_stream():
    """``standard_normals_of`` (numpy's ziggurat on each run's PCG64 row; what the engine draws a block with) gives
    numpy's own ``standard_normal(out=...)`` stream of each seed, 600,000 normals each (the ziggurat's rare tail and
    wedge branches included), for the runs of the block it is given only, and leaves each run's generator where
    numpy's draw leaves it."""
    from ddmr_cli import bit_generators

    assert bit_generators.drawn_compiled(), "numba is a dependency: the engine draws compiled"
    seeds = (0, 7, 12345, 99)
    states = bit_generators.states(seeds)
    drawn = np.zeros((len(seeds), 200_000, 3))
    bit_generators.standard_normals_of(states, drawn, 1, 4)  # the block of runs 1..3
    assert not drawn[0].any()
    assert bit_generators.state_of(states[0]) == np.random.default_rng(seeds[0]).bit_generator.state
    for run in (1, 2, 3):
        numpys = np.random.default_rng(seeds[run])
        expected = numpys.standard_normal((200_000, 3))
        np.testing.assert_allclose(drawn[run], expected, rtol=1e-15, atol=0)  # the same numbers (to the bit here)
        assert bit_generators.state_of(states[run]) == numpys.bit_generator.state
        assert abs(drawn[run]).max() > 4.0  # the draw reached the ziggurat's tail


@pytest.mark.parametrize("spawn_key", [(), (1,), (3, 7)])
def test_the_runs_generators_are_seeded_as_numpy_seeds_them(spawn_key):
    """``bit_generators.states`` (numpy's ``pcg64_set_seed`` of the hashed words, one compiled call for every seed)
    holds each seed's ``default_rng(SeedSequence(seed, spawn_key=...))`` state, seeds beyond one 32-bit word (hashed
    by SeedSequence itself) too; ``generator_at`` gives back a numpy generator that draws on from it."""
    from ddmr_cli import bit_generators

    seeds = list(range(0, 3000, 7)) + [2**31, 2**32 - 1, 2**32, 2**40 + 5]
    for made in (bit_generators.states(seeds, spawn_key), bit_generators.states(seeds[:-2], spawn_key)):
        assert made.dtype == np.uint64 and made.shape[1] == len(bit_generators.STATE_WORDS)
        for seed, row in zip(seeds, made):
            numpys = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn_key))
            assert bit_generators.state_of(row) == numpys.bit_generator.state, seed
            assert row[3] & np.uint64(1) == 1  # PCG64's increment is odd
    row = bit_generators.states([42])[0]
    drawn_on = bit_generators.generator_at(row).standard_normal(9)
    np.testing.assert_allclose(drawn_on, np.random.default_rng(42).standard_normal(9), rtol=1e-15, atol=0)


def test_noise_streams_are_numpys_in_any_chunking():
    """A run's stream is numpy's own whatever the chunk sizes and blocks it is drawn in, and numpy's own draw
    (``generator_at`` the run's state) continues it where the compiled one stopped."""
    from ddmr_cli import bit_generators
    from ddmr_cli.model.noise import NoiseStreams

    sizes = [7, 512, 1, 1025, 64]
    streams = NoiseStreams([3, 4, 5])
    drawn = [streams.next_chunk(n) for n in sizes]
    blocks = np.empty((3, 9, NoiseStreams.channels))
    streams.next_chunk(9, blocks, (2, 3))
    streams.next_chunk(9, blocks, (0, 2))
    drawn = np.concatenate(drawn + [blocks], axis=1)
    tail = [bit_generators.generator_at(row).standard_normal((5, NoiseStreams.channels)) for row in streams.states]
    for run, seed in enumerate((3, 4, 5)):
        expected = np.random.default_rng(seed).standard_normal((sum(sizes) + 9 + 5, NoiseStreams.channels))
        np.testing.assert_allclose(np.concatenate([drawn[run], tail[run]]), expected, rtol=1e-15, atol=0)


def test_without_the_compiled_draw_numpy_draws_the_same_numbers(monkeypatch):
    """Where the draws run as Python (numba off, or lacking the parts the compiled draw builds on), numpy's own
    generators draw: the same streams."""
    from ddmr_cli import bit_generators
    from ddmr_cli.model.noise import NoiseStreams

    compiled = NoiseStreams([11, 12]).next_chunk(300)
    monkeypatch.setattr(bit_generators, "AVAILABLE", False)
    streams = NoiseStreams([11, 12])
    assert streams.states is None and len(streams.generators) == 2
    np.testing.assert_allclose(streams.next_chunk(300), compiled, rtol=1e-15, atol=0)


@pytest.mark.parametrize("spawn_key", [(), (1,), (3, 7)])
def test_generators_seeded_at_once_are_default_rngs(spawn_key):
    """``bit_generators.generators`` (numpy's SeedSequence hash run for every seed at once) gives each seed the
    generator ``default_rng(SeedSequence(seed, spawn_key=...))`` gives it: the same state and the same stream, for
    small and one-word-edge seeds; seeds beyond one 32-bit word go through SeedSequence itself."""
    from ddmr_cli import bit_generators

    seeds = list(range(0, 3000, 7)) + [2**31, 2**32 - 1, 2**32, 2**40 + 5]
    words = bit_generators.seed_words(seeds[:-2], spawn_key)
    for i, seed in enumerate(seeds[:-2]):  # the hash itself: integers, compared exactly
        assert words[i].tolist() == np.random.SeedSequence(seed, spawn_key=spawn_key).generate_state(
            4, np.uint64).tolist(), seed
    assert bit_generators.seed_words(seeds, spawn_key) is None  # a two-word seed: not hashed here
    for made in (bit_generators.generators(seeds, spawn_key), bit_generators.generators(seeds[:-2], spawn_key)):
        for seed, generator in zip(seeds, made):
            numpys = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn_key))
            assert generator.bit_generator.state == numpys.bit_generator.state, seed
            np.testing.assert_allclose(generator.standard_normal(4), numpys.standard_normal(4), rtol=1e-15, atol=0)
