"""Figures mirroring the paper's (Figs. 3-14) plus the NN's share and the voltage spectra, one PNG each, per
scenario, from the jobs' kept time series (and their across-seed bands when the jobs wrote ``bands.npz``).

Each figure uses one seed: the first kept seed common to every job drawn, so every controller faces the same
terrain. A scenario with more than :data:`MAX_JOBS` jobs (a sweep over some setting: realism levels, gains) draws
one job per controller in its time-series figures (:func:`shown_jobs`: the job without a swept setting, else the
ideal loop, else the first) and the sweep itself in a summary figure, one line per controller over the swept
setting (:meth:`ScenarioFigures.fig_sweep`); every figure stays within :data:`MAX_INCHES` on each side. With bands, a time-series figure shows per controller the mean over all seeds (line), the
5-95 % band (shaded) and that seed (thin line). Long lines are thinned to at most
:data:`~ddmr_cli.plots.common.MAX_POINTS` points keeping each bin's minimum and maximum; zooms are drawn at full
resolution. Lines that would overlap are drawn widest-spread first, or split into one panel per controller.

Every caption says in one sentence what the paper reports for the figure and what we see, the latter computed
from the data shown.
"""

from __future__ import annotations

import math
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddmr_cli.storage import io
from ddmr_cli.storage.jobdir import safe_name  # a scenario name as one path component (issue 26)
from ddmr_cli.report import signals as S
from ddmr_cli.paper import numbers as paper_numbers
from ddmr_cli.report.data import Job, ReportData, flatten
from ddmr_cli.report.tables import fmt, stats_frame, table4_frame
from ddmr_cli.plots.common import (OKABE_ITO, REFERENCE_STYLE, StyleBook, draw_order, equal_aspect, log_scale,
                                   pyplot, save, thin)

ZOOM_WIDTH = 0.3  # s
SMC_FAMILY_KEYS = ("lambda",)  # a controller with a sliding surface reports lambda among its parameters
BAND_ALPHA = 0.2
#: The pose errors converge from the offset start pose (0.05 m, 0.05 rad) in about 2 s: their y ranges fit later.
POSE_T_MIN = 2.0
#: Colours of the two parts of the NNO's estimate (not controllers): NDO part and NN part.
PART_COLORS = {"ndo": OKABE_ITO["orange"], "nn": OKABE_ITO["sky_blue"]}


#: At most this many jobs of one scenario are drawn in its time-series figures (:func:`shown_jobs`).
MAX_JOBS = 10
#: Panels per page of the small multiples of a sweep's jobs (:meth:`ScenarioFigures.fig_multiples`).
MULTIPLES = 24
#: No figure is larger than this on either side (inches; at DPI 110 about 2,900 px).
MAX_INCHES = 26.0


@dataclass
class Figure:
    path: Path
    title: str
    caption: str


def _legend(ax, order: list[str] | None = None, **kw) -> None:
    """Legend outside the axes, on the right (the curves and the zone labels stay visible); entries in
    ``order`` (labels) come first, in that order, whatever order the lines were drawn in. Entries that would
    not fit the figure's height in one column go into several (:func:`legend_columns`)."""
    handles, labels = ax.get_legend_handles_labels()
    if order:
        rank = {label: i for i, label in enumerate(order)}
        pairs = sorted(zip(handles, labels), key=lambda hl: rank.get(hl[1], len(rank)))
        handles, labels = [h for h, _ in pairs], [l for _, l in pairs]
    kw.setdefault("ncol", legend_columns(len(labels), ax.figure.get_figheight()))
    ax.legend(handles, labels, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8, **kw)


def legend_columns(entries: int, height_in: float, fontsize: float = 8.0) -> int:
    """Columns a legend of ``entries`` needs to fit ``height_in`` inches (a row is about 1.9 font sizes)."""
    rows = max(1, int(0.8 * height_in * 72 / (1.9 * fontsize)))
    return max(1, math.ceil(entries / rows))


def shown_jobs(jobs: list[Job], limit: int = MAX_JOBS) -> list[Job]:
    """The jobs a scenario's time-series figures draw: all of them up to ``limit``, else one per controller
    (:func:`ddmr_cli.report.realism.representative`, or the controller's first job), in the given order."""
    if len(jobs) <= limit:
        return list(jobs)
    from ddmr_cli.report.realism import representative

    out = []
    for controller in dict.fromkeys(j.controller for j in jobs):
        mine = [j for j in jobs if j.controller == controller]
        out.append(representative(mine) or mine[0])
    return out


def _height(base: float, per_row: float, rows: int) -> float:
    """A figure's height in inches for ``rows`` panels, at most :data:`MAX_INCHES` (the panels shrink)."""
    return min(base + per_row * rows, MAX_INCHES)


