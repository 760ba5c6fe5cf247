"""The report of a sensitivity study dir (``ddmr sensitivity``; docs/model.md §11): "Robustness of the paper's
claims" (per claim: the share of the box where it holds, the parameters it depends on most, Sobol indices), the
calibration against Table 4 (the Optuna search, :mod:`ddmr_cli.study.search`), the figures (OAT curves, Morris,
Sobol, the NN map, calibration residuals and search history) and the cost. Reads each stage's sweep dir,
``OUT/<stage>`` (``study.csv`` and the analyses of :mod:`ddmr_cli.study.analysis`); stages that did not run are left
out with a note.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddmr_cli.storage import io
from ddmr_cli.plots.common import OKABE_ITO, log_scale, pyplot, save
from ddmr_cli.report.tables import md_table
from ddmr_cli.study import analysis
from ddmr_cli.study.claims import CLAIM_IDS, bounds, claims, rule
from ddmr_cli.study.stages import STAGES

if TYPE_CHECKING:
    import pandas as pd

REPORT = "report.md"
FIGURES = "figures"
#: the two readings of the NN parameters (docs/model.md §6): learning rate, width
READINGS = {"table (faithful)": (50.0, 2.0), "text": (2.0, 50.0)}
COLOURS = [OKABE_ITO[c] for c in ("blue", "vermillion", "bluish_green", "reddish_purple", "orange")]


def _read_csv(path: Path) -> "pd.DataFrame | None":
    import pandas as pd

    return pd.read_csv(path) if path.is_file() and path.stat().st_size > 1 else None


def _study_config(stage_dir: Path):
    """The composed config of a stage (its first job's), for the box and the faithful reading."""
    from omegaconf import OmegaConf

    for cfg in sorted(stage_dir.glob("*/.hydra/config.yaml")):
        return OmegaConf.load(cfg)
    return None


def _box_and_faithful(out: Path):
    from ddmr_cli.study.setup import study_setup

    for stage in STAGES:
        cfg = _study_config(out / stage)
        if cfg is not None:
            box, _, faithful, _ = study_setup(cfg, out / stage)
            return box, faithful
    return None, None


def oat_figure(rows: "pd.DataFrame", box, faithful: dict, path: Path) -> Path:
    """Every claim statistic against each parameter (the others faithful), the claim's range shaded, the
    faithful value (vertical line) and both NN readings' statistics (horizontal lines) marked."""
    plt = pyplot()
    names = [p.name for p in box.parameters if p.name in set(rows["label"])]
    ids = list(CLAIM_IDS)
    fig, axes = plt.subplots(len(ids), len(names), figsize=(1.9 * len(names) + 1, 1.7 * len(ids) + 0.6),
                             squeeze=False, sharey="row")
    base = rows[rows["label"] == "faithful"]
    text = rows[rows["label"] == "text_reading"]
    for j, name in enumerate(names):
        p = box[name]
        part = rows[rows["label"] == name]
        xs = part[name].astype(str).tolist() if p.is_choice else part[name].astype(float).to_numpy()
        for i, (cid, claim) in enumerate(zip(ids, claims())):
            ax = axes[i][j]
            low, high = bounds(claim)
            ax.axhspan(max(low, -1e3), min(high, 1e3), color=OKABE_ITO["bluish_green"], alpha=0.15, lw=0)
            ax.plot(xs, part[cid].to_numpy(float), marker="o", ms=3, color=COLOURS[i])
            if not base.empty:
                ax.axhline(float(base[cid].iloc[0]), color="0.3", lw=0.8)
                if not p.is_choice:
                    ax.axvline(float(faithful[name]), color="0.3", lw=0.8, ls=":")
            if not text.empty:
                ax.axhline(float(text[cid].iloc[0]), color=OKABE_ITO["orange"], lw=0.9, ls="--")
            if name in ("nn_learning_rate", "nn_width"):
                k = 0 if name == "nn_learning_rate" else 1
                for style, (reading, values) in zip(("-", "--"), READINGS.items()):
                    ax.axvline(values[k], color=OKABE_ITO["orange"], lw=0.9, ls=style)
            if p.scale == "log" and not p.is_choice:
                log_scale(ax, "x")
            if i == len(ids) - 1:
                ax.set_xlabel(name, fontsize=7)
            if j == 0:
                ax.set_ylabel(f"{cid} [%]", fontsize=7)
            ax.tick_params(labelsize=6)
    fig.suptitle("One at a time: claim statistics (%) vs each parameter; green: the claim's range; grey: faithful "
                 "reading; orange dashed: the text's NN reading", fontsize=9)
    return save(fig, path)


def _cell_edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges of a log-spaced grid: geometric midpoints, the ends mirrored."""
    c = np.log(np.asarray(centres, float))
    mid = (c[1:] + c[:-1]) / 2
    return np.exp(np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]]))


def map_figure(rows: "pd.DataFrame", x: str, y: str, path: Path) -> Path:
    """NNO-vs-NDO improvement over learning rate x width (log axes), both readings marked, the region of
    "about 40 %" (30-50 %) outlined."""
    plt = pyplot()
    grid = rows.pivot_table(index=y, columns=x, values="vs_smc_ndo", aggfunc="mean")
    xs, ys, z = grid.columns.to_numpy(float), grid.index.to_numpy(float), grid.to_numpy(float)
    fig, ax = plt.subplots(figsize=(6.4, 5.0))
    lim = max(10.0, float(np.nanmax(np.abs(z)))) if np.isfinite(z).any() else 10.0
    if len(xs) > 1 and len(ys) > 1:  # cells centred on the grid points on the log axes
        mesh = ax.pcolormesh(_cell_edges(xs), _cell_edges(ys), z, shading="flat", cmap="RdBu", vmin=-lim, vmax=lim)
    else:
        mesh = ax.pcolormesh(xs, ys, z, shading="nearest", cmap="RdBu", vmin=-lim, vmax=lim)
    fig.colorbar(mesh, ax=ax, label="NNO-vs-NDO improvement of the steady-state deviation [%]")
    if len(xs) > 1 and len(ys) > 1 and np.isfinite(z).any():
        ex, ey = _cell_edges(xs), _cell_edges(ys)
        for i, j in zip(*np.nonzero((z >= 30) & (z <= 50))):  # outline every cell where "about 40 %" holds
            ax.add_patch(plt.Rectangle((ex[j], ey[i]), ex[j + 1] - ex[j], ey[i + 1] - ey[i], fill=False, ec="k",
                                       lw=1.8))
        ax.contour(xs, ys, z, levels=[0.0], colors="0.4", linewidths=0.8, linestyles=":")
    for marker, (name, (lr, width)) in zip(("*", "P"), READINGS.items()):
        ax.plot(lr, width, marker=marker, ms=13, color=OKABE_ITO["orange"], mec="k", ls="none",
                label=f"{name} reading (gamma={lr:g}, sigma={width:g})")
    log_scale(ax, "x")
    log_scale(ax)
    ax.set_xlabel(f"{x} (gamma) [1/s^2]")
    ax.set_ylabel(f"{y} (sigma) [rad/s]")
    share = float(np.mean((z >= 30) & (z <= 50))) if z.size else math.nan
    ax.set_title(f"NNO vs NDO, mean of both scenarios; black boxes: cells at 30-50 % ({100 * share:.0f} % of the "
                 f"grid); dotted: 0 %", fontsize=8)
    ax.legend(loc="lower left", fontsize=7)
    return save(fig, path)


def morris_figure(table: "pd.DataFrame", path: Path) -> Path:
    plt = pyplot()
    ids = list(table["claim"].unique())
    fig, axes = plt.subplots(1, len(ids), figsize=(3.3 * len(ids), 4.6), squeeze=False)
    for ax, cid, colour in zip(axes[0], ids, COLOURS):
        part = table[table["claim"] == cid].sort_values("mu_star")
        ax.barh(part["parameter"], part["mu_star"], xerr=part["mu_star_conf"], color=colour, alpha=0.8)
        ax.set_title(cid, fontsize=9)
        ax.set_xlabel("Morris mu* [% points]", fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle("Morris screening: mean absolute elementary effect mu* (95 % CI) per claim statistic", fontsize=9)
    return save(fig, path)


def sobol_figure(table: "pd.DataFrame", path: Path) -> Path:
    plt = pyplot()
    ids = list(table["claim"].unique())
    fig, axes = plt.subplots(1, len(ids), figsize=(3.3 * len(ids), 3.6), squeeze=False, sharey=True)
    for ax, cid in zip(axes[0], ids):
        part = table[table["claim"] == cid]
        pos = np.arange(len(part))
        ax.barh(pos - 0.2, part["S1"], 0.4, xerr=part["S1_conf"], color=OKABE_ITO["sky_blue"], label="S1")
        ax.barh(pos + 0.2, part["ST"], 0.4, xerr=part["ST_conf"], color=OKABE_ITO["vermillion"], label="ST")
        ax.set_yticks(pos, part["parameter"], fontsize=7)
        ax.set_title(cid, fontsize=9)
        ax.set_xlim(-0.1, 1.2)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Sobol indices: first order S1 and total ST (95 % bootstrap CI)", fontsize=9)
    return save(fig, path)


def calibration_figure(result: dict, path: Path) -> Path:
    """The residual per Table 4 number at the best reading and, for a search, its history: each trial's distance,
    the best so far, the warm-start trials marked."""
    plt = pyplot()
    numbers = result["numbers"]
    history = result.get("history") or []
    if history:
        fig, (ax, hx) = plt.subplots(1, 2, figsize=(12.5, 4.2), gridspec_kw={"width_ratios": [3, 2]})
        trials = [h["trial"] for h in history]
        hx.plot(trials, [h["objective"] for h in history], "o", ms=3, color=OKABE_ITO["sky_blue"], label="trial")
        hx.step(trials, [h["best"] for h in history], where="post", color=OKABE_ITO["vermillion"], label="best so far")
        warm = [w["trial"] for w in result.get("warm_start") or []]
        if warm:
            hx.plot(warm, [h["objective"] for h in history if h["trial"] in warm], "D", ms=6, mfc="none", mec="k",
                    ls="none", label="warm start (lhs best)")
        hx.set_xlabel("trial")
        hx.set_ylabel("distance to Table 4 (RMS log ratio, capped)")
        hx.set_title("Optuna TPE search", fontsize=9)
        hx.legend(fontsize=7)
    else:
        fig, ax = plt.subplots(figsize=(7.5, 4.2))
    labels = [n["number"].removeprefix("t4:") for n in numbers]
    values = [n["log_ratio"] for n in numbers]
    ax.barh(labels, values, color=[OKABE_ITO["blue"] if v >= 0 else OKABE_ITO["vermillion"] for v in values])
    ax.axvline(0, color="k", lw=0.8)
    ax.set_xlabel("log(ours / paper)")
    ax.tick_params(labelsize=7)
    ax.set_title(f"Best reading of the box: RMS log ratio {result['distance']:.2f} "
                 f"(x{math.exp(result['distance']):.2f})", fontsize=9)
    return save(fig, path)


def _fmt(v, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}g}"
    return str(v)


def claim_table(holds: "pd.DataFrame | None", morris: "pd.DataFrame | None", sobol: "pd.DataFrame | None",
                faithful_row: "pd.Series | None") -> list[str]:
    """Per claim: rule, faithful statistic, share of the box (95 % CI), top 3 parameters (Morris mu*), Sobol ST."""
    rows = []
    for claim in claims():
        cells = [claim.title, rule(claim)]
        cells.append(_fmt(float(faithful_row[claim.id])) + (" (holds)" if faithful_row[f"{claim.id}_holds"] == 1.0
                                                             else "") if faithful_row is not None else "-")
        if holds is not None:
            h = holds[holds["claim"] == claim.id].iloc[0]
            cells.append(f"{100 * h['share']:.0f} % ({100 * h['share_low']:.0f}-{100 * h['share_high']:.0f}; "
                         f"{int(h['holds'])}/{int(h['samples'])})")
        else:
            cells.append("-")
        if morris is not None:
            part = morris[morris["claim"] == claim.id].sort_values("mu_star", ascending=False).head(3)
            cells.append(", ".join(f"{r.parameter} ({r.mu_star:.3g})" for r in part.itertuples()))
        else:
            cells.append("-")
        if sobol is not None:
            part = sobol[sobol["claim"] == claim.id].sort_values("ST", ascending=False)
            cells.append(", ".join(f"{r.parameter} {_fmt(r.ST, 2)} ± {_fmt(r.ST_conf, 2)}" for r in part.itertuples()))
        else:
            cells.append("-")
        rows.append(cells)
    return [md_table(["Claim", "Holds when (both scenarios)", "Faithful reading", "Share of the box (95 % CI)",
                      "Top 3 parameters (Morris mu*, % points)", "Sobol total index ST ± 95 % CI"], rows)]


def write_report(out: Path) -> Path:
    """Write ``OUT/report.md`` and ``OUT/figures/*.png`` from the stage dirs of a study dir."""
    out = Path(out)
    fig_dir = out / FIGURES
    box, faithful = _box_and_faithful(out)
    stage = {s: _read_csv(out / s / "study.csv") for s in STAGES}
    morris = _read_csv(out / "morris" / analysis.MORRIS_CSV)
    sobol = _read_csv(out / "sobol" / analysis.SOBOL_CSV)
    holds = _read_csv(out / "lhs" / analysis.HOLDS_CSV)
    cal_path = out / "calibration" / analysis.CALIBRATION_JSON
    calibration = json.loads(cal_path.read_text()) if cal_path.is_file() else None
    summary_path = out / "study_summary.json"
    record = json.loads(summary_path.read_text()) if summary_path.is_file() else {"stages": {}}
    points = stage["points"]
    faithful_row = None
    for source in (points, stage["oat"]):
        if source is not None and (source["label"] == "faithful").any():
            faithful_row = source[source["label"] == "faithful"].iloc[0]
            break
    cfg = next((c for c in (_study_config(out / st) for st in stage) if c is not None), None)
    ci_sized = bool(cfg is not None and cfg.study.get("ci_sized", False))
    lines = ["# Robustness of the paper's claims", ""]
    if ci_sized:
        lines += ["> **A CI-sized study (`study=quick`): every stage runs, on a handful of samples, to check the "
                  "pipeline. Its numbers are not to be read.**", ""]
    lines += [
             "Every constant the paper leaves open (docs/model.md §11 gives the box and why) varied over a plausible "
             "box; each sample runs PID, SMC, SMC-NDO and SMC-NDO-NNO in both scenarios on the same paired seeds. "
             "Claim statistics are reductions in % of the second controller against the first, "
             "`100 (1 - sum b / sum a)` over paired seeds, on the steady-state metrics (`_ss`); a claim holds "
             "at a reading when its statistic is in range in both scenarios.", ""]
    seeds_note = []
    if faithful_row is not None:
        src = "points stage" if points is not None and faithful_row is not None and \
            (points["label"] == "faithful").any() else "OAT stage"
        seeds_note.append(f"The faithful reading's statistics come from the {src}.")
    lines += ["## Per claim", "", *claim_table(holds, morris, sobol, faithful_row), "",
              "Share of the box: over the lhs stage's Latin hypercube (uniform on the box's axes, log axes where "
              "marked), with a Wilson 95 % interval; a sample whose runs all diverged counts as not holding. "
              "Top 3: Morris mu* over the whole box. ST: Sobol total indices over the Sobol stage's parameters "
              f"(the others faithful). Morris and Sobol take each statistic clipped to ±{analysis.CLIP:g} % "
              "(a reduction is at most 100 %; below -100 % every claim is equally false, and a diverging NN's "
              "-10^4 % would carry the whole variance). " + " ".join(seeds_note), ""]
    for name, table in (("Morris", morris), ("Sobol", sobol)):
        if table is not None and "undefined" in table and table["undefined"].max() > 0:
            lines += [f"({int(table['undefined'].max())} {name} samples had no defined statistic (every seed "
                      f"diverged for both controllers, or a failed job): taken as -{analysis.CLIP:g} %, a claim that "
                      f"cannot hold there; nothing is imputed.)", ""]
    divergence = _read_csv(out / "lhs" / analysis.DIVERGENCE_CSV)
    if divergence is not None:
        lines += ["### Where each controller diverges", "",
                  "Divergence is an outcome, not a gap: a run that diverged counts as unboundedly worse than one "
                  "that did not, so a claim whose candidate diverges at a reading does not hold there (-100 % in "
                  "Morris and Sobol). The share of the box (lhs stage) where each controller diverges on at least "
                  "one seed, with a Wilson 95 % interval, and the share of its runs that diverged:", "",
                  md_table(["Controller", "Samples", "Diverging samples", "Share of the box [95 % CI]",
                            "Runs diverged"],
                           [[r.controller, r.samples, r.diverging_samples,
                             f"{100 * r.share:.1f} % [{100 * r.share_low:.1f}, {100 * r.share_high:.1f}]",
                             f"{100 * r.runs_diverged:.1f} %"] for r in divergence.itertuples()]), ""]
    for name, table in (("Morris", morris), ("Sobol", sobol)):
        if table is not None and "clipped" in table and table["clipped"].max() > 0:
            per = table.groupby("claim", sort=False)["clipped"].max()
            lines += [f"({name} samples clipped to ±{analysis.CLIP:g} %: "
                      + ", ".join(f"{c} {int(n)}" for c, n in per.items() if n) + ".)", ""]
    if sobol is not None:
        power = analysis.sobol_power(sobol)
        lines += ["### Sobol indices", "",
                  f"Power: the widest 95 % CI half-width of a total index above {analysis.SOBOL_RELEVANT:g} is "
                  f"{power['widest_half_width']:.3f} (target <= {power['target']:g}: "
                  + ("met)." if power["met"] else "**not met**: the indices are not decided; run the study with "
                     "more Sobol samples (study.sobol.base) before reading them).") , "", md_table(["Claim", "Parameter", "S1", "S1 95 % CI", "ST", "ST 95 % CI"],
                  [[r.claim, r.parameter, _fmt(r.S1, 2), f"± {_fmt(r.S1_conf, 2)}", _fmt(r.ST, 2),
                    f"± {_fmt(r.ST_conf, 2)}"] for r in sobol.itertuples()]), ""]
    figures = []
    if stage["oat"] is not None and box is not None:
        figures.append(("One-at-a-time curves", oat_figure(stage["oat"], box, faithful, fig_dir / "oat.png")))
    if morris is not None:
        figures.append(("Morris screening", morris_figure(morris, fig_dir / "morris.png")))
    if sobol is not None:
        figures.append(("Sobol indices", sobol_figure(sobol, fig_dir / "sobol.png")))
    if stage["map"] is not None:
        cfg = _study_config(out / "map")
        x, y = (str(cfg.study.map.x), str(cfg.study.map.y)) if cfg is not None else ("nn_learning_rate", "nn_width")
        figures.append(("NNO vs NDO over learning rate x width", map_figure(stage["map"], x, y,
                                                                            fig_dir / "nn_map.png")))
    lines += ["## Calibration: the reading nearest the paper's Table 4", ""]
    if calibration is not None and calibration.get("distance") is not None:
        figures.append(("Calibration residuals", calibration_figure(calibration, fig_dir / "calibration.png")))
        search_path = out / "calibration" / "search.json"
        search = json.loads(search_path.read_text()) if search_path.is_file() else None
        lines += calibration_lines(calibration, faithful, points, search, _study_config(out / "calibration"))
    else:
        lines += ["(the calibration stage did not run or had no usable sample)", ""]
    lines += ["## Figures", ""] + [f"### {title}\n\n![{title}]({p.relative_to(out)})\n" for title, p in figures]
    lines += ["## Cost", "", md_table(["Stage", "Jobs", "Samples", "Runs", "Of which reused", "Wall time (s)",
                                       "Time in jobs (s)"],
                                      [[s, r.get("jobs", "-"), r.get("samples", "-"), r.get("runs", "-"),
                                        r.get("reused", "-"), f"{r['wall_time']:.0f}", f"{r.get('job_time', 0):.0f}"]
                                       for s, r in record["stages"].items()]), ""]
    total = sum(r["wall_time"] for r in record["stages"].values())
    runs = sum(r.get("runs", 0) for r in record["stages"].values())
    reused = sum(r.get("reused", 0) for r in record["stages"].values())
    lines += [f"Total: {runs} runs (one run = one controller x scenario x seed over 15 s), of which {reused} took the "
              "numbers of an identical run of the same job (a sample that left that controller's config as an "
              f"earlier one did) instead of simulating it again; {total:.0f} s wall time.", ""]
    return io.write_text(out / REPORT, "\n".join(lines))


#: Table 4 counts as reproduced at a reading when every number is within this factor of the paper's
REPRODUCED_FACTOR = 1.5


def verdict(result: dict) -> str:
    """The plain conclusion of a calibration: reproduced (every number within :data:`REPRODUCED_FACTOR`) or not."""
    worst = max(result["numbers"], key=lambda n: abs(n["log_ratio"]) if math.isfinite(n["log_ratio"]) else math.inf)
    factor = math.exp(abs(worst["log_ratio"])) if math.isfinite(worst["log_ratio"]) else math.inf
    name = worst["number"].removeprefix("t4:")
    if factor <= REPRODUCED_FACTOR:
        return (f"**Conclusion: Table 4 is reproducible within the box**, every number within a factor "
                f"{factor:.2f} of the paper's (worst: {name}).")
    return (f"**Conclusion: Table 4 is not reproducible within the box**: at the nearest reading a typical number "
            f"is off by a factor {math.exp(result['distance']):.2f} and the worst ({name}) by {factor:.2f} "
            f"(reproduced would mean every number within {REPRODUCED_FACTOR:g}x).")


def calibration_lines(result: dict, faithful: dict | None, points: "pd.DataFrame | None", search: dict | None = None,
                      cfg=None) -> list[str]:
    reading = result["reading"]
    changed = {k: v for k, v in reading.items() if faithful is None or faithful.get(k) != v}
    d = result["distance"]
    seeds = f" at {int(cfg.run.n_runs)} seeds" if cfg is not None else ""
    if search is not None:
        sessions = search.get("sessions") or [{}]
        how = (f"Searched by ddmr's Optuna sweeper (TPE sampler seeded {sessions[0].get('sampler_seed')}, "
               f"{sessions[0].get('batch', '?')} trials at a time) over the box's {len(search.get('parameters', []))} "
               f"global parameters: {result['usable']} usable of {result['samples']} trials{seeds}, each a sample as "
               f"any other (4 controllers x 2 scenarios).")
        warm = result.get("warm_start") or []
        if warm:
            key = "objective" if "objective" in result and all("objective" in w for w in warm) else "distance"
            best_warm, best = min(w[key] for w in warm), result[key]
            first = "trial was the lhs stage's best reading" if len(warm) == 1 else \
                f"{len(warm)} trials were the lhs stage's best readings"
            how += (f" The first {first} (warm start); re-evaluated{seeds}, the best of them scores "
                    f"{best_warm:.3f} ({key}), so the search "
                    + (f"improved on the uniform sample by {best_warm - best:.3f}." if best_warm > best else
                       "found nothing better than the uniform sample."))
    else:
        how = f"Searched: {result['usable']} usable of {result['samples']} samples of the box{seeds}."
    logs = {n["number"]: n["log_ratio"] for n in result["numbers"]}
    means = [v for k, v in logs.items() if not k.endswith(":deviation_sd")]
    sds = [v for k, v in logs.items() if k.endswith(":deviation_sd")]
    rms = (lambda v: math.sqrt(sum(x * x for x in v) / len(v)) if v else math.nan)
    lines = [how + f" The search fits Table 4's 16 means (RMS of log(ours / paper)); its 4 across-seed SDs are "
             f"reported, not fitted (docs/model.md §11). Best: means **{rms(means):.3f}**, a typical mean off by a "
             f"factor **{math.exp(rms(means)):.2f}**; the SDs at that reading {rms(sds):.3f} (a factor "
             f"{math.exp(rms(sds)):.2f}); all 20 numbers {d:.3f} (median over the trials {result['distance_median']:.3f}).",
             "",
             "Best reading: " + ", ".join(f"`{k}={_fmt(v, 4)}`" for k, v in changed.items()), "",
             md_table(["Table 4 number", "Paper", "Ours (best reading)", "Ours / paper", "log ratio"],
                      [[n["number"].removeprefix("t4:"), _fmt(n["paper"], 3), _fmt(n["ours"], 3),
                        _fmt(n["ratio"], 3), _fmt(n["log_ratio"], 2)] for n in result["numbers"]]), "",
             verdict(result), "",
             md_table(["Claim at the best reading", "Statistic (%)", "Rule", "Holds"],
                      [[cid, _fmt(c["statistic"], 3), c["rule"], "yes" if c["holds"] else "no"]
                       for cid, c in result["claims"].items()]), ""]
    if points is not None:
        from ddmr_cli.study.search import objective_terms

        rows = []
        for r in points.to_dict("records"):
            terms = objective_terms(r)
            rows.append([r["label"], _fmt(terms["means"], 3), _fmt(terms["sds"], 3), _fmt(r["distance"], 3)] +
                        [f"{_fmt(r[cid], 3)}{' ✓' if r[cid + '_holds'] == 1.0 else ''}" for cid in CLAIM_IDS])
        first = int(points["seed_first"].iloc[0]) if "seed_first" in points else None
        held = f", seeds {first}-{first + 49}" if first is not None else ""
        lines += [f"At 50 held-out seeds (the points stage{held}, none of which the search saw; ✓ = holds):", "",
                  md_table(["Reading", "Means (RMS log)", "SDs (RMS log)", "All 20", *CLAIM_IDS], rows), ""]
    return lines


__all__ = ["write_report", "verdict", "oat_figure", "map_figure", "morris_figure", "sobol_figure", "calibration_figure",
           "claim_table"]
