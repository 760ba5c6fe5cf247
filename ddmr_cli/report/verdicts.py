"""Verdicts on the paper's claims, from our numbers, each comparison paired by seed (see :mod:`.stats`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from ddmr_cli.report.data import ReportData, paper_numbers
from ddmr_cli.report.stats import (ALPHA, BOOT_SEED, N_BOOT, Paired, combine, paired, verdict_about, verdict_lower,
                    verdict_over)
from ddmr_cli.report.tables import fmt, isnan, md_table, pct

NNO_READINGS = ("smc_ndo_nno", "smc_ndo_nno_text")
RANKING = ("pid", "smc", "smc_ndo")  # then the NNO reading; largest deviation first
ABOUT_BAND = 0.10


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
    note: str = ""

    def row(self) -> dict:
        out = {"claim": self.claim, "scenario": self.scenario, "nno_reading": self.reading, "reference": self.a,
               "candidate": self.b, "metric": self.metric, "verdict": self.verdict, "note": self.note}
        out.update(self.result.as_dict() if self.result else {})
        return out


@dataclass
class ClaimResult:
    """A claim, its rule, and its checks per scenario and NNO reading, with an overall verdict for each."""

    id: str
    title: str
    rule: str
    checks: list[Check] = field(default_factory=list)
    overall: dict[tuple[str, str], str] = field(default_factory=dict)   # (scenario, reading) -> verdict
    notes: list[str] = field(default_factory=list)


def _key_for(data: ReportData, scenario: str, controller: str) -> tuple[str | None, str]:
    keys = [k for k in data.keys(scenario) if data.controller_of(k) == controller]
    if not keys:
        return None, f"no complete {controller} job in {scenario}"
    if keys != [controller]:
        return None, f"several {controller} jobs in {scenario} ({', '.join(keys)}); verdicts need one per controller"
    return controller, ""


def _per_seed(data: ReportData, scenario: str, key: str, metric: str):
    job = data.job(scenario, key)
    frame = data.metrics[(data.metrics["job"] == job.dir.name) & (data.metrics["status"] == "ok")]
    return frame.set_index("seed")[metric].astype(float)


def _compare(data, claim, scenario, reading, a, b, metric, judge) -> Check:
    result = paired(_per_seed(data, scenario, a, metric), _per_seed(data, scenario, b, metric))
    if result is None:
        return Check(claim, scenario, reading, a, b, metric, None, "skipped", "no seed completed by both")
    return Check(claim, scenario, reading, a, b, metric, result, judge(result))


def evaluate(data: ReportData) -> list[ClaimResult]:
    claims = paper_numbers()["claims"]
    est = claims["estimation"]
    est_reduction = 1.0 - est["ndo_nno"] / est["ndo"]
    results = [
        ClaimResult("ranking", "Ranking PID > SMC > SMC-NDO > SMC-NDO-NNO (mean deviation, largest first)",
                    "each adjacent pair must be ordered as claimed with Wilcoxon p < 0.05 and the 95 % CI of the "
                    "difference excluding 0; the ranking holds when all pairs hold, does not hold when any pair "
                    "is significantly the other way, and is inconclusive otherwise"),
        ClaimResult("vs_smc_ndo", "SMC-NDO-NNO: about 40 % lower deviation MAE than SMC-NDO",
                    f"holds when the reduction is significant (p < 0.05, CI of the difference below 0) and its "
                    f"estimate lies in 40 ± {100 * ABOUT_BAND:.0f} %; does not hold when its 95 % CI lies outside that band"),
        ClaimResult("vs_smc", "SMC-NDO-NNO: over 60 % lower deviation MAE than SMC",
                    "holds when the lower end of the 95 % CI of the reduction is above 60 % (and p < 0.05); "
                    "does not hold when the upper end is below 60 %"),
        ClaimResult("chattering", "SMC-NDO-NNO: near-complete elimination of chattering (vs SMC-NDO)",
                    "read as a reduction of at least 90 %: holds when the 95 % CI of the reduction lies above 90 % "
                    "(and p < 0.05), does not hold when it lies below 90 %; checked on the total variation of u "
                    "(V/s) and on the fraction of var(u) above 10 Hz"),
        ClaimResult("estimation", f"Disturbance-estimation MAE: NDO {est['ndo']:.1f} vs NDO+NNO {est['ndo_nno']:.1f} "
                                  f"(a {100 * est_reduction:.0f} % reduction, 'three times lower')",
                    f"our d_est_mae of SMC-NDO (NDO estimate) vs SMC-NDO-NNO (NDO + NN estimate); holds when the "
                    f"reduction is significant and its estimate lies in {100 * est_reduction:.0f} ± {100 * ABOUT_BAND:.0f} %; "
                    f"does not hold when its 95 % CI lies outside that band"),
    ]
    by_id = {c.id: c for c in results}
    readings = [r for r in NNO_READINGS if any(j.controller == r for j in data.jobs)]
    if not readings:
        for c in results:
            c.notes.append("skipped: the sweep has no SMC-NDO-NNO job (smc_ndo_nno or smc_ndo_nno_text)")
        return results
    specs = [  # claim id, reference controller, metric, judge
        ("vs_smc_ndo", "smc_ndo", "deviation_mae", lambda r: verdict_about(r, 0.40, ABOUT_BAND)),
        ("vs_smc", "smc", "deviation_mae", lambda r: verdict_over(r, 0.60)),
        ("chattering", "smc_ndo", "chattering", lambda r: verdict_over(r, 0.90)),
        ("chattering", "smc_ndo", "hf_fraction", lambda r: verdict_over(r, 0.90)),
        ("estimation", "smc_ndo", "d_est_mae", lambda r: verdict_about(r, est_reduction, ABOUT_BAND)),
    ]
    shared: dict[tuple[str, str, str], Check] = {}
    for scenario in data.scenarios:
        for reading in readings:
            nno, why = _key_for(data, scenario, reading)
            if nno is None:
                for c in results:
                    c.notes.append(f"{scenario}, {reading}: skipped ({why})")
                continue
            # ranking: adjacent pairs among the controllers present, in the claimed order
            chain, missing = [], []
            for ctrl in RANKING:
                key, why = _key_for(data, scenario, ctrl)
                (chain.append(key) if key else missing.append(why))
            chain.append(nno)
            rank = by_id["ranking"]
            if missing:
                rank.notes.append(f"{scenario}, {reading}: " + "; ".join(missing)
                                  + ("; the order is checked among the others" if len(chain) > 1 else ""))
            if len(chain) > 1:
                verdicts = []
                for worse, better in zip(chain, chain[1:]):
                    done = (scenario, worse, better)
                    if done not in shared:  # pairs without the NNO are shared by both readings
                        shared[done] = _compare(data, rank.id, scenario, reading, worse, better, "deviation_mae",
                                                verdict_lower)
                        rank.checks.append(shared[done])
                    chk = shared[done]
                    verdicts.append(chk.verdict)
                rank.overall[(scenario, reading)] = combine(verdicts)
            for cid, ref_ctrl, metric, judge in specs:
                claim = by_id[cid]
                ref, why = _key_for(data, scenario, ref_ctrl)
                if ref is None:
                    claim.notes.append(f"{scenario}, {reading}: skipped ({why})")
                    continue
                chk = _compare(data, cid, scenario, reading, ref, nno, metric, judge)
                claim.checks.append(chk)
            for cid in ("vs_smc_ndo", "vs_smc", "chattering", "estimation"):
                mine = [c.verdict for c in by_id[cid].checks if c.scenario == scenario and c.reading == reading]
                if mine:
                    by_id[cid].overall[(scenario, reading)] = combine(mine) if len(mine) > 1 else mine[0]
    return results


def our_order(data: ReportData, scenario: str, keys: list[str]) -> str:
    means = {k: float(_per_seed(data, scenario, k, "deviation_mae").mean()) for k in keys}
    order = sorted(keys, key=lambda k: -means[k] if not isnan(means[k]) else 0.0)
    return " > ".join(f"{data.label(k)} ({fmt(means[k], 3)} m)" for k in order)


def _ci(lo, hi, f=fmt) -> str:
    return f"[{f(lo)}, {f(hi)}]"


def _p(p) -> str:
    return "–" if isnan(p) else (f"{p:.2g}" if p >= 1e-4 else f"{p:.1e}")


def _bold(verdict: str) -> str:
    return f"**{verdict}**"


def markdown(data: ReportData, results: list[ClaimResult]) -> str:
    """The verdicts section: a summary list, then one subsection per claim."""
    units = {"deviation_mae": "m", "chattering": "V/s", "hf_fraction": "", "d_est_mae": "rad/s²"}
    out = ["## Verdicts on the paper's claims", "",
           f"Every comparison is paired by seed (same seed and scenario -> same terrain and uncertainty), over the "
           f"seeds both controllers completed without diverging: mean of each, 95 % percentile bootstrap CI "
           f"({N_BOOT} resamples of the seeds, numpy Generator seeded {BOOT_SEED}) of the difference and of the "
           f"relative reduction 1 − mean(candidate)/mean(reference), and the two-sided Wilcoxon signed-rank test "
           f"(scipy.stats.wilcoxon) of the paired differences; significance level {ALPHA}. The paper's Table 4 "
           f"does not say which scenario it is; its claims are checked in every scenario.", ""]
    summary = []
    for c in results:
        for (scenario, reading), v in c.overall.items():
            summary.append(f"- {c.title} — {scenario}, {data.label(reading)}: {_bold(v)}")
        for note in c.notes:
            if "skipped" in note and not c.overall:
                summary.append(f"- {c.title}: {note}")
    out += ["### Summary", ""] + (summary or ["- no claim could be checked"]) + [""]
    for c in results:
        out += [f"### {c.title}", "", f"Rule: {c.rule}.", ""]
        if c.id == "ranking":
            rows = []
            for chk in c.checks:
                r = chk.result
                rows.append([chk.scenario, f"{data.label(chk.a)} > {data.label(chk.b)}",
                             *(["–"] * 5 if r is None else
                               [r.n, fmt(r.mean_a), fmt(r.mean_b), f"{fmt(r.diff)} {_ci(*r.diff_ci)}", _p(r.p)]),
                             chk.verdict + (f" ({chk.note})" if chk.note else "")])
            if rows:
                out += [md_table(["Scenario", "Pair (claimed larger > smaller)", "Seeds", "Mean larger (m)",
                                  "Mean smaller (m)", "Difference smaller − larger (m) [95 % CI]", "Wilcoxon p",
                                  "Pair verdict"], rows), ""]
            for (scenario, reading), v in c.overall.items():
                keys = [k for k in data.keys(scenario)
                        if data.controller_of(k) in RANKING + (reading,) and k == data.controller_of(k)]
                out.append(f"- {scenario}, {data.label(reading)}: {_bold(v)}. Our order by mean deviation, "
                           f"largest first: {our_order(data, scenario, keys)}.")
        else:
            rows = []
            for chk in c.checks:
                r = chk.result
                u = units.get(chk.metric, "")
                name = f"{chk.metric} ({u})" if u else chk.metric
                rows.append([chk.scenario, data.label(chk.b), name,
                             *(["–"] * 5 if r is None else
                               [r.n, f"{data.label(chk.a)}: {fmt(r.mean_a)}", fmt(r.mean_b),
                                f"{pct(r.reduction)} {_ci(*r.reduction_ci, f=pct)}", _p(r.p)]),
                             chk.verdict + (f" ({chk.note})" if chk.note else "")])
            if rows:
                out += [md_table(["Scenario", "Candidate", "Metric", "Seeds", "Reference mean", "Candidate mean",
                                  "Reduction [95 % CI]", "Wilcoxon p", "Verdict"], rows), ""]
            for (scenario, reading), v in c.overall.items():
                out.append(f"- {scenario}, {data.label(reading)}: {_bold(v)}")
        if c.id == "estimation" and c.checks:
            est = paper_numbers()["claims"]["estimation"]
            out += ["", f"Paper: NDO {est['ndo']}, NDO+NNO {est['ndo_nno']} (units of d, rad/s²). Ours: the "
                        f"whole-run mean of |d_true − d̂| over both wheels; for SMC-NDO-NNO the NDO part alone is "
                        f"in the estimation table (d_est_mae_ndo)."]
        for note in c.notes:
            out.append(f"- Note: {note}")
        out.append("")
    return "\n".join(out)


def rows(results: list[ClaimResult]) -> list[dict]:
    out = []
    for c in results:
        for chk in c.checks:
            out.append({**chk.row(), "claim_verdict": c.overall.get((chk.scenario, chk.reading), "")})
    return out
