"""Verdicts on the paper's claims, from our numbers, each comparison paired by seed (see :mod:`.stats`).

Each comparison ends in one of four verdicts (the rules are :data:`VERDICT_RULES`, written into the report):
holds, does not hold, inconclusive, and tie (equal within a practical margin), which only a comparison that claims
no improvement can end in (the baselines). Each claim is judged on every metric it can be read on: the deviation
claims on our steady-state deviation and on the paper's own whole-run deviation (its Table 4), the chattering
claim on the switching measure (hf_fraction) and on the total variation of u; its overall verdict rests on the
first (:attr:`ClaimResult.metrics`), and the report prints every one side by side.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

from ddmr_cli.engine.catalog import METRICS, STEADY as SS
from ddmr_cli.paper.claims import (BASELINE, NNO, NNO_READINGS, RANKING as RANKING_KIND, Claim, available, baseline,
                                   paper_controllers)
from ddmr_cli.paper.claims import by_id as claim_definitions
from ddmr_cli.paper.claims import claims as paper_claims
from ddmr_cli.paper import numbers as paper_numbers
from ddmr_cli.report.data import ReportData, controller_rank
from ddmr_cli.report.stats import (ALPHA, BOOT_SEED, FAILS, HOLDS, INCONCLUSIVE, MARGIN_WHY, MIN_PAIRS, N_BOOT, TIE,
                                   Margin, Paired, category, combine, paired, verdict_about, verdict_lower,
                                   verdict_over)
from ddmr_cli.report.tables import fmt, isnan, md_table

#: The ranking's controllers before SMC-NDO-NNO, largest deviation first (the claim's, :mod:`ddmr_cli.paper.claims`).
RANKING = tuple(c for c in claim_definitions()["ranking"].controllers if c != NNO)
#: Controllers the paper's claims name (and ablations of them); every other controller of a report is a baseline
#: that SMC-NDO-NNO is compared against (super-twisting, ADRC, adaptive SMC, ...; not a claim of the paper).
PAPER_CONTROLLERS = tuple(sorted(paper_controllers(), key=controller_rank))
#: How the report names a comparison with a baseline, per aspect of ``paper.claims.BASELINE_METRICS``.
BASELINE_TITLES = {"deviation": "lower {dev} than", "chattering": "less chattering (total variation of u) than"}

VERDICT_RULES = {
    HOLDS: "the claimed difference is there, significant (Wilcoxon p < 0.05, 95 % CI excluding 0) and larger than "
           "the margin (the whole CI beyond it), plus the claim's own threshold where it has one",
    FAILS: "the data contradict the claim: the CI of the reduction lies entirely outside the claimed range "
           "(whatever else is true), the difference is significantly the other way, or the whole 95 % CI of the "
           "paired difference lies inside ±margin (no practical difference refutes a claimed improvement)",
    TIE: "only for comparisons that claim no improvement (SMC-NDO-NNO against a baseline, not a claim of the "
         "paper): the whole 95 % CI of the paired difference lies inside ±margin, the two are equal in practice "
         "(a TOST-style equivalence test)",
    INCONCLUSIVE: f"anything else (too few seeds — fewer than {MIN_PAIRS} pairs —, p ≥ 0.05, or a CI that "
                  f"straddles the margin or the claimed threshold); the reason is given in brackets",
}


@dataclass
class Check:
    """One comparison of a claim: reference ``a`` against candidate ``b`` on one scenario."""

    claim: str
    scenario: str
    reading: str
    a: str
    b: str
    metric: str
    result: Paired | None
    verdict: str
    margin: float = float("nan")   # in the metric's unit
    note: str = ""

    def row(self) -> dict:
        out = {"claim": self.claim, "scenario": self.scenario, "nno_reading": self.reading, "reference": self.a,
               "candidate": self.b, "metric": self.metric, "margin": self.margin, "verdict": self.verdict,
               "verdict_category": category(self.verdict), "note": self.note}
        out.update(self.result.as_dict() if self.result else {})
        return out


@dataclass
class ClaimResult:
    """A claim, its rule, and its checks per scenario and NNO reading, with an overall verdict for each."""

    id: str
    title: str
    rule: str
    checks: list[Check] = field(default_factory=list)
    overall: dict[tuple[str, str], str] = field(default_factory=dict)   # (scenario, reading) -> verdict (metrics[0])
    skipped: list[str] = field(default_factory=list)                      # why a (scenario, reading) was not checked
    #: the metrics the claim is judged on, the one its overall verdict rests on first
    metrics: tuple[str, ...] = ()
    #: (scenario, reading, metric) -> the verdict on that metric alone
    by_metric: dict[tuple[str, str, str], str] = field(default_factory=dict)
    #: the claimed reduction as a sentence ("> 60 %"), for the summary
    claimed: str = ""
    #: the claim's definition (:mod:`ddmr_cli.paper.claims`)
    claim: Claim | None = None

    def skip(self, why: str) -> None:
        if why not in self.skipped:
            self.skipped.append(why)


def unit_of(metric: str) -> str:
    base = metric[:-len(SS)] if metric.endswith(SS) else metric
    return METRICS[base][0] if base in METRICS else ""


def _has(data: ReportData):
    """Whether the jobs' metrics.csv have a metric (some value of a job that did not fail)."""
    m = data.metrics

    def has(metric: str) -> bool:
        return metric in m and m.loc[m["status"] == "ok", metric].notna().any()
    return has


