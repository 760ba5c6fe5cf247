"""Assemble ``report.md``, ``tables/*.csv`` and ``figures/*.png`` for a sweep or run dir."""

from __future__ import annotations

import math
import os
import shlex
from pathlib import Path

import numpy as np

from ddmr_cli.storage import io, jobdir
from ddmr_cli.engine.catalog import METRICS
from ddmr_cli.report import signals as S
from ddmr_cli.report import tables as T
from ddmr_cli.report import realism
from ddmr_cli.report import verdicts as V
from ddmr_cli.paper import PAPER_SCENARIO
from ddmr_cli.paper import numbers as paper_numbers
from ddmr_cli.report.data import Job, ReportData, flatten, load
from ddmr_cli.report.figures import (ACROSS, TABLE4_TASK, common_seed, detailed, figure_tasks, shown_jobs,
                                     start_figures, table4_figure, table4_rows)
from ddmr_cli.plots.common import OKABE_ITO, StyleBook
from ddmr_cli.report.stats import Margin

#: Settings shown in the configuration section (dotted config keys).
KEY_SETTINGS = ("simulation.dt", "simulation.duration", "simulation.integrator", "simulation.initial_pose",
                "simulation.divergence_bound", "run.n_runs", "run.base_seed", "run.keep_series", "terrain.name",
                "terrain.correlation_time", "trajectory._target_", "trajectory.speed", "outer_loop.k_x",
                "outer_loop.k_y", "outer_loop.k_theta", "robot.max_voltage")


def _fmt_value(v) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt_value(x) for x in v) + "]"
    return str(v)


def _params(params: dict) -> str:
    return "; ".join(f"{k} = {_fmt_value(v)}" for k, v in params.items())


def nn_reading(params: dict) -> str | None:
    if "gamma" not in params or "sigma" not in params:
        return None
    gamma, sigma = float(params["gamma"]), float(params["sigma"])
    if (gamma, sigma) == (50.0, 2.0):
        return "Table 3 / eq. (25) reading: learning rate γ = 50, RBF width σ = 2"
    if (gamma, sigma) == (2.0, 50.0):
        return "text reading: learning rate 2, RBF width 50"
    return f"custom: learning rate γ = {gamma:g}, RBF width σ = {sigma:g}"


