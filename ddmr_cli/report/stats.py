"""Paired comparisons between two controllers over the same seeds (same seed and scenario -> same terrain),
and the verdict rules that turn one into holds / tie / does not hold / inconclusive.

For a reference controller ``a`` and a candidate ``b``, over the seeds both completed without diverging:
the mean of each, the mean paired difference ``b - a`` (in the metric's unit and in percent of ``mean(a)``) and
the relative reduction ``1 - mean(b) / mean(a)``, each with a 95 % percentile bootstrap confidence interval
(seeds resampled in pairs, a fixed-seed numpy Generator, so a report is reproducible), and the two-sided
Wilcoxon signed-rank test of the differences.

A practical margin (:class:`Margin`) says which difference is negligible: when the whole 95 % CI of the
difference lies inside ``±margin`` the two controllers are equivalent in practice (a TOST-style equivalence
test, here at the 2.5 % level per side since the CI is the 95 % one). For a claim of an improvement that
refutes the claim (*does not hold*); only a comparison that may end in equality (a baseline, not a claim of the
paper) is then a *tie*.
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
#: The confidence level of the bootstrap intervals (the verdicts read the 95 % ones).
CI_LEVEL = 0.95
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

    @property
    def rel_diff(self) -> float:
        """``(mean(b) - mean(a)) / mean(a)``, i.e. ``-reduction`` (a fraction; x100 for percent)."""
        return -self.reduction

    @property
    def rel_diff_ci(self) -> tuple[float, float]:
        return -self.reduction_ci[1], -self.reduction_ci[0]

    def as_dict(self) -> dict:
        return {"n_pairs": self.n, "mean_a": self.mean_a, "mean_b": self.mean_b, "diff": self.diff,
                "diff_ci_low": self.diff_ci[0], "diff_ci_high": self.diff_ci[1], "diff_pct": 100 * self.rel_diff,
                "diff_pct_ci_low": 100 * self.rel_diff_ci[0], "diff_pct_ci_high": 100 * self.rel_diff_ci[1],
                "reduction": self.reduction,
                "reduction_ci_low": self.reduction_ci[0], "reduction_ci_high": self.reduction_ci[1],
                "wilcoxon_statistic": self.statistic, "p_value": self.p}


def paired(a, b, level: float = CI_LEVEL) -> Paired | None:
    """Compare two per-seed pandas Series (index: seed); None when no seed is common to both.

    ``level``: the confidence level of the percentile bootstrap intervals (default :data:`CI_LEVEL`):
    ``scipy.stats.bootstrap`` with ``paired=True`` (the seeds resampled in pairs), ``method="percentile"``,
    :data:`N_BOOT` resamples from a Generator seeded :data:`BOOT_SEED`, one call for both the difference of the means
    and the reduction (a statistic of two values: both read the same resamples). A resample whose
    reference mean is 0 has an infinite reduction, which the percentiles keep: the interval is then unbounded on that
    side (the hand-written bootstrap this replaced dropped such resamples)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    joined = a.rename("a").to_frame().join(b.rename("b"), how="inner").dropna()
    n = len(joined)
    if n == 0:
        return None
    x, y = joined["a"].to_numpy(float), joined["b"].to_numpy(float)

    def difference(x, y, axis=-1):
        return np.mean(y, axis=axis) - np.mean(x, axis=axis)

    def reduction_of(x, y, axis=-1):
        with np.errstate(divide="ignore", invalid="ignore"):
            return 1.0 - np.mean(y, axis=axis) / np.mean(x, axis=axis)

    def both(x, y, axis=-1):
        return np.stack([difference(x, y, axis), reduction_of(x, y, axis)])

    diff_ci, red_ci = _percentile_cis(x, y, both, level)
    mean_a, mean_b = float(x.mean()), float(y.mean())
    reduction = 1.0 - mean_b / mean_a if mean_a != 0 else math.nan
    p, stat = _wilcoxon(y - x)
    return Paired(n, mean_a, mean_b, mean_b - mean_a, diff_ci, reduction, red_ci, p, stat)


def _percentile_cis(x: np.ndarray, y: np.ndarray, statistic, level: float) -> list[tuple[float, float]]:
    """The paired percentile bootstrap interval of each value of ``statistic(x, y)`` (``scipy.stats.bootstrap``,
    one set of resamples for all); for a single pair (scipy needs two) the interval of width 0 at its value, which
    is what every resample of one pair gives."""
    from scipy import stats

    if len(x) < 2:
        values = np.atleast_1d(np.asarray(statistic(x, y), dtype=float))
        return [(float(v), float(v)) if math.isfinite(v) else (math.nan, math.nan) for v in values]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a degenerate sample (every pair equal) is an interval of width 0 here
        ci = stats.bootstrap((x, y), statistic, paired=True, vectorized=True, n_resamples=N_BOOT,
                             confidence_level=level, method="percentile",
                             random_state=np.random.default_rng(BOOT_SEED)).confidence_interval
    return [(float(low), float(high)) for low, high in zip(np.atleast_1d(ci.low), np.atleast_1d(ci.high))]


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



