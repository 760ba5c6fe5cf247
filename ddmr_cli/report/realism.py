"""The report's realism section (docs/model.md §10): which controller degrades first under sensing, delay and rate.

Every job is placed on one effect axis by its config (:func:`classify`): the ideal loop, one effect alone
(encoder resolution, wheel-speed noise, delay, control rate) at one level, or a combination (the realistic
settings). For each scenario: the steady-state deviation and chattering against each effect (mean and 5-95 %
band over the seeds, one line per controller), the level at which each controller first loses to PID (paired
by seed: the bootstrap 95 % CI of the difference above 0 and Wilcoxon p < 0.05, or more diverged runs), the
realism table (ideal against each combined setting) and the NN's share of its estimate as the noise grows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddmr_cli.report import signals as S
from ddmr_cli.report import tables as T
from ddmr_cli.report.data import Job, ReportData
from ddmr_cli.report.stats import paired

#: effect axes: key -> (title, unit label, severity order: True when a larger level is worse)
EFFECTS = {
    "counts_per_rev": ("Encoder resolution", "counts/rev", False),
    "speed_std": ("Wheel-speed noise", "std (rad/s)", True),
    "delay": ("Delay", "ms", True),
    "rate": ("Control rate", "Hz", False),
}
#: the metrics drawn against each effect
METRICS = (("deviation_mae_ss", "steady-state deviation MAE (m)"), ("chattering_ss", "steady-state chattering (V/s)"))
REFERENCE = "pid"


@dataclass(frozen=True)
class Placement:
    """Where a job sits: ``effect`` (a key of :data:`EFFECTS`, ``ideal`` or ``combined``), its ``level`` and a label."""

    effect: str
    level: float
    label: str


def classify(job: Job) -> Placement:
    """The effect axis and level of a job from its config (module docstring)."""
    dt = float(job.setting("simulation.dt", 1e-3))
    kind = job.setting("sensor.kind", "ideal")
    counts = int(job.setting("sensor.counts_per_rev", 0) or 0)
    speed_std = float(job.setting("sensor.speed_std", 0.0) or 0.0)
    pose_noise = float(job.setting("sensor.position_std", 0.0) or 0.0) + float(job.setting("sensor.heading_std", 0.0) or 0.0)
    delay = float(job.setting("actuator.delay", 0.0) or 0.0)
    lag = float(job.setting("actuator.lag", 0.0) or 0.0)
    bits = int(job.setting("actuator.pwm_bits", 0) or 0)
    rate = job.setting("control.rate", None)
    rate = None if rate is None or float(rate) >= (1.0 - 1e-9) / dt else float(rate)
    parts = []
    if kind == "encoder":
        parts.append(("counts_per_rev", counts, f"{counts} counts"))
    elif kind == "noisy":
        parts.append(("speed_std", speed_std, f"noise {speed_std:g} rad/s" + (" + pose noise" if pose_noise > 0 else "")))
    if delay > 0:
        parts.append(("delay", 1e3 * delay, f"{1e3 * delay:g} ms delay"))
    if rate is not None:
        parts.append(("rate", rate, f"{rate:.0f} Hz"))
    if lag > 0:
        parts.append(("lag", 1e3 * lag, f"{1e3 * lag:g} ms lag"))
    if bits > 0:
        parts.append(("pwm_bits", bits, f"{bits}-bit PWM"))
    if not parts:
        return Placement("ideal", math.nan, "ideal")
    simple = (kind != "encoder" or (job.setting("sensor.pose") == "odometry" and speed_std <= 0
                                    and not float(job.setting("sensor.speed_filter", 0.0) or 0.0) > 0))
    simple = simple and (kind != "noisy" or pose_noise <= 0)
    if len(parts) == 1 and parts[0][0] in EFFECTS and simple:
        return Placement(parts[0][0], float(parts[0][1]), parts[0][2])
    return Placement("combined", math.nan, ", ".join(p[2] for p in parts))


def present(data: ReportData) -> bool:
    """Whether the report has realism jobs (some job not ideal) and an ideal one to compare with."""
    kinds = {classify(j).effect for j in data.jobs}
    return "ideal" in kinds and len(kinds) > 1


def representative(jobs: list[Job]) -> Job | None:
    """Of one controller's jobs on one scenario, the one that stands for it where one job is drawn or compared:
    the job without a swept setting (its key is the controller), else the only one at the ideal loop
    (:func:`classify`); None when there is no such job."""
    plain = [j for j in jobs if j.key == j.controller]
    if len(plain) == 1:
        return plain[0]
    ideal = [j for j in jobs if classify(j).effect == "ideal"]
    return ideal[0] if len(ideal) == 1 else None


def _per_seed(data: ReportData, job: Job, metric: str):
    frame = data.metrics[data.metrics["job"] == job.dir.name]
    return frame.set_index("seed")[metric].astype(float)


def _diverged(data: ReportData, job: Job) -> int:
    return int((job.summary.get("statistics") or {}).get("diverged", 0) or 0)


def frame(data: ReportData):
    """One row per job: scenario, controller, effect, level, label and mean, SD, 5/95 % of each metric."""
    import pandas as pd

    rows = []
    for job in data.jobs:
        place = classify(job)
        row = {"scenario": job.scenario, "controller": job.controller, "effect": place.effect, "level": place.level,
               "setting": place.label, "job": job.dir.name, "diverged": _diverged(data, job)}
        for metric, _ in METRICS:
            v = _per_seed(data, job, metric).to_numpy()
            v = v[np.isfinite(v)]
            row.update({f"{metric}_mean": v.mean() if v.size else math.nan, f"{metric}_sd": v.std(ddof=1) if v.size > 1
                        else math.nan, f"{metric}_p05": np.percentile(v, 5) if v.size else math.nan,
                        f"{metric}_p95": np.percentile(v, 95) if v.size else math.nan, "seeds": int(v.size)})
        rows.append(row)
    return pd.DataFrame(rows)


def _axis(jobs: list[tuple[Job, Placement]], effect: str) -> list[tuple[Job, Placement]]:
    """The ideal job, then this effect's jobs from the mildest level to the harshest."""
    worse_up = EFFECTS[effect][2]
    on = sorted((jp for jp in jobs if jp[1].effect == effect), key=lambda jp: jp[1].level, reverse=not worse_up)
    return [jp for jp in jobs if jp[1].effect == "ideal"] + on


