"""Claim statistics of one reading (docs/model.md §11), from the per-seed metrics of the four controllers in both
scenarios, every comparison paired by seed (the same seed gives every controller the same noise).

A reduction of controller b against a is ``100 (1 - sum_k b_k / sum_k a_k)`` [%] over the paired seeds k (the
paired ratio of means). Divergence is an outcome, not a gap (issue 25): a diverged run's metric counts as
unbounded, so where b diverged on a seed a did not, the reduction is -inf (b unboundedly worse; the global
analyses bound it at -100 %), where only a diverged it is 100 %, and seeds on which both diverged are left out
(the same outcome); NaN only when both diverged on every seed. Each claim has a statistic per scenario and a scalar over both
(their mean; the ranking: the smaller), which the global analyses take, and it *holds* at a reading when its
statistic lies in the claim's range in every scenario:

=================  ====================================================  =====================================
claim              statistic                                             holds when
=================  ====================================================  =====================================
``nno_vs_ndo``     reduction of SMC-NDO-NNO vs SMC-NDO, ``deviation_mae_ss``  in 40 +- 10 % ("about 40 %")
``nno_vs_smc``     reduction of SMC-NDO-NNO vs SMC, ``deviation_mae_ss``      > 60 % ("over 60 %")
``ranking``        smallest reduction between neighbours of PID > SMC >  > 5 % (each neighbour beats the
                   SMC-NDO > SMC-NDO-NNO, ``deviation_mae_ss``               previous by at least 5 %)
``chattering``     reduction of ``chattering_ss`` (V/s), NNO vs NDO     >= 90 % ("near-complete elimination")
``estimation``     reduction of ``d_est_mae_ss``, NNO vs NDO            in 67 +- 10 % (48.3 -> 16.0)
=================  ====================================================  =====================================

Table 4 (calibration): scenario 1 (as the report), whole run, per controller: mean and SD (ddof 1) over seeds of
``deviation_mae``, means of ``e_x_mae``, ``e_y_mae``, ``e_theta_mae``; the distance to the paper is the RMS of
``log(ours / paper)`` over its 20 numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ddmr_cli.report.data import PAPER_SCENARIO, paper_numbers
from ddmr_cli.report.tables import TABLE4_COLUMNS

CONTROLLERS = ("pid", "smc", "smc_ndo", "smc_ndo_nno")
DEVIATION = "deviation_mae_ss"
#: the metrics a study job keeps per controller, scenario and seed
METRICS = (DEVIATION, "chattering_ss", "d_est_mae_ss", "deviation_mae", "e_x_mae", "e_y_mae", "e_theta_mae")


@dataclass(frozen=True)
class Claim:
    """A claim: its statistic (a reduction in %, of ``metric``, of ``better`` against ``reference``) and range."""

    id: str
    text: str
    metric: str
    low: float = -math.inf   # holds when low <= statistic <= high in every scenario
    high: float = math.inf

    def holds(self, value: float) -> bool:
        return bool(np.isfinite(value) and self.low <= value <= self.high)

    @property
    def rule(self) -> str:
        if math.isinf(self.high):
            return f">= {self.low:.3g} %"
        return f"{self.low:.3g} to {self.high:.3g} %"


def _estimation_target() -> float:
    est = paper_numbers()["claims"]["estimation"]
    return 100.0 * (1.0 - est["ndo_nno"] / est["ndo"])


ABOUT = 10.0  # half-width [percentage points] of "about", as the report's verdicts (ABOUT_BAND)
RANKING_MARGIN = 5.0


def claims() -> tuple[Claim, ...]:
    est = _estimation_target()
    return (
        Claim("nno_vs_ndo", "SMC-NDO-NNO about 40 % lower deviation than SMC-NDO", DEVIATION, 40 - ABOUT, 40 + ABOUT),
        Claim("nno_vs_smc", "SMC-NDO-NNO over 60 % lower deviation than SMC", DEVIATION, 60.0),
        Claim("ranking", "ranking PID > SMC > SMC-NDO > SMC-NDO-NNO (deviation)", DEVIATION, RANKING_MARGIN),
        Claim("chattering", "near-complete elimination of chattering (NNO vs NDO)", "chattering_ss", 90.0),
        Claim("estimation", f"disturbance-estimation error about {est:.0f} % lower (NNO vs NDO)", "d_est_mae_ss",
              est - ABOUT, est + ABOUT),
    )


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
    """Each claim's statistic in one scenario."""
    def red(ref: str, cand: str, metric: str) -> float:
        return reduction(runs[(ref, scenario)][metric], runs[(cand, scenario)][metric])

    return {
        "nno_vs_ndo": red("smc_ndo", "smc_ndo_nno", DEVIATION),
        "nno_vs_smc": red("smc", "smc_ndo_nno", DEVIATION),
        "ranking": min(red(a, b, DEVIATION) for a, b in zip(CONTROLLERS, CONTROLLERS[1:])),
        "chattering": red("smc_ndo", "smc_ndo_nno", "chattering_ss"),
        "estimation": red("smc_ndo", "smc_ndo_nno", "d_est_mae_ss"),
    }


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
        out[claim.id] = (min(values) if claim.id == "ranking" else float(np.mean(values))) if defined else math.nan
        out[f"{claim.id}_holds"] = float(all(claim.holds(v) for v in values)) if defined else math.nan
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


__all__ = ["Claim", "claims", "CLAIM_IDS", "CONTROLLERS", "METRICS", "reduction", "divergence", "scenario_statistics",
           "statistics", "table4", "paper_table4", "log_residuals", "distance"]