def _mm(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{1000 * x:.3g} mm"


def _num(x: float, digits: int = 3) -> str:
    return fmt(x, digits)


def _listing(items: list[tuple[str, str]]) -> str:
    return ", ".join(f"{label} {value}" for label, value in items)


class ScenarioFigures:
    """The figures of one scenario."""

    def __init__(self, data: ReportData, scenario: str, out_dir: Path, styles: StyleBook):
        self.data, self.scenario, self.out_dir, self.styles = data, scenario, Path(out_dir), styles
        self.all_jobs = [data.job(scenario, k) for k in data.keys(scenario)]
        self.jobs = shown_jobs(self.all_jobs)
        self.seed = common_seed(self.jobs)
        self.series: dict[str, dict[str, np.ndarray]] = {}
        self.bands: dict[str, object] = {}
        if self.seed is not None:
            for job in self.jobs:
                s = self.series[job.key] = data.series(job, self.seed)
                b = data.bands(job)
                b = b.on(s["t"]) if b is not None else None
                if b is not None:
                    self.bands[job.key] = b
        self.ref = self._reference_job()
        self.paper = paper_numbers()
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

    def style(self, job: Job) -> dict:
        """The job's line style: its controller's, with a variant's marker only when its variants are drawn
        together (one job per controller drawn: no marker)."""
        return self.styles[job.controller].kwargs(job.variant if len(self.jobs) == len(self.all_jobs) else 0)

    def paper_says(self, figure: str) -> str:
        text = (self.paper.get("figures", {}).get(figure) or {}).get(self.scenario)
        return f"Paper — {text}." if text else "Paper — no counterpart for this scenario."

    def _band_note(self, jobs: list[Job]) -> str:
        with_bands = [j for j in jobs if j.key in self.bands]
        if not with_bands:
            return ""
        runs = {int((j.summary.get("statistics") or {}).get("runs", 0)) for j in with_bands}
        n = f"{max(runs)} seeds" if runs and max(runs) else "all seeds"
        return (f" Lines: mean over {n}; shaded: 5–95 % band; thin line: seed {self.seed}"
                + ("" if len(with_bands) == len(jobs) else " (jobs without bands.npz: seed line only)") + ".")

    def _trace(self, ax, job: Job, channel: str, window=None, full: bool = False, label: str | None = None,
               **override):
        """One job's channel against time: with bands the 5-95 % band, the mean and the seed as a thin line,
        else the seed's line in the job's style."""
        s = self._s(job)
        t = s["t"]
        sel = np.arange(len(t)) if window is None else np.flatnonzero(window)
        kw = {**self.style(job), **override}
        label = label if label is not None else job.label
        band = self.bands.get(job.key)
        if band is not None and channel in band:
            lo, hi, mean = band.p05[channel][sel], band.p95[channel][sel], band.mean[channel][sel]
            idx = np.arange(len(sel)) if full else np.union1d(thin(lo), thin(hi))
            ax.fill_between(t[sel][idx], lo[idx], hi[idx], color=kw["color"], alpha=BAND_ALPHA, lw=0,
                            zorder=kw.get("zorder", 2) - 0.5)
            y = s[channel][sel]
            idx = np.arange(len(sel)) if full else thin(y)
            ax.plot(t[sel][idx], y[idx], color=kw["color"], lw=0.5, alpha=0.7, zorder=kw.get("zorder", 2))
            idx = np.arange(len(sel)) if full else thin(mean)
            return ax.plot(t[sel][idx], mean[idx], label=label, **kw)
        y = s[channel][sel]
        idx = np.arange(len(sel)) if full else thin(y)
        return ax.plot(t[sel][idx], y[idx], label=label, **kw)

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

    def _by_distance(self) -> bool:
        """Whether the scenario's phases switch by the distance travelled (``phase_clock: distance``)."""
        return (self.ref.config.get("scenario") or {}).get("phase_clock", "distance") == "distance"

    def _phases(self) -> list[tuple[float, str]]:
        """(start time [s], name) of each phase of the reference job; a phase that starts at a distance travelled
        starts at the time the reference seed reached it."""
        phases = (self.ref.config.get("scenario") or {}).get("phases") or {}
        if len(phases) < 2:
            return []
        starts = sorted((float(p.get("start", 0.0)), name) for name, p in phases.items())
        if self._by_distance():
            s = self._s(self.ref)
            if "distance" in s:
                return [(float(np.interp(start, s["distance"], s["t"])), name) for start, name in starts]
        return starts

    def _spans(self) -> list[tuple[float, float, str]]:
        """What a time axis is divided into: the scenario's phases when it has several, else the terrain zones."""
        phases = self._phases()
        if phases:
            t_end = float(self._s(self.ref)["t"][-1])
            ends = [p[0] for p in phases[1:]] + [t_end]
            return [(start, end, f"phase: {name}") for (start, name), end in zip(phases, ends)]
        return self._zone_spans("t")

    def _spans_text(self) -> str:
        if not self._phases():
            return "shaded bands alternate the terrain zones (named at the top)"
        if self._by_distance():
            return ("shaded bands alternate the scenario's phases (named at the top), which switch by the distance "
                    "travelled (at the times this seed reached them), not by time")
        return "shaded bands alternate the scenario's phases (named at the top), which switch by time"

    def _decorate_time(self, ax, labels: bool = False):
        """Shade every other phase (or terrain zone) on a time axis and name them at the top."""
        spans = self._spans()
        total = (spans[-1][1] - spans[0][0]) if spans else 0.0
        for i, (a, b, name) in enumerate(spans):
            if i % 2:
                ax.axvspan(a, b, color="0.92", zorder=0)
            if labels and b - a >= 0.05 * total:  # a span too narrow for its name (a short run) stays unnamed
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

    def _arrays(self, job: Job, channel: str) -> list[tuple[np.ndarray, np.ndarray]]:
        """The (time, values) arrays a trace of ``channel`` draws (seed, and band edges when present), for
        y-limits; each job on its own time grid (a sweep over simulation.dt or duration has several)."""
        t = self._s(job)["t"]
        out = [(t, self._s(job)[channel])]
        band = self.bands.get(job.key)
        if band is not None and channel in band:
            out += [(t, band.p05[channel]), (t, band.p95[channel])]
        return out

    def _robust_ylim(self, ax, arrays, t_min: float = 1.0, margin: float = 0.15, extra=()) -> bool:
        """Fit the y range to t >= t_min (and the values in ``extra``); True when something before t_min is
        off-scale. ``arrays``: (time, values) pairs."""
        later = [t >= t_min for t, _ in arrays]
        arrays = [a for _, a in arrays]
        vals = np.concatenate([a[m] for a, m in zip(arrays, later)] + [np.asarray(extra, float)])
        vals = vals[np.isfinite(vals)]
        if vals.size == 0:
            return False
        lo, hi = float(vals.min()), float(vals.max())
        pad = margin * (hi - lo or abs(hi) or 1.0)
        lo, hi = lo - pad, hi + pad
        ax.set_ylim(lo, hi)
        early = np.concatenate([a[~m] for a, m in zip(arrays, later)])
        early = early[np.isfinite(early)]
        return bool(early.size and (early.min() < lo or early.max() > hi))

    def _title(self, text: str, bands: bool = False) -> str:
        """``text — scenario, seed k``; with ``bands`` (a figure drawing them) the mean and band are named first."""
        if bands and self.bands:
            return f"{text} — {self.scenario}, mean and 5–95 % band over seeds, thin: seed {self.seed}"
        return f"{text} — {self.scenario}, seed {self.seed}"

    def _save(self, fig, name: str, title: str, caption: str, tight: bool = True) -> None:
        self.figures.append(Figure(save(fig, self.out_dir / f"{safe_name(self.scenario)}_{name}.png", tight=tight), title,
                                   caption))

    def _ordered(self, jobs: list[Job], channel: str, t_min: float = 1.0) -> list[Job]:
        """``jobs`` from the widest spread of ``channel`` (t >= t_min) to the narrowest: the drawing order."""
        arrays = [self._s(j)[channel][self._s(j)["t"] >= t_min] for j in jobs]
        return [jobs[i] for i in draw_order(arrays, [self.style(j)["lw"] for j in jobs])]

    def _labels(self) -> list[str]:
        return [j.label for j in self.jobs]

    def _by_controller(self, controller: str) -> Job | None:
        return next((j for j in self.jobs if j.controller == controller), None)

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
        idx = thin(s["d_true_right"])
        ax2.plot(dist[idx], s["d_true_right"][idx], color="0.25", lw=0.6, label="true d, right wheel")
        idx = thin(s["d_true_left"])
        ax2.plot(dist[idx], s["d_true_left"][idx], color=OKABE_ITO["sky_blue"], lw=0.6, alpha=0.7,
                 label="true d, left wheel")
        ax2.set(xlabel="distance travelled [m]", ylabel="disturbance d [rad/s²]")
        ax2.legend(loc="lower left")
        zones = self._zone_spans("d")
        for ax in (ax1, ax2):
            for a, b, name in zones:
                if a > dist[0]:
                    ax.axvline(a, color=OKABE_ITO["vermillion"], ls="--", lw=1.0)
                if ax is ax1:
                    ax.text((a + b) / 2, 0.95, name.replace("_", " "), transform=ax.get_xaxis_transform(),
                            ha="center", va="top", fontsize=9)
            ax.grid(alpha=0.3)
        ours = []
        for a, b, name in zones:
            m = (dist >= a) & (dist <= b)
            levels = sorted({float(v) for v in np.unique(s["roughness"][m])})
            ours.append((name.replace("_", " "), f"{'/'.join(f'{v:g}' for v in levels)} (SD of d "
                                                 f"{_num(float(np.std(s['d_true_right'][m])))})"))
        self._save(fig, "fig03_terrain", "Terrain roughness along the path (paper Fig. 3)",
                   f"Roughness amplitude per terrain zone (zone boundaries dashed) and the resulting lumped "
                   f"disturbance d on both wheels vs distance travelled (seed {self.seed}, {self.ref.label} run)."
                   + (" The scenario's phases switch the roughness off in places and add the damping uncertainty to d "
                      "(see Fig. 10)." if self._phases() else "")
                   + f" {self.paper_says('terrain')} Ours — roughness amplitude per zone (rad/s²): {_listing(ours)}.")

    def fig_trajectory(self, plt):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 6.5), gridspec_kw={"height_ratios": [1, 1.3]})
        s0 = self._s(self.ref)
        ordered = self._ordered(self.jobs, "e_y")
        idx = thin(s0["y_ref"])
        ax1.plot(s0["x_ref"][idx], s0["y_ref"][idx], label="reference", zorder=10, **REFERENCE_STYLE)
        for job in ordered:
            s = self._s(job)
            idx = thin(s["y"])
            ax1.plot(s["x"][idx], s["y"][idx], label=job.label, **self.style(job))
        equal_aspect(ax1)
        ax1.set(xlabel="x [m]", ylabel="y [m]", title=self._title("Fig. 4: trajectories (equal axes)"))
        _legend(ax1, ["reference"] + self._labels())
        # zoom: the lateral offset in mm after the first metre; for a reference along the x axis (the paper's
        # line) the position y against x as in the paper, for any other path the lateral error e_y against the
        # distance travelled
        along_x = float(np.ptp(s0["y_ref"])) < 1e-9 and float(np.ptp(np.cos(s0["theta_ref"]))) < 1e-9
        if along_x:
            xs = {j.key: self._s(j)["x"] for j in self.jobs}
            ys = {j.key: self._s(j)["y"] * 1000 for j in self.jobs}
            idx = thin(s0["y_ref"])
            ax2.plot(s0["x_ref"][idx], s0["y_ref"][idx] * 1000, zorder=10, **REFERENCE_STYLE)
            xlabel, ylabel, what = "x [m]", "y [mm]", "lateral position"
        else:
            xs = {j.key: self._s(j).get("distance", self._s(j)["t"]) for j in self.jobs}
            ys = {j.key: self._s(j)["e_y"] * 1000 for j in self.jobs}
            ax2.axhline(0, **REFERENCE_STYLE)
            xlabel, ylabel, what = "distance travelled [m]", "e_y [mm]", "lateral error"
        x0 = float(min(x[0] for x in xs.values())) + 1.0
        for job in ordered:
            idx = thin(ys[job.key])
            ax2.plot(xs[job.key][idx], ys[job.key][idx], **self.style(job))
        ax2.set_xlim(x0, float(max(np.nanmax(x) for x in xs.values())))
        vals = np.concatenate([ys[k][xs[k] >= x0] for k in ys] + ([np.array([0.0])] if not along_x else []))
        vals = vals[np.isfinite(vals)]
        if vals.size:
            pad = 0.1 * (vals.max() - vals.min() or 1.0)
            ax2.set_ylim(vals.min() - pad, vals.max() + pad)
        ax2.set(xlabel=xlabel, ylabel=ylabel, title=f"zoom: {what} after the first metre (mm; not to scale)")
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
        worst = []
        for job in self.jobs:
            m = xs[job.key] >= x0
            worst.append((job.label, float(np.nanmax(np.abs(self._s(job)["deviation"][m]))) if m.any() else math.nan))
        worst.sort(key=lambda lv: -lv[1] if math.isfinite(lv[1]) else 0.0)
        self._save(fig, "fig04_trajectory", "Trajectories of all controllers (paper Fig. 4)",
                   f"Paths in the plane with the reference (grey dashed), equal scale on both axes; bottom: {what} in "
                   f"mm after the first metre. {self.paper_says('trajectory')} Ours — largest deviation after the "
                   f"first metre: {_listing([(l, _mm(v)) for l, v in worst])}.")

    def fig_deviation(self, plt):
        fig, ax = plt.subplots(figsize=(11, 4.2))
        self._decorate_time(ax, labels=True)
        for job in self._ordered(self.jobs, "deviation"):
            s = self._s(job)
            self._trace(ax, job, "deviation")
        log_scale(ax)
        lo = min(float(np.nanpercentile(self._s(j)["deviation"], 0.5)) for j in self.jobs)
        ax.set_ylim(bottom=max(lo / 2, 1e-7))
        ax.set(xlabel="t [s]", ylabel="deviation [m] (log scale)",
               title=self._title("Fig. 5/11: deviation from the reference", bands=True))
        _legend(ax, self._labels())
        ax.grid(alpha=0.3, which="both")
        spans = self._spans()
        a, b, name = spans[1] if self.scenario == "paper_2" and len(spans) > 1 else spans[-1]
        means = [(j.label, S.mean_in(self._s(j)["t"], self._s(j)["deviation"], a, b + 1e-9)) for j in self.jobs]
        means.sort(key=lambda lv: lv[1] if math.isfinite(lv[1]) else math.inf)
        ours = (f"mean deviation over {name.replace('_', ' ')} ({a:.3g}–{b:.3g} s): "
                f"{_listing([(l, _mm(v)) for l, v in means])}")
        nno, ndo = self._by_controller("smc_ndo_nno"), self._by_controller("smc_ndo")
        if nno and ndo:
            vn, vd = dict(means)[nno.label], dict(means)[ndo.label]
            if math.isfinite(vn) and math.isfinite(vd) and vd > 0:
                ours += (f"; there SMC-NDO-NNO's is {vn / vd:.3g} × SMC-NDO's" if vn > 2 * vd or vn < 0.5 * vd
                         else f"; there SMC-NDO-NNO is {abs(vn / vd - 1) * 100:.1f} % "
                              f"{'above' if vn > vd else 'below'} SMC-NDO")
        self._save(fig, "fig05_deviation", "Deviation vs time (paper Figs. 5 and 11)",
                   f"Distance to the reference point over time, log scale; {self._spans_text()}."
                   f"{self._band_note(self.jobs)} {self.paper_says('deviation')} Ours (seed {self.seed}) — {ours}.")

    def fig_pose_errors(self, plt):
        fig, axes = plt.subplots(3, 1, figsize=(11, 8), sharex=True)
        clipped = False
        for ax, key, ylabel in zip(axes, ("e_x", "e_y", "e_theta"), ("e_x [m]", "e_y [m]", "e_θ [rad]")):
            self._decorate_time(ax, labels=ax is axes[0])
            for job in self._ordered(self.jobs, key):
                self._trace(ax, job, key)
            clipped |= self._robust_ylim(ax, [a for j in self.jobs for a in self._arrays(j, key)],
                                         t_min=POSE_T_MIN)
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        axes[0].set_title(self._title("Figs. 6/12: longitudinal, lateral and heading errors", bands=True))
        _legend(axes[0], self._labels())
        axes[-1].set_xlabel("t [s]")
        sds = []
        for job in self.jobs:
            s = self._s(job)
            m = S.window_mask(s["t"], 5.0, 10.0)
            e = s["e_theta"][m]
            sds.append((job.label, f"{1000 * float(np.mean(np.abs(e))):.3g} / {1000 * float(np.std(e)):.2g}"
                        if m.any() else "–"))
        note = (f" The y ranges fit t ≥ {POSE_T_MIN:g} s; the convergence from the offset start pose is off-scale."
                if clipped else "")
        self._save(fig, "fig06_pose_errors", "Pose errors e_x, e_y, e_θ vs time (paper Figs. 6 and 12)",
                   f"Errors in the robot frame; {self._spans_text()}.{note}{self._band_note(self.jobs)} "
                   f"{self.paper_says('pose_errors')} Ours (seed {self.seed}) — mean |e_θ| / SD of e_θ over 5–10 s "
                   f"(mrad): {_listing(sds)}.")

    def _panel_grid(self, plt, n_rows: int, ratios=(2.4, 1.0), row_height: float = 1.55):
        fig, axes = plt.subplots(n_rows, 2, figsize=(12, _height(1.0, row_height, n_rows)), squeeze=False,
                                 gridspec_kw={"width_ratios": list(ratios)}, sharex="col", sharey="col")
        return fig, axes

    def _row_label(self, ax, text: str, color: str) -> None:
        ax.text(0.005, 0.04, text, transform=ax.transAxes, ha="left", va="bottom", fontsize=8.5, color=color,
                fontweight="bold", bbox={"facecolor": "white", "alpha": 0.8, "lw": 0, "pad": 1.5}, zorder=20)

    def fig_disturbance(self, plt):
        observers = [j for j in self.jobs if "L" in (j.summary.get("parameters") or {})]
        if not observers:
            self.notes.append(f"{self.scenario}: no job with a disturbance observer; Fig. 7 skipped")
            return
        from ddmr_cli.engine.series import d_hat as whole_estimate, estimate_names

        t0, t1 = self._zoom_window()
        fig, axes = self._panel_grid(plt, len(observers))
        errors = []
        for i, (row, job) in enumerate(zip(axes, observers)):
            s = self._s(job)
            d_hat = whole_estimate(s, "right")
            what = " + ".join(estimate_names(s)) or "none"
            for ax, full in zip(row, (False, True)):
                win = S.window_mask(s["t"], t0, t1) if full else np.ones(len(s["t"]), bool)
                idx = np.flatnonzero(win) if full else thin(d_hat)
                ax.plot(s["t"][idx], d_hat[idx], label=f"d̂ ({what})", **self.style(job))
                idx = np.flatnonzero(win) if full else thin(s["d_true_right"])
                ax.plot(s["t"][idx], s["d_true_right"][idx], label="true d", zorder=5 if full else 1.5,
                        **{**REFERENCE_STYLE, "lw": 1.0 if full else 0.6})
                ax.grid(alpha=0.3)
            self._decorate_time(row[0], labels=i == 0)
            row[0].axvspan(t0, t1, color=OKABE_ITO["yellow"], alpha=0.35, zorder=0)
            self._row_label(row[0], f"{job.label}: d̂ ({what})", self.style(job)["color"])
            row[0].set_ylabel("d_R [rad/s²]")
            errors.append((job.label, _num(S.mean_abs(s["d_true_right"] - d_hat), 3)))
        axes[0, 0].set_title(self._title("Figs. 7/14: disturbance estimates, right wheel"))
        axes[0, 1].set_title(f"zoom: t = {t0:.2f} – {t1:.2f} s (highlighted)")
        axes[0, 1].set_xlim(t0, t1)
        axes[0, 1].legend(loc="lower right", fontsize=7)
        axes[-1, 0].set_xlabel("t [s]")
        axes[-1, 1].set_xlabel("t [s]")
        est = self.paper["claims"]["estimation"]
        self._save(fig, "fig07_disturbance", "Disturbance estimates of NDO and NDO+NNO vs the true disturbance "
                   "(paper Figs. 7 and 14)",
                   f"One row per controller with an observer: its estimate d̂ of the right wheel and its own true "
                   f"lumped disturbance (grey dashed); right: full-resolution zoom into the roughest stretch. "
                   f"{self.paper_says('disturbance')} Ours (seed {self.seed}) — mean |d − d̂|, right wheel, rad/s²: "
                   f"{_listing(errors)} (paper {est['ndo']:.1f} NDO, {est['ndo_nno']:.1f} NDO+NNO).")

    def fig_nn_share(self, plt):
        nnos = [j for j in self.jobs if S.has_nn(self._s(j))]
        if not nnos:
            return
        t0, t1 = self._zoom_window()
        fig, axes = plt.subplots(len(nnos), 3, figsize=(13, _height(1.2, 2.0, len(nnos))), squeeze=False, sharex="col",
                                 sharey="col", gridspec_kw={"width_ratios": [2.2, 1.0, 1.6]})
        shares = []
        for i, (row, job) in enumerate(zip(axes, nnos)):
            s = self._s(job)
            nn_part = ("d_hat_nn_right", "d̂_NN", {"color": PART_COLORS["nn"], "lw": 1.1})
            parts = tuple(part for part in (("d_true_right", "true d", {**REFERENCE_STYLE, "lw": 0.6}),
                                            ("d_hat_ndo_right", "d̂_NDO", {"color": PART_COLORS["ndo"], "lw": 0.9}),
                                            nn_part) if part[0] in s)  # a network without an NDO: no NDO part
            for ax, full in zip(row[:2], (False, True)):
                win = S.window_mask(s["t"], t0, t1) if full else np.ones(len(s["t"]), bool)
                for z, (channel, label, kw) in enumerate(parts):
                    y = s[channel]
                    idx = np.flatnonzero(win) if full else thin(y)
                    ax.plot(s["t"][idx], y[idx], label=label, zorder=2 + z, **kw)
            idx = thin(s["d_hat_nn_right"])
            row[2].plot(s["t"][idx], s["d_hat_nn_right"][idx], label="d̂_NN", **nn_part[2])
            for ax in row:
                ax.axhline(0, color="0.3", lw=0.5)
                ax.grid(alpha=0.3)
            for ax in (row[0], row[2]):
                self._decorate_time(ax, labels=i == 0)
            row[0].axvspan(t0, t1, color=OKABE_ITO["yellow"], alpha=0.35, zorder=0)
            share = S.nn_share([s], S.nominal_input_inverse(job.config.get("robot")))
            self._row_label(row[0], f"{job.label}: NN share of |d̂| {100 * share['share_of_estimate']:.1f} %",
                            self.style(job)["color"])
            row[0].set_ylabel("d_R [rad/s²]")
            shares.append((job.label, f"{100 * share['share_of_estimate']:.1f} % of the estimate, "
                                      f"{100 * share['share_of_u']:.1f} % of |u|"))
        axes[0, 0].set_title(self._title("The NN's share: NDO part, NN part, true d (right wheel)"))
        axes[0, 1].set_title(f"zoom: t = {t0:.2f} – {t1:.2f} s")
        axes[0, 2].set_title("the NN part alone (own scale)")
        axes[0, 1].set_xlim(t0, t1)
        axes[0, 1].legend(loc="lower right", fontsize=7)
        for ax in axes[-1]:
            ax.set_xlabel("t [s]")
        self._save(fig, "nn_share", "The NN's share of the disturbance estimate",
                   f"Per NNO job (each reading of the NN parameters): the NDO part d̂_NDO (orange), the NN part d̂_NN "
                   f"(sky blue) and the true d (grey dashed), right wheel; middle: zoom into the roughest stretch "
                   f"(highlighted); right: the NN part alone on its own scale. {self.paper_says('nn_share')} Ours "
                   f"(seed {self.seed}, both wheels; share = mean |d̂_NN| / mean |d̂_NDO + d̂_NN|, voltage share = "
                   f"mean |g⁻¹ d̂_NN| / mean |u|) — {_listing(shares)}.")

    def fig_voltage(self, plt):
        t0, t1 = self._zoom_window()
        fig, axes = self._panel_grid(plt, len(self.jobs))
        for i, (row, job) in enumerate(zip(axes, self.jobs)):
            s = self._s(job)
            self._trace(row[0], job, "u_right", lw=0.9)
            self._trace(row[1], job, "u_right", window=S.window_mask(s["t"], t0, t1), full=True, lw=1.2)
            self._decorate_time(row[0], labels=i == 0)
            row[0].axvspan(t0, t1, color=OKABE_ITO["yellow"], alpha=0.35, zorder=0)
            self._row_label(row[0], job.label, self.style(job)["color"])
            row[0].set_ylabel("u_R [V]")
            for ax in row:
                ax.grid(alpha=0.3)
        clipped = self._robust_ylim(axes[0, 0], [a for j in self.jobs for a in self._arrays(j, "u_right")])
        axes[0, 0].set_title(self._title("Figs. 8/13: right-wheel control voltage", bands=True))
        axes[0, 1].set_title(f"zoom: t = {t0:.2f} – {t1:.2f} s (highlighted)")
        axes[0, 1].set_xlim(t0, t1)
        axes[-1, 0].set_xlabel("t [s]")
        axes[-1, 1].set_xlabel("t [s]")
        ours = []
        fig13 = self.paper["figure13_voltage_range_V"]
        for job in self.jobs:
            s = self._s(job)
            if self.scenario == "paper_2":
                lo, hi = S.range_in(s["t"], s["u_right"], t0, t1, q=(0, 100))
                ours.append((job.label, f"{lo:.1f}–{hi:.1f} V"))
            else:
                tv = float(np.sum(np.abs(np.diff(s["u_right"])))) / float(s["t"][-1] - s["t"][0])
                ours.append((job.label, f"{tv:.3g} V/s"))
        ours_text = (f"u_R range in the zoom window: {_listing(ours)} (paper: SMC-NDO "
                     f"{fig13['smc_ndo'][0]:g}–{fig13['smc_ndo'][1]:g} V, SMC-NDO-NNO {fig13['smc_ndo_nno'][0]:g}–"
                     f"{fig13['smc_ndo_nno'][1]:g} V)" if self.scenario == "paper_2"
                     else f"total variation of u_R per second: {_listing(ours)}")
        self._save(fig, "fig08_voltage", "Right-wheel control voltage with a zoom (paper Figs. 8 and 13)",
                   f"One row per controller (same y scale): the applied (saturated) voltage of the right wheel; right: "
                   f"full-resolution zoom into the roughest stretch (highlighted)."
                   + (" The y range fits t ≥ 1 s; the start-up transient is off-scale." if clipped else "")
                   + f"{self._band_note(self.jobs)} {self.paper_says('voltage')} Ours (seed {self.seed}) — "
                     f"{ours_text}.")

    def fig_sliding(self, plt):
        jobs = [j for j in self.jobs if any(k in (j.summary.get("parameters") or {}) for k in SMC_FAMILY_KEYS)]
        if not jobs:
            self.notes.append(f"{self.scenario}: no sliding-mode controller; Fig. 9 skipped")
            return
        sigma = self.paper["figure9_smc_sigma"]
        show_paper = self.scenario == "paper_1" and any(j.controller == "smc" for j in jobs)
        fig, axes = plt.subplots(len(jobs), 2, figsize=(12, _height(1.0, 1.55, len(jobs))), squeeze=False, sharex=True,
                                 sharey=True)
        for i, (row, job) in enumerate(zip(axes, jobs)):
            for ax, wheel in zip(row, ("right", "left")):
                self._decorate_time(ax, labels=i == 0)
                self._trace(ax, job, f"s_{wheel}", lw=0.9)
                ax.axhline(0, color="0.3", lw=0.6)
                if show_paper and job.controller == "smc":
                    line = ax.axhline(sigma[wheel], color=OKABE_ITO["vermillion"], ls=":", lw=1.2,
                                      label=f"paper's SMC σ ≈ {sigma[wheel]:g}")
                    ax.legend(handles=[line], loc="lower right", fontsize=7)
                ax.grid(alpha=0.3)
            self._row_label(row[0], job.label, self.style(job)["color"])
            row[0].set_ylabel("s [rad/s]")
        arrays = [a for j in jobs for w in ("right", "left") for a in self._arrays(j, f"s_{w}")]
        clipped = self._robust_ylim(axes[0, 0], arrays,
                                    extra=[sigma["right"], sigma["left"]] if show_paper else ())
        axes[0, 0].set_title(self._title("Fig. 9: sliding variable, right wheel", bands=True))
        axes[0, 1].set_title("left wheel")
        axes[-1, 0].set_xlabel("t [s]")
        axes[-1, 1].set_xlabel("t [s]")
        ours = []
        for job in jobs:
            s = self._s(job)
            r, l = (S.mean_in(s["t"], s[f"s_{w}"], 1.0) for w in ("right", "left"))
            ours.append((job.label, f"{r:+.2f} / {l:+.2f}"))
        smc = next((j for j in jobs if j.controller == "smc"), None)
        if smc is not None and show_paper:
            s = self._s(smc)
            within = max(abs(S.mean_in(s["t"], s[f"s_{w}"], 1.0)) for w in ("right", "left"))
            lead = (f"the SMC σ sits within ±{within:.2g} of 0 on average (paper: near {sigma['right']:g} and "
                    f"{sigma['left']:g}); ")
        else:
            lead = ""
        self._save(fig, "fig09_sliding", "Sliding variable of both wheels (paper Fig. 9)",
                   "s = w_d − w per wheel (columns) for the sliding-mode controllers (rows, same y scale)"
                   + (", with the level the paper reports for SMC (dotted)" if show_paper else "") + "."
                   + (" The y range fits t ≥ 1 s; the start-up transient is off-scale." if clipped else "")
                   + f"{self._band_note(jobs)} {self.paper_says('sliding')} Ours (seed {self.seed}) — {lead}mean s "
                     f"for t ≥ 1 s (right / left, rad/s): {_listing(ours)}.")

    def fig_environment(self, plt):
        s = self._s(self.ref)
        if np.allclose(s["damping_scale"], 1.0):
            return  # no parametric uncertainty in this scenario: Fig. 10 belongs to scenario 2
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True)
        ax1.plot(s["t"], s["roughness"], color="0.2", lw=1.2, drawstyle="steps-post")
        ax1.set(ylabel="roughness amplitude [rad/s²]",
                title=self._title("Fig. 10: terrain roughness and damping (electromechanical resistance)"))
        idx = thin(s["damping_scale"])
        ax2.plot(s["t"][idx], s["damping_scale"][idx], color=OKABE_ITO["vermillion"], lw=1.0)
        ax2.axhline(1.0, color="0.3", ls=":", lw=0.8)
        ax2.set(xlabel="t [s]", ylabel="B_true / B_nominal [–]")
        for ax in (ax1, ax2):
            self._decorate_time(ax, labels=ax is ax1)
            ax.grid(alpha=0.3)
        ours = []
        for a, b, name in self._spans():
            lo, hi = S.range_in(s["t"], s["damping_scale"], a, b, q=(0, 100))
            rough = sorted({float(v) for v in np.unique(s["roughness"][S.window_mask(s["t"], a, b)])})
            ours.append((name.replace("phase: ", ""), f"roughness {'/'.join(f'{v:g}' for v in rough)}, "
                                                      f"B/B_nom {lo:.2f}–{hi:.2f}"))
        self._save(fig, "fig10_environment", "Roughness and damping profile (paper Fig. 10)",
                   f"The roughness amplitude the terrain applies and the true viscous damping relative to its nominal "
                   f"value (the parametric uncertainty); {self._spans_text()}. {self.paper_says('environment')} "
                   f"Ours (seed {self.seed}) — {'; '.join(f'{n}: {v}' for n, v in ours)}.")

    def fig_spectrum(self, plt):
        dt = float(self.ref.summary.get("dt") or self.ref.setting("simulation.dt") or 0.0)
        if not dt > 0:
            self.notes.append(f"{self.scenario}: no time step in the summaries; voltage spectra skipped")
            return
        cutoff = S.hf_cutoff(flatten(self.ref.config))
        spectra = {j.key: S.welch_u(self._s(j), dt) for j in self.jobs}
        fig, ax = plt.subplots(figsize=(11, 4.5))
        order = draw_order([np.log10(spectra[j.key][1][1:] + 1e-30) for j in self.jobs],
                           [self.style(j)["lw"] for j in self.jobs])
        for i in order:
            job = self.jobs[i]
            f, p = spectra[job.key]
            ax.plot(f[1:], p[1:], label=job.label, **self.style(job))
        ax.axvline(cutoff, color="0.2", lw=1.0, ls="--")
        ax.text(cutoff, 0.98, f" {cutoff:g} Hz: hf_fraction cutoff", transform=ax.get_xaxis_transform(),
                ha="left", va="top", fontsize=8)
        log_scale(ax, "x")
        log_scale(ax)
        ax.set(xlabel="frequency [Hz]", ylabel="PSD of u [V²/Hz] (mean of both wheels)",
               title=self._title("Chattering in frequency: Welch spectrum of the applied voltage"))
        ax.grid(alpha=0.3, which="both")
        _legend(ax, self._labels())
        hf = []
        for job in self.jobs:
            vals = self.data.ok_metrics(job)["hf_fraction"].astype(float)
            hf.append((job.label, f"{100 * float(vals.mean()):.2g} %" if vals.notna().any() else "–"))
        self._save(fig, "spectrum_u", "Welch spectrum of the control voltage",
                   f"Power spectral density of u − mean(u) over the whole run (Welch's method, Hann windows of "
                   f"2 s, half overlap; mean of both wheels), log-log; dashed: the {cutoff:g} Hz cutoff of the "
                   f"hf_fraction metric. {self.paper_says('spectrum')} Ours — fraction of var(u) above {cutoff:g} Hz "
                   f"(hf_fraction, mean over seeds): {_listing(hf)}.")

    def swept(self) -> dict[str, list[Job]]:
        """Per controller with several jobs on this scenario (a sweep over some setting), its jobs; empty when
        the realism section draws them (:mod:`ddmr_cli.report.realism`)."""
        from ddmr_cli.report import realism

        groups: dict[str, list[Job]] = {}
        for job in self.all_jobs:
            groups.setdefault(job.controller, []).append(job)
        groups = {c: js for c, js in groups.items() if len(js) > 1}
        if groups and realism.present(self.data):
            return {}
        return groups

    def fig_sweep(self, plt):
        """The sweep at a glance: per controller with several jobs, the deviation and chattering (steady state
        when the jobs have it) against the setting its jobs differ in, mean and 5-95 % band over the seeds."""
        groups = self.swept()
        if not groups:
            return
        m = self.data.metrics
        ok = m[m["status"] == "ok"]
        metrics = [(c if f"{c}_ss" not in m.columns else f"{c}_ss", label) for c, label in
                   (("deviation_mae", "deviation MAE [mm]"), ("chattering", "chattering [V/s]"))]
        levels = sorted(dict.fromkeys(_setting(j) for js in groups.values() for j in js), key=_level_order)
        keys = list(dict.fromkeys(o.partition("=")[0].lstrip("+~") for js in groups.values() for j in js
                                  for o in j.extra))
        width = min(max(7.0, 0.45 * len(levels) + 4.5), MAX_INCHES)
        fig, axes = plt.subplots(len(metrics), 1, figsize=(width, 6.5), sharex=True, squeeze=False)
        xs = {level: i for i, level in enumerate(levels)}
        for ax, (metric, ylabel) in zip(axes[:, 0], metrics):
            scale = 1000.0 if metric.startswith("deviation") else 1.0
            for controller, jobs in groups.items():
                pts = [(xs[_setting(job)], *b) for job in jobs if (b := _band(ok, job, metric, scale))]
                if not pts:
                    continue
                x, mean, lo, hi = (np.array(c) for c in zip(*sorted(pts)))
                style = self.styles[controller]
                ax.plot(x, mean, color=style.color, ls=style.kwargs()["ls"], marker=style.marker or "o", ms=3.5,
                        lw=1.2, label=jobs[0].display.label)
                ax.fill_between(x, lo, hi, color=style.color, alpha=BAND_ALPHA, lw=0)
            if np.all([v > 0 for line in ax.get_lines() for v in line.get_ydata()]) and ax.get_lines():
                log_scale(ax)
            ax.set_ylabel(ylabel + (" (steady state)" if metric.endswith("_ss") else ""))
            ax.grid(alpha=0.3, which="both")
        bottom = axes[-1, 0]
        bottom.set_xticks(range(len(levels)), [_short(level) for level in levels],
                          rotation=30 if len(levels) > 5 else 0, ha="right" if len(levels) > 5 else "center",
                          fontsize=7 if len(levels) > 12 else 8)
        bottom.set_xlabel(", ".join(keys) or "swept setting")
        axes[0, 0].set_title(f"The sweep at a glance — {self.scenario}: mean and 5–95 % band over seeds")
        _legend(axes[0, 0])
        drawn = ", ".join(j.label for j in self.jobs)
        self._save(fig, "sweep", "The sweep at a glance: one line per controller over the swept setting",
                   f"{len(self.all_jobs)} jobs on this scenario; per controller, its jobs' deviation (mm) and "
                   f"chattering (mean over seeds, 5–95 % band) against the setting they differ in. The time-series "
                   f"figures below draw {len(self.jobs)} of them ({drawn})"
                   + ("." if len(self.jobs) == len(self.all_jobs) else
                      "; every job's numbers are in tables/statistics.csv."))

    def fig_multiples(self, plt):
        """Every job of a scenario with more than the figures draw (a sweep), in small multiples: per controller,
        pages of at most :data:`MULTIPLES` panels, each the deviation of the job's first kept seed against time
        (log scale, shared), titled by its setting (``ddmr report --all-figures``)."""
        if len(self.jobs) == len(self.all_jobs):
            return
        for controller in dict.fromkeys(j.controller for j in self.all_jobs):
            jobs = sorted((j for j in self.all_jobs if j.controller == controller), key=_sweep_order)
            for page in range(0, len(jobs), MULTIPLES):
                chunk = jobs[page:page + MULTIPLES]
                rows = math.ceil(len(chunk) / 4)
                fig, axes = plt.subplots(rows, 4, figsize=(12, 0.8 + 1.7 * rows), sharex=True, sharey=True,
                                         squeeze=False)
                for ax, job in zip(axes.flat, chunk):
                    seeds = job.series_seeds
                    if not seeds or not (job.dir / io.SERIES).is_file():
                        ax.text(0.5, 0.5, "no kept series", transform=ax.transAxes, ha="center", fontsize=7)
                    else:  # two channels of one seed, not cached: a large sweep's series would not fit in memory
                        s = io.read_series(job.dir / io.SERIES, ("t", "deviation"))[seeds[0]]
                        idx = thin(s["deviation"], 1500)
                        ax.plot(s["t"][idx], 1000 * s["deviation"][idx], **{**self.style(job), "marker": None})
                        if (s["deviation"] > 0).any():
                            log_scale(ax)
                    ax.set_title(_short(_setting(job), 34), fontsize=8)
                    ax.grid(alpha=0.3, which="both")
                for ax in list(axes.flat)[len(chunk):]:
                    ax.axis("off")
                for ax in axes[:, 0]:
                    ax.set_ylabel("deviation [mm]", fontsize=8)
                label = chunk[0].display.label
                part = f" ({page // MULTIPLES + 1} of {math.ceil(len(jobs) / MULTIPLES)})" if len(jobs) > MULTIPLES else ""
                fig.suptitle(f"{label}: every job of the sweep — {self.scenario}, its first kept seed{part}",
                             fontsize=10)
                self._save(fig, f"multiples_{safe_name(controller)}_{page // MULTIPLES + 1}",
                           f"Every {label} job, one panel each{part}",
                           f"Deviation from the reference (mm, log scale, shared axes) of each {label} job's first "
                           f"kept seed, titled by the setting the job differs in.")

    def fig_spread(self, plt):
        values, labels, colors = [], [], []
        for job in self.jobs:
            values.append(self.data.ok_metrics(job)["deviation_mae"].astype(float).dropna().to_numpy())
            labels.append(job.label)
            colors.append(self.style(job)["color"])
        fig, ax = plt.subplots(figsize=(min(max(6, 1.6 * len(self.jobs) + 2), MAX_INCHES), 4.2))
        if any(v.size for v in values):
            box = ax.boxplot([v if v.size else [np.nan] for v in values], widths=0.5, showfliers=False,
                             patch_artist=True, medianprops={"color": "k"})
            for patch, c in zip(box["boxes"], colors):
                patch.set(facecolor=c, alpha=0.25, edgecolor=c)
            rng = np.random.default_rng(0)
            for i, (v, c) in enumerate(zip(values, colors), start=1):
                ax.scatter(i + rng.uniform(-0.15, 0.15, v.size), v, s=10, color=c, alpha=0.8, zorder=3)
        crowded = len(labels) > 4 or sum(map(len, labels)) > 60  # long labels (a sweep's settings) overlap
        ax.set_xticks(range(1, len(labels) + 1), labels, rotation=15 if crowded else 0, ha="right" if crowded else "center")
        log_scale(ax)
        ax.set(ylabel="deviation MAE per seed [m] (log scale)",
               title=f"Spread of the deviation MAE over seeds — {self.scenario}")
        ax.grid(alpha=0.3, axis="y", which="both")
        paper = self.paper["table4"]["rows"]
        names = self.paper["controller_names"]
        ours = [(l, _mm(float(np.std(v, ddof=1))) if v.size > 1 else "–") for l, v in zip(labels, values)]
        theirs = [(n, _mm(r["deviation_sd"])) for n, r in paper.items()]
        paper_text = (f"Paper — Table 4 SD over {self.paper['table4']['runs']} runs: {_listing(theirs)}."
                      if self.scenario == "paper_1" else
                      "Paper — Table 4 is compared with scenario 1 only.")
        self._save(fig, "deviation_spread", "Per-seed spread of the deviation MAE",
                   f"One point per seed (non-diverged runs), box: quartiles and median. {paper_text} Ours — SD over "
                   f"seeds: {_listing(ours)}" + (" (names map to the paper's rows as in Table 4)."
                                                 if any(j.controller in names for j in self.jobs) else "."))


