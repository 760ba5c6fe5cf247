"""Known values of the report's statistics (issue 27, "tests that cannot fail": statistics internals).

- The Wilson score interval (the sensitivity study's shares, :func:`ddmr_cli.study.analysis.wilson`, scipy's
  ``binomtest(k, n).proportion_ci(method="wilson")`` since issue 29): the roots of its defining quadratic at the
  exact z = 1.95996..., and within 1e-4 of the hand-written formula at z = 1.96 it replaced.
- The paired bootstrap (:func:`ddmr_cli.report.stats.paired`): its 95 % interval of the mean difference has the
  width ``2 z sd / sqrt(n)`` of the normal theory on a large sample, that of the relative reduction the delta
  method's, a 90 % interval is strictly inside the 95 % one and a 99 % one strictly outside, and over many
  samples from a known distribution the 95 % interval covers the true difference about 95 % of the time.

Before, the fast tier checked only ``0 < low < 0.5 < high < 1`` for one Wilson interval and the bootstrap's
reproducibility, so a 90 % interval in place of the 95 % one (or z = 1.645) passed.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from ddmr_cli.report import stats as S
from ddmr_cli.study.analysis import wilson

Z95 = float(norm.ppf(0.975))
CASES = [(0, 1), (1, 1), (0, 10), (1, 10), (5, 10), (9, 10), (10, 10), (3, 37), (17, 50), (120, 256), (1, 1000),
         (999, 1000), (4711, 10000)]


def _wilson_roots(k: int, n: int, z: float) -> tuple[float, float]:
    """The Wilson interval from its definition: the p with ``(p_hat - p)^2 = z^2 p (1 - p) / n``, the roots of
    ``(1 + z^2/n) p^2 - (2 p_hat + z^2/n) p + p_hat^2 = 0``."""
    p_hat, c = k / n, z * z / n
    a, b, cc = 1.0 + c, -(2.0 * p_hat + c), p_hat * p_hat
    root = math.sqrt(b * b - 4.0 * a * cc)
    return (-b - root) / (2.0 * a), (-b + root) / (2.0 * a)


@pytest.mark.parametrize("k, n", CASES)
def test_wilson_interval_is_the_roots_of_its_quadratic_at_the_exact_z(k, n):
    low, high = wilson(k, n)
    r_low, r_high = _wilson_roots(k, n, Z95)
    assert low == pytest.approx(max(0.0, r_low), abs=1e-12) and high == pytest.approx(min(1.0, r_high), abs=1e-12)
    assert 0.0 <= low <= k / n <= high <= 1.0
    assert (low == 0.0) == (k == 0) and (high == 1.0) == (k == n)


def _hand_written(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The formula ddmr used before scipy's (issue 29), at its z = 1.96."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


@pytest.mark.parametrize("k, n", CASES)
def test_wilson_interval_moves_less_than_1e_4_from_the_hand_written_one(k, n):
    """scipy takes the exact normal quantile (1.959964 for 95 %), the formula it replaced 1.96; the same formula
    at the exact z agrees to 1e-12."""
    low, high = wilson(k, n)
    old = _hand_written(k, n)
    assert low == pytest.approx(old[0], abs=1e-4) and high == pytest.approx(old[1], abs=1e-4)
    exact = _hand_written(k, n, Z95)
    assert exact[0] == pytest.approx(low, abs=1e-12) and exact[1] == pytest.approx(high, abs=1e-12)


def test_wilson_interval_of_nothing_is_nan():
    assert all(math.isnan(v) for v in wilson(0, 0))


# --- the paired bootstrap -------------------------------------------------------------------------------------


def _sample(n: int, seed: int, true_diff: float = -0.3, sd_diff: float = 0.5):
    """Per-seed metrics of a reference ``a`` ~ N(10, 1) and a candidate ``b = a + N(true_diff, sd_diff)``."""
    rng = np.random.default_rng(seed)
    a = 10.0 + rng.standard_normal(n)
    b = a + true_diff + sd_diff * rng.standard_normal(n)
    index = pd.Index(range(n), name="seed")
    return pd.Series(a, index=index), pd.Series(b, index=index)


def _width(ci) -> float:
    return ci[1] - ci[0]


def test_the_95_percent_interval_of_the_difference_has_the_normal_width_and_covers_the_truth():
    a, b = _sample(2000, seed=1)
    r = S.paired(a, b)
    d = (b - a).to_numpy()
    se = d.std() / math.sqrt(len(d))  # the bootstrap's own: the resampled means' sd is the plug-in sd / sqrt(n)
    assert _width(r.diff_ci) == pytest.approx(2 * Z95 * se, rel=0.04)  # 90 %: 16 % narrower, 99 %: 31 % wider
    assert r.diff_ci[0] < -0.3 < r.diff_ci[1]
    assert r.diff_ci[0] < r.diff < r.diff_ci[1] and r.diff == pytest.approx(d.mean(), rel=1e-12)


def test_the_95_percent_interval_of_the_reduction_has_the_delta_method_width():
    a, b = _sample(2000, seed=2)
    r = S.paired(a, b)
    x, y = a.to_numpy(), b.to_numpy()
    n, mx, my = len(x), x.mean(), y.mean()
    # 1 - mean(b)/mean(a): its gradient in (mean a, mean b) is (my/mx^2, -1/mx), with the sample covariance / n
    cov = np.cov(np.vstack([x, y]), bias=True) / n
    grad = np.array([my / mx**2, -1.0 / mx])
    se = math.sqrt(grad @ cov @ grad)
    assert _width(r.reduction_ci) == pytest.approx(2 * Z95 * se, rel=0.05)
    assert r.reduction_ci[0] < r.reduction < r.reduction_ci[1]
    assert r.rel_diff_ci == (-r.reduction_ci[1], -r.reduction_ci[0])


def test_a_90_percent_interval_is_inside_the_95_one_and_a_99_percent_one_outside():
    a, b = _sample(200, seed=3)
    r90, r95, r99 = (S.paired(a, b, level=q) for q in (0.90, 0.95, 0.99))
    for name in ("diff_ci", "reduction_ci"):
        i90, i95, i99 = (getattr(r, name) for r in (r90, r95, r99))
        assert i99[0] < i95[0] < i90[0] < i90[1] < i95[1] < i99[1], name
    assert _width(r90.diff_ci) / _width(r95.diff_ci) == pytest.approx(norm.ppf(0.95) / norm.ppf(0.975), rel=0.06)
    assert S.paired(a, b).as_dict() == r95.as_dict()  # the default is 95 %
    with pytest.raises(ValueError, match="level"):
        S.paired(a, b, level=95)


def test_the_default_interval_is_the_2_5_and_97_5_percentiles_of_the_seeded_resampling():
    """The report's numbers: the percentile bootstrap of the mean difference with the fixed Generator, as the
    module documents it (N_BOOT resamples of the seeds, in pairs): the hand-written resampling it replaced."""
    a, b = _sample(30, seed=4)
    r = S.paired(a, b)
    x, y = a.to_numpy(), b.to_numpy()
    idx = np.random.default_rng(S.BOOT_SEED).integers(0, len(x), size=(S.N_BOOT, len(x)))
    ma, mb = x[idx].mean(axis=1), y[idx].mean(axis=1)
    # the same resamples (scipy.stats.bootstrap draws the same indices from the same seed); its means may round
    # differently in the last bit
    np.testing.assert_allclose(r.diff_ci, np.percentile(mb - ma, [2.5, 97.5]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(r.reduction_ci, np.percentile(1.0 - mb / ma, [2.5, 97.5]), rtol=1e-12, atol=0)


def test_the_95_percent_interval_covers_the_true_difference_about_95_percent_of_the_time():
    """300 samples of 50 pairs: the coverage of a 95 % interval is 0.95 +- 0.013 (binomial sd); the percentile
    bootstrap runs a little short at n = 50 (about 0.94). A 90 % interval would cover about 0.89."""
    covered = 0
    trials = 300
    for seed in range(trials):
        a, b = _sample(50, seed=1000 + seed)
        low, high = S.paired(a, b).diff_ci
        covered += low < -0.3 < high
    assert 0.915 <= covered / trials <= 0.98


def test_the_bootstrap_edge_cases_one_pair_equal_pairs_and_a_zero_reference():
    """scipy.stats.bootstrap does the resampling (ddmr_cli/report/stats.py); what it does not decide: one pair is an
    interval of width 0 at the difference, pairs that are all equal give a width-0 interval (scipy warns, the report
    does not), and a reference whose mean is 0 on some resamples leaves the reduction's interval unbounded on that
    side (the percentiles keep the infinite reductions: no resample is dropped)."""
    import pandas as pd

    one = S.paired(pd.Series([2.0]), pd.Series([1.5]))
    assert one.diff_ci == pytest.approx((-0.5, -0.5)) and one.reduction_ci == pytest.approx((0.25, 0.25))
    same = S.paired(pd.Series([1.0] * 8), pd.Series([0.5] * 8))
    assert same.diff_ci == pytest.approx((-0.5, -0.5)) and same.reduction_ci == pytest.approx((0.5, 0.5))
    zero = S.paired(pd.Series([0.0] * 7 + [1.0]), pd.Series([0.5] * 8))
    assert zero.reduction_ci[0] == -math.inf and math.isfinite(zero.reduction_ci[1])
    assert all(math.isfinite(v) for v in zero.diff_ci)
