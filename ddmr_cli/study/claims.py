"""Claim statistics of one reading (docs/model.md §11), from the per-seed metrics of the four controllers in both
scenarios, every comparison paired by seed (the same seed gives every controller the same noise).

The claims are the paper's, as :mod:`ddmr_cli.paper.claims` defines them (the report's verdicts judge the same
ones): each claim's statistic is the reduction of its candidate against its reference on the metric its verdict
rests on (:attr:`~ddmr_cli.paper.claims.Claim.metrics`'s first: the steady-state deviation, the share of var(u)
above the high-pass cutoff for chattering, the whole-run estimation MAE); a ranking's is the smallest reduction
between neighbours. A reduction of controller b against a is ``100 (1 - sum_k b_k / sum_k a_k)`` [%] over the
paired seeds k (the paired ratio of means). Divergence is an outcome, not a gap (issue 25): a diverged run's
metric counts as unbounded, so where b diverged on a seed a did not, the reduction is -inf (b unboundedly worse;
the global analyses bound it at -100 %), where only a diverged it is 100 %, and seeds on which both diverged are
left out (the same outcome); NaN only when both diverged on every seed. Each claim has a statistic per scenario
and a scalar over both (their mean; the ranking: the smaller), which the global analyses take, and it *holds* at a
reading when its statistic lies in the claim's range (:func:`bounds`, in %) in every scenario: the claimed range
of :mod:`ddmr_cli.paper.claims` (about 40 %: 30-50 %; over 60 %: >= 60 %; chattering: >= 90 %; estimation:
67 +- 10 %), and for the ranking each neighbour better than the previous by :data:`RANKING_MARGIN` (the study's
stand-in for the report's practical margin: it has no confidence intervals).

Table 4 (calibration): scenario 1 (as the report), whole run, per controller: mean and SD (ddof 1) over seeds of
``deviation_mae``, means of ``e_x_mae``, ``e_y_mae``, ``e_theta_mae``; the distance to the paper is the RMS of
``log(ours / paper)`` over its 20 numbers.
"""

from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from ddmr_cli.paper import PAPER_SCENARIO, TABLE4_COLUMNS
from ddmr_cli.paper import numbers as paper_numbers
from ddmr_cli.paper.claims import RANKING, Claim
from ddmr_cli.paper.claims import claims as paper_claims

#: the controllers a study job runs: the ranking's, largest deviation first
CONTROLLERS = next(c.controllers for c in paper_claims() if c.kind == RANKING)
#: the metric divergence is read on (NaN where the run diverged): the deviation claims' own
DEVIATION = next(c.metrics[0] for c in paper_claims() if c.kind == RANKING)
#: the smallest reduction [%] between neighbours for the ranking to hold
RANKING_MARGIN = 5.0


def metric(claim: Claim) -> str:
    """The metric a claim's statistic is computed on: the one its report verdict rests on."""
    return claim.metrics[0]


#: the metrics a study job keeps per controller, scenario and seed: the claims' and Table 4's
METRICS = tuple(dict.fromkeys([metric(c) for c in paper_claims()] + [m for m, *_ in TABLE4_COLUMNS]))


def claims() -> tuple[Claim, ...]:
    """The paper's claims (:func:`ddmr_cli.paper.claims.claims`)."""
    return paper_claims()


def bounds(claim: Claim) -> tuple[float, float]:
    """The range [%] a claim's statistic lies in where the claim holds."""
    if claim.kind == RANKING:
        return RANKING_MARGIN, math.inf
    return claim.bounds(100.0)


def holds(claim: Claim, value: float) -> bool:
    low, high = bounds(claim)
    return bool(np.isfinite(value) and low <= value <= high)


def rule(claim: Claim) -> str:
    """The range of :func:`bounds` as text (">= 60 %", "30 to 50 %")."""
    low, high = bounds(claim)
    return f">= {low:.3g} %" if math.isinf(high) else f"{low:.3g} to {high:.3g} %"


CLAIM_IDS = tuple(c.id for c in claims())

#: per controller and scenario: metric -> per-seed values (NaN where the run diverged)
Runs = Mapping[tuple[str, str], Mapping[str, np.ndarray]]


