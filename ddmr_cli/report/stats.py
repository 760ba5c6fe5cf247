"""Paired comparisons between two controllers over the same seeds (same seed and scenario -> same terrain).

For a reference controller ``a`` and a candidate ``b``, over the seeds both completed without diverging:
the mean of each, the mean paired difference ``b - a`` and the relative reduction ``1 - mean(b) / mean(a)``,
each with a 95 % percentile bootstrap confidence interval (seeds resampled in pairs, a fixed-seed numpy
Generator, so a report is reproducible), and the two-sided Wilcoxon signed-rank test of the differences.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

#: Bootstrap resamples and the Generator's seed (fixed: the same sweep gives the same report).
N_BOOT = 10_000
BOOT_SEED = 20_240_917
ALPHA = 0.05
#: Fewer paired seeds than this cannot reach p < 0.05 in a two-sided Wilcoxon test: no verdict either way.
MIN_PAIRS = 6


@dataclass
class Paired:
    """Outcome of :func:`paired` (``a`` the reference, ``b`` the candidate)."""

    n: int
    mean_a: float
    mean_b: float
    diff: float
    diff_ci: tuple[float, float]
    reduction: float
    reduction_ci: tuple[float, float]
    p: float
    statistic: float

    @property
    def b_lower(self) -> bool:
        """``b`` significantly below ``a``: Wilcoxon p < 0.05 and the CI of ``b - a`` below 0."""
        return self.p < ALPHA and self.diff_ci[1] < 0

    @property
    def b_higher(self) -> bool:
        return self.p < ALPHA and self.diff_ci[0] > 0

    def as_dict(self) -> dict:
        return {"n_pairs": self.n, "mean_a": self.mean_a, "mean_b": self.mean_b, "diff": self.diff,
                "diff_ci_low": self.diff_ci[0], "diff_ci_high": self.diff_ci[1], "reduction": self.reduction,
                "reduction_ci_low": self.reduction_ci[0], "reduction_ci_high": self.reduction_ci[1],
                "wilcoxon_statistic": self.statistic, "p_value": self.p}


def paired(a, b) -> Paired | None:
    """Compare two per-seed pandas Series (index: seed); None when no seed is common to both."""
    joined = a.rename("a").to_frame().join(b.rename("b"), how="inner").dropna()
    n = len(joined)
    if n == 0:
        return None
    x, y = joined["a"].to_numpy(float), joined["b"].to_numpy(float)
    rng = np.random.default_rng(BOOT_SEED)
    idx = rng.integers(0, n, size=(N_BOOT, n))
    ma, mb = x[idx].mean(axis=1), y[idx].mean(axis=1)
    diff_ci = tuple(float(v) for v in np.percentile(mb - ma, [2.5, 97.5]))
    with np.errstate(divide="ignore", invalid="ignore"):
        red = 1.0 - mb / ma
    red = red[np.isfinite(red)]
    red_ci = tuple(float(v) for v in np.percentile(red, [2.5, 97.5])) if red.size else (math.nan, math.nan)
    mean_a, mean_b = float(x.mean()), float(y.mean())
    reduction = 1.0 - mean_b / mean_a if mean_a != 0 else math.nan
    p, stat = _wilcoxon(y - x)
    return Paired(n, mean_a, mean_b, mean_b - mean_a, diff_ci, reduction, red_ci, p, stat)


def _wilcoxon(d: np.ndarray) -> tuple[float, float]:
    """Two-sided Wilcoxon signed-rank test of paired differences; NaN when it cannot be computed."""
    from scipy.stats import wilcoxon

    if not np.any(d != 0):
        return math.nan, math.nan
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = wilcoxon(d)
    except ValueError:
        return math.nan, math.nan
    return float(res.pvalue), float(res.statistic)


# --- verdicts ------------------------------------------------------------------------------------------------
HOLDS, FAILS = "holds", "does not hold"


def _too_few(pr: Paired) -> str | None:
    return f"inconclusive (only {pr.n} paired seeds; at least {MIN_PAIRS} needed)" if pr.n < MIN_PAIRS else None


def _not_significant(pr: Paired) -> str:
    if math.isnan(pr.p):
        return "inconclusive (no paired difference to test)"
    if pr.p >= ALPHA:
        return f"inconclusive (p >= {ALPHA:g})"
    return "inconclusive (Wilcoxon and bootstrap CI disagree)"


def verdict_lower(pr: Paired) -> str:
    """Claim: ``b`` is below ``a``."""
    if _too_few(pr):
        return _too_few(pr)
    if pr.b_lower:
        return HOLDS
    if pr.b_higher:
        return f"{FAILS} (significantly the other way)"
    return _not_significant(pr)


def verdict_about(pr: Paired, target: float, band: float = 0.10) -> str:
    """Claim: ``b`` is about ``target`` (a fraction) lower than ``a``, i.e. the reduction is in target +- band."""
    if _too_few(pr):
        return _too_few(pr)
    lo, hi = target - band, target + band
    r_lo, r_hi = pr.reduction_ci
    if r_hi < lo or r_lo > hi:
        return f"{FAILS} (95 % CI outside {100 * lo:.0f}–{100 * hi:.0f} %)"
    if pr.b_lower and lo <= pr.reduction <= hi:
        return HOLDS
    if not pr.b_lower:
        return _not_significant(pr) if not pr.b_higher else f"{FAILS} (significantly the other way)"
    return "inconclusive (the CI overlaps the band, the estimate is outside it)"


def verdict_over(pr: Paired, threshold: float) -> str:
    """Claim: ``b`` is more than ``threshold`` (a fraction) lower than ``a``."""
    if _too_few(pr):
        return _too_few(pr)
    r_lo, r_hi = pr.reduction_ci
    if pr.b_lower and r_lo > threshold:
        return HOLDS
    if r_hi < threshold:
        return f"{FAILS} (95 % CI below {100 * threshold:.0f} %)"
    if not pr.b_lower:
        return _not_significant(pr)
    return f"inconclusive (the 95 % CI includes {100 * threshold:.0f} %)"


def combine(verdicts: list[str]) -> str:
    """All parts hold -> holds; any part fails -> does not hold; else inconclusive."""
    if verdicts and all(v == HOLDS for v in verdicts):
        return HOLDS
    if any(v.startswith(FAILS) for v in verdicts):
        return FAILS
    return "inconclusive"