class Report:
    """The report of ``data`` written into ``out`` (a staging dir: :func:`staged`); ``final`` is the dir it is
    moved into, the ``--out`` its markdown names (default ``out``)."""

    def __init__(self, data: ReportData, out: Path, margin: Margin | None = None, draw_figures: bool = True,
                 final: Path | None = None, step=None, all_figures: bool = False, on_verdicts=None):
        self.data, self.out, self.margin = data, out, margin or Margin()
        self.step = step or (lambda n=1: None)  # advances the report's progress bar
        #: called with the verdicts in plain text (:func:`~ddmr_cli.report.verdicts.answer_lines`) as soon as they
        #: are known: first of the sections, while the figure processes draw
        self.on_verdicts = on_verdicts
        self._results = None  # the verdicts (V.evaluate), once
        self.final = Path(final) if final is not None else Path(out)
        self.draw_figures = draw_figures
        self.all_figures = all_figures  # every figure of every scenario (figures.figure_tasks)
        self.pending_figures = None  # what start_figures returned: waits for the figures
        self.styles = StyleBook((j.controller for j in data.jobs), data.displays())
        self.tables_dir, self.figures_dir = out / "tables", out / "figures"
        self.md: list[str] = []
        self.csvs: list[tuple[str, Path]] = []

    # --- helpers -----------------------------------------------------------------------------------------
    def csv(self, name: str, frame, what: str) -> str:
        path = io.write_csv(self.tables_dir / name, frame)
        self.csvs.append((what, path))
        return self.link(path)

    def link(self, path: Path) -> str:
        rel = Path(path).relative_to(self.out).as_posix()
        return f"[{rel}]({rel})"

    def add(self, *lines: str) -> None:
        self.md.extend(lines)

    # --- sections ----------------------------------------------------------------------------------------
    def header(self) -> None:
        from ddmr_cli.version import __version__

        d = self.data
        kind = "run dir" if d.single_run else "sweep dir"
        self.add(f"# ddmr report: {d.path.name}", "",
                 f"From the {kind} `{d.path}` by ddmr {__version__}: {len(d.jobs)} complete job(s), "
                 f"{len(d.failed)} failed, {len(d.missing)} missing. Paper: *SMC integrated with NDO and RBF "
                 f"neural network for trajectory tracking of DDMRs considering terrain factor*; its numbers are "
                 f"shipped in `ddmr_cli/data/paper_numbers.json` (docs/model.md §8).", "")
        if d.running is not None:
            from ddmr_cli.storage.jobdir import describe_holder

            self.add(f"**Written while the {kind.split()[0]} was still running** ({describe_holder(d.running)}): "
                     f"its missing jobs may not have run yet. Run `ddmr report {d.path}` again when it has "
                     f"finished.", "")

    def configuration(self) -> None:
        d = self.data
        report_cmd = f"ddmr report {shlex.quote(str(d.path))}"
        if self.final != d.path / "report":
            report_cmd += f" --out {shlex.quote(str(self.final))}"
        if self.margin != Margin():
            m = self.margin
            spec = f"{1000 * m.metres:g}mm" if m.metres is not None else f"{100 * m.relative:g}%"
            report_cmd += f" --margin {shlex.quote(spec)}"
        self.add("## Configuration", "", "Regenerate the results (jobs already complete with the same config hash are "
                 "skipped) and this report:", "", "```sh", d.run_command(), report_cmd, "```", "")
        flat = {j.dir.name: flatten(j.config) for j in d.jobs}
        rows = []
        for key in KEY_SETTINGS:
            values = list(dict.fromkeys(_fmt_value(f.get(key)) for f in flat.values() if key in f))
            if values:
                rows.append([key, ", ".join(values) + (" (varies between jobs)" if len(values) > 1 else "")])
        seeds = list(dict.fromkeys(f"{j.summary['seeds'][0]}–{j.summary['seeds'][-1]}" for j in d.jobs
                                   if j.summary.get("seeds")))
        if seeds:
            rows.append(["seeds", ", ".join(seeds)])
        readings = list(dict.fromkeys(f"{j.controller}: {r}" for j in d.jobs
                                      if (r := nn_reading(j.summary.get("parameters") or {}))))
        rows.append(["NN-parameter reading (docs/model.md §6)", "; ".join(readings) if readings else "no NN observer"])
        steady = {k: _fmt_value(v) for f in flat.values() for k, v in f.items() if "steady" in k.lower()}
        rows += [[k, v] for k, v in sorted(steady.items())]
        self.add(T.md_table(["Setting", "Value"], rows), "")
        all_keys = set().union(*flat.values()) if flat else set()
        differ = sorted(k for k in all_keys if not k.startswith(("controller.", "scenario."))
                        and len({_fmt_value(f.get(k)) for f in flat.values()}) > 1)
        if differ:
            self.add("Settings that differ between jobs besides controller and scenario: "
                     + ", ".join(f"`{k}`" for k in differ) + ".", "")
        self.add("Jobs (the overrides each was run with):", "")
        jrows = []
        for j in sorted(d.jobs, key=lambda j: (d.scenarios.index(j.scenario), d.keys().index(j.key))):
            st = j.summary.get("statistics") or {}
            jrows.append([f"`{j.dir.name}`", j.label, j.scenario, st.get("runs", "–"), st.get("diverged", "–"),
                          " ".join(f"`{o}`" for o in j.overrides), T.fmt(j.summary.get("wall_time"), 3)])
        self.add(T.md_table(["Job", "Controller", "Scenario", "Runs", "Diverged", "Overrides", "Wall time (s)"],
                            jrows), "")

    def status(self) -> None:
        import pandas as pd

        d = self.data
        rows = [{"job": j.dir.name, "status": "complete", "controller": j.controller, "scenario": j.scenario,
                 "overrides": " ".join(j.overrides), "error": ""} for j in d.jobs]
        rows += [{"job": p.name, "status": s.get("status", "failed"), "controller": s.get("controller"),
                  "scenario": s.get("scenario"), "overrides": " ".join(map(str, s.get("overrides") or [])),
                  "error": s.get("error", "")} for p, s in d.failed]
        rows += [{"job": m["dir"], "status": "missing", "controller": "", "scenario": "",
                  "overrides": " ".join(map(str, m.get("overrides") or [])),
                  "error": "no summary.json (not finished yet: the sweep is still running)" if d.running is not None
                  else "no summary.json (not run, or killed before it finished)"} for m in d.missing]
        link = self.csv("jobs.csv", pd.DataFrame(rows), "every job and its status")
        self.add("## Missing or failed jobs", "")
        if not d.failed and not d.missing:
            self.add(f"None: every job of the {'run' if d.single_run else 'sweep'} is complete ({link}).", "")
            return
        self.add(f"**The report is partial**: {len(d.failed)} failed and {len(d.missing)} missing job(s); tables, "
                 f"verdicts and figures cover the complete jobs only ({link}).", "")
        self.add(T.md_table(["Job", "Status", "Overrides", "Error"],
                            [[f"`{r['job']}`", r["status"], r["overrides"], r["error"]] for r in rows
                             if r["status"] != "complete"]), "")

    def table3(self) -> None:
        import pandas as pd

        d = self.data
        paper = paper_numbers()["table3"]
        rows, seen = [], {}
        for key in d.keys():
            for j in d.jobs:
                if j.key != key:
                    continue
                params = j.summary.get("parameters") or {}
                sig = _params(params)
                if (key, sig) in seen:
                    seen[(key, sig)]["scenarios"].append(j.scenario)
                    continue
                row = {"controller": j.controller, "key": key, "label": j.label, "scenarios": [j.scenario],
                       **{f"param_{k}": v for k, v in params.items()}, "parameters": sig,
                       "paper_table3": paper["by_controller"].get(j.controller, "")}
                seen[(key, sig)] = row
                rows.append(row)
        for r in rows:
            r["scenarios"] = ",".join(r["scenarios"])
        link = self.csv("table3_parameters.csv", pd.DataFrame(rows), "Table 3: controller parameters")
        self.add("## Table 3: controller parameters", "",
                 f"From the jobs' summaries (the parameters each controller actually ran with), beside the paper's "
                 f"Table 3 ({link}). Symbols: docs/model.md §6 (λ reaching-law gain, K switching gain, Φ boundary layer, "
                 f"L NDO gain, n neurons, σ RBF width, γ learning rate).", "")
        self.add(T.md_table(["Controller", "Scenarios", "Ours", "Paper Table 3"],
                            [[r["label"], r["scenarios"], r["parameters"], r["paper_table3"] or "–"] for r in rows]),
                 "", f"Note: {paper['note']}", "")

    def table4(self, stats) -> None:
        d = self.data
        t4 = T.table4_frame(stats)
        link = self.csv("table4.csv", t4, "Table 4: tracking statistics with the paper's numbers")
        self.add("## Table 4: tracking performance over seeds", "",
                 f"Per scenario and controller, over the seeds that did not diverge: mean deviation (the mean over "
                 f"the run of the distance to the reference point, MAE), its SD across seeds, and the MAE of e_x, "
                 f"e_y, e_θ; runs and diverged runs counted ({link}). "
                 f"**The paper's Table 4 does not say which scenario it reports; it is compared against scenario 1 "
                 f"(`{PAPER_SCENARIO}`) only**: each of our numbers is followed by the paper's and the ratio "
                 f"ours/paper. Names map pid → PID, smc → SMC, smc_ndo → SMC+NDO, smc_ndo_nno → SMC-NDO-NN; "
                 f"**smc_ndo_nno_text (the other reading of the NN parameters, docs/model.md §6) is compared to the same "
                 f"SMC-NDO-NN row**. The paper prints e_θ in m; it is rad.", "")
        if T.has_ss(t4):
            self.add("**Steady-state columns are present** (`<metric>_ss` in the jobs' metrics.csv, the engine's "
                     "steady-state window): each table shows the whole-run block (compared with the paper) and the "
                     "steady-state block side by side; the deviation verdicts use the steady-state deviation.", "")
        if PAPER_SCENARIO not in d.scenarios:
            self.add(f"(No `{PAPER_SCENARIO}` job in this sweep: no comparison with the paper's numbers.)", "")
        for scenario in d.scenarios:
            self.add(f"### {scenario}" + (" (compared with the paper's Table 4)" if scenario == PAPER_SCENARIO
                                           else ""), "", T.md_table4(t4, scenario), "")
        self.add(f"The paper's Table 4 ({paper_numbers()['table4']['runs']} runs), for reference:", "")
        paper = paper_numbers()["table4"]["rows"]
        self.add(T.md_table(["Paper row"] + [h for *_, h in T.TABLE4_COLUMNS],
                            [[name] + [T.fmt(v[c]) for _, _, c, _ in T.TABLE4_COLUMNS] for name, v in paper.items()]),
                 "")
        if self.draw_figures and not table4_rows(t4).empty:  # drawn in a figure process (TABLE4_TASK)
            figure = table4_figure(self.figures_dir)
            self.add(f"**{figure.title}.** {figure.caption}", "",
                     f"![{figure.title}]({figure.path.relative_to(self.out).as_posix()})", "")

    def results(self) -> list:
        """The verdicts on the paper's claims (:func:`~ddmr_cli.report.verdicts.evaluate`), evaluated once."""
        if self._results is None:
            self._results = V.evaluate(self.data, self.margin)
        return self._results

    def answer(self) -> None:
        """Hand the verdicts in plain text to :attr:`on_verdicts`, if any (the answer before the figures)."""
        if self.on_verdicts is not None:
            lines = V.answer_lines(self.data, self.results())
            if lines:
                self.on_verdicts(lines)

    def verdicts(self) -> None:
        import pandas as pd

        results = self.results()
        link = self.csv("verdicts.csv", pd.DataFrame(V.rows(results)), "paired comparisons behind the verdicts")
        self.add(V.markdown(self.data, results, self.margin), f"Every paired comparison: {link}.", "")

    def voltage_ranges(self, stats):
        """1st–99th percentile of u_R for t >= 1 s in the figures' seed, per scenario and controller."""
        lo, hi, seeds = [], [], []
        for _, r in stats.iterrows():
            jobs = [self.data.job(r["scenario"], k) for k in self.data.keys(r["scenario"])]
            seed = common_seed(jobs)
            if seed is None:
                lo.append(math.nan), hi.append(math.nan), seeds.append(math.nan)
                continue
            s = self.data.series(self.data.job(r["scenario"], r["key"]), seed)
            u = s["u_right"][s["t"] >= 1.0]
            p = np.nanpercentile(u, [1, 99]) if u.size else (math.nan, math.nan)
            lo.append(float(p[0])), hi.append(float(p[1])), seeds.append(seed)
        return lo, hi, seeds

    def effort(self, stats) -> None:
        d = self.data
        ch = T.select(stats, ["chattering", "chattering_right", "chattering_left", "hf_fraction", "mean_voltage"])
        ch["u_right_p01"], ch["u_right_p99"], ch["series_seed"] = self.voltage_ranges(stats)
        link = self.csv("chattering.csv", ch, "chattering and voltage range")
        fig13 = paper_numbers()["figure13_voltage_range_V"]
        self.add("## Chattering", "",
                 f"Total variation of the applied voltage per second (V/s, mean of both wheels), the fraction of "
                 f"var(u) above 10 Hz, the mean |u|, and the range of u_R (1st–99th percentile for t ≥ 1 s, in the "
                 f"seed of the figures) ({link}). Paper Fig. 13 (scenario 2): SMC-NDO about "
                 f"{fig13['smc_ndo'][0]:g}–{fig13['smc_ndo'][1]:g} V, SMC-NDO-NNO about "
                 f"{fig13['smc_ndo_nno'][0]:g}–{fig13['smc_ndo_nno'][1]:g} V.", "")
        for scenario in d.scenarios:
            self.add(f"### {scenario}", "", T.md_metric_table(
                ch, scenario, [("chattering", "Chattering (V/s)"), ("hf_fraction", "HF fraction (>10 Hz)"),
                               ("mean_voltage", "Mean |u| (V)")],
                [("u_R range (V)", lambda r: f"{T.fmt(r['u_right_p01'], 3)} – {T.fmt(r['u_right_p99'], 3)}")]), "")
        en = T.select(stats, ["energy_u2", "electrical_energy", "mean_voltage"])
        link = self.csv("energy.csv", en, "energy")
        self.add("## Energy", "", f"∫(u_R² + u_L²) dt and the electrical energy ∫ u·i dt over both motors, per run "
                 f"({link}).", "")
        for scenario in d.scenarios:
            self.add(f"### {scenario}", "", T.md_metric_table(
                en, scenario, [("energy_u2", "∫u² dt (V² s)"), ("electrical_energy", "Electrical energy (J)")]), "")
        sat = T.select(stats, ["saturation_fraction"])
        durations = {j.dir.name: float(j.summary.get("simulated_time") or j.setting("simulation.duration") or math.nan)
                     for j in d.jobs}
        sat["duration"] = [durations[d.job(r["scenario"], r["key"]).dir.name] for _, r in sat.iterrows()]
        sat["saturated_time_mean"] = sat["saturation_fraction_mean"] * sat["duration"]
        sat["saturated_time_sd"] = sat["saturation_fraction_sd"] * sat["duration"]
        link = self.csv("saturation.csv", sat, "saturation time")
        self.add("## Saturation", "", f"Fraction of the steps with a wheel voltage at ±U_max, and that time in seconds "
                 f"({link}).", "")
        for scenario in d.scenarios:
            self.add(f"### {scenario}", "", T.md_metric_table(
                sat, scenario, [("saturation_fraction", "Fraction saturated"), ("saturated_time", "Time saturated (s)")]),
                "")

    def estimation(self, stats) -> None:
        d = self.data
        est = T.select(stats, ["d_est_mae", "d_est_mae_ndo", "s_mae"])
        claim = paper_numbers()["claims"]["estimation"]
        paper = {"smc_ndo": claim["ndo"], "smc_ndo_nno": claim["ndo_nno"], "smc_ndo_nno_text": claim["ndo_nno"]}
        est["paper_d_est_mae"] = [paper.get(r["controller"], math.nan) if r["scenario"] == PAPER_SCENARIO
                                  else math.nan for _, r in est.iterrows()]
        est["ratio_d_est_mae"] = est["d_est_mae_mean"] / est["paper_d_est_mae"]
        # the estimators each controller names (its ESTIMATE channels); a controller without one reports d-hat = 0:
        # its "estimation MAE" is the mean |d|, not shown, and the NDO-alone column only for a controller with an NDO
        names = [d.job(r["scenario"], r["key"]).summary.get("estimators") for _, r in est.iterrows()]
        est["estimators"] = [" + ".join(n) if n else ("–" if n is not None else "") for n in names]
        blind = [n == [] for n in names]
        est.loc[blind, [c for c in est.columns if c.startswith(("d_est_mae", "ratio_d_est_mae"))]] = math.nan
        no_ndo = [n is not None and "NDO" not in n for n in names]
        est.loc[no_ndo, [c for c in est.columns if c.startswith("d_est_mae_ndo")]] = math.nan
        link = self.csv("estimation.csv", est, "disturbance estimation")
        self.add("## Disturbance estimation", "",
                 f"MAE of d_true − d̂ over both wheels (rad/s², units of d), d̂ the sum of the estimates of the "
                 f"estimators each controller names (an NDO, a network, ADRC's ESO), of the NDO part alone (controllers "
                 f"with an NDO), and the MAE of the sliding variable ({link}). Controllers without an estimator (PID, "
                 f"SMC, ...) report d̂ = 0: theirs would only be the mean |d| and is left out (–). "
                 f"The paper's 48.3 (NDO) and 16.0 (NDO+NNO) are compared with scenario 1.", "")
        for scenario in d.scenarios:
            paper_columns = [("Paper", lambda r: T.fmt(r["paper_d_est_mae"])),
                             ("Ours/paper", lambda r: "–" if T.isnan(r["ratio_d_est_mae"])
                              else f"×{r['ratio_d_est_mae']:.2f}")]
            extra = [("Estimators", lambda r: r["estimators"])] + (paper_columns if scenario == PAPER_SCENARIO else [])
            self.add(f"### {scenario}", "", T.md_metric_table(
                est, scenario, [("d_est_mae", "d estimation MAE"), ("d_est_mae_ndo", "NDO part alone"),
                                ("s_mae", "s MAE (rad/s)")], extra), "")

    def nn_share(self) -> None:
        """The NN's share of the disturbance estimate and of the voltage, per NNO job, from its kept series."""
        import pandas as pd

        d = self.data
        rows = []
        for scenario in d.scenarios:
            for key in d.keys(scenario):
                job = d.job(scenario, key)
                runs = list(d.all_series(job).values())
                if not runs or not any(S.has_nn(r) for r in runs):
                    continue
                share = S.nn_share(runs, S.nominal_input_inverse(job.config.get("robot")))
                rows.append({"scenario": scenario, "controller": job.controller, "key": key, "label": job.label,
                             "reading": nn_reading(job.summary.get("parameters") or {}) or "",
                             "series_seeds": len(runs), **share})
        if not rows:
            return
        frame = pd.DataFrame(rows)
        link = self.csv("nn_share.csv", frame, "the NN's share of the disturbance estimate and of u")
        self.add("## The NN's share of the estimate", "",
                 f"For each job with an NN observer, over its kept time series (both wheels): mean |d̂_NDO|, mean "
                 f"|d̂_NN|, the NN's share of the estimate mean |d̂_NN| / mean |d̂_NDO + d̂_NN|, and the voltage the NN "
                 f"term adds through eq. (17), mean |g⁻¹ d̂_NN| (nominal g), against the mean |u| applied ({link}). "
                 f"Figure: *The NN's share of the disturbance estimate* below.", "")
        self.add(T.md_table(
            ["Scenario", "Controller", "Seeds", "mean |d̂_NDO| (rad/s²)", "mean |d̂_NN| (rad/s²)",
             "NN share of the estimate", "mean |g⁻¹ d̂_NN| (V)", "NN share of |u|"],
            [[r["scenario"], r["label"], r["series_seeds"], T.fmt(r["mean_abs_d_ndo"], 3),
              T.fmt(r["mean_abs_d_nn"], 3), T.pct(r["share_of_estimate"]), T.fmt(r["mean_abs_u_nn"], 3),
              T.pct(r["share_of_u"])] for r in rows]), "")

    def segments(self) -> None:
        d = self.data
        for kind, title, what in (("zone", "Deviation per terrain zone", "zones along the distance travelled"),
                                  ("phase", "Deviation per scenario phase", "phases of the scenario in time")):
            frame = T.segment_frame(d, kind)
            link = self.csv(f"deviation_by_{kind}.csv", frame, title.lower())
            if frame.empty:
                self.add(f"## {title}", "", f"(no segment rows; {link})", "")
                continue
            shown, single = [], []
            for scenario in d.scenarios:
                part = frame[frame["scenario"] == scenario]
                if part.empty:
                    continue
                (shown if part[kind].nunique() > 1 else single).append(scenario)
            self.add(f"## {title}", "")
            if shown:
                self.add(f"Deviation MAE (m), mean ± SD over seeds, within each of the {what} ({link}; also e_x, "
                         f"e_y, e_θ, chattering, estimation MAE and saturation there).", "")
            if single:
                self.add(f"{', '.join(f'`{x}`' for x in single)}: a single {kind} — its table would repeat Table 4 "
                         f"(the rows are in {link}).", "")
            for scenario in shown:
                self.add(f"### {scenario}", "", T.md_segments(frame, scenario, kind), "")

    def figures(self) -> None:
        if not self.draw_figures:
            self.add("## Figures", "", "Not drawn (`ddmr report --no-figures`); the tables below hold every number.",
                     "")
            return
        figures, notes = self.start_figures()()
        figures.pop(TABLE4_TASK[0], None)  # in the Table 4 section
        present = list(dict.fromkeys(j.controller for j in self.data.jobs))
        names = {v: k.replace("_", " ") for k, v in OKABE_ITO.items()}
        shown = self.data.displays()
        legend = "; ".join(f"{shown[c].label} {names.get(self.styles[c].color, self.styles[c].color)} "
                           f"{self.styles[c].dash}" + (f" with {self.styles[c].marker} markers"
                                                        if self.styles[c].marker else "") for c in present)
        self.add("## Figures", "",
                 f"Colour-blind-safe colours (Okabe–Ito) and a distinct line style per controller, the same in every "
                 f"figure: {legend}. The reference and the true disturbance are grey dashed. Overlapping lines are "
                 f"drawn widest-spread first, or split into one panel per controller (same scale). Each scenario's "
                 f"time-series figures use the first kept seed common to all its jobs; where the jobs wrote "
                 f"bands.npz, the mean over all seeds and the 5–95 % band are drawn with that seed. Every caption "
                 f"ends with what the paper reports for the figure and what we see.", "")
        brief = [s for s in self.data.scenarios if not self.all_figures and not detailed(self.data, s)]
        if brief:
            self.add(f"Scenarios on a reference other than the paper's line ({', '.join(f'`{s}`' for s in brief)}) "
                     f"get the summary figures (trajectory, deviation, spread over seeds); `ddmr report "
                     f"{shlex.quote(str(self.data.path))} --all-figures` draws all of theirs too.", "")
        for scenario, figs in figures.items():
            self.add(f"### {scenario or 'All scenarios'}", "")
            if scenario == ACROSS:
                self.add(*(line for f in figs for line in (
                    f"**{f.title}.** {f.caption}", "", f"![{f.title}]({f.path.relative_to(self.out).as_posix()})",
                    "")))
                continue
            jobs = [self.data.job(scenario, k) for k in self.data.keys(scenario)]
            drawn = shown_jobs(jobs)
            if len(drawn) < len(jobs):
                where = ("the Realism section above draws every job against each effect" if realism.present(self.data)
                         else "the first figure draws every job against the setting they differ in")
                self.add(f"{len(jobs)} jobs on this scenario: the time-series figures draw one per controller ("
                         + ", ".join(f"`{j.key}`" for j in drawn) + f"); {where}, and every job's numbers are in "
                         f"{self.link(self.tables_dir / 'statistics.csv')}.", "")
            for f in figs:
                rel = f.path.relative_to(self.out).as_posix()
                self.add(f"**{f.title}.** {f.caption}", "", f"![{f.title}]({rel})", "")
        for note in notes:
            self.add(f"- Note: {note}")
        self.add("")

    def files(self) -> None:
        self.add("## Tables (CSV)", "")
        for what, path in self.csvs:
            self.add(f"- {self.link(path)}: {what}")
        self.add("", "Units of every metric: " + "; ".join(f"{m} [{u}]" for m, (u, _) in METRICS.items()) + ".", "")

    #: the sections, in order (``figures`` also advances the bar once per figure task)
    SECTIONS = ("header", "configuration", "status", "table3", "table4", "verdicts", "effort", "estimation",
                "nn_share", "realism", "segments", "figures", "files")

    def steps(self) -> int:
        """The steps of :meth:`build` for its progress bar: one per section, one per figure task."""
        return len(self.SECTIONS) + (len(figure_tasks(self.data, self.all_figures)) if self.draw_figures else 0)

    def start_figures(self):
        """Start drawing the figures (in forked processes while the tables are computed, issue 28), once; returns
        the function that waits for them (:func:`ddmr_cli.report.figures.start_figures`), each figure task
        advancing the progress bar (:attr:`step`)."""
        if self.pending_figures is None:
            self.pending_figures = start_figures(self.data, self.figures_dir, self.styles, every=self.all_figures,
                                                 done=lambda: self.step())
        return self.pending_figures

    def build(self) -> Path:
        if self.draw_figures:
            self.start_figures()
        self.answer()
        stats = T.stats_frame(self.data)
        with_stats = {"table4", "effort", "estimation"}
        for name in self.SECTIONS:
            if name == "realism":
                realism.section(self)
            elif name == "files":
                self.csv("statistics.csv", stats, "mean and SD over seeds of every metric")
                self.files()
            else:
                getattr(self, name)(*([stats] if name in with_stats else []))
            self.step()
        io.write_text(self.out / "report.md", "\n".join(self.md))
        return self.out