def _level_text(effect: str, place: Placement) -> str:
    if place.effect == "ideal":
        return "ideal"
    return f"{place.level:g}" if effect != "rate" else f"{place.level:.0f}"


def loses_to_pid(data: ReportData, scenario: str, metric: str = "deviation_mae_ss") -> list[dict]:
    """Per controller and effect: the mildest level at which it first loses to PID on ``metric`` (module
    docstring), or None when it never does on the grid."""
    jobs = [(j, classify(j)) for j in data.jobs if j.scenario == scenario]
    out = []
    for controller in sorted({j.controller for j, _ in jobs} - {REFERENCE}, key=_rank):
        row = {"scenario": scenario, "controller": controller}
        for effect in EFFECTS:
            row[effect] = None
            for job, place in _axis([jp for jp in jobs if jp[0].controller == controller], effect):
                ref = next((j for j, p in jobs if j.controller == REFERENCE and p == place), None)
                if ref is None:
                    continue
                pr = paired(_per_seed(data, ref, metric), _per_seed(data, job, metric))
                if _diverged(data, job) > _diverged(data, ref) or (pr is not None and pr.b_higher):
                    row[effect] = _level_text(effect, place)
                    break
        out.append(row)
    return out


def _rank(controller: str):
    from ddmr_cli.report.data import controller_rank

    return controller_rank(controller)


