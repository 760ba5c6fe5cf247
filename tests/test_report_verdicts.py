"""The verdict logic of ``ddmr report`` on constructed data: every branch of the rules (holds / tie / does not hold
/ inconclusive), the paired statistics they read, the practical margin, and the claims wired to them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ddmr_cli.report import stats as S
from ddmr_cli.report.stats import FAILS, HOLDS, INCONCLUSIVE, TIE, Margin, Paired, category


def pr(diff_ci, reduction_ci=(0.0, 0.0), p=1e-6, n=50, mean_a=1.0, diff=None, reduction=None) -> Paired:
    """A constructed comparison: only what the rules read."""
    diff = sum(diff_ci) / 2 if diff is None else diff
    reduction = sum(reduction_ci) / 2 if reduction is None else reduction
    return Paired(n, mean_a, mean_a + diff, diff, tuple(diff_ci), reduction, tuple(reduction_ci), p, 0.0)


M = 0.1  # margin in the metric's unit


# --- verdict_lower: "b is below a" ---------------------------------------------------------------------------
@pytest.mark.parametrize("case, expected", [
    (dict(diff_ci=(-0.5, -0.2)), HOLDS),                          # below -margin, significant
    (dict(diff_ci=(-0.05, 0.08)), FAILS),                          # inside ±margin: no claimed improvement
    (dict(diff_ci=(-0.09, -0.01)), FAILS),                         # significant, but negligible: refuted
    (dict(diff_ci=(0.2, 0.5)), FAILS),                             # significantly the other way
    (dict(diff_ci=(-0.3, -0.05)), INCONCLUSIVE),                   # lower, but reaching into the margin
    (dict(diff_ci=(-0.5, 0.3), p=0.4), INCONCLUSIVE),              # straddles 0, not significant
    (dict(diff_ci=(-0.5, -0.2), p=0.2), INCONCLUSIVE),             # CI below, Wilcoxon disagrees
    (dict(diff_ci=(-0.5, -0.2), n=5), INCONCLUSIVE),               # too few seeds
    (dict(diff_ci=(-0.05, 0.05), n=3), INCONCLUSIVE),              # too few seeds beats a tie
])
def test_verdict_lower_every_branch(case, expected):
    assert category(S.verdict_lower(pr(**case), M)) == expected


@pytest.mark.parametrize("diff_ci", [(-0.05, 0.08), (-0.09, -0.01)])
def test_only_a_comparison_that_claims_no_improvement_ties(diff_ci):
    """Inside the margin an improvement claim does not hold; a baseline comparison (equality possible) ties."""
    assert category(S.verdict_lower(pr(diff_ci), M, equality_possible=True)) == TIE
    assert "no practical difference" in S.verdict_lower(pr(diff_ci), M)


def test_verdict_lower_reasons():
    assert "significantly the other way" in S.verdict_lower(pr((0.2, 0.5)), M)
    assert "reaches into" in S.verdict_lower(pr((-0.3, -0.05)), M)
    assert "p >= 0.05" in S.verdict_lower(pr((-0.5, 0.3), p=0.4), M)
    assert "only 5 paired seeds" in S.verdict_lower(pr((-0.5, -0.2), n=5), M)
    assert "no paired difference" in S.verdict_lower(pr((-0.5, 0.3), p=math.nan), M)


def test_zero_margin_never_ties():
    assert category(S.verdict_lower(pr((-0.05, -0.01)), 0.0)) == HOLDS
    assert category(S.verdict_lower(pr((-0.01, 0.01), p=0.5), 0.0)) == INCONCLUSIVE


# --- verdict_over: "b is more than threshold lower than a" ------------------------------------------------------
@pytest.mark.parametrize("case, expected", [
    (dict(diff_ci=(-0.8, -0.7), reduction_ci=(0.7, 0.8)), HOLDS),
    (dict(diff_ci=(-0.8, -0.7), reduction_ci=(0.4, 0.5)), FAILS),          # CI of the reduction below 60 %
    (dict(diff_ci=(0.1, 0.3), reduction_ci=(-0.3, -0.1)), FAILS),           # higher, not lower
    (dict(diff_ci=(-0.08, 0.05), reduction_ci=(-0.05, 0.08)), FAILS),       # equal within the margin: refuted
    (dict(diff_ci=(-0.08, 0.05), reduction_ci=(0.55, 0.7)), FAILS),         # reduction CI fine, but negligible
    (dict(diff_ci=(-0.8, -0.5), reduction_ci=(0.5, 0.8)), INCONCLUSIVE),    # CI of the reduction includes 60 %
    (dict(diff_ci=(-0.8, 0.1), reduction_ci=(-0.1, 0.8), p=0.3), INCONCLUSIVE),
    (dict(diff_ci=(-0.8, -0.7), reduction_ci=(0.7, 0.8), n=4), INCONCLUSIVE),
])
def test_verdict_over_every_branch(case, expected):
    assert category(S.verdict_over(pr(**case), 0.60, M)) == expected


def test_verdict_over_is_not_always_holds():
    """The mutation this suite must catch: a verdict_over that always says holds."""
    verdicts = {category(S.verdict_over(pr((-0.8, -0.7), (0.4, 0.5)), 0.6, M)),
                category(S.verdict_over(pr((-0.05, 0.05), (-0.05, 0.05)), 0.6, M))}
    assert verdicts == {FAILS}


# --- verdict_about: "b is about target lower than a" ------------------------------------------------------------
@pytest.mark.parametrize("case, expected", [
    (dict(diff_ci=(-0.45, -0.35), reduction_ci=(0.35, 0.45), reduction=0.4), HOLDS),
    (dict(diff_ci=(-0.8, -0.7), reduction_ci=(0.7, 0.8)), FAILS),               # far more than 40 %
    (dict(diff_ci=(-0.2, -0.15), reduction_ci=(0.15, 0.2)), FAILS),             # far less
    (dict(diff_ci=(-0.05, 0.05), reduction_ci=(-0.05, 0.05)), FAILS),          # no difference: refuted
    (dict(diff_ci=(-0.6, -0.25), reduction_ci=(0.25, 0.6), reduction=0.55), INCONCLUSIVE),  # estimate outside
    (dict(diff_ci=(-0.6, 0.1), reduction_ci=(-0.1, 0.6), p=0.2), INCONCLUSIVE),  # not significant
    (dict(diff_ci=(-0.45, -0.35), reduction_ci=(0.35, 0.45), reduction=0.4, n=2), INCONCLUSIVE),
])
def test_verdict_about_every_branch(case, expected):
    assert category(S.verdict_about(pr(**case), 0.40, 0.10, M)) == expected


def test_verdict_about_needs_the_difference_beyond_the_margin():
    """A reduction of 40 % of a tiny mean is within a physical margin: not a practical improvement."""
    small = pr((-0.45, -0.35), (0.35, 0.45), reduction=0.4)
    assert category(S.verdict_about(small, 0.40, 0.10, margin=0.4)) == INCONCLUSIVE
    assert category(S.verdict_about(small, 0.40, 0.10, margin=0.5)) == FAILS


# --- combining the parts of a claim -----------------------------------------------------------------------------
@pytest.mark.parametrize("parts, expected", [
    ([HOLDS, HOLDS, HOLDS], HOLDS),
    ([HOLDS, "tie (…)", HOLDS], TIE),
    (["tie (…)", "tie (…)"], TIE),
    ([HOLDS, "does not hold (…)", "tie (…)"], FAILS),
    ([HOLDS, "inconclusive (p >= 0.05)"], INCONCLUSIVE),
    (["tie (…)", "inconclusive (…)"], INCONCLUSIVE),
    ([], INCONCLUSIVE),
])
def test_combine(parts, expected):
    assert S.combine(parts) == expected


# --- the paired statistics ---------------------------------------------------------------------------------------
def test_paired_on_constructed_series():
    rng = np.random.default_rng(1)
    seeds = np.arange(40)
    a = pd.Series(0.003 + 0.0002 * rng.standard_normal(40), index=seeds)
    b = a - 0.001 + 0.00005 * rng.standard_normal(40)  # b is 1 mm lower, paired
    r = S.paired(a, b)
    assert r.n == 40
    assert r.diff == pytest.approx(float((b - a).mean()))
    assert r.diff_ci[0] < r.diff < r.diff_ci[1] and r.diff_ci[1] < -0.0009 and r.diff_ci[0] > -0.0011
    assert r.rel_diff == pytest.approx(r.diff / r.mean_a)
    assert r.rel_diff_ci[0] == pytest.approx(-r.reduction_ci[1]) and r.rel_diff_ci[1] == pytest.approx(-r.reduction_ci[0])
    assert r.p < 1e-6 and r.b_lower and not r.b_higher
    assert category(S.verdict_lower(r, 1e-4)) == HOLDS
    assert category(S.verdict_lower(r, 2e-3)) == FAILS   # a 2 mm margin makes 1 mm negligible: no improvement
    assert category(S.verdict_lower(r, 2e-3, equality_possible=True)) == TIE
    assert S.paired(a, b).as_dict() == r.as_dict()        # seeded bootstrap: reproducible


def test_paired_intervals_are_each_statistics_own_bootstrap():
    """Both intervals come from one bootstrap call with a two-valued statistic: each equals scipy's bootstrap of that
    statistic alone from the same seeded Generator (the same resamples)."""
    from scipy import stats

    rng = np.random.default_rng(3)
    a = pd.Series(0.004 + 0.0005 * rng.standard_normal(30), index=np.arange(30))
    b = 0.8 * a + 0.0002 * rng.standard_normal(30)
    r = S.paired(a, b)
    x, y = a.to_numpy(), b.to_numpy()
    alone = {}
    for name, statistic in (("diff", lambda x, y, axis=-1: np.mean(y, axis=axis) - np.mean(x, axis=axis)),
                            ("reduction", lambda x, y, axis=-1: 1.0 - np.mean(y, axis=axis) / np.mean(x, axis=axis))):
        ci = stats.bootstrap((x, y), statistic, paired=True, vectorized=True, n_resamples=S.N_BOOT,
                             confidence_level=S.CI_LEVEL, method="percentile",
                             random_state=np.random.default_rng(S.BOOT_SEED)).confidence_interval
        alone[name] = (ci.low, ci.high)
    assert r.diff_ci == pytest.approx(alone["diff"], rel=1e-12, abs=1e-15)
    assert r.reduction_ci == pytest.approx(alone["reduction"], rel=1e-12, abs=1e-15)
    one = S.paired(a.iloc[:1], b.iloc[:1])  # a single pair: intervals of width 0 at the values
    assert one.diff_ci == pytest.approx((one.diff, one.diff)) and one.reduction_ci == pytest.approx((one.reduction,) * 2)


def test_paired_uses_common_seeds_only():
    a = pd.Series([1.0, 2.0, 3.0, np.nan], index=[0, 1, 2, 3])
    b = pd.Series([1.5, 2.5, 9.0], index=[1, 2, 5])
    r = S.paired(a, b)
    assert r.n == 2 and r.mean_a == pytest.approx(2.5) and r.mean_b == pytest.approx(2.0)
    assert S.paired(a, pd.Series([1.0], index=[7])) is None


# --- the margin --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, metres, relative", [
    (None, 1e-4, 0.05), ("0.1mm", 1e-4, 0.05), ("1e-4m", 1e-4, 0.05), ("100um", 1e-4, 0.05),
    ("0.0003 m", 3e-4, 0.05), ("5%", None, 0.05), ("12.5 %", None, 0.125), ("0mm", 0.0, 0.05),
])
def test_margin_parse(text, metres, relative):
    m = Margin.parse(text)
    assert (m.metres is None) == (metres is None)
    if metres is not None:
        assert m.metres == pytest.approx(metres)
    assert m.relative == pytest.approx(relative)


@pytest.mark.parametrize("bad", ["lots", "-1mm", "nan", "%", "5 furlongs", "inf", "5", "1e-4", 2e-4, "0"])
def test_margin_parse_rejects(bad):
    with pytest.raises(ValueError, match="margin"):
        Margin.parse(bad)


def test_margin_absolute_per_unit():
    m = Margin()
    assert m.absolute("m", 0.002) == pytest.approx(1e-4)           # 0.1 mm ...
    assert m.absolute("m", 0.0003) == pytest.approx(1.5e-5)        # ... or 5 % of the reference where smaller
    assert Margin.parse("0.1mm").absolute("m", 0.0003) == pytest.approx(1e-4)  # an explicit length is just that
    assert m.absolute("V/s", 40.0) == pytest.approx(2.0)            # 5 % of the reference elsewhere
    assert Margin.parse("10%").absolute("m", 0.002) == pytest.approx(2e-4)
    assert "0.1 mm" in m.describe() and "5 %" in m.describe() and "whichever is smaller" in m.describe()
    assert "whichever" not in Margin.parse("0.2mm").describe()


# --- the claims, wired to the rules, on a constructed ReportData ------------------------------------------------
def make_data(per_controller: dict, n_seeds: int = 30, scenario: str = "paper_1", extra_cols=None, seed=0):
    """A ReportData with one job per controller and per-seed metrics ``mean + noise`` (paired by seed: a shared
    per-seed terrain term), no files."""
    from ddmr_cli.report.data import Job, ReportData

    rng = np.random.default_rng(seed)
    terrain = rng.standard_normal(n_seeds)
    jobs, rows = [], []
    for controller, metrics in per_controller.items():
        job = Job(Path(f"/nowhere/{controller}"), {"controller": controller, "scenario": scenario,
                                                   "status": "complete", "parameters": {}}, {})
        job.key = controller
        jobs.append(job)
        for i in range(n_seeds):
            row = {"job": job.dir.name, "seed": i, "status": "ok", "key": controller}
            for metric, (mean, sd) in metrics.items():
                row[metric] = mean * (1 + sd * terrain[i]) + 1e-3 * mean * rng.standard_normal()
            rows.append(row)
    metrics = pd.DataFrame(rows)
    return ReportData(Path("/nowhere"), False, jobs, [], [], metrics, pd.DataFrame(columns=["job", "segment"]))


def base(dev_mm: float, chat: float = 40.0, hf: float = 0.2, dest: float = 20.0) -> dict:
    return {"deviation_mae": (dev_mm / 1000, 0.05), "chattering": (chat, 0.05), "hf_fraction": (hf, 0.05),
            "d_est_mae": (dest, 0.05)}


def by_id(results):
    return {c.id: c for c in results}


def test_claims_hold_when_the_data_say_so():
    from ddmr_cli.report import verdicts as V

    data = make_data({"pid": base(18.7), "smc": base(5.2), "smc_ndo": base(3.2),
                      "smc_ndo_nno": base(1.9, chat=1.0, hf=0.005, dest=6.6)})
    res = by_id(V.evaluate(data))
    key = ("paper_1", "smc_ndo_nno")
    assert category(res["ranking"].overall[key]) == HOLDS
    assert category(res["vs_smc_ndo"].overall[key]) == HOLDS      # 1.9 / 3.2: a 41 % reduction
    assert category(res["vs_smc"].overall[key]) == HOLDS          # 63 %
    assert category(res["chattering"].overall[key]) == HOLDS      # 97.5 % on both metrics
    assert category(res["estimation"].overall[key]) == HOLDS      # 67 %


def test_claims_of_improvement_do_not_hold_where_our_sweep_shows_none():
    """Our sweep's picture: SMC-NDO-NNO equal to SMC-NDO within 0.1 mm, chattering alike: every claimed
    improvement that is not there does not hold (never a tie)."""
    from ddmr_cli.report import verdicts as V

    data = make_data({"pid": base(6.9), "smc": base(2.93), "smc_ndo": base(1.792),
                      "smc_ndo_nno": base(1.828, chat=40.5, hf=0.205, dest=20.3)})
    res = by_id(V.evaluate(data))
    key = ("paper_1", "smc_ndo_nno")
    assert category(res["ranking"].overall[key]) == FAILS         # PID > SMC > SMC-NDO hold, the last pair is equal
    pair = next(c for c in res["ranking"].checks if c.b == "smc_ndo_nno")
    assert category(pair.verdict) == FAILS and pair.margin == pytest.approx(0.05 * 1.792e-3, rel=0.05)  # 5 % < 0.1 mm
    assert category(res["vs_smc_ndo"].overall[key]) == FAILS
    assert category(res["vs_smc"].overall[key]) == FAILS          # 38 % < 60 %
    assert category(res["chattering"].overall[key]) == FAILS
    assert category(res["estimation"].overall[key]) == FAILS
    assert TIE not in {category(v) for c in res.values() for v in c.by_metric.values()}
    # with no margin the same data give the strict verdicts: the NNO is significantly worse than SMC-NDO
    strict = by_id(V.evaluate(data, Margin(0.0, 0.0)))
    assert category(strict["ranking"].overall[key]) == FAILS


def test_claims_use_the_steady_state_deviation_when_present():
    from ddmr_cli.report import verdicts as V

    dev = {"pid": 6.9, "smc": 2.9, "smc_ndo": 1.8, "smc_ndo_nno": 1.83}
    ss = {"pid": 5.0, "smc": 0.40, "smc_ndo": 0.30, "smc_ndo_nno": 0.15}
    data = make_data({c: {**base(dev[c]), "deviation_mae_ss": (ss[c] / 1000, 0.05)} for c in dev})
    assert V.deviation_metric(data) == "deviation_mae_ss"
    res = by_id(V.evaluate(data))
    key = ("paper_1", "smc_ndo_nno")
    assert {c.metric for c in res["ranking"].checks} == {"deviation_mae_ss", "deviation_mae"}
    assert res["ranking"].metrics == ("deviation_mae_ss", "deviation_mae")  # the overall verdict rests on the first
    assert category(res["ranking"].overall[key]) == HOLDS  # SMC-NDO -> NNO: 0.15 mm lower, beyond 5 % of 0.30 mm
    # on the paper's whole-run metric the same data refute it (1.83 vs 1.8 mm), and both verdicts are printed
    assert category(res["ranking"].by_metric[key + ("deviation_mae",)]) == FAILS
    assert category(res["vs_smc"].by_metric[key + ("deviation_mae_ss",)]) == HOLDS     # 0.15 / 0.40: 62 %
    assert category(res["vs_smc"].by_metric[key + ("deviation_mae",)]) == FAILS        # 1.83 / 2.9: 37 %
    md = V.markdown(data, V.evaluate(data))
    line = next(ln for ln in md.splitlines() if ln.startswith("- SMC-NDO-NNO: over 60 %"))
    assert "steady-state deviation MAE (ours): **holds**" in line
    assert "whole-run deviation MAE (the paper's Table 4): **does not hold**" in line
    assert "claimed: a reduction of at least 60 %" in line and "95 % CI" in line
    assert "18.8 %" in md and "50.0 %" in md and "Table 1" in md  # the paper's own Table 4 against its text
    # without the column: the whole-run deviation
    plain = make_data({c: base(dev[c]) for c in dev})
    assert V.deviation_metric(plain) == "deviation_mae"


def test_the_printed_answer_is_each_claims_verdict_on_each_metric():
    """answer_lines (what `ddmr report` prints before its figures): one line per claim, scenario and reading, with
    the verdict on each metric the claim is judged on, the one its overall verdict rests on first; none when no
    claim could be checked."""
    from ddmr_cli.report import verdicts as V

    dev = {"pid": 6.9, "smc": 2.9, "smc_ndo": 1.8, "smc_ndo_nno": 1.83}
    ss = {"pid": 5.0, "smc": 0.40, "smc_ndo": 0.30, "smc_ndo_nno": 0.15}
    data = make_data({c: {**base(dev[c]), "deviation_mae_ss": (ss[c] / 1000, 0.05)} for c in dev})
    results = V.evaluate(data)
    lines = V.answer_lines(data, results)
    assert len(lines) == sum(len(c.overall) for c in results) == 5
    for c in results:
        for (scenario, reading), overall in c.overall.items():
            line = next(ln for ln in lines if ln.startswith(f"{c.title} [{scenario}, SMC-NDO-NNO]: "))
            assert line.split("]: ", 1)[1].startswith(f"{category(overall)} on the {V.metric_name(c.metrics[0])}")
    vs_smc = next(ln for ln in lines if ln.startswith("SMC-NDO-NNO: over 60 %"))
    assert vs_smc.endswith(": holds on the steady-state deviation MAE (ours); does not hold on the whole-run "
                           "deviation MAE (the paper's Table 4)")
    assert V.answer_lines(make_data({"smc_ndo_nno": base(1.8)}), V.evaluate(make_data({"smc_ndo_nno": base(1.8)}))) == []


def test_missing_controllers_are_listed_once():
    from ddmr_cli.report import verdicts as V

    data = make_data({"smc_ndo_nno": base(1.8)})
    results = V.evaluate(data)
    assert not any(c.checks for c in results)
    md = V.markdown(data, results)
    assert md.count("### Claims not checked") == 1
    assert md.count("no complete smc_ndo job in paper_1") == 1
    assert "no claim could be checked with these jobs" in md
    none = make_data({"smc": base(3.0)})
    md = V.markdown(none, V.evaluate(none))
    assert md.count("the sweep has no SMC-NDO-NNO job") == 1


def test_every_other_controller_is_a_baseline_judged_against_smc_ndo_nno():
    """Controllers outside the paper's claims (super-twisting, ADRC, ...) each get SMC-NDO-NNO compared with them
    on the deviation and on chattering, by the ranking pairs' rule: here STA tracks better (the claim that
    SMC-NDO-NNO is lower does not hold) but chatters more (holds), and ADRC ties on deviation."""
    from ddmr_cli.report import verdicts as V

    data = make_data({"smc_ndo": base(1.8), "smc_ndo_nno": base(1.83), "sta_ndo": base(1.5, chat=200.0),
                      "adrc": base(1.83)})
    assert V.baselines(data) == ["sta_ndo", "adrc"]  # in the report's controller order
    res = by_id(V.evaluate(data))
    key = ("paper_1", "smc_ndo_nno")
    assert category(res["sta_ndo:deviation"].overall[key]) == FAILS
    assert category(res["sta_ndo:chattering"].overall[key]) == HOLDS
    assert category(res["adrc:deviation"].overall[key]) == TIE
    chk = res["sta_ndo:deviation"].checks[0]
    assert (chk.a, chk.b, chk.metric) == ("sta_ndo", "smc_ndo_nno", "deviation_mae")
    assert "STA-NDO" in res["sta_ndo:deviation"].title and "not a paper claim" in res["sta_ndo:deviation"].title
    md = V.markdown(data, V.evaluate(data))
    assert "SMC-NDO-NNO: less chattering (total variation of u) than STA-NDO (not a paper claim)" in md
    assert "SMC-NDO-NNO: lower deviation MAE than ADRC" in md
    # what `ddmr report` prints first: the paper's claims one by one, the baselines counted on one line
    results = V.evaluate(data)
    lines = V.answer_lines(data, results)
    assert not any("not a paper claim" in line for line in lines)
    n_paper = sum(len(c.overall) for c in results if c.claim.kind != "baseline")
    assert len(lines) == n_paper + 1
    verdicts = sorted(category(v) for c in results if c.claim.kind == "baseline" for v in c.overall.values())
    assert verdicts == sorted([FAILS, HOLDS, TIE, TIE])  # STA: deviation, chattering; ADRC: both equal
    assert lines[-1] == ("SMC-NDO-NNO against 2 baseline controller(s), not the paper's claims: 4 comparisons, "
                         "1 holds, 1 does not hold, 2 tie (each in the report)")


def test_the_claims_on_both_plants_stand_side_by_side_and_the_changes_are_named():
    """Jobs on plant=mujoco (their saved config's plant.name) are scenario `paper_1@mujoco`; the report lists each
    claim's verdict on both plants and names the claims that change (docs/model.md §13)."""
    from ddmr_cli.report import verdicts as V
    from ddmr_cli.report.data import Job

    wheel = make_data({"pid": base(18.7), "smc": base(5.2), "smc_ndo": base(3.2),
                       "smc_ndo_nno": base(1.9, chat=1.0, hf=0.005, dest=6.6)})
    physics = make_data({"pid": base(18.7), "smc": base(5.2), "smc_ndo": base(3.2),
                         "smc_ndo_nno": base(3.21, chat=1.0, hf=0.005, dest=6.6)}, seed=1)
    for job in physics.jobs:  # the same controllers on the physics plant, in their own job dirs
        job.dir, job.config = Path(f"/nowhere/mujoco/{job.controller}-mujoco"), {"plant": {"name": "mujoco"}}
    physics.metrics["job"] = physics.metrics["job"] + "-mujoco"
    wheel.jobs += physics.jobs
    wheel.metrics = pd.concat([wheel.metrics, physics.metrics], ignore_index=True)
    assert [j.scenario for j in wheel.jobs] == ["paper_1"] * 4 + ["paper_1@mujoco"] * 4
    assert wheel.plant_pairs() == [("paper_1", "paper_1@mujoco", "mujoco")]
    res = by_id(V.evaluate(wheel))
    assert category(res["vs_smc_ndo"].overall[("paper_1", "smc_ndo_nno")]) == HOLDS
    assert category(res["vs_smc_ndo"].overall[("paper_1@mujoco", "smc_ndo_nno")]) == FAILS
    assert category(res["chattering"].overall[("paper_1@mujoco", "smc_ndo_nno")]) == HOLDS
    text = "\n".join(V.plant_comparison(wheel, list(res.values())))
    print(text)
    lines = text.splitlines()
    assert lines[0] == "### The claims on both plants"
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in lines if line.startswith("|")]
    row = next(c for c in cells if c[0] == res['vs_smc_ndo'].title)
    assert "mujoco" in row and row[-1] == "**changes**"
    chat = next(c for c in cells if c[0] == res['chattering'].title)
    assert chat[-1] == "same"
    assert f"{res['vs_smc_ndo'].title} (paper_1, SMC-NDO-NNO: holds -> does not hold on mujoco)" in text
    assert "### The claims on both plants" in V.markdown(wheel, list(res.values()))
    assert V.plant_comparison(make_data({"smc_ndo": base(3.2), "smc_ndo_nno": base(1.9)}), []) == []  # one plant
