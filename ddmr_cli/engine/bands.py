"""Seed bands: the mean and the 5-95 % band over every seed of a batch, per step, in bounded memory (docs/model.md §7).

The step loop writes a few channels of every run into a buffer that holds one chunk of steps on a grid of every
``stride``-th step (:func:`band_row`); after each chunk :meth:`BandAccumulator.add_chunk` reduces it over the
runs to the mean and the 5th and 95th percentiles (exact, over the runs that are still finite) and drops it. The
buffer is bounded by the engine's chunk budget, the result by the grid: memory does not grow with the seeds.

Two reductions give the same bits: numpy's (a transpose, then each row sorted or partitioned), and from
:data:`WINDOW_MIN_RUNS` runs on, for a block whose values are all finite, the compiled windowed pass of
:mod:`ddmr_cli.engine.band_windows`, which finds each grid point's order statistics from a narrow window carried
from the point before instead of sorting every run's value.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from ddmr_cli.compiled import jit_enabled, law

#: The channels the bands cover, in the order :func:`band_row` writes them (names as in SERIES_CHANNELS).
BAND_CHANNELS = ("deviation", "e_x", "e_y", "e_theta", "u_right", "u_left", "s_right", "s_left")
#: Percentiles of the band [%].
LOW, HIGH = 5.0, 95.0
#: Most grid points of a band: the grid is every ``ceil(n_steps / MAX_POINTS)``-th step.
MAX_POINTS = 3000
#: Bytes of a buffer's values one reduction copies at a time: a chunk's grid points are reduced in blocks of at
#: most this (at least one point), so the reduction's copy stays small at any number of seeds (10,000 seeds: a 1 MiB
#: copy, not one of the whole buffer).
REDUCE_BLOCK_BYTES = 2**20
#: From this many runs on, the order statistics come from a partition (O(n)) instead of a sort: measured here,
#: numpy's SIMD sort is faster up to about a thousand values a row, the partition twice as fast at 10,000.
#: Either gives the same order statistics, so the bands do not depend on it.
PARTITION_MIN_RUNS = 2000
#: From this many runs on, a chunk of finite values is reduced by the compiled windowed pass
#: (:mod:`ddmr_cli.engine.band_windows`) instead of numpy's transpose and sort: the same numbers, bit for bit.
#: Measured on band buffers of the engine's own runs (smc_ndo on the paper's terrain, chunked as the engine chunks),
#: ns a value, numpy against windowed: 50 runs 5.5 / 13.9, 200 runs 4.0 / 6.0, 400 runs 8.5 / 4.9, 1,000 runs
#: 15.1 / 4.3 (smc_ndo_nno 15.3 / 4.1), 2,000 runs 16.0 / 4.3, 10,000 runs 18.9 / 5.7.
WINDOW_MIN_RUNS = 400


@law
def band_row(row, deviation, e_x, e_y, e_theta, u_R, u_L, s_R, s_L):
    """Write one grid step of one run into ``row``, in the order of :data:`BAND_CHANNELS`."""
    row[0], row[1], row[2], row[3] = deviation, e_x, e_y, e_theta
    row[4], row[5], row[6], row[7] = u_R, u_L, s_R, s_L


def order_rows(rows: np.ndarray, percents) -> None:
    """Put in place, in every row of ``rows`` (all finite), the order statistics that :func:`percentiles_of_sorted`
    reads for ``percents``: sort the rows, or, from :data:`PARTITION_MIN_RUNS` values a row on, partition them at
    each percentile's lower order statistic and place the next one (the smallest value above it) beside it."""
    n = rows.shape[-1]
    if n < PARTITION_MIN_RUNS:
        rows.sort(axis=-1)
        return
    ks = sorted({_virtual_index(n, p)[0] for p in percents})
    rows.partition(ks, axis=-1)
    # after the partition, everything right of position k is >= rows[k], and everything up to the next k' is <=
    # rows[k']: the (k + 1)-th order statistic is the smallest value in (k, k'] (or (k, n) for the last k)
    nexts = {k: rows[..., k + 1:end + 1].min(axis=-1) for k, end in zip(ks, ks[1:] + [n - 1]) if k + 1 < n}
    for k, nxt in nexts.items():  # all read before any is written
        rows[..., k + 1] = nxt


