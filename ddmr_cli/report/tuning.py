"""``ddmr report`` on tuning studies (docs/model.md §9): paper gains against tuned gains on held-out seeds.

For a study dir (``outputs/tune/<objective>/<controller>``) or a dir holding several (``outputs/tune``), the
report re-runs every single-objective study's controller at its paper gains and at its best trial's gains on the
held-out seeds (:func:`ddmr_cli.study.tuning.run_held_out`), builds the standard report (Table 4, verdicts, figures)
of each set, and writes beside them ``report.md`` with the study budgets and wall times, a "paper gains vs tuned
gains" table, the held-out Table 4 of both side by side, the paper's ranking and claims at both, the
optimisation-history figure and the deviation-chattering (Pareto) figure with the paper's gains marked.
"""

from __future__ import annotations

import math
from pathlib import Path

from ddmr_cli.storage import io
from ddmr_cli.study import tuning as TU
from ddmr_cli.errors import DDMRError
from ddmr_cli.report import verdicts as V
from ddmr_cli.report.data import controller_rank, load
from ddmr_cli.plots.common import StyleBook, label_of, pyplot, save
from ddmr_cli.report.stats import Margin
from ddmr_cli.report.tables import fmt, md_table

MM = 1000.0


def is_tuning_dir(path) -> bool:
    """True when ``path`` is a study dir or holds one (a ``tuning.json`` below it)."""
    path = Path(path)
    return (path / TU.STUDY_FILE).is_file() or (path.is_dir() and next(path.rglob(TU.STUDY_FILE), None) is not None)


def _plain_log_axes(ax) -> None:
    """Log axes labelled with plain numbers (8, 10, 20) rather than powers of ten."""
    from matplotlib.ticker import FuncFormatter, NullFormatter

    for axis in (ax.xaxis, ax.yaxis):
        if axis.get_scale() == "log":
            axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            axis.set_minor_formatter(NullFormatter())


def _order(studies):
    return sorted(studies, key=lambda s: (controller_rank(s.controller), s.objective))


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the non-dominated points (both coordinates minimised), by increasing first coordinate."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best_y = [], math.inf
    for i in order:
        if points[i][1] < best_y:
            front.append(i)
            best_y = points[i][1]
    return front


def session_wall_time(info: dict, study) -> float:
    """The study's wall time: the sum over its sessions. A killed session recorded no end: it counts until the
    last trial it completed (the trials' own time stamps in the storage)."""
    sessions = info.get("sessions", [])
    done = [t.datetime_complete.timestamp() for t in study.get_trials(deepcopy=False) if t.datetime_complete]
    total = 0.0
    for i, s in enumerate(sessions):
        if "wall_time" in s:
            total += float(s["wall_time"])
            continue
        end = sessions[i + 1]["started"] if i + 1 < len(sessions) else math.inf
        last = [t for t in done if s["started"] <= t < end]
        total += (max(last) - s["started"]) if last else 0.0
    return total


def killed_sessions(info: dict) -> int:
    return sum(1 for s in info.get("sessions", []) if "wall_time" not in s)