def _band(ok, job: Job, metric: str, scale: float = 1.0) -> tuple[float, float, float] | None:
    """Mean, 5th and 95th percentile over the job's seeds of ``metric`` (times ``scale``) in the metrics rows
    ``ok``; None when it has no finite value."""
    v = scale * ok.loc[ok["job"] == job.dir.name, metric].astype(float).to_numpy()
    v = v[np.isfinite(v)]
    return (float(v.mean()), float(np.percentile(v, 5)), float(np.percentile(v, 95))) if v.size else None


def _setting(job: Job) -> str:
    """What sets a job apart from its controller's other jobs: its distinguishing overrides' values."""
    return ", ".join(o.partition("=")[2] or o for o in job.extra) or "(default)"


def _sweep_order(job: Job) -> tuple:
    """Sort key of a sweep's jobs: on a realism axis (ideal first, then each effect from mild to harsh), else by
    :func:`_level_order` of the setting."""
    from ddmr_cli.report.realism import EFFECTS, classify

    place = classify(job)
    effects = ["ideal", *EFFECTS, "combined"]
    if place.effect in effects and (place.effect != "ideal" or not job.extra or "ideal" in _setting(job)):
        worse_up = EFFECTS.get(place.effect, ("", "", True))[2]
        level = place.level if math.isfinite(place.level) else 0.0
        return (0, effects.index(place.effect), level if worse_up else -level, _setting(job))
    return (1, 0, 0.0, "", *_level_order(_setting(job)))


