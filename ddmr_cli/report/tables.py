"""The report's tables: pandas frames (written as CSV) and their markdown renderings."""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING, Iterable, Sequence

from ddmr_cli.engine.catalog import METRICS
from ddmr_cli.paper import PAPER_SCENARIO, TABLE4_COLUMNS
from ddmr_cli.paper import numbers as paper_numbers
from ddmr_cli.report.data import ReportData

if TYPE_CHECKING:
    import pandas as pd



_NUMERIC = re.compile(r"^\s*([-+−–×]|\d|\[|\(\d|\(-)")

# --- formatting ----------------------------------------------------------------------------------------------
def isnan(x) -> bool:
    try:
        return x is None or math.isnan(float(x))
    except (TypeError, ValueError):
        return False


def fmt(x, digits: int = 4) -> str:
    """A number with ``digits`` significant digits; an en dash for missing values."""
    if isnan(x):
        return "–"
    if isinstance(x, str):
        return x
    x = float(x)
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits or abs(x) < 1e-4:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def pct(x, digits: int = 1) -> str:
    return "–" if isnan(x) else f"{100 * float(x):.{digits}f} %"


def pm(mean, sd, sd_digits: int = 2, max_digits: int = 6) -> str:
    """``mean ± SD`` with no spurious precision: the SD to ``sd_digits`` significant digits and the mean to the
    same decimal place (at most ``max_digits`` significant digits); an SD below 1e-12 of |mean| (rounding noise of
    identical runs) is shown as 0. Numbers below 1e-4 or from 1e5 on share one power of ten:
    ``(8.0 ± 1.1)e-05``."""
    if isnan(mean):
        return "–"
    mean = float(mean)
    if isnan(sd):
        return fmt(mean)
    sd = abs(float(sd))
    if sd <= 1e-12 * abs(mean) or sd == 0.0:
        return f"{fmt(mean)} ± 0"
    exp = math.floor(math.log10(max(abs(mean), sd)))
    shared = exp < -4 or exp >= 5
    scale = 10.0 ** exp if shared else 1.0
    m, s = mean / scale, sd / scale
    place_sd = max(sd_digits - 1 - math.floor(math.log10(s)), 0)
    place_m = place_sd if m == 0 else max(min(place_sd, max_digits - 1 - math.floor(math.log10(abs(m)))), 0)
    body = f"{m:.{place_m}f} ± {s:.{place_sd}f}"
    return f"({body})e{exp:+03d}" if shared else body


def md_table(headers: Sequence[str], rows: Iterable[Sequence], align: str | None = None) -> str:
    """A GitHub-flavoured markdown table: pandas ``DataFrame.to_markdown`` (tabulate's ``pipe`` format), the cells
    as given (no number parsing), numbers right-aligned and text left-aligned unless ``align`` (``"lrr"``) says."""
    import pandas as pd

    def cell(v) -> str:
        return str(v).replace("|", "\\|").replace("\n", " ")

    rows = [[cell(v) for v in r] for r in rows]
    if align is None:  # numbers right-aligned, text left-aligned
        align = "".join("r" if rows and all(_NUMERIC.match(r[i]) for r in rows) else "l"
                        for i in range(len(headers)))
    frame = pd.DataFrame(rows, columns=range(len(headers))) if rows else pd.DataFrame(columns=range(len(headers)))
    return frame.to_markdown(index=False, headers=[cell(h) for h in headers], disable_numparse=True,
                             colalign=["right" if a == "r" else "left" for a in align])


def unit(metric: str) -> str:
    return METRICS[metric][0] if metric in METRICS else ""


# --- frames --------------------------------------------------------------------------------------------------
def _base_columns(data: ReportData, scenario: str, key: str) -> dict:
    job = data.job(scenario, key)
    return {"scenario": scenario, "controller": job.controller, "key": key, "label": job.label, "job": job.dir.name}


#: Suffix of the steady-state metric columns a job's metrics.csv may have (``deviation_mae_ss``, ...).
SS = "_ss"


def ss_metrics(data: ReportData) -> list[str]:
    """The steady-state columns (``<metric>_ss``) present in the jobs' metrics.csv, in the order of METRICS."""
    return [m + SS for m in METRICS if m + SS in data.metrics.columns]


def stats_frame(data: ReportData, metrics: Sequence[str] | None = None) -> "pd.DataFrame":
    """Per scenario and controller, over seeds: runs, diverged runs, mean and SD of each metric (non-diverged);
    by default every metric of METRICS and the steady-state columns the jobs have."""
    import pandas as pd

    metrics = list(METRICS) + ss_metrics(data) if metrics is None else metrics
    rows = []
    for scenario in data.scenarios:
        for key in data.keys(scenario):
            job = data.job(scenario, key)
            frame = data.metrics[data.metrics["job"] == job.dir.name]
            ok = frame[frame["status"] == "ok"]
            row = {**_base_columns(data, scenario, key), "runs": len(frame), "diverged": int((frame["status"] != "ok")
                                                                                               .sum())}
            for m in metrics:
                vals = ok[m].astype(float) if m in ok else pd.Series(dtype=float)
                row[f"{m}_mean"] = float(vals.mean()) if vals.notna().any() else math.nan
                row[f"{m}_sd"] = float(vals.std(ddof=1)) if vals.notna().sum() > 1 else math.nan
            rows.append(row)
    return pd.DataFrame(rows)


def paper_row_name(controller: str) -> str | None:
    return paper_numbers()["controller_names"].get(controller)