def build(path, out=None, margin=None, figures: bool = True, progress: bool = True, all_figures: bool = False,
          on_verdicts=None) -> Path:
    """Write the report of a sweep or run dir into ``out`` (default ``PATH/report``), staged (:func:`staged`);
    ``progress``: a bar over the sections and the figures, with an ETA (:mod:`ddmr_cli.progress`), drawn once the
    report's dir is locked, so a refused report prints its one error line only; ``all_figures``: every figure of
    every scenario (:func:`ddmr_cli.report.figures.figure_tasks`); ``on_verdicts``: called with the verdicts in plain
    text as soon as they are known (:meth:`Report.answer`)."""
    from ddmr_cli.progress import Ticker, bar, delay_since_start, interactive, status

    margin = Margin.parse(margin)
    # reading the jobs' tables (about 1 s for 72 jobs) said on a terminal, where it is cleared when done (a log gets
    # no line for it: a report refused after it prints its one error line only)
    with status("report: reading the jobs", progress and interactive(), delay=delay_since_start()):
        data = load(path)
    out_dir = Path(out).expanduser().resolve() if out is not None else data.path / "report"

    def write(root: Path) -> Path:
        report = Report(data, root, margin, figures, final=out_dir, all_figures=all_figures, on_verdicts=on_verdicts)
        if figures:
            report.start_figures()  # the figure processes forked before the bar's thread starts
        with bar(report.steps(), "report", "steps", progress, postfix=f"{len(data.jobs)} jobs",
                 delay=delay_since_start()) as b, Ticker(b):
            report.step = b.update
            return report.build()

    return staged(out_dir, write)


