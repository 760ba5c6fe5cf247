"""The seed bands' order statistics, compiled: each grid point's from a narrow window carried from the one before.

The bands (:mod:`ddmr_cli.engine.bands`) need, at every grid point and channel, the mean over the runs and four
order statistics: the two either side of the 5th percentile's virtual index and the two either side of the 95th's.
numpy gets them by sorting the row of every run's value (or partitioning it), after a transpose of the engine's
buffer: about 15 ns a value at 1,000 runs (a 1,000-value sort there is 12.6 ns a value; the transpose 6).

Neighbouring grid points hold nearly the same distribution, shifted: every run moves on by a step or a few, and the
whole population drifts together much more than it spreads. So the order statistics, taken relative to the mean,
move little from one grid point to the next. :func:`reduce_points` keeps, per channel and percentile, a window of
values ``[lo, hi]`` relative to the mean, and at the next point, in one branch-free pass, counts the values below
each window and collects those inside. When the wanted ranks fall inside (``below <= k`` and ``below + inside >
k + 1``), sorting those few (by insertion: a dozen or two) gives exactly the order statistics, as a sort of the
whole row would: every value below the window ranks below every value in it. Otherwise the window is
widened and counted again; where no window was carried or it still misses (the first grid point of a call, which
a second thread may start in the middle of a chunk, or a jump), windows are taken from a sample of 64 runs; and if
those miss too the row is sorted whole. The window for the next point is taken :data:`MARGIN` ranks out from the
wanted ones (more at more runs), widened by half its span.

The windows only decide how fast the answer comes, never what it is: the order statistics are exact, so the bands
are the same to the bit as numpy's reduction (tests/test_band_windows.py), in any chunking and with any thread
count. Measured on buffers of the engine's own runs (1,000 runs, smc_ndo and smc_ndo_nno): see
:data:`~ddmr_cli.engine.bands.WINDOW_MIN_RUNS`. The mean is the sum over the runs in their order divided by the
count, as numpy's ``mean(axis=0)`` of the buffer computes it; the sums are taken as the point's values are gathered,
the eight channels' in step (eight independent chains of additions, not one after the other).
"""

from __future__ import annotations

import math

import numpy as np

from ddmr_cli.compiled import law, loop_law

#: ranks kept either side of the wanted order statistics by the window carried to the next grid point (at least;
#: ``n // MARGIN_FRACTION`` at n runs when that is more: ranks are denser at more runs)
MARGIN = 4
MARGIN_FRACTION = 256
#: a window that missed is widened this many times its span either side, and counted again, up to ATTEMPTS
#: windows a grid point; then the row is sorted whole
WIDEN = 2.0
ATTEMPTS = 4
#: without carried windows, or when they miss ATTEMPTS times (the first grid point of a call, a jump), windows come
#: from a sample of this many runs, evenly spaced, SAMPLE_SLACK sample values out either side of each wanted rank,
#: tried SAMPLE_ATTEMPTS times (widened as above), from SAMPLE_MIN_RUNS runs on; then the row is sorted whole
SAMPLE = 64
SAMPLE_SLACK = 3
SAMPLE_ATTEMPTS = 2
SAMPLE_MIN_RUNS = 4 * SAMPLE
#: candidates sorted by insertion at most; more (ties, a wide window, a whole row) by heapsort
INSERTION_MAX = 48