class TuningReport:
    def __init__(self, root: Path, out: Path, margin: Margin):
        self.root, self.out, self.margin = root, out, margin
        self.studies = _order(TU.find_studies(root))
        if not self.studies:
            raise DDMRError(f"{root}: no tuning study (a dir with {TU.STUDY_FILE} and {TU.STORAGE_FILE})")
        self.styles = StyleBook(s.controller for s in self.studies)
        self.md: list[str] = []
        self.paper_points = {s.dir: TU.evaluate_gains(s.config()) for s in self.studies}
        self.tables = {s.dir: TU.trials_table(s.dir, s.study) for s in self.studies}

    def rel(self, path: Path) -> str:
        return Path(path).relative_to(self.out).as_posix()

    def link(self, path: Path) -> str:
        return f"[{self.rel(path)}]({self.rel(path)})"

    def csv(self, name: str, rows) -> str:
        import pandas as pd

        return self.link(io.write_csv(self.out / "tables" / name, pd.DataFrame(rows)))

    # --- sections ------------------------------------------------------------------------------------------
    def studies_section(self) -> None:
        rows, csv_rows = [], []
        for s in self.studies:
            t = self.tables[s.dir]
            done = int((t["state"] == "COMPLETE").sum()) if len(t) else 0
            feasible = int((t["feasible"] == True).sum()) if "feasible" in t else 0  # noqa: E712 (object column)
            best = s.best()
            paper = self.paper_points[s.dir]
            wall = session_wall_time(s.info, s.study)
            sampler = "NSGA-II" if s.objective == "pareto" else "TPE"
            best_text = (f"{MM * best[0].values[0]:.4g} mm" if s.objective == "deviation" and best
                         else f"{len(best)} Pareto trials")
            rows.append([label_of(s.controller), s.objective, sampler, f"{done}/{s.info['budget']}", feasible,
                         len(s.info.get("sessions", [])), killed_sessions(s.info), fmt(wall, 3), best_text,
                         f"{MM * paper.deviation:.4g} mm"])
            csv_rows.append({"controller": s.controller, "objective": s.objective, "sampler": sampler,
                             "trials_complete": done, "budget": s.info["budget"], "feasible": feasible,
                             "sessions": len(s.info.get("sessions", [])), "killed_sessions": killed_sessions(s.info),
                             "wall_time_s": wall, "best_value": best[0].values[0] if best else math.nan,
                             "paper_gains_deviation": paper.deviation, "paper_gains_chattering": paper.chattering,
                             "dir": str(s.dir)})
        total = math.fsum(r["wall_time_s"] for r in csv_rows)
        info = self.studies[0].info
        cfg = self.studies[0].config()
        self.add("## Studies", "",
                 f"Each study is ddmr's Optuna sweeper over the controller's gains (`ddmr run -m +tune=<controller>`; "
                 f"search spaces in conf/tune). A trial simulates the tuning seeds {int(cfg.run.base_seed)}–"
                 f"{int(cfg.run.base_seed) + int(cfg.run.n_runs) - 1} in {', '.join(cfg.tuning.scenarios)} and scores "
                 f"the mean `{info.get('metric', TU.OBJECTIVE_METRIC)}` over the runs and scenarios; a trial with a "
                 f"diverged run, a mean saturation fraction above {float(cfg.tuning.saturation_limit):g} or an "
                 f"unstable discrete-time loop is infeasible and scores above every feasible trial (docs/model.md §9). "
                 f"Wall time: the sum over a study's sessions (a killed session until its last complete trial); all "
                 f"studies: "
                 f"{fmt(total, 3)} s.", "",
                 md_table(["Controller", "Objective", "Sampler", "Trials", "Feasible", "Sessions", "Killed sessions",
                           "Wall time (s)", "Best (tuning seeds)", "Paper gains (tuning seeds)"], rows), "",
                 f"Table: {self.csv('studies.csv', csv_rows)}; every trial: `tuning_trials.csv` in each study dir.", "")

    def gains_section(self) -> None:
        rows, csv_rows = [], []
        for s in self.studies:
            if s.objective != "deviation" or not s.best():
                continue
            cfg = s.config()
            best = s.best()[0]
            for key, text in s.info["search_space"].items():
                from omegaconf import OmegaConf

                paper, tuned = OmegaConf.select(cfg, key), best.params.get(key)
                ratio = tuned / paper if isinstance(paper, (int, float)) and paper else math.nan
                rows.append([label_of(s.controller), f"`{key}`", fmt(paper, 4), fmt(tuned, 4), fmt(ratio, 3), text])
                csv_rows.append({"controller": s.controller, "key": key, "paper": paper, "tuned": tuned,
                                 "tuned_over_paper": ratio, "search_space": text, "trial": best.number})
        if rows:
            self.add("## Paper gains vs tuned gains", "",
                     "The tuned gains are each study's best trial on the tuning seeds.", "",
                     md_table(["Controller", "Key", "Paper", "Tuned", "Tuned / paper", "Search space"], rows), "",
                     f"Table: {self.csv('gains.csv', csv_rows)}.", "")

    def equal_chattering_section(self) -> None:
        """The ranking at matched chattering: each controller's lowest deviation among the feasible trials (of
        all its studies) whose chattering is at most a cap, the caps being the paper gains' chattering."""
        controllers = sorted({s.controller for s in self.studies}, key=controller_rank)
        pooled = {}
        for ctrl in controllers:
            import pandas as pd

            frames = [self.tables[s.dir] for s in self.studies if s.controller == ctrl]
            t = pd.concat(frames, ignore_index=True)
            pooled[ctrl] = t[(t["state"] == "COMPLETE") & (t["feasible"] == True)]  # noqa: E712
        caps = sorted({(self.paper_points[s.dir].chattering, s.controller) for s in self.studies
                       if math.isfinite(self.paper_points[s.dir].chattering)})
        caps = list(dict((round(c, 9), (c, who)) for c, who in caps).values())
        rows, csv_rows = [], []
        for cap, who in caps:
            best = {}
            for ctrl in controllers:
                t = pooled[ctrl]
                under = t[t[TU.CHATTERING_METRIC].astype(float) <= cap][TU.OBJECTIVE_METRIC].astype(float)
                best[ctrl] = float(under.min()) if len(under) else math.nan
                csv_rows.append({"chattering_cap": cap, "cap_from_paper_gains_of": who, "controller": ctrl,
                                 "best_deviation": best[ctrl], "trials_under_cap": int(len(under))})
            ranked = sorted((c for c in controllers if math.isfinite(best[c])), key=lambda c: -best[c])
            rows.append([f"{fmt(cap, 3)} ({label_of(who)} at paper gains)",
                         *(f"{MM * best[c]:.3g}" if math.isfinite(best[c]) else "none" for c in controllers),
                         " > ".join(label_of(c) for c in ranked)])
        if rows:
            self.add("## Deviation at equal chattering (tuning seeds)", "",
                     f"Deviation alone rewards gains at the edge of the stable region, whose voltage chatters. For a "
                     f"like-for-like comparison: each controller's lowest `{TU.OBJECTIVE_METRIC}` (mm) among the "
                     f"feasible trials of all its studies whose `{TU.CHATTERING_METRIC}` is at most a cap, the caps "
                     f"being the paper gains' own chattering; on the tuning seeds (the trials' numbers), not held out.",
                     "", md_table([f"{TU.CHATTERING_METRIC} cap (V/s)", *(label_of(c) for c in controllers),
                                   "Order, largest deviation first"], rows), "",
                     f"Table: {self.csv('equal_chattering.csv', csv_rows)}.", "")

    def held_out_section(self, held: Path, subreports: dict[str, Path]) -> None:
        data = {g: load(held / g) for g in TU.GAINS if (held / g).is_dir()}
        if not data:
            return
        metric = V.deviation_metric(data["tuned"])
        chat = TU.CHATTERING_METRIC if TU.CHATTERING_METRIC in data["tuned"].metrics else "chattering"
        h = self.studies[0].config().tuning.held_out
        seeds = f"{int(h.base_seed)}–{int(h.base_seed) + int(h.n_runs) - 1}"
        self.add("## Held-out evaluation", "",
                 f"Every tuned controller re-run at its paper gains and at its tuned gains on the held-out seeds "
                 f"{seeds} (never seen by the tuning), in every scenario: job dirs under `{held}`. The full report "
                 f"of each set (Table 4 beside the paper's numbers, verdicts, figures): "
                 + ", ".join(f"{g} gains {self.link(p / 'report.md')}" for g, p in subreports.items()) + ".", "")
        csv_rows = []
        for scenario in data["tuned"].scenarios:
            rows = []
            for ctrl in sorted({j.controller for d in data.values() for j in d.jobs}, key=controller_rank):
                cells = [label_of(ctrl)]
                for g, d in data.items():
                    job = next((j for j in d.jobs if j.scenario == scenario and j.controller == ctrl), None)
                    st = (job.summary.get("statistics") or {}) if job else {}
                    row = {"scenario": scenario, "controller": ctrl, "gains": g, "runs": st.get("runs"),
                           "diverged": st.get("diverged")}
                    for m in (metric, "deviation_mae", chat, "saturation_fraction"):
                        row[f"{m}_mean"], row[f"{m}_sd"] = st.get(f"{m}_mean", math.nan), st.get(f"{m}_sd", math.nan)
                    csv_rows.append(row)
                    cells += [f"{fmt(MM * row[f'{metric}_mean'], 3)} ± {fmt(MM * row[f'{metric}_sd'], 2)}",
                              fmt(row[f"{chat}_mean"], 3), fmt(row["saturation_fraction_mean"], 2),
                              str(row["diverged"] if row["diverged"] is not None else "–")]
                rows.append(cells)
            headers = ["Controller"]
            for g in data:
                headers += [f"{g}: {metric} (mm)", f"{g}: {chat} (V/s)", f"{g}: saturation", f"{g}: diverged"]
            self.add(f"### {scenario}", "", md_table(headers, rows), "")
            for g, d in data.items():
                keys = [k for k in d.keys(scenario) if d.controller_of(k) == k]
                self.add(f"- Order at {g} gains by mean {metric}, largest first: {V.our_order(d, scenario, keys, metric)}.")
            self.add("")
        self.add(f"Table: {self.csv('heldout.csv', csv_rows)}.", "")
        self.claims_section(data)

    def claims_section(self, data: dict) -> None:
        results = {g: V.evaluate(d, self.margin) for g, d in data.items()}
        cells: dict[tuple[str, str, str], dict[str, str]] = {}
        titles = {}
        for g, res in results.items():
            for c in res:
                titles[c.id] = c.title
                for (scenario, reading), verdict in c.overall.items():
                    cells.setdefault((c.id, scenario, reading), {})[g] = verdict
        rows = [[titles[cid], scenario, label_of(reading), *(v.get(g, "not checked") for g in data)]
                for (cid, scenario, reading), v in cells.items()]
        csv_rows = [{"claim": cid, "scenario": scenario, "nno_reading": reading, **{f"verdict_{g}": v.get(g, "")
                                                                                     for g in data}}
                    for (cid, scenario, reading), v in cells.items()]
        self.add("## The paper's claims at paper gains and at tuned gains", "",
                 f"Verdicts of ddmr_cli/report/verdicts.py on the held-out seeds (rules, paired statistics and margin "
                 f"({self.margin.describe()}) in the sub-reports). The ranking claim answers whether the paper's order "
                 f"holds when every controller gets the same tuning budget.", "",
                 md_table(["Claim", "Scenario", "NNO reading", *(f"at {g} gains" for g in data)], rows) if rows
                 else "No claim could be checked (the studies lack SMC-NDO-NNO or its references).", "",
                 f"Table: {self.csv('verdicts.csv', csv_rows)}.", "")

    # --- figures -------------------------------------------------------------------------------------------
    def history_figure(self) -> Path:
        plt = pyplot()
        n = len(self.studies)
        cols = min(n, 4)
        rows = math.ceil(n / cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.7 * rows), squeeze=False)
        for ax, s in zip(axes.flat, self.studies):
            t = self.tables[s.dir]
            t = t[t["state"] == "COMPLETE"]
            style = self.styles[s.controller]
            ok = t[t["feasible"] == True]  # noqa: E712
            bad = t[t["feasible"] != True]  # noqa: E712
            ax.plot(ok["number"], MM * ok["value_0"], "o", ms=3, color=style.color, alpha=0.6, label="feasible trial")
            if len(ok):
                top = MM * float(ok["value_0"].max()) * 1.5
                ax.plot(bad["number"], [top] * len(bad), "x", ms=4, color="0.5", label="infeasible (penalised)")
                best = ok.sort_values("number")["value_0"].cummin()
                ax.step(ok.sort_values("number")["number"], MM * best, where="post", color="black", lw=1.2,
                        label="best so far")
            ax.axhline(MM * self.paper_points[s.dir].deviation, color="0.3", ls="--", lw=1, label="paper gains")
            ax.set_yscale("log")
            _plain_log_axes(ax)
            ax.set_title(f"{label_of(s.controller)} ({s.objective})")
            ax.set_xlabel("trial")
            ax.set_ylabel(f"{s.info.get('metric', TU.OBJECTIVE_METRIC)} (mm)")
        for ax in list(axes.flat)[n:]:
            ax.axis("off")
        axes.flat[0].legend(loc="best", fontsize=7)
        fig.suptitle("Optimisation history: objective on the tuning seeds per trial (log scale)")
        return save(fig, self.out / "figures" / "history.png")

    def pareto_figure(self) -> Path:
        """Deviation against chattering of every feasible trial, per controller; the non-dominated trials joined
        (for a pareto study, Optuna's own Pareto front), the paper's gains and the tuned gains marked."""
        plt = pyplot()
        controllers = sorted({s.controller for s in self.studies}, key=controller_rank)
        fig, axes = plt.subplots(1, len(controllers), figsize=(3.3 * len(controllers), 3.0), squeeze=False)
        for ax, ctrl in zip(axes.flat, controllers):
            style = self.styles[ctrl]
            for s in (s for s in self.studies if s.controller == ctrl):
                t = self.tables[s.dir]
                ok = t[(t["state"] == "COMPLETE") & (t["feasible"] == True)]  # noqa: E712
                pts = list(zip(MM * ok[TU.OBJECTIVE_METRIC].astype(float), ok[TU.CHATTERING_METRIC].astype(float)))
                marker = "s" if s.objective == "pareto" else "o"
                ax.plot([p[0] for p in pts], [p[1] for p in pts], marker, ms=2.5, color=style.color, alpha=0.35,
                        ls="none", label=f"trials ({s.objective})")
                if s.objective == "pareto":
                    front = sorted((MM * t.values[0], t.values[1]) for t in s.best())
                else:
                    front = [pts[i] for i in pareto_front(pts)]
                ax.plot([p[0] for p in front], [p[1] for p in front], "-", marker=marker, ms=3, color=style.color,
                        lw=1, label=f"front ({s.objective})")
                if s.objective == "deviation" and s.best():
                    best = ok[ok["number"] == s.best()[0].number]
                    ax.plot(MM * best[TU.OBJECTIVE_METRIC].astype(float), best[TU.CHATTERING_METRIC].astype(float),
                            "D", ms=7, mfc="none", mec="black", label="tuned gains")
            paper = next(self.paper_points[s.dir] for s in self.studies if s.controller == ctrl)
            ax.plot([MM * paper.deviation], [paper.chattering], "*", ms=12, color="black", label="paper gains")
            ax.set_xscale("log")
            ax.set_yscale("log")
            _plain_log_axes(ax)
            ax.set_title(label_of(ctrl))
            ax.set_xlabel(f"{TU.OBJECTIVE_METRIC} (mm)")
            ax.set_ylabel("chattering (V/s)")
            ax.legend(fontsize=6)
        fig.suptitle("Deviation against chattering on the tuning seeds (feasible trials; lower left is better)")
        return save(fig, self.out / "figures" / "pareto.png")

    def add(self, *lines: str) -> None:
        self.md.extend(lines)

    def build(self) -> Path:
        from ddmr_cli.report import build_report

        held = TU.run_held_out(self.studies, self.root)
        subreports = {g: build_report(held / g, self.out / f"heldout_{g}", self.margin)
                      for g in TU.GAINS if (held / g).is_dir()}
        self.add(f"# ddmr tuning report: {self.root.name}", "",
                 f"From `{self.root}`: {len(self.studies)} stud{'y' if len(self.studies) == 1 else 'ies'}. Regenerate "
                 f"with `ddmr report {self.root}` (held-out jobs already complete with the same config are kept).", "")
        self.studies_section()
        self.gains_section()
        self.held_out_section(held, subreports)
        self.equal_chattering_section()
        self.add("## Figures", "", f"![history]({self.rel(self.history_figure())})", "",
                 "Optimisation history: each study's objective per trial on the tuning seeds, the best so far, and "
                 "the paper's gains on the same seeds (dashed); infeasible trials as crosses above the feasible ones.",
                 "", f"![pareto]({self.rel(self.pareto_figure())})", "",
                 "Deviation against chattering of the feasible trials of each controller on the tuning seeds: the "
                 "non-dominated trials joined (for `objective=pareto` studies, NSGA-II's Pareto front as Optuna "
                 "reports it), the paper's gains (star) and the tuned gains (diamond).", "")
        io.write_text(self.out / "report.md", "\n".join(self.md) + "\n")
        return self.out


def build(path, out=None, margin=None) -> Path:
    """The tuning report of a study dir or a dir of studies; returns the output dir (default ``PATH/report``)."""
    root = Path(path).expanduser().resolve()
    out_dir = Path(out).expanduser().resolve() if out is not None else root / "report"
    return TuningReport(root, out_dir, Margin.parse(margin)).build()


__all__ = ["build", "is_tuning_dir", "pareto_front", "TuningReport"]
