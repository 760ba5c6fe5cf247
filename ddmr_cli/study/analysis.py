"""The analyses of a study stage's rows (docs/model.md §11): Morris elementary effects, Sobol indices (SALib),
the share of the box where each claim holds, the calibration's best reading.

Each writes CSV/JSON into the stage's sweep dir (:func:`analyse`, called by the sweep callback at the end of the
multirun) and the report (:mod:`ddmr_cli.report.sensitivity`) reads them back.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ddmr_cli.storage import io
from ddmr_cli.study import claims as claim_stats
from ddmr_cli.study.design import Design, problem

if TYPE_CHECKING:
    import pandas as pd

MORRIS_CSV = "morris.csv"
DIVERGENCE_CSV = "divergence.csv"
SOBOL_CSV = "sobol.csv"
HOLDS_CSV = "holds.csv"
CALIBRATION_JSON = "calibration.json"


#: bound [%] of a claim statistic in the global analyses (docs/model.md §11): a reduction is at most 100 % (the
#: candidate at zero); below -100 % (the candidate more than twice as bad) every claim is equally false, and an NN
#: that blows up (-10^4 %) would otherwise carry the whole variance Morris and Sobol apportion
CLIP = 100.0


#: the widest 95 % CI half-width the Sobol stage aims at for a total index above :data:`SOBOL_RELEVANT`
SOBOL_TARGET_HALF_WIDTH = 0.1
SOBOL_RELEVANT = 0.1


def outputs(rows: "pd.DataFrame", claim: str) -> tuple[np.ndarray, int, int]:
    """A claim statistic per sample as the global analyses take it, bounded to +-:data:`CLIP`: a diverged
    candidate's -inf (:func:`ddmr_cli.study.claims.reduction`) is -100 %, nothing is imputed; a sample with no
    defined statistic (every seed diverged for both controllers, or a failed job) is a claim that cannot hold
    there, also -100 %. Returns the values, how many samples were undefined and how many were bounded."""
    y = rows[claim].to_numpy(float) if claim in rows else np.full(len(rows), np.nan)
    undefined = np.isnan(y)
    y = np.where(undefined, -CLIP, y)
    clipped = int(np.sum(np.abs(y[~undefined]) > CLIP))
    return np.clip(y, -CLIP, CLIP), int(undefined.sum()), clipped


def divergence(rows: "pd.DataFrame") -> "pd.DataFrame":
    """Per controller: the share of samples (readings of the box) on which it diverged on at least one seed, with
    a 95 % Wilson interval, and the mean share of its runs that diverged."""
    import pandas as pd

    out = []
    for controller in claim_stats.CONTROLLERS:
        col = f"diverged:{controller}"
        share = rows[col].to_numpy(float) if col in rows else np.full(len(rows), np.nan)
        known = np.isfinite(share)
        k, n = int(np.sum(share[known] > 0)), int(known.sum())
        low, high = wilson(k, n)
        out.append({"controller": controller, "samples": n, "diverging_samples": k,
                    "share": k / n if n else math.nan, "share_low": low, "share_high": high,
                    "runs_diverged": float(share[known].mean()) if n else math.nan})
    return pd.DataFrame(out)


def sobol_power(table: "pd.DataFrame") -> dict:
    """Whether the Sobol stage decides: the widest 95 % CI half-width among total indices above
    :data:`SOBOL_RELEVANT`, against :data:`SOBOL_TARGET_HALF_WIDTH`."""
    relevant = table[table["ST"] > SOBOL_RELEVANT]
    widest = float(relevant["ST_conf"].max()) if len(relevant) else float(table["ST_conf"].max())
    return {"relevant": int(len(relevant)), "widest_half_width": widest, "target": SOBOL_TARGET_HALF_WIDTH,
            "met": bool(widest <= SOBOL_TARGET_HALF_WIDTH)}


def _aligned(rows: "pd.DataFrame", design: Design) -> "pd.DataFrame":
    """The rows in design order, one per sample (the analyses need the whole design)."""
    rows = rows.drop_duplicates("sample", keep="last").set_index("sample")
    missing = sorted(set(range(len(design.samples))) - set(rows.index))
    if missing:
        raise ValueError(f"{len(missing)} samples of the {design.stage} design have no row (first: {missing[0]})")
    return rows.loc[list(range(len(design.samples)))].reset_index()


def bootstrap_seed(seed: int) -> int:
    """The seed of SALib's bootstrap confidence intervals for a study's ``sampler_seed``: never 0, because
    ``SALib.analyze.sobol.analyze`` seeds only when ``if seed:`` holds, so 0 (our default) left the intervals
    random, different at every analysis of the same rows."""
    return int(np.random.SeedSequence(int(seed)).generate_state(1)[0]) or 1


def morris(rows: "pd.DataFrame", design: Design, levels: int, seed: int) -> "pd.DataFrame":
    """Per claim and parameter: mu, mu*, its 95 % CI half-width, sigma (SALib ``morris.analyze``) of the clipped
    statistic (:func:`outputs`)."""
    import pandas as pd
    from SALib.analyze import morris as morris_analyze

    rows = _aligned(rows, design)
    out = []
    for claim in claim_stats.CLAIM_IDS:
        y, undefined, clipped = outputs(rows, claim)
        res = morris_analyze.analyze(problem(design.names), design.unit, y, num_levels=levels,
                                     seed=bootstrap_seed(seed), print_to_console=False)
        for i, name in enumerate(design.names):
            out.append({"claim": claim, "parameter": name, "mu": res["mu"][i], "mu_star": res["mu_star"][i],
                        "mu_star_conf": res["mu_star_conf"][i], "sigma": res["sigma"][i], "undefined": undefined,
                        "clipped": clipped})
    return pd.DataFrame(out)


def sobol(rows: "pd.DataFrame", design: Design, resamples: int, seed: int) -> "pd.DataFrame":
    """Per claim and parameter: first-order S1 and total ST with 95 % CI half-widths (SALib ``sobol.analyze``,
    bootstrap) of the clipped statistic (:func:`outputs`)."""
    import pandas as pd
    from SALib.analyze import sobol as sobol_analyze

    rows = _aligned(rows, design)
    out = []
    for claim in claim_stats.CLAIM_IDS:
        y, undefined, clipped = outputs(rows, claim)
        if np.ptp(y) <= 0:  # a constant statistic: no variance to apportion
            res = {k: np.full(len(design.names), np.nan) for k in ("S1", "S1_conf", "ST", "ST_conf")}
        else:
            res = sobol_analyze.analyze(problem(design.names), y, calc_second_order=False, num_resamples=resamples,
                                        conf_level=0.95, seed=bootstrap_seed(seed), print_to_console=False)
        for i, name in enumerate(design.names):
            out.append({"claim": claim, "parameter": name, "S1": res["S1"][i], "S1_conf": res["S1_conf"][i],
                        "ST": res["ST"][i], "ST_conf": res["ST_conf"][i], "undefined": undefined,
                        "clipped": clipped})
    return pd.DataFrame(out)


def wilson(successes: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a proportion at confidence ``level``: scipy's
    ``binomtest(k, n).proportion_ci(method="wilson")`` (the exact normal quantile, 1.959964 for 95 %); NaN for
    ``n == 0``, which scipy refuses."""
    from scipy.stats import binomtest

    if n == 0:
        return math.nan, math.nan
    ci = binomtest(int(successes), int(n)).proportion_ci(confidence_level=level, method="wilson")
    return float(ci.low), float(ci.high)