def realism_table(data: ReportData, scenario: str, metric: str = "deviation_mae_ss") -> list[dict]:
    """Each controller's ``metric`` at the ideal loop and at each combined setting (mean ± SD over seeds, and the
    ratio to ideal)."""
    jobs = [(j, classify(j)) for j in data.jobs if j.scenario == scenario]
    settings = sorted({p.label for _, p in jobs if p.effect == "combined"})
    rows = []
    for controller in sorted({j.controller for j, _ in jobs}, key=_rank):
        mine = {p.label if p.effect == "combined" else p.effect: j for j, p in jobs if j.controller == controller}
        ideal = mine.get("ideal")
        if ideal is None:
            continue
        base = _per_seed(data, ideal, metric)
        row = {"scenario": scenario, "controller": controller, "ideal_mean": base.mean(), "ideal_sd": base.std()}
        for label in settings:
            if label in mine:
                v = _per_seed(data, mine[label], metric)
                row[f"{label}|mean"], row[f"{label}|sd"] = v.mean(), v.std()
                row[f"{label}|diverged"] = _diverged(data, mine[label])
        rows.append(row)
    return rows


def nn_shares(data: ReportData, scenario: str) -> list[dict]:
    """The NN's share of the estimate (kept series) of each NN-observer job on the noise axis, ideal first."""
    rows = []
    jobs = [(j, classify(j)) for j in data.jobs if j.scenario == scenario]
    for job, place in _axis(jobs, "speed_std"):
        runs = list(data.all_series(job).values())
        if not runs or not any(S.has_nn(r) for r in runs):
            continue
        share = S.nn_share(runs, S.nominal_input_inverse(job.config.get("robot")))
        rows.append({"scenario": scenario, "controller": job.controller,
                     "speed_std": 0.0 if place.effect == "ideal" else place.level, "series_seeds": len(runs), **share})
    return rows


def figure(data: ReportData, scenario: str, out_dir: Path, styles) -> Path | None:
    """Steady-state deviation and chattering against each effect, one line per controller (mean and 5-95 % band
    over the seeds), and the NN's share of the estimate against the noise."""
    from ddmr_cli.plots.common import label_of, pyplot, save

    plt = pyplot()

    jobs = [(j, classify(j)) for j in data.jobs if j.scenario == scenario]
    effects = [e for e in EFFECTS if any(p.effect == e for _, p in jobs)]
    if not effects:
        return None
    shares = nn_shares(data, scenario)
    ncols = len(effects) + (1 if shares else 0)
    # constrained layout: the legend outside on the right ("outside" placement), all inside the figure
    fig, axes = plt.subplots(len(METRICS), ncols, figsize=(3.6 * ncols + 1.6, 3.0 * len(METRICS) + 0.4),
                             squeeze=False, layout="constrained")
    controllers = sorted({j.controller for j, _ in jobs}, key=_rank)
    for c_i, effect in enumerate(effects):
        for r_i, (metric, ylabel) in enumerate(METRICS):
            ax = axes[r_i, c_i]
            for controller in controllers:
                axis = _axis([jp for jp in jobs if jp[0].controller == controller], effect)
                if not axis:
                    continue
                xs = np.arange(len(axis))
                values = [_per_seed(data, j, metric).to_numpy() for j, _ in axis]
                mean = np.array([np.nanmean(v) if np.isfinite(v).any() else np.nan for v in values])
                lo = np.array([np.nanpercentile(v, 5) if np.isfinite(v).any() else np.nan for v in values])
                hi = np.array([np.nanpercentile(v, 95) if np.isfinite(v).any() else np.nan for v in values])
                style = styles[controller]
                ax.plot(xs, mean, color=style.color, linestyle=style.dash, marker=style.marker or "o", ms=3,
                        label=label_of(controller))
                ax.fill_between(xs, lo, hi, color=style.color, alpha=0.15, lw=0)
                ax.set_xticks(xs, [_level_text(effect, p) for _, p in axis], fontsize=7)
            _y_scale(ax)
            ax.grid(alpha=0.3, which="both", lw=0.4)
            if r_i == 0:
                ax.set_title(f"{EFFECTS[effect][0]}", fontsize=9)
            if r_i == len(METRICS) - 1:
                ax.set_xlabel(EFFECTS[effect][1], fontsize=8)
            if c_i == 0:
                ax.set_ylabel(ylabel, fontsize=8)
    if shares:
        ax = axes[0, -1]
        for controller in sorted({r["controller"] for r in shares}, key=_rank):
            pts = [r for r in shares if r["controller"] == controller]
            style = styles[controller]
            ax.plot([_level_text("speed_std", Placement("x", r["speed_std"], "")) if r["speed_std"] > 0 else "ideal"
                     for r in pts], [100 * r["share_of_estimate"] for r in pts], color=style.color,
                    linestyle=style.dash, marker="o", ms=3, label=label_of(controller))
        ax.set_title("NN share of the estimate", fontsize=9)
        ax.set_xlabel("wheel-speed noise std (rad/s)", fontsize=8)
        ax.set_ylabel("mean |d̂_NN| / mean |d̂| (%)", fontsize=8)
        ax.grid(alpha=0.3, lw=0.4)
        axes[1, -1].axis("off")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside right upper", fontsize=7)
    fig.suptitle(f"{scenario}: steady state against each effect (mean, 5-95 % band over seeds)", fontsize=10)
    out_dir.mkdir(parents=True, exist_ok=True)
    from ddmr_cli.storage.jobdir import safe_name

    path = out_dir / f"realism_{safe_name(scenario)}.png"  # one path component, whatever the name (issue 26)
    return save(fig, path, tight=False)  # atomically, as every figure


