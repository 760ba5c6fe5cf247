"""Figures mirroring the paper's (Figs. 3-14), one PNG each, per scenario, from the jobs' kept time series.

Each figure uses one seed: the first kept seed common to every job of the scenario, so every controller
faces the same terrain. Long lines are thinned (:func:`~ddmr_cli.report.plotting.thin`) by keeping each bin's
minimum and maximum (the envelope of a chattering signal survives); zoom panels are drawn at full resolution.
"""

from __future__ import annotations

import math
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddmr_cli.cli import io
from ddmr_cli.report.data import Job, ReportData
from ddmr_cli.report.plotting import color_of, pyplot, save, thin

ZOOM_WIDTH = 0.3  # s
LINESTYLES = ("-", "--", ":", "-.")
REFERENCE_STYLE = {"color": "0.55", "ls": "--", "lw": 1.4}   # reference path / true disturbance: grey dashed
SMC_FAMILY_KEYS = ("lambda",)  # a controller with a sliding surface reports lambda among its parameters


@dataclass
class Figure:
    path: Path
    title: str
    caption: str


def _legend(ax) -> None:
    """Legend outside the axes, on the right (the curves and the zone labels stay visible)."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)


def _line(ax, x, y, job: Job | None = None, label: str | None = None, full: bool = False, **kw):
    idx = np.arange(len(y)) if full else thin(y)
    if job is not None:
        kw.setdefault("color", color_of(job.controller))
        kw.setdefault("ls", LINESTYLES[job.variant % len(LINESTYLES)])
        kw.setdefault("lw", 1.6 if job.controller == "smc_ndo_nno" else 1.0)
        kw.setdefault("zorder", 2.0 if job.controller == "smc_ndo_nno" else 2.5)  # thick black line beneath
        label = label or job.label
    return ax.plot(np.asarray(x)[idx], np.asarray(y)[idx], label=label, **kw)


class ScenarioFigures:
    """The figures of one scenario."""

    def __init__(self, data: ReportData, scenario: str, out_dir: Path):
        self.data, self.scenario, self.out_dir = data, scenario, Path(out_dir)
        self.jobs = [data.job(scenario, k) for k in data.keys(scenario)]
        self.seed = common_seed(self.jobs)
        self.series: dict[str, dict[str, np.ndarray]] = {}
        if self.seed is not None:
            for job in self.jobs:
                self.series[job.key] = data.series(job, self.seed)
        self.ref = self._reference_job()
        self.figures: list[Figure] = []
        self.notes: list[str] = []

    # --- helpers -----------------------------------------------------------------------------------------
    def _reference_job(self) -> Job | None:
        if not self.series:
            return None
        for name in ("smc_ndo_nno", "smc_ndo", "smc"):
            for job in self.jobs:
                if job.controller == name:
                    return job
        return self.jobs[0]

    def _s(self, job: Job) -> dict[str, np.ndarray]:
        return self.series[job.key]

    def _zone_names(self, job: Job) -> list[str]:
        seg = self.data.segments
        names = seg.loc[(seg["job"] == job.dir.name), "segment"].astype(str)
        return [n.split(":", 1)[1] for n in dict.fromkeys(names) if n.startswith("zone:")]

    def _zone_spans(self, axis: str = "t") -> list[tuple[float, float, str]]:
        """(start, end, zone name) along time or distance, from the reference job's zone channel."""
        s = self._s(self.ref)
        x = s["t"] if axis == "t" else s.get("distance", s["x"])
        zone = s["zone"].astype(int)
        names = self._zone_names(self.ref)
        cuts = np.flatnonzero(np.diff(zone)) + 1
        starts, ends = np.r_[0, cuts], np.r_[cuts, len(zone)]
        return [(float(x[a]), float(x[b - 1]), names[zone[a]] if zone[a] < len(names) else f"zone {zone[a]}")
                for a, b in zip(starts, ends)]

    def _phases(self) -> list[tuple[float, str]]:
        phases = (self.ref.config.get("scenario") or {}).get("phases") or {}
        return sorted((float(p.get("start", 0.0)), name) for name, p in phases.items()) if len(phases) > 1 else []

    def _spans(self) -> list[tuple[float, float, str]]:
        """What a time axis is divided into: the scenario's phases when it has several, else the terrain zones."""
        phases = self._phases()
        if phases:
            t_end = float(self._s(self.ref)["t"][-1])
            ends = [p[0] for p in phases[1:]] + [t_end]
            return [(start, end, f"phase: {name}") for (start, name), end in zip(phases, ends)]
        return self._zone_spans("t")

    def _spans_text(self) -> str:
        """What the shading of a time axis means (see :meth:`_decorate_time`)."""
        return ("shaded bands alternate the scenario's phases (named at the top)" if self._phases()
                else "shaded bands alternate the terrain zones (named at the top)")

    def _decorate_time(self, ax, labels: bool = False):
        """Shade every other phase (or terrain zone) on a time axis and name them at the top."""
        for i, (a, b, name) in enumerate(self._spans()):
            if i % 2:
                ax.axvspan(a, b, color="0.93", zorder=0)
            if labels:
                ax.text((a + b) / 2, 0.98, name.replace("_", " "), transform=ax.get_xaxis_transform(),
                        ha="center", va="top", fontsize=8, color="0.35")

    def _zoom_window(self) -> tuple[float, float]:
        """ZOOM_WIDTH seconds in the middle of the roughest stretch of constant roughness lasting at least 1 s
        (the reference job's roughness channel; the longest stretch when none lasts that long)."""
        s = self._s(self.ref)
        t, rough = s["t"], s["roughness"]
        cuts = np.flatnonzero(np.diff(rough)) + 1
        stretches = list(zip(np.r_[0, cuts], np.r_[cuts, len(t)]))
        long = [(a, b) for a, b in stretches if t[b - 1] - t[a] >= 1.0]
        a, b = (max(long, key=lambda ab: (rough[ab[0]], ab[1] - ab[0])) if long
                else max(stretches, key=lambda ab: ab[1] - ab[0]))
        mid = 0.5 * (t[a] + t[b - 1])
        width = min(ZOOM_WIDTH, t[b - 1] - t[a]) or ZOOM_WIDTH
        return mid - width / 2, mid + width / 2

    def _robust_ylim(self, ax, arrays, t, t_min: float = 1.0, margin: float = 0.15) -> bool:
        """Fit the y range to t >= t_min; True when something before t_min is off-scale."""
        later = t >= t_min
        vals = np.concatenate([a[later] for a in arrays])
        vals = vals[np.isfinite(vals)]
        if vals.size == 0:
            return False
        lo, hi = float(vals.min()), float(vals.max())
        pad = margin * (hi - lo or abs(hi) or 1.0)
        lo, hi = lo - pad, hi + pad
        ax.set_ylim(lo, hi)
        early = np.concatenate([a[~later] for a in arrays])
        early = early[np.isfinite(early)]
        return bool(early.size and (early.min() < lo or early.max() > hi))

    def _title(self, text: str) -> str:
        return f"{text} — {self.scenario}, seed {self.seed}"

    def _save(self, fig, name: str, title: str, caption: str) -> None:
        self.figures.append(Figure(save(fig, self.out_dir / f"{self.scenario}_{name}.png"), title, caption))

    # --- the figures -------------------------------------------------------------------------------------
    def fig_terrain(self, plt):
        s = self._s(self.ref)
        dist = s.get("distance", s["x"])
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
        ax1.plot(dist, s["roughness"], color="0.2", lw=1.2, drawstyle="steps-post")
        ax1.set_yscale("symlog", linthresh=0.1)  # log above 0.1, linear down to 0 (roughness switched off)
        ax1.set_ylim(bottom=0)
        ax1.set(ylabel="roughness amplitude [rad/s²]",
                title=self._title(f"Fig. 3: terrain along the path (disturbance seen by {self.ref.label})"))
        _line(ax2, dist, s["d_true_right"], color="0.35", lw=0.6, label="true d, right wheel")
        _line(ax2, dist, s["d_true_left"], color="#e377c2", lw=0.6, alpha=0.6, label="true d, left wheel")
        ax2.set(xlabel="distance travelled [m]", ylabel="disturbance d [rad/s²]")
        ax2.legend(loc="lower left")
        for ax in (ax1, ax2):
            for i, (a, b, name) in enumerate(self._zone_spans("d")):
                if a > dist[0]:
                    ax.axvline(a, color="tab:red", ls="--", lw=1.0)
                if ax is ax1:
                    ax.text((a + b) / 2, 0.95, name.replace("_", " "), transform=ax.get_xaxis_transform(),
                            ha="center", va="top", fontsize=9)
            ax.grid(alpha=0.3)
        self._save(fig, "fig03_terrain", "Terrain roughness along the path (paper Fig. 3)",
                   f"Roughness amplitude per terrain zone (zone boundaries dashed) and the resulting lumped "
                   f"disturbance d on both wheels vs distance travelled (seed {self.seed}, {self.ref.label} run)."
                   + (" The scenario's phases switch the roughness off in places and add the damping uncertainty to d "
                      "(see Fig. 10)."
                      if self._phases() else ""))

    def fig_trajectory(self, plt):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 6), gridspec_kw={"height_ratios": [1, 1.3]})
        s0 = self._s(self.ref)
        for ax, scale in ((ax1, 1.0), (ax2, 1000.0)):
            _line(ax, s0["x_ref"], s0["y_ref"] * scale, label="reference", **REFERENCE_STYLE)
            for job in self.jobs:
                s = self._s(job)
                _line(ax, s["x"], s["y"] * scale, job)
            ax.grid(alpha=0.3)
        ax1.set(xlabel="x [m]", ylabel="y [m]", title=self._title("Fig. 4: trajectories"))
        _legend(ax1)
        x0 = float(s0["x_ref"][0]) + 1.0
        ax2.set_xlim(x0, float(np.nanmax(s0["x_ref"])))
        later = [self._s(j)["y"][self._s(j)["x"] >= x0] * 1000 for j in self.jobs]
        vals = np.concatenate(later + [s0["y_ref"][s0["x_ref"] >= x0] * 1000])
        vals = vals[np.isfinite(vals)]
        if vals.size:
            pad = 0.1 * (vals.max() - vals.min() or 1.0)
            ax2.set_ylim(vals.min() - pad, vals.max() + pad)
        ax2.set(xlabel="x [m]", ylabel="y [mm]", title=f"zoom: lateral position after x = {x0:g} m (mm)")
        self._save(fig, "fig04_trajectory", "Trajectories of all controllers (paper Fig. 4)",
                   "Paths in the plane with the reference (grey dashed); bottom: lateral position in mm after the "
                   "first metre.")

    def fig_deviation(self, plt):
        fig, ax = plt.subplots(figsize=(11, 4))
        self._decorate_time(ax, labels=True)
        for job in self.jobs:
            s = self._s(job)
            _line(ax, s["t"], np.maximum(s["deviation"], 1e-7), job)
        ax.set_yscale("log")
        ax.set(xlabel="t [s]", ylabel="deviation [m] (log scale)",
               title=self._title("Fig. 5/11: deviation from the reference"))
        _legend(ax)
        ax.grid(alpha=0.3, which="both")
        self._save(fig, "fig05_deviation", "Deviation vs time (paper Figs. 5 and 11)",
                   f"Distance to the reference point over time, log scale; {self._spans_text()}.")

    def _time_panels(self, axes, jobs, keys, ylabels, zero_line: bool = False) -> bool:
        """One channel per panel against time, every job a line; returns whether a y range was clipped."""
        clipped = False
        for ax, key, ylabel in zip(axes, keys, ylabels):
            self._decorate_time(ax, labels=ax is axes[0])
            for job in jobs:
                s = self._s(job)
                _line(ax, s["t"], s[key], job)
            if zero_line:
                ax.axhline(0, color="0.3", lw=0.6)
            clipped |= self._robust_ylim(ax, [self._s(j)[key] for j in jobs], self._s(self.ref)["t"])
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        return clipped

    def _save_time_panels(self, fig, axes, clipped: bool, title: str, name: str, caption: str, text: str) -> None:
        """Title, legend and time axis of a :meth:`_time_panels` figure, then save it with its caption."""
        axes[0].set_title(self._title(title))
        _legend(axes[0])
        axes[-1].set_xlabel("t [s]")
        note = " The y ranges fit t ≥ 1 s; the initial transient is off-scale." if clipped else ""
        self._save(fig, name, caption, text + note)

    def fig_pose_errors(self, plt):
        fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
        clipped = self._time_panels(axes, self.jobs, ("e_x", "e_y", "e_theta"), ("e_x [m]", "e_y [m]", "e_θ [rad]"))
        self._save_time_panels(fig, axes, clipped, "Figs. 6/12: longitudinal, lateral and heading errors",
                               "fig06_pose_errors", "Pose errors e_x, e_y, e_θ vs time (paper Figs. 6 and 12)",
                               "Errors in the robot frame.")

    def fig_disturbance(self, plt):
        observers = [j for j in self.jobs if "L" in (j.summary.get("parameters") or {})]
        if not observers:
            self.notes.append(f"{self.scenario}: no job with a disturbance observer; Fig. 7 skipped")
            return
        truth = next((j for j in observers if j.controller == "smc_ndo_nno"), observers[0])
        t0, t1 = self._zoom_window()
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 7))
        for ax, full in ((ax1, False), (ax2, True)):
            s = self._s(truth)
            t = s["t"]
            win = (t >= t0) & (t <= t1) if full else slice(None)
            _line(ax, t[win], s["d_true_right"][win], label=f"true d (from the {truth.label} run)", full=full,
                  color="0.55", lw=2.0 if full else 1.0)
            for job in observers:
                s = self._s(job)
                d_hat = s["d_hat_ndo_right"] + s["d_hat_nn_right"]
                what = "NDO + NNO" if np.any(s["d_hat_nn_right"] != 0) else "NDO"
                _line(ax, s["t"][win], d_hat[win], job, label=f"{job.label}: d̂ ({what})", full=full)
            ax.set(xlabel="t [s]", ylabel="d, right wheel [rad/s²]")
            ax.grid(alpha=0.3)
        self._decorate_time(ax1, labels=True)
        ax1.axvspan(t0, t1, color="gold", alpha=0.35, zorder=0)
        ax1.set_title(self._title("Figs. 7/14: disturbance estimates, right wheel"))
        _legend(ax1)
        ax2.set_title(f"zoom: t = {t0:.2f} – {t1:.2f} s (highlighted above)")
        ax2.set_xlim(t0, t1)
        self._save(fig, "fig07_disturbance", "Disturbance estimates of NDO and NDO+NNO vs the true disturbance "
                   "(paper Figs. 7 and 14)",
                   f"Right wheel; the true lumped disturbance (grey) is that of the {truth.label} run (each "
                   f"controller's own differs where uncertainty depends on the wheel speed). Bottom: full-resolution "
                   f"zoom into the roughest stretch.")

    def fig_voltage(self, plt):
        t0, t1 = self._zoom_window()
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 7))
        for ax, full in ((ax1, False), (ax2, True)):
            for job in self.jobs:
                s = self._s(job)
                win = (s["t"] >= t0) & (s["t"] <= t1) if full else slice(None)
                _line(ax, s["t"][win], s["u_right"][win], job, full=full, lw=0.9 if not full else 1.2)
            ax.set(xlabel="t [s]", ylabel="u_R [V]")
            ax.grid(alpha=0.3)
        self._decorate_time(ax1, labels=True)
        clipped = self._robust_ylim(ax1, [self._s(j)["u_right"] for j in self.jobs], self._s(self.ref)["t"])
        ax1.axvspan(t0, t1, color="gold", alpha=0.35, zorder=0)
        ax1.set_title(self._title("Figs. 8/13: right-wheel control voltage"))
        _legend(ax1)
        ax2.set_title(f"zoom: t = {t0:.2f} – {t1:.2f} s (highlighted above)")
        ax2.set_xlim(t0, t1)
        self._save(fig, "fig08_voltage", "Right-wheel control voltage with a zoom (paper Figs. 8 and 13)",
                   "Applied (saturated) voltage of the right wheel; bottom: full-resolution zoom into the roughest "
                   "stretch." + (" The top panel's y range fits t ≥ 1 s; the start-up transient is off-scale."
                                 if clipped else ""))

    def fig_sliding(self, plt):
        jobs = [j for j in self.jobs if any(k in (j.summary.get("parameters") or {}) for k in SMC_FAMILY_KEYS)]
        if not jobs:
            self.notes.append(f"{self.scenario}: no sliding-mode controller; Fig. 9 skipped")
            return
        fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
        clipped = self._time_panels(axes, jobs, ("s_right", "s_left"),
                                    ("s, right wheel [rad/s]", "s, left wheel [rad/s]"), zero_line=True)
        self._save_time_panels(fig, axes, clipped, "Fig. 9: sliding variable", "fig09_sliding",
                               "Sliding variable of both wheels (paper Fig. 9)",
                               "s = w_d − w per wheel for the sliding-mode controllers.")

    def fig_environment(self, plt):
        s = self._s(self.ref)
        if np.allclose(s["damping_scale"], 1.0):
            return  # no parametric uncertainty in this scenario: Fig. 10 belongs to scenario 2
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
        ax1.plot(s["t"], s["roughness"], color="0.2", lw=1.2, drawstyle="steps-post")
        ax1.set(ylabel="roughness amplitude [rad/s²]",
                title=self._title("Fig. 10: terrain roughness and damping (electromechanical resistance)"))
        idx = thin(s["damping_scale"])
        ax2.plot(s["t"][idx], s["damping_scale"][idx], color="tab:brown", lw=1.0)
        ax2.axhline(1.0, color="0.3", ls=":", lw=0.8)
        ax2.set(xlabel="t [s]", ylabel="B_true / B_nominal [–]")
        for ax in (ax1, ax2):
            self._decorate_time(ax, labels=ax is ax1)
            ax.grid(alpha=0.3)
        self._save(fig, "fig10_environment", "Roughness and damping profile (paper Fig. 10)",
                   f"The roughness amplitude the terrain applies and the true viscous damping relative to its nominal "
                   f"value (the parametric uncertainty); {self._spans_text()}.")

    def fig_spread(self, plt):
        keys = self.data.keys(self.scenario)
        values, labels, colors = [], [], []
        for key in keys:
            job = self.data.job(self.scenario, key)
            frame = self.data.metrics[(self.data.metrics["job"] == job.dir.name)
                                      & (self.data.metrics["status"] == "ok")]
            values.append(frame["deviation_mae"].astype(float).dropna().to_numpy())
            labels.append(job.label)
            colors.append(color_of(job.controller))
        fig, ax = plt.subplots(figsize=(max(6, 1.6 * len(keys) + 2), 4.2))
        if any(v.size for v in values):
            box = ax.boxplot([v if v.size else [np.nan] for v in values], widths=0.5, showfliers=False,
                             patch_artist=True, medianprops={"color": "k"})
            for patch, c in zip(box["boxes"], colors):
                patch.set(facecolor=c, alpha=0.25, edgecolor=c)
            rng = np.random.default_rng(0)
            for i, (v, c) in enumerate(zip(values, colors), start=1):
                ax.scatter(i + rng.uniform(-0.15, 0.15, v.size), v, s=10, color=c, alpha=0.8, zorder=3)
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=15 if len(labels) > 4 else 0)
        ax.set_yscale("log")
        ax.set(ylabel="deviation MAE per seed [m] (log scale)",
               title=f"Spread of the deviation MAE over seeds — {self.scenario}")
        ax.grid(alpha=0.3, axis="y", which="both")
        self._save(fig, "deviation_spread", "Per-seed spread of the deviation MAE",
                   "One point per seed (non-diverged runs), box: quartiles and median.")