def percentiles_of_sorted(rows: np.ndarray, percents) -> list[np.ndarray]:
    """Percentiles of each row of ``rows`` (sorted ascending along the last axis or ordered by :func:`order_rows`;
    all finite) by numpy's default
    ``linear`` method, operation for operation: virtual index ``h = (n - 1) p / 100``, order statistics ``a =
    x[floor h]``, ``b`` the next, ``g = h - floor h``, then ``a + (b - a) g`` or, for ``g >= 0.5``,
    ``b - (b - a)(1 - g)``. Sorting the rows (SIMD) and reading two columns is several times faster than
    ``np.percentile``'s selection per row at tens to hundreds of runs."""
    out = []
    for p in percents:
        k, k_next, g = _virtual_index(rows.shape[-1], p)
        out.append(_interpolated(rows[..., k], rows[..., k_next], g))
    return out


def _virtual_index(n: int, percent: float) -> tuple[int, int, float]:
    """numpy's ``linear`` method over n values: the two order statistics either side of the virtual index
    ``h = (n - 1) p / 100`` (``floor h`` and the next, the last at most) and the fraction ``h - floor h``."""
    h = (n - 1) * (float(percent) / 100.0)
    k = math.floor(h)
    return k, min(k + 1, n - 1), h - k


def _interpolated(a: np.ndarray, b: np.ndarray, g: float) -> np.ndarray:
    """numpy's ``linear`` percentile between order statistics ``a`` and the next, ``b``, at fraction ``g`` of the way:
    ``a + (b - a) g`` or, for ``g >= 0.5``, ``b - (b - a)(1 - g)``."""
    return b - (b - a) * (1.0 - g) if g >= 0.5 else a + (b - a) * g


def _finite_mean(buffer: np.ndarray) -> np.ndarray:
    """The mean over the runs (axis 0) of the finite values, NaN where none is: ``np.nanmean`` with the non-finite
    values as NaN, operation for operation (the sum with 0 in their place, divided by the count), without its
    warning for an all-NaN slice."""
    finite = np.isfinite(buffer)
    return np.sum(np.where(finite, buffer, 0.0), axis=0) / np.sum(finite, axis=0, dtype=np.intp)


def _finite_percentiles(rows: np.ndarray, percents) -> list[np.ndarray]:
    """``np.nanpercentile`` of each row's finite values (rows without one: NaN), without its warning for an all-NaN
    row; non-finite values are set to NaN in place."""
    rows[~np.isfinite(rows)] = np.nan
    some = ~np.isnan(rows).all(axis=1)
    out = [np.full(rows.shape[0], np.nan) for _ in percents]
    if some.any():
        for o, values in zip(out, np.nanpercentile(rows[some], percents, axis=1)):
            o[some] = values
    return out


def band_stride(n_steps: int) -> int:
    """Steps between two grid points of a band of ``n_steps`` steps."""
    return max(1, math.ceil(n_steps / MAX_POINTS))