def _level_order(level: str) -> tuple:
    """Sort key of a swept setting's text: numerically when it is one number, else as text, numbers first."""
    try:
        return (0, float(level), "")
    except ValueError:
        return (1, 0.0, level)


def _short(text: str, width: int = 28) -> str:
    return text if len(text) <= width else text[:width - 1] + "…"


def common_seed(jobs: list[Job]) -> int | None:
    """The first kept seed common to every job (None when there is none)."""
    if not jobs or not all((j.dir / io.SERIES).is_file() for j in jobs):
        return None
    common = set(jobs[0].series_seeds)
    for j in jobs[1:]:
        common &= set(j.series_seeds)
    ordered = [s for s in jobs[0].series_seeds if s in common]
    return ordered[0] if ordered else None


FIGURE_METHODS = ("fig_sweep", "fig_terrain", "fig_trajectory", "fig_deviation", "fig_pose_errors", "fig_disturbance",
                  "fig_nn_share", "fig_voltage", "fig_spectrum", "fig_sliding", "fig_environment", "fig_spread",
                  "fig_multiples")
#: Figures drawn only when every figure is asked for (``ddmr report --all-figures``): a sweep's jobs one by one.
ON_DEMAND = ("fig_multiples",)


#: Our Table 4 beside the paper's (:func:`fig_table4`): a figure task like the others (:func:`figure_tasks`, first),
#: drawn in a figure process from the report's data; its figure goes in the report's Table 4 section
TABLE4_TASK = (None, "fig_table4")