def metrics_of(data: ReportData, claim: Claim) -> tuple[str, ...]:
    """The metrics a claim is judged on in this report: its own, a steady-state one the jobs lack read on its
    whole-run twin (:func:`ddmr_cli.paper.claims.available`)."""
    return available(claim.metrics, _has(data))


def deviation_metric(data: ReportData) -> str:
    """``deviation_mae_ss`` (steady state) when every job's metrics.csv has it, else ``deviation_mae``."""
    return deviation_metrics(data)[0]


def _key_for(data: ReportData, scenario: str, controller: str) -> tuple[str | None, str]:
    """The key of the job that stands for ``controller`` in ``scenario``: its only job, or in a sweep with several
    its job without a swept setting or at the ideal loop (:func:`ddmr_cli.report.realism.representative`); else
    None and why."""
    from ddmr_cli.report.realism import representative

    keys = [k for k in data.keys(scenario) if data.controller_of(k) == controller]
    if not keys:
        return None, f"no complete {controller} job in {scenario}"
    if keys != [controller]:
        stand_in = representative([data.job(scenario, k) for k in keys])
        if stand_in is not None:
            return stand_in.key, ""
        return None, (f"several {controller} jobs in {scenario} ({', '.join(keys)}) and none at the ideal loop; "
                      f"verdicts need one per controller")
    return controller, ""


def per_seed(data: ReportData, scenario: str, key: str, metric: str):
    """The job's ``metric`` per seed that did not diverge (index: seed)."""
    return data.ok_metrics(data.job(scenario, key))[metric].astype(float)


def _compare(data, claim, scenario, reading, a, b, metric, judge, margin: Margin) -> Check:
    result = paired(per_seed(data, scenario, a, metric), per_seed(data, scenario, b, metric))
    if result is None:
        return Check(claim, scenario, reading, a, b, metric, None, f"{INCONCLUSIVE} (no seed completed by both)")
    m = margin.absolute(unit_of(metric), result.mean_a)
    return Check(claim, scenario, reading, a, b, metric, result, judge(result, m), m)


def deviation_metrics(data: ReportData) -> tuple[str, ...]:
    """The deviation metrics the claims are judged on: ours (steady state) first when the jobs have it, then the
    paper's own whole-run deviation MAE (its Table 4)."""
    return metrics_of(data, claim_definitions()["vs_smc_ndo"])


def metric_name(metric: str) -> str:
    """How the report names a metric a claim is judged on."""
    return {"deviation_mae" + SS: "steady-state deviation MAE (ours)",
            "deviation_mae": "whole-run deviation MAE (the paper's Table 4)",
            "hf_fraction": "share of var(u) above 10 Hz (switching)",
            "chattering": "total variation of u per second",
            "d_est_mae": "estimation MAE"}.get(metric, metric)