# --- the practical margin ------------------------------------------------------------------------------------
#: Default margin for metrics in metres (the deviation and e_x, e_y): 0.1 mm, or 5 % of the reference's mean where
#: that is smaller. See :data:`MARGIN_WHY`.
DEFAULT_MARGIN_M = 1e-4
#: Default margin for metrics in other units (V/s, rad/s^2, fractions): 5 % of the reference controller's mean.
DEFAULT_MARGIN_REL = 0.05
MARGIN_WHY = (
    "0.1 mm is the resolution of the paper's own Table 4 (deviations printed in m to four decimals), about 4 % of "
    "its smallest mean deviation (2.6 mm), 300 times smaller than the wheel radius (30 mm), and far below what "
    "wheel odometry or an external positioning system resolves on a robot crossing 15 m of rough terrain; no "
    "engineer would choose one controller over another for a 0.1 mm smaller mean deviation. Where 5 % of the "
    "reference's mean is smaller than 0.1 mm (the steady-state deviations of the observer-based controllers are "
    "0.2-0.3 mm), the margin is that 5 %, so a 20 % difference at steady state is never called a tie")
_UNITS = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "cm": 1e-2}


@dataclass(frozen=True)
class Margin:
    """What counts as a negligible difference: ``metres`` for metrics in metres (None: use ``relative`` for them
    too; with ``capped``, the smaller of ``metres`` and ``relative`` x the reference's mean), ``relative`` x the
    reference's mean for every other metric."""

    metres: float | None = DEFAULT_MARGIN_M
    relative: float = DEFAULT_MARGIN_REL
    capped: bool = True

    @classmethod
    def parse(cls, value) -> "Margin":
        """``Margin``, or text with a unit: ``0.1mm``, ``100um``, ``1e-4m`` (absolute, for metrics in metres; 5 %
        for the others) or ``5%`` (relative, for every metric). A bare number is refused: ``5`` would be 5 m."""
        if isinstance(value, Margin):
            return value
        if value is None:
            return cls()
        text = str(value).strip().replace(" ", "")
        if text.endswith("%"):
            try:
                rel = float(text[:-1]) / 100.0
            except ValueError:
                raise ValueError(f"margin {value!r}: expected a percentage such as 5%") from None
            return cls._checked(None, rel)
        for unit in sorted(_UNITS, key=len, reverse=True):
            if text.endswith(unit) and text[:-len(unit)]:
                try:
                    return cls._checked(float(text[:-len(unit)]) * _UNITS[unit], DEFAULT_MARGIN_REL, capped=False)
                except ValueError:
                    break
        raise ValueError(f"margin {value!r}: needs a unit: a length (0.05mm, 50um, 5e-5m) or a percentage (2%)")

    @classmethod
    def _checked(cls, metres: float | None, relative: float, capped: bool = True) -> "Margin":
        for v in (metres, relative):
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise ValueError(f"margin must be a finite number >= 0, got {v!r}")
        return cls(metres, relative, capped)

    def absolute(self, unit: str, reference_mean: float) -> float:
        """The margin in the metric's unit, for a metric in ``unit`` whose reference mean is ``reference_mean``."""
        relative = self.relative * abs(reference_mean)
        if unit == "m" and self.metres is not None:
            return min(self.metres, relative) if self.capped else self.metres
        return relative

    def describe(self) -> str:
        rel = f"{100 * self.relative:g} % of the reference controller's mean"
        if self.metres is None:
            return f"±{rel} for every metric"
        metres = (f"±{1000 * self.metres:g} mm or ±{rel}, whichever is smaller," if self.capped
                  else f"±{1000 * self.metres:g} mm")
        return f"{metres} for metrics in metres (deviation, e_x, e_y), ±{rel} for the others"


# --- verdicts ------------------------------------------------------------------------------------------------
HOLDS, TIE, FAILS, INCONCLUSIVE = "holds", "tie", "does not hold", "inconclusive"
CATEGORIES = (HOLDS, TIE, FAILS, INCONCLUSIVE)


def category(verdict: str) -> str:
    """The verdict without its reason: ``"does not hold (…)"`` -> ``"does not hold"``."""
    return verdict.split(" (", 1)[0]


def _too_few(pr: Paired) -> str | None:
    return f"{INCONCLUSIVE} (only {pr.n} paired seeds; at least {MIN_PAIRS} needed)" if pr.n < MIN_PAIRS else None