def table4_rows(t4):
    """The rows of ``t4`` (:func:`ddmr_cli.report.tables.table4_frame`) that have a paper row: what
    :func:`fig_table4` draws (no figure without them)."""
    return t4[t4["paper_row"].astype(str) != ""]


def table4_figure(out_dir: Path) -> Figure:
    """The figure :func:`fig_table4` writes into ``out_dir``: its path, title and caption."""
    return Figure(Path(out_dir) / "table4_vs_paper.png", "Our Table 4 beside the paper's",
                  "Scenario 1 (the paper's Table 4 does not say which scenario it reports), whole-run MAE; our bar in "
                  "each controller's colour, the paper's hatched grey; on the deviation, the SD over seeds as an error "
                  "bar. The paper prints e_θ in m; it is rad (here mrad).")


def fig_table4(t4, out_dir: Path, styles: StyleBook, displays: dict) -> Figure | None:
    """Our Table 4 beside the paper's: per column (deviation mean with its SD over seeds, e_x, e_y, e_θ MAE) and
    per row compared with the paper (scenario 1), our bar in the controller's colour and the paper's hatched grey,
    linear from 0, millimetres (mrad); ``t4`` is :func:`ddmr_cli.report.tables.table4_frame`. None without such rows
    (:func:`table4_rows`)."""
    from ddmr_cli.paper import TABLE4_COLUMNS

    rows = table4_rows(t4)
    if rows.empty:
        return None
    plt = pyplot()
    columns = [c for c in TABLE4_COLUMNS if c[1] == "mean"]
    fig, axes = plt.subplots(1, len(columns), figsize=(min(3.2 * len(columns) + 1.0, MAX_INCHES), 3.8))
    x = np.arange(len(rows))
    for ax, (metric, _, col, header) in zip(axes, columns):
        ours, theirs = 1000 * rows[col].astype(float).to_numpy(), 1000 * rows[f"paper_{col}"].astype(float).to_numpy()
        err = 1000 * rows["deviation_sd"].astype(float).to_numpy() if col == "deviation_mean" else None
        perr = 1000 * rows["paper_deviation_sd"].astype(float).to_numpy() if col == "deviation_mean" else None
        colors = [styles[c].color for c in rows["controller"]]
        ax.bar(x - 0.2, ours, 0.4, yerr=err, color=colors, edgecolor="k", lw=0.5, capsize=2, label="ours")
        ax.bar(x + 0.2, theirs, 0.4, yerr=perr, color="0.85", edgecolor="0.4", hatch="///", lw=0.5, capsize=2,
               label="paper")
        ax.set_ylim(bottom=0)  # linear from 0: a bar's length is its value
        unit = "mrad" if "theta" in metric else "mm"
        ax.set_title(header.split(" (")[0] + f" [{unit}]", fontsize=9)
        ax.set_xticks(x, [_short(displays[c].label, 14) for c in rows["controller"]], rotation=30, ha="right",
                      fontsize=8)
        ax.grid(alpha=0.3, axis="y", which="both")
    axes[0].legend(loc="upper right", fontsize=7)
    fig.suptitle("Table 4, scenario 1: ours (colour, SD over seeds as error bar) beside the paper's (hatched)",
                 fontsize=10)
    figure = table4_figure(out_dir)
    save(fig, figure.path)
    return figure