RANKING_RULE = ("each adjacent pair is judged by the rules above on the difference smaller − larger; the ranking "
                "holds when every pair holds, does not hold when a pair does not (significantly the other way, or no "
                "practical difference), and is inconclusive otherwise")
BASELINE_RULE = ("as each ranking pair: holds when SMC-NDO-NNO's value is significantly lower and the whole CI of "
                 "the difference lies beyond the margin; tie inside the margin; does not hold when it is "
                 "significantly higher")


def rule(claim: Claim) -> str:
    """The report's rule for a claim, from its kind and claimed reduction."""
    if claim.kind == RANKING_KIND:
        return RANKING_RULE
    if claim.kind == BASELINE:
        return BASELINE_RULE
    v = 100 * claim.value
    if claim.about:
        text = (f"holds when the difference is significant and beyond the margin and the reduction (= −difference "
                f"in %) lies in {v:.0f} ± {100 * claim.band:.0f} %; does not hold when the 95 % CI of the "
                f"reduction lies outside that band or the difference inside the margin")
    else:
        text = (f"holds when the lower end of the 95 % CI of the reduction is above {v:.0f} % (p < 0.05, beyond "
                f"the margin); does not hold when its upper end is below {v:.0f} % or the difference is inside "
                f"the margin")
    if len(claim.metrics) > 1:
        text += (f"; the verdict rests on the {metric_name(claim.metrics[0])}, the "
                 + " and the ".join(metric_name(m) for m in claim.metrics[1:]) + " judged beside it")
    return f"{claim.reading}: {text}" if claim.reading else text


def judge(claim: Claim):
    """The verdict function ``(paired result, margin) -> verdict`` of a claim's kind."""
    if claim.kind == RANKING_KIND:
        return verdict_lower
    if claim.kind == BASELINE:
        return lambda r, m: verdict_lower(r, m, equality_possible=True)
    if claim.about:
        return lambda r, m: verdict_about(r, claim.value, claim.band, m)
    return lambda r, m: verdict_over(r, claim.value, m)


def claims(data: ReportData) -> list[ClaimResult]:
    """The paper's claims (:mod:`ddmr_cli.paper.claims`) with their rules (no checks yet)."""
    return [ClaimResult(c.id, c.title, rule(c), metrics=metrics_of(data, c), claimed=c.claimed, claim=c)
            for c in paper_claims()]


def paper_self_contradiction() -> str:
    """What the paper's own Table 4 says of the reductions its text (and Table 1) claims."""
    t4 = paper_numbers()["table4"]["rows"]
    nno, ndo, smc = (t4[k]["deviation_mean"] for k in ("SMC-NDO-NN", "SMC+NDO", "SMC"))
    return (f"The paper contradicts itself here: its own Table 4 gives a reduction of {100 * (1 - nno / ndo):.1f} % "
            f"against SMC-NDO ({1000 * ndo:.1f} -> {1000 * nno:.1f} mm) and {100 * (1 - nno / smc):.1f} % against "
            f"SMC ({1000 * smc:.1f} -> {1000 * nno:.1f} mm); the 'about 40 %' and 'over 60 %' of its text come from "
            f"its Table 1. The claims are judged as the text states them.")


def baselines(data: ReportData) -> list[str]:
    """The report's controllers outside the paper's claims, in the report's controller order."""
    return sorted({j.controller for j in data.jobs} - set(PAPER_CONTROLLERS), key=controller_rank)


def baseline_claims(data: ReportData) -> list[ClaimResult]:
    """One comparison per baseline and aspect: SMC-NDO-NNO (candidate) against the baseline (reference)."""
    dev = "steady-state deviation MAE" if deviation_metric(data).endswith(SS) else "deviation MAE"
    out = []
    for ctrl in baselines(data):
        label = next(j.label for j in data.jobs if j.controller == ctrl)
        for c in baseline(ctrl):
            aspect = c.id.partition(":")[2]
            out.append(ClaimResult(c.id, f"SMC-NDO-NNO: {BASELINE_TITLES[aspect].format(dev=dev)} {label} (not a "
                                         f"paper claim)", rule(c), metrics=metrics_of(data, c), claim=c))
    return out