def _inside_margin(pr: Paired, margin: float) -> bool:
    """Equivalent in practice: the whole 95 % CI of the difference inside (-margin, +margin)."""
    lo, hi = pr.diff_ci
    return margin > 0 and -margin < lo and hi < margin


def _tie(pr: Paired, margin: float) -> str | None:
    """For a comparison that may end in equality (not a claim of an improvement): a tie inside the margin."""
    return f"{TIE} (95 % CI of the difference inside ±margin)" if _inside_margin(pr, margin) else None


def _no_improvement(pr: Paired, margin: float) -> str | None:
    """For a claim of an improvement: no practical difference refutes it."""
    if _inside_margin(pr, margin):
        return f"{FAILS} (no practical difference: the 95 % CI of the difference lies inside ±margin)"
    return None


def _not_significant(pr: Paired) -> str:
    if math.isnan(pr.p):
        return f"{INCONCLUSIVE} (no paired difference to test)"
    if pr.p >= ALPHA:
        return f"{INCONCLUSIVE} (p >= {ALPHA:g})"
    return f"{INCONCLUSIVE} (Wilcoxon and bootstrap CI disagree)"


def verdict_lower(pr: Paired, margin: float, equality_possible: bool = False) -> str:
    """Claim: ``b`` is below ``a`` by more than a negligible amount.

    holds: p < 0.05 and the CI of ``b - a`` below -margin; does not hold: p < 0.05 and the CI above 0 (``b`` is
    higher), or the whole CI inside ±margin (no practical difference refutes a claimed improvement); with
    ``equality_possible`` (a comparison that claims nothing, e.g. against a baseline) the latter is a tie;
    inconclusive otherwise."""
    if (v := _too_few(pr) or (_tie(pr, margin) if equality_possible else _no_improvement(pr, margin))):
        return v
    lo, hi = pr.diff_ci
    if pr.p < ALPHA and hi < -margin:
        return HOLDS
    if pr.b_higher:
        return f"{FAILS} (significantly the other way)"
    if pr.b_lower:
        return f"{INCONCLUSIVE} (lower, but the 95 % CI reaches into ±margin)"
    return _not_significant(pr)


def verdict_over(pr: Paired, threshold: float, margin: float) -> str:
    """Claim: ``b`` is more than ``threshold`` (a fraction) lower than ``a``.

    does not hold: the CI of the reduction below ``threshold`` (checked first: whatever else is true), or the CI
    of the difference inside ±margin; holds: p < 0.05, the CI of the difference below -margin and the CI of the
    reduction above ``threshold``; inconclusive otherwise."""
    if (v := _too_few(pr)):
        return v
    r_lo, r_hi = pr.reduction_ci
    if r_hi < threshold:
        return f"{FAILS} (95 % CI of the reduction below {100 * threshold:.0f} %)"
    if (v := _no_improvement(pr, margin)):
        return v
    if pr.b_lower and pr.diff_ci[1] < -margin and r_lo > threshold:
        return HOLDS
    if not pr.b_lower:
        return _not_significant(pr)
    return f"{INCONCLUSIVE} (the 95 % CI of the reduction includes {100 * threshold:.0f} %)"


def verdict_about(pr: Paired, target: float, band: float, margin: float) -> str:
    """Claim: ``b`` is about ``target`` (a fraction) lower than ``a``: the reduction is in target ± band.

    does not hold: the CI of the reduction entirely outside the band (checked first: whatever else is true), or
    the CI of the difference inside ±margin; holds: p < 0.05, the CI of the difference below -margin and the
    reduction's estimate in the band; inconclusive otherwise."""
    if (v := _too_few(pr)):
        return v
    lo, hi = target - band, target + band
    r_lo, r_hi = pr.reduction_ci
    if r_hi < lo or r_lo > hi:
        return f"{FAILS} (95 % CI of the reduction outside {100 * lo:.0f}–{100 * hi:.0f} %)"
    if (v := _no_improvement(pr, margin)):
        return v
    if not pr.b_lower:
        return _not_significant(pr)
    if not lo <= pr.reduction <= hi:
        return f"{INCONCLUSIVE} (the 95 % CI overlaps {100 * lo:.0f}–{100 * hi:.0f} %, the estimate is outside it)"
    if pr.diff_ci[1] >= -margin:
        return f"{INCONCLUSIVE} (the 95 % CI of the difference reaches into ±margin)"
    return HOLDS


def combine(verdicts: list[str]) -> str:
    """Any part does not hold -> does not hold; all hold -> holds; all hold or tie, one at least ties -> tie
    (only comparisons that may end in equality tie); else inconclusive."""
    cats = [category(v) for v in verdicts]
    if not cats:
        return INCONCLUSIVE
    if FAILS in cats:
        return FAILS
    if all(c == HOLDS for c in cats):
        return HOLDS
    if all(c in (HOLDS, TIE) for c in cats):
        return TIE
    return INCONCLUSIVE