def _y_scale(ax) -> None:
    """Log scale when the axes hold positive values, else linear with a note: with an empty steady-state window
    (metrics.settle_time >= simulation.duration) every steady-state metric is NaN and there is nothing to draw."""
    values = np.concatenate([np.asarray(line.get_ydata(), float) for line in ax.get_lines()] or [np.array([])])
    if (values[np.isfinite(values)] > 0).any():
        ax.set_yscale("log")
    elif not np.isfinite(values).any():
        ax.text(0.5, 0.5, "no steady-state data\n(metrics.settle_time ≥ duration?)", transform=ax.transAxes,
                ha="center", va="center", fontsize=7, color="0.4")


def empty_steady_state(data: ReportData) -> bool:
    """Whether no job has a finite steady-state deviation (the window after metrics.settle_time is empty)."""
    column = METRICS[0][0]
    return column not in data.metrics or not np.isfinite(data.metrics[column].astype(float)).any()


def cost_rows(controllers: list[str]) -> list[dict]:
    """The cost-per-step table for the packaged controllers among ``controllers`` (:mod:`ddmr_cli.bench.cost`)."""
    from ddmr_cli.config import group_options
    from ddmr_cli.bench.cost import cost_table

    names = [c for c in controllers if c in group_options("controller")]
    return cost_table(names, repeats=15, n=1000) if names else []