def evaluate(data: ReportData, margin: Margin | None = None) -> list[ClaimResult]:
    """Every claim's checks, its verdict on each of its metrics and its overall verdict (on its first metric)."""
    margin = margin or Margin()
    results = claims(data) + baseline_claims(data)
    readings = [r for r in NNO_READINGS if any(j.controller == r for j in data.jobs)]
    if not readings:
        for c in results:
            c.skip("the sweep has no SMC-NDO-NNO job (smc_ndo_nno or smc_ndo_nno_text)")
        return results
    shared: dict[tuple[str, str, str, str], Check] = {}
    for scenario in data.scenarios:
        for reading in readings:
            nno, why = _key_for(data, scenario, reading)
            if nno is None:
                for c in results:
                    c.skip(why)
                continue
            for c in results:
                if c.claim.kind == RANKING_KIND:
                    _rank(data, c, scenario, reading, nno, margin, shared)
                    continue
                ref, why = _key_for(data, scenario, c.claim.reference)
                if ref is None:
                    c.skip(why)
                    continue
                for metric in c.metrics:
                    c.checks.append(_compare(data, c.id, scenario, reading, ref, nno, metric, judge(c.claim), margin))
            for c in results:
                if c.claim.kind == RANKING_KIND:
                    continue
                for metric in c.metrics:
                    mine = [k.verdict for k in c.checks
                            if k.scenario == scenario and k.reading == reading and k.metric == metric]
                    if mine:
                        c.by_metric[(scenario, reading, metric)] = combine(mine) if len(mine) > 1 else mine[0]
            for c in results:
                if (scenario, reading, c.metrics[0]) in c.by_metric:
                    c.overall[(scenario, reading)] = c.by_metric[(scenario, reading, c.metrics[0])]
    return results


def _rank(data: ReportData, rank: ClaimResult, scenario: str, reading: str, nno: str, margin: Margin,
          shared: dict) -> None:
    """A ranking's adjacent pairs among the controllers present, in the claimed order (SMC-NDO-NNO as ``reading``);
    a pair without the NNO is checked once for both readings (``shared``)."""
    chain, missing = [], []
    for ctrl in rank.claim.controllers:
        key, why = (nno, "") if ctrl == NNO else _key_for(data, scenario, ctrl)
        (chain.append(key) if key else missing.append(why))
    for why in missing:
        rank.skip(why + ("; the order is checked among the others" if len(chain) > 1 else ""))
    if len(chain) < 2:
        return
    for metric in rank.metrics:
        verdicts = []
        for worse, better in zip(chain, chain[1:]):
            done = (scenario, worse, better, metric)
            if done not in shared:
                shared[done] = _compare(data, rank.id, scenario, reading, worse, better, metric, judge(rank.claim),
                                        margin)
                rank.checks.append(shared[done])
            verdicts.append(shared[done].verdict)
        rank.by_metric[(scenario, reading, metric)] = combine(verdicts)


def our_order(data: ReportData, scenario: str, keys: list[str], metric: str) -> str:
    means = {k: float(per_seed(data, scenario, k, metric).mean()) for k in keys}
    order = sorted(keys, key=lambda k: -means[k] if not isnan(means[k]) else 0.0)
    return " > ".join(f"{data.label(k)} ({fmt(1000 * means[k], 3)} mm)" for k in order)


def _p(p) -> str:
    return "–" if isnan(p) else (f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}")


def _bold(verdict: str) -> str:
    cat = category(verdict)
    return f"**{cat}**{verdict[len(cat):]}"


def _scaled(metric: str) -> tuple[float, str]:
    """Display scale and unit: metres are shown in mm."""
    u = unit_of(metric)
    return (1000.0, "mm") if u == "m" else (1.0, {"1": "", "rad/s^2": "rad/s²"}.get(u, u))