#: The figures every scenario gets. A scenario on the paper's reference (its line: the figures the paper draws)
#: gets every one of :data:`FIGURE_METHODS`; one on another reference (``paper_1@circle``) only these, unless
#: every figure is asked for (``ddmr report --all-figures``): a large sweep's report draws what is read first.
SUMMARY_METHODS = ("fig_sweep", "fig_trajectory", "fig_deviation", "fig_spread")
#: The task of the figure across all scenarios (:func:`fig_scenarios`); its figures are listed under this key.
ACROSS = ""


def detailed(data: ReportData, scenario: str) -> bool:
    """Whether ``scenario`` gets every figure by default: its jobs track the paper's reference."""
    from ddmr_cli.report.data import PAPER_TRAJECTORY

    return any(j.trajectory == PAPER_TRAJECTORY for j in data.jobs if j.scenario == scenario)


def figure_tasks(data: ReportData, every: bool = False) -> list[tuple[str, str]]:
    """The figure tasks ``(scenario, method)`` of a report, the summaries first: our Table 4 beside the paper's
    (:data:`TABLE4_TASK`), the figure across scenarios when there are more than two, then per scenario its figures
    (every one with ``every``, else as :data:`SUMMARY_METHODS` says)."""
    tasks = [TABLE4_TASK] + ([(ACROSS, "fig_scenarios")] if len(data.scenarios) > 2 else [])
    for scenario in data.scenarios:
        methods = FIGURE_METHODS if every or detailed(data, scenario) else SUMMARY_METHODS
        tasks += [(scenario, m) for m in FIGURE_METHODS if m in methods and (every or m not in ON_DEMAND)]
    return tasks