def section(report) -> None:
    """Add the realism section to ``report`` (a :class:`ddmr_cli.report.build.Report`)."""
    import pandas as pd

    from ddmr_cli.bench.cost import assumptions
    from ddmr_cli.plots.common import label_of

    d = report.data
    if not present(d):
        return
    link = report.csv("realism.csv", frame(d), "steady-state deviation and chattering of every job, by effect")
    report.add("## Realism: sensing, delay and control rate (docs/model.md §10)", "",
               f"Each job placed on one effect axis by its config ({link}). Steady-state metrics (after "
               f"metrics.settle_time), on the true pose and voltage; the controller saw only the measured signals.", "")
    if empty_steady_state(d):
        report.add("**No steady-state numbers**: every job's steady-state window is empty (metrics.settle_time is "
                   "not below simulation.duration), so the tables below show – and the figures are empty. Run "
                   "longer or lower metrics.settle_time.", "")
    for scenario in d.scenarios:
        report.add(f"### {scenario}", "")
        table = realism_table(d, scenario)
        if table:
            settings = sorted({k.split("|")[0] for r in table for k in r if "|" in k})
            headers = ["Controller", "ideal (mm)"] + [f"{s} (mm)" for s in settings] + [f"×ideal: {s}" for s in settings]
            rows = []
            for r in table:
                cells = [T.fmt(1e3 * r.get(f"{s}|mean", math.nan), 3) + " ± " + T.fmt(1e3 * r.get(f"{s}|sd", math.nan), 2)
                         + (f" ({r[f'{s}|diverged']} diverged)" if r.get(f"{s}|diverged") else "") for s in settings]
                ratios = [f"{r.get(f'{s}|mean', math.nan) / r['ideal_mean']:.3g}" for s in settings]
                rows.append([label_of(r["controller"]),
                             T.fmt(1e3 * r["ideal_mean"], 3) + " ± " + T.fmt(1e3 * r["ideal_sd"], 2), *cells, *ratios])
            report.add("Steady-state deviation MAE, mean ± SD over seeds, ideal against each combined setting:", "",
                       T.md_table(headers, rows), "")
        loses = loses_to_pid(d, scenario)
        if loses:
            report.add("The mildest level at which each controller's steady-state deviation is worse than PID's "
                       "(paired by seed: bootstrap 95 % CI of the difference above 0 and Wilcoxon p < 0.05, or more "
                       "diverged runs; 'ideal' = already at the ideal loop, – = never on this grid):", "",
                       T.md_table(["Controller"] + [f"{EFFECTS[e][0]} ({EFFECTS[e][1]})" for e in EFFECTS],
                                  [[label_of(r["controller"])] + [r[e] or "–" for e in EFFECTS] for r in loses]), "")
        shares = nn_shares(d, scenario)
        if shares:
            report.add("The NN's share of its estimate, mean |d̂_NN| / mean |d̂_NDO + d̂_NN| over the kept series "
                       f"({shares[0]['series_seeds']} seed(s)), as the wheel-speed noise grows: "
                       + ", ".join(f"{r['speed_std']:g} rad/s → {T.pct(r['share_of_estimate'])}" for r in shares)
                       + ".", "")
        path = figure(d, scenario, report.figures_dir, report.styles) if report.draw_figures else None
        if path is not None:
            rel = path.relative_to(report.out).as_posix()
            report.add(f"![realism {scenario}]({rel})", "")
    rows = cost_rows(sorted({j.controller for j in d.jobs}, key=_rank))
    if rows:
        link = report.csv("control_step_cost.csv", pd.DataFrame(rows), "the cost of a control step per controller")
        report.add("### The cost of a control step", "",
                   f"The controller's command + update laws alone, compiled, one run, warm, on the machine that "
                   f"wrote this report ({link}). {assumptions()}", "",
                   T.md_table(["Controller", "ns/step min", "median", "flops", "exp/tanh", "div", "M4F cycles",
                               "M4F µs", "of 1 kHz"],
                              [[r["controller"], f"{r['ns_min']:.1f}", f"{r['ns_median']:.1f}", f"{r['flops']:.0f}",
                                f"{r['transcendental']:.0f}", f"{r['divisions']:.0f}", f"{r['m4f_cycles']:.0f}",
                                f"{r['m4f_us']:.2f}", T.pct(r["budget_1khz"], 2)] for r in rows]), "")


__all__ = ["classify", "representative", "present", "frame", "loses_to_pid", "realism_table", "nn_shares", "figure", "section",
           "EFFECTS", "Placement"]