def _diff_cells(r: Paired, metric: str) -> list[str]:
    k, u = _scaled(metric)
    lo, hi = r.diff_ci
    plo, phi = r.rel_diff_ci
    return [f"{fmt(k * r.diff, 3)} [{fmt(k * lo, 3)}, {fmt(k * hi, 3)}]",
            f"{100 * r.rel_diff:+.1f} % [{100 * plo:+.1f}, {100 * phi:+.1f}]"]


def _margin_cell(chk: Check) -> str:
    k, u = _scaled(chk.metric)
    return "–" if isnan(chk.margin) else f"±{fmt(k * chk.margin, 2)}{' ' + u if u else ''}"


def markdown(data: ReportData, results: list[ClaimResult], margin: Margin | None = None) -> str:
    """The verdicts section: rules, a summary of the verdicts that could be reached, then one subsection per
    checked claim; the claims that could not be checked are listed once, with why."""
    margin = margin or Margin()
    dev = deviation_metric(data)
    out = ["## Verdicts on the paper's claims", "",
           f"Every comparison is paired by seed (same seed and scenario -> same terrain and uncertainty), over the "
           f"seeds both controllers completed without diverging: the mean of each, the paired mean difference "
           f"candidate − reference in the metric's unit and in percent of the reference's mean, each with its 95 % "
           f"percentile bootstrap CI ({N_BOOT} resamples of the seeds, numpy Generator seeded {BOOT_SEED}), and "
           f"the two-sided Wilcoxon signed-rank test (scipy.stats.wilcoxon) of the paired differences; "
           f"significance level {ALPHA}. The paper's Table 4 does not say which scenario it is; its claims are "
           f"checked in every scenario.", "",
           f"**Practical margin: {margin.describe()}.** A difference inside it is negligible: "
           + (f"{MARGIN_WHY}. " if margin.metres is not None else "")
           + "Change it with `ddmr report PATH --margin 0.05mm` (a length with its unit, for the metrics in "
             "metres) or `--margin 2%` (relative, for every metric); a bare number is refused.", ""]
    if dev.endswith(SS):
        out += [f"**Each deviation claim is judged twice, side by side**: on our steady-state deviation (`{dev}` in "
                f"metrics.csv), so the initial convergence from the offset start pose does not decide it, and on the "
                f"paper's own metric, the whole-run deviation MAE of its Table 4 (`deviation_mae`). The overall "
                f"verdict (Summary, first) rests on the steady-state metric; where the two differ, the claim holds "
                f"only in the reading named. The chattering claim rests on the share of var(u) above 10 Hz, which "
                f"isolates switching, with the total variation of u beside it (docs/model.md §7).", ""]
    else:
        out += ["The deviation claims use the whole-run deviation MAE (`deviation_mae`, as the paper's Table 4); "
                "the jobs have no steady-state column (`deviation_mae_ss`).", ""]
    out += [paper_self_contradiction(), ""]
    out += ["Verdicts:", ""] + [f"- **{k}**: {v}." for k, v in VERDICT_RULES.items()] + [""]
    stand_ins = sorted({k for c in results for chk in c.checks for k in (chk.a, chk.b)
                        if k != data.controller_of(k)})
    if stand_ins:
        out += ["Where a controller has several jobs on a scenario (a sweep), its verdicts use the job without a "
                "swept setting or at the ideal loop: " + ", ".join(f"`{k}`" for k in stand_ins) + ".", ""]
    summary = [summary_line(data, c, scenario, reading) for c in results for (scenario, reading) in c.overall]
    not_checked = [c for c in results if not c.checks]
    out += ["### Summary", ""] + (summary or ["- no claim could be checked with these jobs"]) + [""]
    out += plant_comparison(data, results)
    for c in results:
        if not c.checks:
            continue
        out += [f"### {c.title}", "", f"Rule: {c.rule}.", ""]
        rows = []
        for chk in c.checks:
            r = chk.result
            k, u = _scaled(chk.metric)
            if c.claim.kind == RANKING_KIND:
                first = [chk.scenario, f"{data.label(chk.a)} > {data.label(chk.b)}", chk.metric + (f" ({u})" if u else "")]
            else:
                first = [chk.scenario, data.label(chk.b), chk.metric + (f" ({u})" if u else "")]
            nums = (["–"] * 6 if r is None else
                    [r.n, fmt(k * r.mean_a, 4), fmt(k * r.mean_b, 4), *_diff_cells(r, chk.metric), _p(r.p)])
            rows.append(first + nums + [_margin_cell(chk), chk.verdict + (f" ({chk.note})" if chk.note else "")])
        if c.claim.kind == RANKING_KIND:
            _, u = _scaled(dev)
            headers = ["Scenario", "Pair (claimed larger > smaller)", "Metric", "Seeds", f"Mean larger ({u})",
                       f"Mean smaller ({u})", f"Difference smaller − larger ({u}) [95 % CI]",
                       "Difference (% of larger) [95 % CI]", "Wilcoxon p", "Margin", "Pair verdict"]
        else:
            headers = ["Scenario", "Candidate", "Metric", "Seeds", "Reference mean", "Candidate mean",
                       "Difference candidate − reference [95 % CI]", "Difference (% of reference) [95 % CI]",
                       "Wilcoxon p", "Margin", "Verdict"]
        out += [md_table(headers, rows), ""]
        for (scenario, reading) in c.overall:
            out.append(summary_line(data, c, scenario, reading, title=False))
            if c.claim.kind == RANKING_KIND:
                keys = [k for c_ in RANKING + (reading,) if (k := _key_for(data, scenario, c_)[0]) is not None]
                keys = [k for k in data.keys(scenario) if k in keys]
                for metric in c.metrics:
                    out.append(f"  Our order by mean {metric}, largest first: "
                               f"{our_order(data, scenario, keys, metric)}.")
        if c.id == "estimation":
            est = paper_numbers()["claims"]["estimation"]
            out += ["", f"Paper: NDO {est['ndo']}, NDO+NNO {est['ndo_nno']} (units of d, rad/s²). Ours: the "
                        f"whole-run mean of |d_true − d̂| over both wheels; for SMC-NDO-NNO the NDO part alone is "
                        f"in the estimation table (d_est_mae_ndo)."]
        for why in c.skipped:
            out.append(f"- Not checked here: {why}.")
        out.append("")
    if not_checked:
        reasons = list(dict.fromkeys(why for c in not_checked for why in c.skipped))
        out += ["### Claims not checked", "",
                "These claims need controllers this report has no (single) job for: "
                + "; ".join(c.title for c in not_checked) + ".", "",
                "Why: " + "; ".join(reasons) + ".", ""]
    return "\n".join(out)