def holds(rows: "pd.DataFrame") -> "pd.DataFrame":
    """Per claim: the share of samples where it holds (failed samples count as not holding), with a 95 %
    Wilson interval, and the median of its statistic. On the ``lhs`` stage's Latin hypercube this is the share of
    the box."""
    import pandas as pd

    out = []
    for claim in claim_stats.claims():
        flag = rows[f"{claim.id}_holds"].to_numpy(float) if f"{claim.id}_holds" in rows else np.zeros(len(rows))
        k, n = int(np.nansum(flag)), len(rows)
        low, high = wilson(k, n)
        out.append({"claim": claim.id, "text": claim.title, "rule": claim_stats.rule(claim), "samples": n, "holds": k,
                    "share": k / n if n else math.nan, "share_low": low, "share_high": high,
                    "unusable": int(np.sum(~np.isfinite(flag))),
                    "median": float(np.nanmedian(rows[claim.id])) if claim.id in rows and n else math.nan})
    return pd.DataFrame(out)


def calibration(rows: "pd.DataFrame", names: Sequence[str]) -> dict:
    """The sample nearest the paper's Table 4: its reading, distance, residual per number, claims; for the
    search's trials (an ``objective`` column) also the best so far per trial and the warm-start trials."""
    ok = rows[np.isfinite(rows["distance"].to_numpy(float))] if "distance" in rows else rows.iloc[:0]
    if ok.empty:
        return {"samples": len(rows), "usable": 0, "distance": None}
    best = ok.loc[ok["objective" if "objective" in ok else "distance"].idxmin()]  # the search's own criterion
    ours = {k: float(best[k]) for k in claim_stats.paper_table4()}
    residuals = claim_stats.log_residuals(ours)
    paper = claim_stats.paper_table4()
    search = {}
    if "objective" in rows:  # the Optuna search: its best so far per trial, and its warm start
        objective = rows["objective"].to_numpy(float)
        search["history"] = [{"trial": int(t), "objective": float(v), "best": float(b)} for t, v, b in
                             zip(rows["sample"], objective, np.minimum.accumulate(objective))]
        warm = ok[ok["warm_start"] == 1] if "warm_start" in ok else ok.iloc[:0]
        search["warm_start"] = [{"trial": int(r["sample"]), "distance": float(r["distance"]),
                                 "objective": float(r["objective"])} for _, r in warm.iterrows()]
    return {
        "samples": len(rows), "usable": len(ok), "distance": float(best["distance"]),
        **({"objective": float(best["objective"])} if "objective" in best else {}),
        "distance_median": float(ok["distance"].median()),
        "sample": int(best["sample"]), **search,
        "reading": {n: _scalar(best[n]) for n in names},
        "numbers": [{"number": k, "paper": paper[k], "ours": ours[k], "log_ratio": residuals[k],
                     "ratio": math.exp(residuals[k]) if np.isfinite(residuals[k]) else math.nan} for k in paper],
        "claims": {c.id: {"statistic": float(best[c.id]), "holds": bool(best[f"{c.id}_holds"] == 1.0),
                          "rule": claim_stats.rule(c)} for c in claim_stats.claims()},
    }