# --- one report per output dir, moved in whole ---------------------------------------------------------------

#: the lock of a report's output dir (not ``.ddmr.lock``: a report dir is not a run's dir)
REPORT_LOCK = ".ddmr-report.lock"
#: the files a report wrote into its output dir, with their digests: what the next report may remove
MANIFEST = ".ddmr-report.json"


def _report_files(root: Path) -> list[str]:
    skip = {jobdir.STAGE_MARK, REPORT_LOCK}
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                  if p.is_file() and p.name not in skip)


def staged(out: Path, write) -> Path:
    """Write a report with ``write(root)`` into a staging dir inside ``out`` and move it in whole, holding
    ``out``'s report lock (a second report into ``out`` is refused with one line naming the holder, exit 1).

    The report replaces only files an earlier report wrote there (listed with their digests in
    :data:`MANIFEST`; one changed since is kept as ``<name>.changed``); a file of the new report's name that no
    report wrote is refused (nothing changes). The new files' digests are recorded before they are moved in,
    ``report.md`` last. Raises :class:`ddmr_cli.storage.jobdir.FaultError` on a fault or refusal."""
    out = Path(out)
    try:
        with jobdir.DirLock(out, name=REPORT_LOCK):
            with jobdir.Stage(out / "ddmr-report", create=False) as stage:
                write(stage.path)
                _install(out, stage.path)
    except jobdir.FaultError:
        raise
    except OSError as exc:
        fault = jobdir.fault(exc)
        staging = str(jobdir.Stage(out / "ddmr-report", create=False).path)
        raise jobdir.FaultError(fault.path.replace(staging, str(out)), fault.reason) from None
    return out