def plant_comparison(data: ReportData, results: list[ClaimResult]) -> list[str]:
    """The claims on both plants (docs/model.md §13): each claim's overall verdict on the wheel plant beside its
    verdict on another plant, per scenario and NNO reading, and whether it changes (its category, not its reason);
    no lines when the jobs ran on one plant."""
    pairs = data.plant_pairs()
    if not pairs:
        return []
    rows, changed = [], []
    for c in results:
        readings = list(dict.fromkeys(reading for (_, reading) in c.overall))
        for wheel, other, plant in pairs:
            for reading in readings:
                a, b = c.overall.get((wheel, reading)), c.overall.get((other, reading))
                if a is None and b is None:
                    continue
                change = a is None or b is None or category(a) != category(b)
                if change:
                    changed.append(f"{c.title} ({wheel}, {data.label(reading)}: {category(a) if a else 'not checked'}"
                                   f" -> {category(b) if b else 'not checked'} on {plant})")
                rows.append([c.title, wheel, plant, data.label(reading), _bold(a) if a else "not checked",
                             _bold(b) if b else "not checked", "**changes**" if change else "same"])
    plants = ", ".join(dict.fromkeys(p for _, _, p in pairs))
    return ["### The claims on both plants", "",
            f"The same controllers, seeds and scenarios on the paper's wheel-space plant (8) and on {plants} "
            f"(docs/model.md §13: a rigid-body robot on a heightfield, terrain from the physics; scenario "
            f"`<scenario>@{pairs[0][2]}` in every table of this report). Each claim's overall verdict on each plant:", "",
            md_table(["Claim", "Scenario", "Plant", "SMC-NDO-NNO reading", "On the wheel plant", "On that plant", "Verdict"],
                     rows), "",
            ("Claims whose verdict changes: " + "; ".join(changed) + ".") if changed else
            "No claim's verdict changes between the plants.", ""]