def common_seed(jobs: list[Job]) -> int | None:
    """The first kept seed common to every job (None when there is none)."""
    if not jobs or not all((j.dir / io.SERIES).is_file() for j in jobs):
        return None
    common = set(jobs[0].series_seeds)
    for j in jobs[1:]:
        common &= set(j.series_seeds)
    ordered = [s for s in jobs[0].series_seeds if s in common]
    return ordered[0] if ordered else None


FIGURE_METHODS = ("fig_terrain", "fig_trajectory", "fig_deviation", "fig_pose_errors", "fig_disturbance",
                  "fig_voltage", "fig_sliding", "fig_environment", "fig_spread")

def make_one(data: ReportData, out_dir: Path, task: tuple[str, str]) -> tuple[list[Figure], list[str]]:
    """One figure task ``(scenario, method)``: its figures and notes."""
    scenario, method = task
    sf = ScenarioFigures(data, scenario, out_dir)
    if sf.seed is None and method != "fig_spread":
        if method == FIGURE_METHODS[0]:
            sf.notes.append(f"{scenario}: no kept time-series seed common to every job (run.keep_series); "
                            f"time-series figures skipped")
        return [], sf.notes
    getattr(sf, method)(pyplot())
    return sf.figures, sf.notes


def _worker(data, out_dir, tasks, results) -> None:
    """A forked figure process: takes ``(i, task)`` from ``tasks`` until None, puts ``(i, result, error)``.
    Its arguments are inherited through the fork, not pickled; only the small results travel back."""
    while (item := tasks.get()) is not None:
        i, task = item
        try:
            results.put((i, make_one(data, out_dir, task), None))
        except BaseException:  # noqa: BLE001 - reported to the parent, which raises it
            results.put((i, None, traceback.format_exc()))