class BandAccumulator:
    """Mean, 5th and 95th percentile over runs at every grid step, filled chunk by chunk.

    Parameters
    ----------
    n_steps : int
        Steps of a run; the grid is steps ``0, stride, 2 stride, ...``.
    dt : float
        Step [s].
    """

    def __init__(self, n_steps: int, dt: float) -> None:
        self.stride = band_stride(n_steps)
        self.n_points = (n_steps - 1) // self.stride + 1
        self.t = np.arange(self.n_points) * self.stride * dt
        self.mean = np.full((len(BAND_CHANNELS), self.n_points), np.nan)
        self.low = np.full_like(self.mean, np.nan)
        self.high = np.full_like(self.mean, np.nan)
        # the windowed pass's windows, carried from one call to the next (a hint for speed only: any windows give
        # the same numbers), and the lock that keeps threads reducing disjoint ranges from tearing them
        self._windows = np.full((len(BAND_CHANNELS), 4), np.nan)
        self._windows_lock = threading.Lock()

    def grid_range(self, k0: int, n_steps: int) -> tuple[int, int]:
        """The grid points ``[first, end)`` that fall on steps ``k0 .. k0 + n_steps - 1``."""
        first = -(-k0 // self.stride)
        end = -(-(k0 + n_steps) // self.stride)
        return first, end

    def most_points(self, n_steps: int) -> int:
        """The most grid points ``n_steps`` consecutive steps hold (:meth:`grid_range` of any first step):
        ``ceil(n_steps / stride)``, reached by a run of steps that starts on a grid point."""
        return -(-n_steps // self.stride)

    def add_chunk(self, buffer: np.ndarray, first: int, points: tuple[int, int] | None = None) -> None:
        """Reduce ``buffer[run, j, channel]`` (grid points ``first + j``) over the runs; only the buffer's grid
        points ``points = (a, b)`` when given (threads may reduce disjoint ranges of one buffer at once: every
        number is reduced over the runs of its own grid point and channel alone, so the split changes no bits)."""
        a, b = points if points is not None else (0, buffer.shape[1])
        if buffer.shape[0] >= WINDOW_MIN_RUNS and jit_enabled() and self._reduce_windowed(buffer, first, a, b):
            return
        buffer, first = buffer[:, a:b], first + a
        block = max(1, REDUCE_BLOCK_BYTES // max(1, buffer.shape[0] * buffer.shape[2] * buffer.itemsize))
        for a in range(0, buffer.shape[1], block):
            self._reduce(buffer[:, a:a + block], first + a)

    def _reduce_windowed(self, buffer: np.ndarray, first: int, a: int, b: int) -> bool:
        """:meth:`add_chunk` of grid points ``a .. b - 1`` by the compiled windowed pass
        (:func:`~ddmr_cli.engine.band_windows.reduce_points`); False, with nothing written, when a value is not finite
        (a run has diverged: numpy's reduction drops it)."""
        from ddmr_cli.engine.band_windows import reduce_points

        n, n_points = buffer.shape[0], b - a
        (k1, k1_next, g1), (k2, k2_next, g2) = _virtual_index(n, LOW), _virtual_index(n, HIGH)
        sums = np.empty((n_points, len(BAND_CHANNELS)))
        stats = np.empty((4, n_points, len(BAND_CHANNELS)))
        with self._windows_lock:
            windows = self._windows.copy()
        ks = np.array([k1, k1_next, k2, k2_next], dtype=np.int64)
        columns, scratch = np.empty((len(BAND_CHANNELS), n)), np.empty((3, n))
        if reduce_points(np.ascontiguousarray(buffer), a, b, ks, sums, stats, windows, columns, scratch) < 0:
            return False
        with self._windows_lock:
            self._windows = windows
        mean = sums / n
        low, high = _interpolated(stats[0], stats[1], g1), _interpolated(stats[2], stats[3], g2)
        self.mean[:, first + a:first + b] = mean.T
        self.low[:, first + a:first + b] = low.T
        self.high[:, first + a:first + b] = high.T
        return True

    def _reduce(self, buffer: np.ndarray, first: int) -> None:
        """:meth:`add_chunk` on one block of grid points (all of ``buffer``)."""
        n = buffer.shape[1]
        # one contiguous row of runs per grid point and channel: the percentiles partition rows, not strided columns
        columns = np.ascontiguousarray(buffer.reshape(buffer.shape[0], -1).T)
        with np.errstate(all="ignore"):
            if np.isfinite(columns).all():
                order_rows(columns, [LOW, HIGH])
                mean, (low, high) = buffer.mean(axis=0), percentiles_of_sorted(columns, [LOW, HIGH])
            else:  # diverged runs (inf or NaN) drop out; a grid step where every run has diverged is NaN
                mean, (low, high) = _finite_mean(buffer), _finite_percentiles(columns, [LOW, HIGH])
        low, high = (a.reshape(n, len(BAND_CHANNELS)) for a in (low, high))
        self.mean[:, first:first + n] = mean.T
        self.low[:, first:first + n] = low.T
        self.high[:, first:first + n] = high.T

    def arrays(self) -> dict[str, np.ndarray]:
        """``{"t": grid times, "<channel>/mean": ..., "<channel>/p05": ..., "<channel>/p95": ...}``."""
        out = {"t": self.t}
        for c, name in enumerate(BAND_CHANNELS):
            out[f"{name}/mean"], out[f"{name}/p05"], out[f"{name}/p95"] = self.mean[c], self.low[c], self.high[c]
        return out


__all__ = ["BAND_CHANNELS", "BandAccumulator", "REDUCE_BLOCK_BYTES", "band_row", "band_stride", "order_rows",
           "percentiles_of_sorted"]