def fig_scenarios(data: ReportData, out_dir: Path, styles: StyleBook, plt) -> list[Figure]:
    """Every scenario at a glance: per controller (one job per scenario, :func:`shown_jobs`) its deviation and
    chattering (steady state when the jobs have it), mean and 5-95 % band over the seeds, one line per
    controller over the scenarios."""
    m = data.metrics
    ok = m[m["status"] == "ok"]
    metrics = [(c if f"{c}_ss" not in m.columns else f"{c}_ss", label) for c, label in
               (("deviation_mae", "deviation MAE [mm]"), ("chattering", "chattering [V/s]"))]
    scenarios = data.scenarios
    shown = {s: shown_jobs([data.job(s, k) for k in data.keys(s)]) for s in scenarios}
    controllers = list(dict.fromkeys(j.controller for s in scenarios for j in shown[s]))
    width = min(max(8.0, 0.9 * len(scenarios) + 4.5), MAX_INCHES)
    fig, axes = plt.subplots(len(metrics), 1, figsize=(width, 6.5), sharex=True, squeeze=False)
    for ax, (metric, ylabel) in zip(axes[:, 0], metrics):
        scale = 1000.0 if metric.startswith("deviation") else 1.0
        for controller in controllers:
            pts = []
            for i, scenario in enumerate(scenarios):
                job = next((j for j in shown[scenario] if j.controller == controller), None)
                if job is not None and (b := _band(ok, job, metric, scale)):
                    pts.append((i, *b))
            if not pts:
                continue
            x, mean, lo, hi = (np.array(c) for c in zip(*pts))
            style = styles[controller]
            ax.plot(x, mean, color=style.color, ls=style.kwargs()["ls"], marker=style.marker or "o", ms=3.5, lw=1.2,
                    label=data.displays()[controller].label)
            ax.fill_between(x, lo, hi, color=style.color, alpha=BAND_ALPHA, lw=0)
        if ax.get_lines() and all((line.get_ydata() > 0).all() for line in ax.get_lines()):
            log_scale(ax)
        ax.set_ylabel(ylabel + (" (steady state)" if metric.endswith("_ss") else ""))
        ax.grid(alpha=0.3, which="both")
    axes[-1, 0].set_xticks(range(len(scenarios)), [_short(s) for s in scenarios], rotation=20, ha="right")
    axes[-1, 0].set_xlabel("scenario (@ the reference when not the paper's line)")
    axes[0, 0].set_title("Every scenario at a glance: mean and 5–95 % band over seeds")
    _legend(axes[0, 0])
    path = save(fig, Path(out_dir) / "scenarios.png")
    return [Figure(path, "Every scenario at a glance: one line per controller over the scenarios",
                   f"{len(scenarios)} scenarios; per controller its deviation (mm) and chattering, mean over seeds "
                   f"and 5–95 % band (one job per controller and scenario; every number in Table 4 and "
                   f"tables/statistics.csv).")]