def table4_frame(stats: "pd.DataFrame") -> "pd.DataFrame":
    """Table 4 with the paper's numbers and the ratio ours/paper (scenario 1 rows only)."""
    import pandas as pd

    paper = paper_numbers()["table4"]["rows"]
    rows = []
    for _, r in stats.iterrows():
        row = {k: r[k] for k in ("scenario", "controller", "key", "label", "runs", "diverged")}
        name = paper_row_name(r["controller"]) if r["scenario"] == PAPER_SCENARIO else None
        row["paper_row"] = name or ""
        for metric, stat, col, _ in TABLE4_COLUMNS:
            ours = r[f"{metric}_{stat}"]
            row[col] = ours
            published = paper[name][col] if name in paper else math.nan
            row[f"paper_{col}"] = published
            row[f"ratio_{col}"] = ours / published if not isnan(published) and not isnan(ours) else math.nan
        for metric, stat, col, _ in TABLE4_COLUMNS:  # the steady-state block, when the jobs have it
            if f"{metric}{SS}_{stat}" in r:
                row[f"{col}{SS}"] = r[f"{metric}{SS}_{stat}"]
        rows.append(row)
    return pd.DataFrame(rows)


def segment_frame(data: ReportData, kind: str,
                  metrics: Sequence[str] = ("deviation_mae", "e_x_mae", "e_y_mae", "e_theta_mae", "chattering",
                                            "d_est_mae", "saturation_fraction")) -> "pd.DataFrame":
    """Per scenario, controller and ``kind`` segment (``zone`` or ``phase``): mean and SD over seeds."""
    import pandas as pd

    seg = data.segments
    seg = seg[seg["segment"].astype(str).str.startswith(f"{kind}:") & (seg["status"] == "ok")]
    rows = []
    for scenario in data.scenarios:
        for key in data.keys(scenario):
            job = data.job(scenario, key)
            frame = seg[seg["job"] == job.dir.name]
            for name in dict.fromkeys(frame["segment"]):  # in the job's order
                part = frame[frame["segment"] == name]
                row = {**_base_columns(data, scenario, key), kind: name.split(":", 1)[1], "runs": len(part)}
                for m in metrics:
                    vals = part[m].astype(float)
                    row[f"{m}_mean"] = float(vals.mean()) if vals.notna().any() else math.nan
                    row[f"{m}_sd"] = float(vals.std(ddof=1)) if vals.notna().sum() > 1 else math.nan
                rows.append(row)
    return pd.DataFrame(rows)


def select(stats: "pd.DataFrame", metrics: Sequence[str]) -> "pd.DataFrame":
    keep = ["scenario", "controller", "key", "label", "runs", "diverged"]
    return stats[keep + [f"{m}_{s}" for m in metrics for s in ("mean", "sd")]].copy()


# --- markdown ------------------------------------------------------------------------------------------------
def md_metric_table(frame: "pd.DataFrame", scenario: str, metrics: Sequence[tuple[str, str]],
                    extra: Sequence[tuple[str, callable]] = ()) -> str:
    """Rows: controllers of one scenario; cells: mean ± SD of each ``(metric, header)``."""
    part = frame[frame["scenario"] == scenario]
    headers = ["Controller"] + [h for _, h in metrics] + [h for h, _ in extra]
    rows = []
    for _, r in part.iterrows():
        rows.append([r["label"]] + [pm(r[f"{m}_mean"], r[f"{m}_sd"]) for m, _ in metrics]
                    + [f(r) for _, f in extra])
    return md_table(headers, rows)


def has_ss(t4: "pd.DataFrame") -> bool:
    return all(f"{col}{SS}" in t4 for _, _, col, _ in TABLE4_COLUMNS)


def md_table4(t4: "pd.DataFrame", scenario: str) -> str:
    """Table 4 of one scenario; with the steady-state columns, the whole-run block then the steady-state block."""
    part = t4[t4["scenario"] == scenario]
    with_paper = scenario == PAPER_SCENARIO
    ss = has_ss(t4)
    headers = ["Controller", "Runs", "Diverged"] + [("Whole run: " if ss else "") + h for *_, h in TABLE4_COLUMNS]
    if ss:
        headers += [f"Steady state: {h}" for *_, h in TABLE4_COLUMNS]
    rows = []
    for _, r in part.iterrows():
        cells = [r["label"], str(int(r["runs"])), str(int(r["diverged"]))]
        for _, _, col, _ in TABLE4_COLUMNS:
            ours = fmt(r[col])
            if with_paper and not isnan(r[f"paper_{col}"]):
                ours += f" (paper {fmt(r[f'paper_{col}'])}, ×{r[f'ratio_{col}']:.2f})"
            elif with_paper:
                ours += " (paper –)"
            cells.append(ours)
        if ss:
            cells += [fmt(r[f"{col}{SS}"]) for _, _, col, _ in TABLE4_COLUMNS]
        rows.append(cells)
    return md_table(headers, rows)


def md_segments(frame: "pd.DataFrame", scenario: str, kind: str, metric: str = "deviation_mae") -> str:
    """Rows: controllers; columns: segments; cells: mean ± SD of ``metric``."""
    part = frame[frame["scenario"] == scenario]
    names = list(dict.fromkeys(part[kind]))
    headers = ["Controller"] + [f"{n} ({unit(metric)})" for n in names]
    rows = []
    for label in dict.fromkeys(part["label"]):
        sub = part[part["label"] == label].set_index(kind)
        rows.append([label] + [pm(sub.loc[n, f"{metric}_mean"], sub.loc[n, f"{metric}_sd"]) if n in sub.index
                               else "–" for n in names])
    return md_table(headers, rows)