def workers(n_tasks: int) -> int:
    """Figure processes: forked on Linux (they inherit the loaded data), at most 4, else one;
    ``DDMR_REPORT_WORKERS`` overrides the count."""
    import multiprocessing
    import os
    import sys

    if not sys.platform.startswith("linux") or "fork" not in multiprocessing.get_all_start_methods():
        return 1  # fork is unsafe on macOS and absent on Windows
    env = os.environ.get("DDMR_REPORT_WORKERS", "")
    n = int(env) if env.isdigit() and int(env) > 0 else min(os.cpu_count() or 1, 4)
    return max(1, min(n, n_tasks))


def _run_forked(data: ReportData, out_dir: Path, tasks: list, n: int) -> list:
    """Run ``tasks`` in ``n`` forked processes, each handed the data explicitly; results in task order."""
    import multiprocessing
    import queue

    ctx = multiprocessing.get_context("fork")
    task_q, result_q = ctx.Queue(), ctx.Queue()
    procs = [ctx.Process(target=_worker, args=(data, out_dir, task_q, result_q), daemon=True) for _ in range(n)]
    for p in procs:
        p.start()
    for item in enumerate(tasks):
        task_q.put(item)
    for _ in procs:
        task_q.put(None)
    results: list = [None] * len(tasks)
    pending = len(tasks)
    try:
        while pending:
            try:
                i, result, error = result_q.get(timeout=1.0)
            except queue.Empty:
                if not any(p.is_alive() for p in procs):
                    raise RuntimeError("a figure process died without reporting") from None
                continue
            if error is not None:
                raise RuntimeError(f"figure {tasks[i][1]} of {tasks[i][0]} failed:\n{error}")
            results[i] = result
            pending -= 1
    finally:
        for p in procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
    return results


def _warm_up() -> None:
    """Initialise in the parent what every figure process needs (matplotlib's fonts and text layout), so the
    forked processes share it instead of each paying for it."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1], label="d̂ σ θ")
    ax.set_title("warm-up")
    ax.legend()
    fig.canvas.draw()
    plt.close(fig)


def make_figures(data: ReportData, out_dir: Path) -> tuple[dict[str, list[Figure]], list[str]]:
    """All figures, per scenario (in forked processes when the machine has several cores); returns them and
    notes on what was skipped."""
    tasks = [(scenario, method) for scenario in data.scenarios for method in FIGURE_METHODS]
    for scenario in data.scenarios:  # read the series once, before any fork
        ScenarioFigures(data, scenario, out_dir)
    n = workers(len(tasks))
    if n > 1:
        _warm_up()
        results = _run_forked(data, Path(out_dir), tasks, n)
    else:
        results = [make_one(data, Path(out_dir), task) for task in tasks]
    figures: dict[str, list[Figure]] = {s: [] for s in data.scenarios}
    notes: list[str] = []
    for (scenario, _), (figs, task_notes) in zip(tasks, results):
        figures[scenario] += figs
        notes += task_notes
    return figures, notes