def make_one(data: ReportData, out_dir: Path, styles: StyleBook, task: tuple[str, str]):
    """One figure task ``(scenario, method)``: its figures and notes."""
    scenario, method = task
    if task == TABLE4_TASK:
        figure = fig_table4(table4_frame(stats_frame(data)), out_dir, styles, data.displays())
        return ([] if figure is None else [figure]), []
    if scenario == ACROSS:
        return fig_scenarios(data, out_dir, styles, pyplot()), []
    sf = ScenarioFigures(data, scenario, out_dir, styles)
    if sf.seed is None and method not in ("fig_spread", "fig_sweep", "fig_multiples"):
        if method == "fig_terrain":
            sf.notes.append(f"{scenario}: no kept time-series seed common to every job (run.keep_series); "
                            f"time-series figures skipped")
        return [], sf.notes
    getattr(sf, method)(pyplot())
    return sf.figures, sf.notes


#: the figure processes' niceness above the report's process: with as many processes as cores plus the report's
#: own, the verdicts come first (printed by ``ddmr report`` before the figures are done) while the figures take
#: whatever CPU is left; the report's whole wall time is the figures' either way. table4's report, 3 pairs:
#: verdicts after 4.0-5.9 s against 5.4-8.4 s at equal priority, done at 11.4-13.2 s against 11.4-16.1 s
FIGURE_NICE = 10


def _worker(data, out_dir, styles, tasks, results, watch) -> None:
    """A figure process: takes ``(i, task)`` from ``tasks`` until None, puts ``(i, result, error)``. ``watch`` is the
    read end of a pipe whose write end only the report's process holds, and never writes to: it reads as ready once
    that process is gone, and then this one takes no further task (a killed report's figure processes end with the
    figure they are drawing, not with the report's last one)."""
    import queue

    while not watch.poll():
        try:
            item = tasks.get(timeout=1.0)
        except queue.Empty:
            continue
        if item is None:
            return
        i, task = item
        try:
            results.put((i, make_one(data, out_dir, styles, task), None))
        except BaseException:  # noqa: BLE001 - reported to the parent, which raises it
            results.put((i, None, traceback.format_exc()))


def _lead(data, out_dir, styles, tasks, results, n: int, watch, keep) -> None:
    """The first figure process, at :data:`FIGURE_NICE`: imports and initialises matplotlib (:func:`_warm_up`),
    then starts ``n - 1`` more figure processes, forked from itself so that they share what it loaded, and works
    as one of them (:func:`_worker`); it ends when they all have. The report's own process never imports pyplot for
    its figures: it goes on to its tables and verdicts while this process loads (table4's report: the verdicts 0.6 s
    sooner, medians of 5 alternating runs), and the import is paid once, as before. ``keep``: this process's copy of
    the write end of ``watch``'s pipe, closed first (:func:`_worker`)."""
    import multiprocessing
    import os

    keep.close()
    try:
        os.nice(FIGURE_NICE)
    except OSError:  # not allowed here: drawn at the parent's priority
        pass
    try:
        _warm_up()
    except Exception:  # noqa: BLE001 - each task then fails and reports why, as without the warm-up
        pass
    ctx = multiprocessing.get_context("fork")
    helpers = [ctx.Process(target=_worker, args=(data, out_dir, styles, tasks, results, watch), daemon=True)
               for _ in range(n - 1)]
    for p in helpers:
        p.start()
    _worker(data, out_dir, styles, tasks, results, watch)
    for p in helpers:
        p.join()


def workers(n_tasks: int) -> int:
    """Figure processes: forked on Linux (they inherit the loaded data, nothing is pickled but the results), at
    most 4, else one; ``DDMR_REPORT_WORKERS`` overrides the count."""
    import multiprocessing
    import os
    import sys

    if not sys.platform.startswith("linux") or "fork" not in multiprocessing.get_all_start_methods():
        return 1  # fork is unsafe on macOS and absent on Windows
    env = os.environ.get("DDMR_REPORT_WORKERS", "")
    n = int(env) if env.isdigit() and int(env) > 0 else min(os.cpu_count() or 1, 4)
    return max(1, min(n, n_tasks))


def _start_forked(data, out_dir, styles, tasks, n: int):
    """``n`` forked figure processes (:func:`_lead` and the ``n - 1`` it forks), given every task; :func:`_collect`
    gathers their results. The returned process list holds the lead alone: it is alive until every figure process
    has ended; the last item is the write end of the pipe the figure processes watch (:func:`_worker`), held here
    until :func:`_collect` ends."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    task_q, result_q = ctx.Queue(), ctx.Queue()
    watch, keep = ctx.Pipe(duplex=False)
    lead = ctx.Process(target=_lead, args=(data, out_dir, styles, task_q, result_q, n, watch, keep), daemon=False)
    lead.start()
    watch.close()
    for item in enumerate(tasks):
        task_q.put(item)
    for _ in range(n):
        task_q.put(None)
    return [lead], result_q, tasks, keep


def _run_forked(data, out_dir, styles, tasks, n: int, done=lambda: None) -> list:
    return _collect(*_start_forked(data, out_dir, styles, tasks, n), done=done)


def _collect(procs, result_q, tasks, keep=None, done=lambda: None) -> list:
    """The results of the figure processes, in task order (a task's failure raised here; ``done()`` called as
    each arrives); the processes ended: ``keep`` (:func:`_start_forked`) is closed first, so that after a failure
    they take no further task."""
    import queue

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
            done()
    finally:
        if keep is not None:
            keep.close()
        for p in procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
    return results


def _warm_up() -> None:
    """Import and initialise what every figure process needs (matplotlib's fonts and text layout), in the process
    the others are forked from (:func:`_lead`), so that they share it instead of each paying for it."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [0, 1], label="d̂ σ θ")
    ax.set_title("warm-up")
    ax.legend()
    fig.canvas.draw()
    plt.close(fig)


def make_figures(data: ReportData, out_dir: Path, styles: StyleBook | None = None, every: bool = False,
                 done=lambda: None) -> tuple[dict[str, list[Figure]], list[str]]:
    """The report's figures (:func:`figure_tasks`; every one with ``every``), per scenario (the figure across
    scenarios under :data:`ACROSS`, first), drawn in forked processes when the machine has several cores;
    returns them and notes on what was skipped. ``done()`` is called as each figure task ends (the report's
    progress bar)."""
    return start_figures(data, out_dir, styles, every, done)()


def start_figures(data: ReportData, out_dir: Path, styles: StyleBook | None = None, every: bool = False,
                  done=lambda: None):
    """Start drawing :func:`make_figures`' figures in forked processes (the caller goes on with its tables
    meanwhile); returns the function that waits for them and returns what :func:`make_figures` returns. With one
    process the figures are drawn when that function is called. ``done()`` is called as each figure task's
    result is gathered."""
    styles = styles or StyleBook((j.controller for j in data.jobs), data.displays())
    tasks = figure_tasks(data, every)
    for scenario in data.scenarios:  # read the series (and bands) once, before any fork
        ScenarioFigures(data, scenario, out_dir, styles)
    n = workers(len(tasks))
    if n > 1:
        started = _start_forked(data, Path(out_dir), styles, tasks, n)
        return lambda: _gather(data, tasks, _collect(*started, done=done))

    def draw_here():
        results = []
        for task in tasks:
            results.append(make_one(data, Path(out_dir), styles, task))
            done()
        return _gather(data, tasks, results)

    return draw_here


def _gather(data: ReportData, tasks, results) -> tuple[dict[str, list[Figure]], list[str]]:
    figures: dict[str, list[Figure]] = {s: [] for s in dict.fromkeys(s for s, _ in tasks)}
    notes: list[str] = []
    for (scenario, _), (figs, task_notes) in zip(tasks, results):
        figures[scenario] += figs
        notes += task_notes
    return figures, notes