def reduction(reference: np.ndarray, candidate: np.ndarray) -> float:
    """``100 (1 - sum candidate / sum reference)`` [%] over the paired seeds, a diverged run's metric (NaN)
    counting as unbounded: -inf when the candidate diverged on a seed the reference did not, 100 when only the
    reference diverged; seeds both diverged on are left out; NaN when that leaves none."""
    a, b = np.asarray(reference, float), np.asarray(candidate, float)
    lost_a, lost_b = ~np.isfinite(a), ~np.isfinite(b)
    keep = ~(lost_a & lost_b)
    if not keep.any():
        return math.nan
    if lost_b[keep].any():
        return -math.inf
    if lost_a[keep].any():
        return 100.0
    total = float(np.sum(a[keep]))
    if not total > 0:
        return math.nan
    return 100.0 * (1.0 - float(np.sum(b[keep])) / total)


def divergence(runs: "Runs", scenarios: Sequence[str]) -> dict[str, float]:
    """``diverged:<controller>``: the share of this reading's seeds and scenarios on which the controller diverged
    (its steady-state deviation is NaN)."""
    out = {}
    for controller in CONTROLLERS:
        lost = [~np.isfinite(np.asarray(runs[(controller, s)][DEVIATION], float)) for s in scenarios]
        out[f"diverged:{controller}"] = float(np.mean(np.concatenate(lost))) if lost else math.nan
    return out


def scenario_statistics(runs: Runs, scenario: str) -> dict[str, float]:
    """Each claim's statistic in one scenario: the reduction of its candidate against its reference, on its
    metric; a ranking's, the smallest over its neighbours."""
    out = {}
    for claim in claims():
        m = metric(claim)
        out[claim.id] = min(reduction(runs[(a, scenario)][m], runs[(b, scenario)][m]) for a, b in claim.pairs)
    return out


def statistics(runs: Runs, scenarios: Sequence[str]) -> dict[str, float]:
    """Per claim: ``<claim>@<scenario>`` statistics, the scalar ``<claim>`` over scenarios (mean; ranking: min)
    and ``<claim>_holds`` (1.0 / 0.0; NaN when a statistic is NaN)."""
    out: dict[str, float] = {}
    per = {s: scenario_statistics(runs, s) for s in scenarios}
    for claim in claims():
        values = [per[s][claim.id] for s in scenarios]
        for s, v in zip(scenarios, values):
            out[f"{claim.id}@{s}"] = v
        defined = not any(math.isnan(v) for v in values)  # -inf (the candidate diverged) is defined: false
        out[claim.id] = (min(values) if claim.kind == RANKING else float(np.mean(values))) if defined else math.nan
        out[f"{claim.id}_holds"] = float(all(holds(claim, v) for v in values)) if defined else math.nan
    out.update(divergence(runs, scenarios))
    return out


def table4(runs: Runs, scenario: str = PAPER_SCENARIO) -> dict[str, float]:
    """Our Table 4 numbers, ``t4:<controller>:<column>`` (columns as the paper's, scenario 1)."""
    out = {}
    for controller in CONTROLLERS:
        metrics = runs[(controller, scenario)]
        for metric, stat, column, _ in TABLE4_COLUMNS:
            values = np.asarray(metrics[metric], float)
            values = values[np.isfinite(values)]
            if stat == "mean":
                value = float(values.mean()) if values.size else math.nan
            else:
                value = float(values.std(ddof=1)) if values.size > 1 else math.nan
            out[f"t4:{controller}:{column}"] = value
    return out


def paper_table4() -> dict[str, float]:
    """The paper's Table 4, keyed as :func:`table4`."""
    numbers = paper_numbers()
    rows, names = numbers["table4"]["rows"], numbers["controller_names"]
    return {f"t4:{c}:{column}": float(rows[names[c]][column]) for c in CONTROLLERS
            for _, _, column, _ in TABLE4_COLUMNS}


def log_residuals(ours: Mapping[str, float]) -> dict[str, float]:
    """``log(ours / paper)`` per Table 4 number (NaN where ours is not positive)."""
    paper = paper_table4()
    return {k: (math.log(ours[k] / p) if ours.get(k, math.nan) > 0 else math.nan) for k, p in paper.items()}


def distance(ours: Mapping[str, float]) -> float:
    """RMS of ``log(ours / paper)`` over the paper's 20 Table 4 numbers (NaN if any is missing)."""
    r = np.array(list(log_residuals(ours).values()))
    return float(np.sqrt(np.mean(r ** 2))) if np.all(np.isfinite(r)) else math.nan


__all__ = ["claims", "bounds", "holds", "rule", "metric", "CLAIM_IDS", "CONTROLLERS", "METRICS", "RANKING_MARGIN",
           "reduction", "divergence", "scenario_statistics",
           "statistics", "table4", "paper_table4", "log_residuals", "distance"]