def _scalar(value):
    if isinstance(value, (np.floating, float)):
        return float(value)
    if isinstance(value, (np.integer, int)):
        return int(value)
    return str(value)


def analyse(sweep_dir: Path, config, rows: "pd.DataFrame") -> list[str]:
    """Write the stage's analysis into ``sweep_dir``; returns summary lines for the terminal."""
    from ddmr_cli.study.setup import study_setup

    box, _, _, design = study_setup(config, sweep_dir)
    study = config.study
    lines = []
    if design.stage == "morris":
        table = morris(rows, design, int(study.morris.levels), int(study.sampler_seed))
        io.write_csv(sweep_dir / MORRIS_CSV, table)
        for claim, part in table.groupby("claim", sort=False):
            top = part.sort_values("mu_star", ascending=False).head(3)
            lines.append(f"morris {claim}: " + ", ".join(f"{r.parameter} {r.mu_star:.3g}" for r in top.itertuples()))
    elif design.stage == "sobol":
        table = sobol(rows, design, int(study.sobol.resamples), int(study.sampler_seed))
        io.write_csv(sweep_dir / SOBOL_CSV, table)
        for claim, part in table.groupby("claim", sort=False):
            lines.append(f"sobol {claim} ST: " + ", ".join(f"{r.parameter} {r.ST:.2f} +- {r.ST_conf:.2f}"
                                                            for r in part.itertuples()))
        power = sobol_power(table)
        lines.append(f"sobol CI: widest 95 % half-width of a total index above {SOBOL_RELEVANT:g}: "
                     f"{power['widest_half_width']:.3f} (target <= {power['target']:g}: "
                     f"{'met' if power['met'] else 'NOT met, more samples needed'})")
    if design.stage in ("lhs", "morris", "sobol"):
        table = holds(rows)
        io.write_csv(sweep_dir / HOLDS_CSV, table)
        lines += [f"{r.claim} holds in {r.holds}/{r.samples} samples" for r in table.itertuples()]
        table = divergence(rows)
        io.write_csv(sweep_dir / DIVERGENCE_CSV, table)
        lines += [f"{r.controller} diverges in {r.diverging_samples}/{r.samples} samples" for r in table.itertuples()]
    if design.stage == "calibration":
        result = calibration(rows, box.global_names())
        io.write_text(sweep_dir / CALIBRATION_JSON, json.dumps(result, indent=2))
        if result["distance"] is not None:
            lines.append(f"calibration: best distance {result['distance']:.3f} (RMS log ratio) at trial "
                         f"{result['sample']}")
    return lines


__all__ = ["bootstrap_seed", "morris", "sobol", "sobol_power", "holds", "divergence", "calibration", "analyse",
           "outputs", "wilson", "DIVERGENCE_CSV", "MORRIS_CSV",
           "SOBOL_CSV", "HOLDS_CSV", "CALIBRATION_JSON", "CLIP"]