@law
def _sort(values, m):
    """``values[:m]`` in ascending order, in place (finite values): by insertion up to :data:`INSERTION_MAX` values
    (a window's dozen or two), else by heapsort (a wide window, ties, or a row sorted whole). Neither allocates, so
    the pass runs without numba's allocator (loading a compiled function that allocates costs a process megabytes)."""
    if m <= INSERTION_MAX:
        for i in range(1, m):
            v = values[i]
            j = i - 1
            while j >= 0 and values[j] > v:
                values[j + 1] = values[j]
                j -= 1
            values[j + 1] = v
        return
    for start in range(m // 2 - 1, -1, -1):
        _sift_down(values, start, m)
    for end in range(m - 1, 0, -1):
        values[0], values[end] = values[end], values[0]
        _sift_down(values, 0, end)


@law
def _sift_down(values, root, end):
    """Heapsort's sift: move ``values[root]`` down the max-heap ``values[:end]`` to its place."""
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and values[child] < values[child + 1]:
            child += 1
        if values[root] >= values[child]:
            return
        values[root], values[child] = values[child], values[root]
        root = child


@law
def _window(ordered, base, m, k, k_next, margin, mean):
    """The window for the next grid point around ranks ``k``, ``k_next``, relative to ``mean``: from the value
    ``margin`` ranks below ``k`` to the one ``margin`` ranks above ``k_next`` (as far as ``ordered[:m]``, whose first
    value has rank ``base``, reaches), widened by half their span either side."""
    lo = ordered[max(k - margin - base, 0)]
    hi = ordered[min(k_next + margin - base, m - 1)]
    half = 0.5 * (hi - lo)
    return lo - half - mean, hi + half - mean


@law
def _count_collect(column, n, lo1, hi1, lo2, hi2, inside1, inside2):
    """How many values of ``column[:n]`` lie below ``lo1`` and below ``lo2``, and the values inside ``[lo1, hi1]``
    into ``inside1`` and those inside ``[lo2, hi2]`` into ``inside2``, in run order, with their counts. One
    branch-free pass: every value is stored at the next free place, which moves on only when the value is inside."""
    below1 = below2 = m1 = m2 = 0
    for r in range(n):
        v = column[r]
        below1 += v < lo1
        below2 += v < lo2
        inside1[m1] = v
        m1 += (lo1 <= v) & (v <= hi1)
        inside2[m2] = v
        m2 += (lo2 <= v) & (v <= hi2)
    return below1, m1, below2, m2


@law
def _search(column, n, ks, lo1, hi1, lo2, hi2, tries, inside1, inside2):
    """Count and collect ``column[:n]`` against the windows, widening them after a miss, up to ``tries`` times.
    Returns (hit, values below the first window, inside it, below the second, inside it, windows that missed).
    Windows that are NaN or meet (``hi1 >= lo2``) are not tried."""
    k1, k1b, k2, k2b = ks[0], ks[1], ks[2], ks[3]
    for attempt in range(tries):
        if not lo1 <= hi1 < lo2 <= hi2:
            return False, 0, 0, 0, 0, attempt
        below1, m1, below2, m2 = _count_collect(column, n, lo1, hi1, lo2, hi2, inside1, inside2)
        if below1 <= k1 and below1 + m1 > k1b and below2 <= k2 and below2 + m2 > k2b:
            return True, below1, m1, below2, m2, attempt
        # widen both windows, keeping them apart
        span1, span2, gap = hi1 - lo1, hi2 - lo2, lo2 - hi1
        lo1, hi1 = lo1 - WIDEN * span1, hi1 + min(WIDEN * span1, 0.5 * gap)
        lo2, hi2 = lo2 - min(WIDEN * span2, 0.5 * gap), hi2 + WIDEN * span2
    return False, 0, 0, 0, 0, tries


@law
def _sampled(sample, i):
    """The sample's value of rank ``i``: -inf below the first, inf past the last."""
    if i < 0:
        return -math.inf
    if i >= SAMPLE:
        return math.inf
    return sample[i]


@law
def _sample_windows(column, n, ks, sample):
    """Windows from a sample: :data:`SAMPLE` values evenly spaced over the runs, sorted, and from each wanted rank's
    place among them :data:`SAMPLE_SLACK` sample values out either side (absolute values, not relative)."""
    for i in range(SAMPLE):
        sample[i] = column[(i * n) // SAMPLE]
    _sort(sample, SAMPLE)
    lo1 = _sampled(sample, (ks[0] * SAMPLE) // n - SAMPLE_SLACK)
    hi1 = _sampled(sample, (ks[1] * SAMPLE) // n + 1 + SAMPLE_SLACK)
    lo2 = _sampled(sample, (ks[2] * SAMPLE) // n - SAMPLE_SLACK)
    hi2 = _sampled(sample, (ks[3] * SAMPLE) // n + 1 + SAMPLE_SLACK)
    return lo1, hi1, lo2, hi2


@law
def _column(column, n, ks, mean, window, inside1, inside2, whole):
    """The order statistics ``ks`` (k1, k1 + 1, k2, k2 + 1, clipped to n - 1; k1 <= k2) of ``column[:n]``, by the
    windows ``window`` (lo1, hi1, lo2, hi2 relative to ``mean``; NaN: none), which it updates for the next grid
    point: the carried windows (widened after a miss), then, from :data:`SAMPLE_MIN_RUNS` runs, windows from a
    sample, then a sort of the whole row. Returns the four statistics and how many windows missed (a whole sort
    counts one more)."""
    k1, k1b, k2, k2b = ks[0], ks[1], ks[2], ks[3]
    margin = max(MARGIN, n // MARGIN_FRACTION)
    hit, below1, m1, below2, m2, missed = _search(column, n, ks, mean + window[0], mean + window[1],
                                                  mean + window[2], mean + window[3], ATTEMPTS, inside1, inside2)
    if not hit and n >= SAMPLE_MIN_RUNS:
        lo1, hi1, lo2, hi2 = _sample_windows(column, n, ks, whole)
        hit, below1, m1, below2, m2, more = _search(column, n, ks, lo1, hi1, lo2, hi2, SAMPLE_ATTEMPTS, inside1,
                                                    inside2)
        missed += more
    if hit:
        _sort(inside1, m1)
        _sort(inside2, m2)
    else:  # the whole row, sorted, serves both percentiles
        for r in range(n):
            whole[r] = column[r]
        _sort(whole, n)
        inside1 = inside2 = whole
        below1 = below2 = 0
        m1 = m2 = n
        missed += 1
    window[0], window[1] = _window(inside1, below1, m1, k1, k1b, margin, mean)
    window[2], window[3] = _window(inside2, below2, m2, k2, k2b, margin, mean)
    return inside1[k1 - below1], inside1[k1b - below1], inside2[k2 - below2], inside2[k2b - below2], missed


@loop_law
def reduce_points(buffer, a, b, ks, sums, stats, windows, columns, scratch):
    """Reduce grid points ``a .. b - 1`` of ``buffer[run, point, channel]`` over the runs: ``sums[j, c]`` the sum of
    point ``a + j``'s values in run order, ``stats[q, j, c]`` its order statistic ``ks[q]`` (module docstring);
    ``windows[c]`` the carried windows (updated); ``columns`` ``(channels, runs)`` and ``scratch`` ``(3, runs)``
    the pass's working memory. Returns the number of windows that missed, or -1 as soon as a point holds a value that
    is not finite (the caller then drops what the pass wrote, ``windows`` too, and reduces the block by numpy's rules
    for diverged runs)."""
    n, _, n_channels = buffer.shape
    inside1, inside2, whole = scratch[0], scratch[1], scratch[2]
    missed = 0
    for j in range(b - a):
        finite = True
        for c in range(n_channels):
            sums[j, c] = 0.0
        for r in range(n):  # the point's values, one row per channel (each buffer row holds all its channels),
            for c in range(n_channels):  # their sums (the channels' in step, each in run order), and whether finite
                v = buffer[r, a + j, c]
                columns[c, r] = v
                sums[j, c] += v
                finite &= math.isfinite(v)
        if not finite:
            return -1
        for c in range(n_channels):
            s0, s1, s2, s3, attempts = _column(columns[c], n, ks, sums[j, c] / n, windows[c], inside1, inside2, whole)
            stats[0, j, c], stats[1, j, c], stats[2, j, c], stats[3, j, c] = s0, s1, s2, s3
            missed += attempts
    return missed


__all__ = ["ATTEMPTS", "MARGIN", "MARGIN_FRACTION", "SAMPLE", "SAMPLE_ATTEMPTS", "SAMPLE_MIN_RUNS", "SAMPLE_SLACK",
           "WIDEN", "reduce_points"]