def _install(out: Path, staging: Path) -> None:
    old = io.read_json(out / MANIFEST)
    old = old.get("digests", {}) if isinstance(old, dict) and isinstance(old.get("digests"), dict) else {}
    new = _report_files(staging)
    for name in [*new, MANIFEST]:
        target = out / name
        if os.path.lexists(target) and name not in old and name != MANIFEST or target.is_symlink():
            raise jobdir.FaultError(target, "in the way: no earlier report wrote it (it is not in "
                                            f"{MANIFEST}); nothing was changed; move it away or choose another --out")
    manifest = out / MANIFEST
    if os.path.lexists(manifest) and not isinstance(io.read_json(manifest), dict):
        raise jobdir.FaultError(manifest, "in the way: not a record ddmr wrote; nothing was changed")
    for name, want in sorted(old.items()):  # the earlier report's files: gone, or kept when changed since
        path = out / name
        if not path.is_file() or path.is_symlink() or not jobdir.inside(path, out):
            continue
        if jobdir.digest(path) == {"size": want.get("size"), "sha256": want.get("sha256")}:
            path.unlink()
        else:
            jobdir.log.warning("kept %s as %s: it differs from what the earlier report wrote", path,
                               jobdir._set_aside(path).name)
    io.write_json(manifest, {"digests": {name: jobdir.digest(staging / name) for name in new}})
    for name in sorted(new, key=lambda n: n == "report.md"):  # report.md last
        target = out / name
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / name, target)
    for name in old:  # dirs the earlier report's files leave empty
        parent = (out / name).parent
        while parent != out and jobdir.inside(parent, out):
            try:
                parent.rmdir()
            except OSError:
                break
            parent = parent.parent


__all__ = ["build", "staged", "Report", "Job", "REPORT_LOCK", "MANIFEST"]
