"""The paper's claims are defined once (``ddmr_cli.paper.claims``, issue 27): their numbers are the paper's, and
the report's verdicts and the sensitivity study judge the same claims, on the same metric, with the same claimed
range."""

from __future__ import annotations

import math

import pytest

from ddmr_cli.engine.catalog import METRICS, STEADY
from ddmr_cli.paper import claims as C
from ddmr_cli.paper import numbers
from ddmr_cli.study import claims as study

from test_report_verdicts import make_data

PAPER = numbers()
CLAIMS = C.by_id()


def _table1(controller_row: str) -> float:
    return PAPER["table1"]["rows"][controller_row]["tracking_accuracy"]


def test_the_claimed_numbers_are_the_papers():
    """"approximately 40%" and "over 60%" are Table 1's tracking accuracies (3.5 -> 2.1 mm, 5.5 -> 2.1 mm); the
    estimation claim is 48.3152 -> 15.9876, "three times lower"; chattering's "near-complete elimination" is read
    as at least 90 %."""
    nno = _table1("SMC-NDO-NNO")
    assert CLAIMS["vs_smc_ndo"].value == pytest.approx(1 - nno / _table1("SMC-NDO"), abs=0.005)
    assert CLAIMS["vs_smc_ndo"].bounds() == pytest.approx((0.30, 0.50))
    assert CLAIMS["vs_smc"].value == 0.60 < 1 - nno / _table1("SMC")
    assert CLAIMS["vs_smc"].bounds() == (0.60, math.inf)
    est = PAPER["claims"]["estimation"]
    assert (est["ndo"], est["ndo_nno"]) == (48.3152, 15.9876)
    assert CLAIMS["estimation"].value == pytest.approx(1 - 15.9876 / 48.3152, rel=1e-12)
    assert 1 / (1 - CLAIMS["estimation"].value) == pytest.approx(3.0, abs=0.05)        # "three times lower"
    assert CLAIMS["chattering"].bounds() == (0.90, math.inf)
    for cid, words in [("vs_smc_ndo", "approximately 40%"), ("vs_smc", "over 60%"),
                       ("chattering", "Near-complete elimination"), ("estimation", "three times lower")]:
        assert words in CLAIMS[cid].text, cid
    assert "Table 1" in CLAIMS["vs_smc_ndo"].source and "Table 1" in CLAIMS["vs_smc"].source
    # the ranking is Table 4's order of the deviation means, largest first
    names = PAPER["controller_names"]
    means = [PAPER["table4"]["rows"][names[c]]["deviation_mean"] for c in CLAIMS["ranking"].controllers]
    assert means == sorted(means, reverse=True)


def test_every_claim_names_engine_metrics_and_a_kind():
    for claim in C.claims():
        assert claim.kind in C.KINDS
        for m in claim.metrics:
            assert (m[:-len(STEADY)] if m.endswith(STEADY) else m) in METRICS, (claim.id, m)
    assert CLAIMS["chattering"].metrics[0] == "hf_fraction"      # the switching measure (docs/model.md §7)
    with pytest.raises(ValueError):
        C.Claim("x", "", "", "", "maybe", ("a", "b"), ("deviation_mae",))


def _base(dev_mm: float, hf: float = 0.2, dest: float = 20.0) -> dict:
    return {"deviation_mae": (1.4 * dev_mm / 1000, 0.05), "deviation_mae_ss": (dev_mm / 1000, 0.05),
            "chattering": (40.0, 0.05), "hf_fraction": (hf, 0.05), "d_est_mae": (dest, 0.05)}


def test_verdicts_and_study_judge_the_same_claims_on_the_same_metric():
    from ddmr_cli.report import verdicts as V

    data = make_data({"pid": _base(18.7), "smc": _base(5.2), "smc_ndo": _base(3.2),
                      "smc_ndo_nno": _base(1.9, hf=0.005, dest=6.6)})
    results = {c.id: c for c in V.evaluate(data)}
    assert [c.id for c in V.claims(data)] == [c.id for c in C.claims()] == list(study.CLAIM_IDS)
    runs = {}
    for job in data.jobs:
        frame = data.metrics[data.metrics["job"] == job.dir.name].sort_values("seed")
        runs[(job.controller, "paper_1")] = {m: frame[m].to_numpy(float) for m in _base(1.0)}
    stats = study.statistics(runs, ["paper_1"])
    for claim in C.claims():
        assert results[claim.id].metrics[0] == study.metric(claim) == claim.metrics[0]
        if claim.kind == C.RANKING:
            continue
        check = next(k for k in results[claim.id].checks if k.metric == claim.metrics[0])
        # the report's paired reduction and the study's statistic are the same number
        assert 100 * check.result.reduction == pytest.approx(stats[f"{claim.id}@paper_1"], rel=1e-9)
        assert study.bounds(claim) == pytest.approx(claim.bounds(100.0))


def test_every_claim_column_of_the_study_csv_is_a_claim():
    runs = {(c, s): {m: [1.0, 2.0] for m in study.METRICS} for c in study.CONTROLLERS for s in ("paper_1", "paper_2")}
    columns = study.statistics(runs, ["paper_1", "paper_2"])
    ids = {k.split("@")[0].removesuffix("_holds") for k in columns if not k.startswith("diverged:")}
    assert ids == set(CLAIMS)