def _numbers(c: ClaimResult, scenario: str, reading: str, metric: str) -> str:
    """Ours against the claim, with the CI: for a claim on one pair, its reduction."""
    found = [k for k in c.checks if k.scenario == scenario and k.reading == reading and k.metric == metric]
    if c.claim.kind == RANKING_KIND or len(found) != 1 or found[0].result is None:
        return ""
    r = found[0].result
    lo, hi = r.reduction_ci
    return f" (ours: a reduction of {100 * r.reduction:.1f} % [95 % CI {100 * lo:.1f}, {100 * hi:.1f}]" + (
        f"; claimed: {c.claimed})" if c.claimed else ")")


def _judged(c: ClaimResult, scenario: str, reading: str) -> list[tuple[str, str]]:
    """(metric, verdict) of a claim in one scenario and reading, in the claim's metric order (the one its overall
    verdict rests on first)."""
    return [(m, c.by_metric[(scenario, reading, m)]) for m in c.metrics if (scenario, reading, m) in c.by_metric]


def _reading_label(data: ReportData, reading: str) -> str:
    """The label of the controller an NNO reading names (the controller's, not a job's)."""
    return next(j.display.label for j in data.jobs if j.controller == reading)


def summary_line(data: ReportData, c: ClaimResult, scenario: str, reading: str, title: bool = True) -> str:
    """One claim in one scenario and reading: its verdict on each of its metrics, side by side, with the numbers."""
    parts = [f"on the {metric_name(m)}: {_bold(verdict)}{_numbers(c, scenario, reading, m)}"
             for m, verdict in _judged(c, scenario, reading)]
    head = f"{c.title} — " if title else ""
    return f"- {head}{scenario}, {_reading_label(data, reading)}: " + "; ".join(parts)


def answer_lines(data: ReportData, results: list[ClaimResult]) -> list[str]:
    """The verdicts in plain text: one line per paper claim, scenario and NNO reading, with the verdict on each
    metric the claim is judged on, the one its overall verdict rests on first (the Summary of :func:`markdown`
    without its numbers or reasons); then one line counting the comparisons against the baselines, which are not
    the paper's claims, by verdict. What ``ddmr report`` prints as soon as the verdicts are known, before the
    figures are drawn; none when no claim could be checked."""
    lines, others = [], Counter()
    for c in results:
        for (scenario, reading), overall in c.overall.items():
            if c.claim is not None and c.claim.kind == BASELINE:
                others[category(overall)] += 1
                continue
            on = [f"{category(verdict)} on the {metric_name(m)}" for m, verdict in _judged(c, scenario, reading)]
            lines.append(f"{c.title} [{scenario}, {_reading_label(data, reading)}]: " + "; ".join(on))
    if others:
        counts = ", ".join(f"{others[v]} {v}" for v in VERDICT_RULES if others[v])
        lines.append(f"SMC-NDO-NNO against {len(baselines(data))} baseline controller(s), not the paper's claims: "
                     f"{sum(others.values())} comparisons, {counts} (each in the report)")
    return lines


def rows(results: list[ClaimResult]) -> list[dict]:
    out = []
    for c in results:
        for chk in c.checks:
            out.append({**chk.row(), "claim_verdict": c.overall.get((chk.scenario, chk.reading), ""),
                        "claim_verdict_on_metric": c.by_metric.get((chk.scenario, chk.reading, chk.metric), ""),
                        "claim_rests_on": c.metrics[0] if c.metrics else ""})
    return out
