"""The report at any sweep size (issue 29): a 150-job realism sweep and a 72-job gain sweep render figures of
bounded size with every legend inside its figure, draw one job per controller in the time-series figures and the
sweep in a summary figure; short runs (an empty steady-state window) neither crash the report nor pass silently.

The large sweeps are clones of a few real jobs (written by :func:`ddmr_cli.job.execute`, as in test_report.py)
with their configs and overrides set to each sweep point and their metrics scaled: the report reads only the job
dirs, so this is the report a real sweep of that size gets, in seconds instead of minutes of compiling.
"""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import pytest
import yaml

from test_report import write_job

#: the bound on each side of every PNG of the report (px)
MAX_PX = 3000
SHORT = ("simulation.duration=0.6", "metrics.settle_time=0.2")
CONTROLLERS = ("pid", "smc_ndo", "smc_ndo_nno")
SCENARIOS = ("paper_1", "paper_2")
#: realism points per controller and scenario: the ideal loop and six levels of each of the four effects (25)
LEVELS = ([("ideal", {})]
          + [(f"counts_{c}", {"sensor.kind": "encoder", "sensor.counts_per_rev": c})
             for c in (65536, 16384, 4096, 1024, 512, 256)]
          + [(f"noise_{v:g}", {"sensor.kind": "noisy", "sensor.speed_std": v}) for v in (0.02, 0.05, 0.1, 0.2, 0.5, 1.0)]
          + [(f"delay_{d}ms", {"actuator.delay": d / 1000}) for d in (1, 2, 3, 5, 7, 10)]
          + [(f"rate_{r}hz", {"control.rate": float(r)}) for r in (400, 333, 250, 200, 125, 100)])


def _png_size(path: Path) -> tuple[int, int]:
    return struct.unpack(">II", path.read_bytes()[16:24])


def _set(config: dict, dotted: str, value) -> None:
    *parents, key = dotted.split(".")
    for p in parents:
        config = config.setdefault(p, {})
    config[key] = value


def clone(src: Path, dst: Path, overrides: list[str], settings: dict, scale: float) -> None:
    """A copy of job ``src`` as the job of ``overrides``: its config set to ``settings`` (dotted keys) and its
    deviation and chattering metrics scaled by ``scale``."""
    import pandas as pd

    from ddmr_cli.storage.jobdir import digest

    shutil.copytree(src, dst)
    config = yaml.safe_load((dst / "config.yaml").read_text())
    for dotted, value in settings.items():
        _set(config, dotted, value)
    (dst / "config.yaml").write_text(yaml.safe_dump(config))
    (dst / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    metrics = pd.read_csv(dst / "metrics.csv")
    for col in metrics.columns:
        if col.startswith(("deviation", "chattering", "e_y")):
            metrics[col] = metrics[col] * scale
    metrics.to_csv(dst / "metrics.csv", index=False)
    summary = json.loads((dst / "summary.json").read_text())
    summary["overrides"] = overrides
    summary["digests"] = {name: digest(dst / name) for name in summary.get("digests", {})}  # the files it now has
    (dst / "summary.json").write_text(json.dumps(summary))


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> Path:
    """One short real job per controller and scenario."""
    root = tmp_path_factory.mktemp("seeds")
    for controller in CONTROLLERS:
        for scenario in SCENARIOS:
            write_job(root, controller, scenario, SHORT)
    return root


def _source(seeds: Path, controller: str, scenario: str) -> Path:
    return seeds / f"controller={controller},scenario={scenario}"


@pytest.fixture(scope="module")
def realism_sweep(seeds, tmp_path_factory) -> Path:
    sweep = tmp_path_factory.mktemp("realism150") / "sweep"
    for controller in CONTROLLERS:
        for scenario in SCENARIOS:
            for i, (name, settings) in enumerate(LEVELS):
                overrides = [f"controller={controller}", f"scenario={scenario}", f"+realism={name}"]
                clone(_source(seeds, controller, scenario), sweep / ",".join(overrides), overrides, settings,
                      1.0 + 0.1 * i)
    assert len(list(sweep.iterdir())) == 150
    return sweep


@pytest.fixture(scope="module")
def gain_sweep(seeds, tmp_path_factory) -> Path:
    """72 jobs: 3 controllers x 2 scenarios x 12 values of a (nominal) gain override."""
    sweep = tmp_path_factory.mktemp("gains72") / "sweep"
    for controller in CONTROLLERS:
        for scenario in SCENARIOS:
            for k in range(12):
                overrides = [f"controller={controller}", f"scenario={scenario}", f"outer_loop.k_x={5 + k}"]
                clone(_source(seeds, controller, scenario), sweep / ",".join(overrides), overrides, {}, 1.0 + 0.05 * k)
    return sweep


def render(sweep: Path, monkeypatch) -> tuple[Path, list[str]]:
    """The sweep's report, drawn in this process; every legend that reaches outside its figure, as text."""
    from matplotlib.figure import Figure

    from ddmr_cli.report import build_report

    outside: list[str] = []
    savefig = Figure.savefig

    def checked(fig, fname, *args, **kwargs):
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        box = fig.bbox
        legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
        for legend in legends:
            ext = legend.get_window_extent(renderer)
            if ext.x0 < box.x0 - 1 or ext.y0 < box.y0 - 1 or ext.x1 > box.x1 + 1 or ext.y1 > box.y1 + 1:
                outside.append(f"{fig.axes[0].get_title() or fname}: legend {ext.bounds} outside {box.bounds}")
        return savefig(fig, fname, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", checked)
    monkeypatch.setenv("DDMR_REPORT_WORKERS", "1")  # drawn here, where the check is
    monkeypatch.setattr("ddmr_cli.report.realism.cost_rows", lambda controllers: [])  # compiles: not under test
    return build_report(sweep, figures=True), outside


def test_a_150_job_realism_report_has_bounded_figures_with_legends_inside(realism_sweep, monkeypatch):
    out, outside = render(realism_sweep, monkeypatch)
    pngs = sorted((out / "figures").glob("*.png"))
    assert pngs
    sizes = {p.name: _png_size(p) for p in pngs}
    too_big = {n: s for n, s in sizes.items() if max(s) > MAX_PX}
    assert not too_big, too_big
    assert not outside, outside
    assert {"realism_paper_1.png", "realism_paper_2.png"} <= set(sizes)
    md = (out / "report.md").read_text()
    # the time-series figures draw one job per controller: the ideal loop
    voltage = md.split("**Right-wheel control voltage", 1)[1].split("\n\n", 1)[0]
    assert "PID (+realism=ideal)" in voltage and "counts" not in voltage
    assert "75 jobs on this scenario: the time-series figures draw one per controller" in md
    # verdicts are reached on the ideal-loop jobs instead of "no claim could be checked"
    assert "no claim could be checked" not in md
    assert "`smc_ndo_nno[+realism=ideal]`" in md


@pytest.mark.slow
def test_a_72_job_gain_sweep_gets_a_summary_figure(gain_sweep, monkeypatch):
    out, outside = render(gain_sweep, monkeypatch)
    sizes = {p.name: _png_size(p) for p in (out / "figures").glob("*.png")}
    assert not {n: s for n, s in sizes.items() if max(s) > MAX_PX}
    assert not outside, outside
    assert {"paper_1_sweep.png", "paper_2_sweep.png"} <= set(sizes)
    md = (out / "report.md").read_text()
    # summary figures come first in each scenario's figures
    assert md.index("paper_1_sweep.png") < md.index("paper_1_fig03_terrain.png")
    assert "36 jobs on this scenario" in md


def test_shown_jobs_keep_small_sweeps_whole_and_pick_one_per_controller_in_large_ones(realism_sweep):
    from ddmr_cli.report.data import load
    from ddmr_cli.report.figures import MAX_JOBS, shown_jobs

    data = load(realism_sweep)
    jobs = [data.job("paper_1", k) for k in data.keys("paper_1")]
    assert len(jobs) == 75
    shown = shown_jobs(jobs)
    assert [j.controller for j in shown] == list(CONTROLLERS)
    assert all(j.key.endswith("[+realism=ideal]") for j in shown)
    assert shown_jobs(jobs[:MAX_JOBS]) == jobs[:MAX_JOBS]


# --- short runs: an empty steady-state window ---------------------------------------------------------------

@pytest.fixture(scope="module")
def short_sweep(tmp_path_factory) -> Path:
    """PID and SMC-NDO-NNO, ideal and noisy sensing, 0.6 s: shorter than metrics.settle_time (3 s)."""
    sweep = tmp_path_factory.mktemp("short") / "sweep"
    for controller in ("pid", "smc_ndo_nno"):
        for realism in ("ideal", "noise_0.2"):
            job = write_job(sweep, controller, "paper_1", ("simulation.duration=0.6", f"+realism={realism}"))
            job.rename(sweep / f"controller={controller},realism={realism}")
    return sweep


@pytest.mark.parametrize("figures", [False, True])
def test_a_report_of_runs_shorter_than_the_settle_time(short_sweep, tmp_path, figures):
    from ddmr_cli.report import build_report

    out = build_report(short_sweep, tmp_path / "report", figures=figures)
    md = (out / "report.md").read_text()
    assert "No steady-state numbers" in md
    assert ("realism_paper_1.png" in md) is figures


def test_the_empty_steady_state_window_is_warned(tmp_path):
    import ddmr_cli
    from ddmr_cli.cli.modes import _validate_jobs
    from ddmr_cli.config.validate import steady_state_warning, validate_config
    from omegaconf import OmegaConf

    assert steady_state_warning(validate_config(ddmr_cli.compose_config([]))) is None
    assert steady_state_warning(validate_config(ddmr_cli.compose_config(["simulation.duration=3.5"]))) is None
    text = steady_state_warning(validate_config(ddmr_cli.compose_config(["simulation.duration=3"])))
    assert "metrics.settle_time=3 s" in text and "simulation.duration=3 s" in text

    jobs = [{"dir": c, "overrides": [f"controller={c}", "simulation.duration=2"]} for c in ("pid", "smc")]
    base = OmegaConf.merge(OmegaConf.create({"hydra": {"launcher": {"_target_": "basic", "n_jobs": 1}}}),
                           ddmr_cli.compose_config(jobs[0]["overrides"]))  # as Hydra composes it: with its node
    warnings = _validate_jobs(jobs, base, True, ddmr_cli.compose_config).warnings
    assert len(warnings) == 1 and warnings[0].startswith("metrics.settle_time=3 s")  # once, not per job


# --- what a large report draws first (issue 28) --------------------------------------------------------------

def test_scenarios_off_the_paper_line_get_the_summary_figures_unless_all_are_asked_for(seeds, tmp_path):
    from ddmr_cli.report.data import load
    from ddmr_cli.report.figures import ACROSS, FIGURE_METHODS, ON_DEMAND, SUMMARY_METHODS, TABLE4_TASK, figure_tasks

    sweep = tmp_path / "sweep"
    for controller in CONTROLLERS:
        for scenario in SCENARIOS:
            for trajectory in ("line", "circle"):
                overrides = [f"controller={controller}", f"scenario={scenario}", f"trajectory={trajectory}"]
                clone(_source(seeds, controller, scenario), sweep / ",".join(overrides), overrides, {}, 1.0)
    data = load(sweep)
    assert data.scenarios == ["paper_1", "paper_1@circle", "paper_2", "paper_2@circle"]
    tasks = figure_tasks(data)
    assert tasks[:2] == [TABLE4_TASK, (ACROSS, "fig_scenarios")]  # the summaries first
    default = [m for m in FIGURE_METHODS if m not in ON_DEMAND]
    assert [m for s, m in tasks if s == "paper_1"] == default
    assert [m for s, m in tasks if s == "paper_1@circle"] == list(SUMMARY_METHODS)
    assert len(tasks) == 2 + 2 * len(default) + 2 * len(SUMMARY_METHODS)
    every = figure_tasks(data, every=True)
    assert [m for s, m in every if s == "paper_2@circle"] == list(FIGURE_METHODS)


def test_table4_sized_reports_draw_every_figure_and_no_summary(seeds):
    from ddmr_cli.report.data import load
    from ddmr_cli.report.figures import FIGURE_METHODS, ON_DEMAND, TABLE4_TASK, figure_tasks

    tasks = figure_tasks(load(seeds))
    assert tasks == [TABLE4_TASK] + [(s, m) for s in SCENARIOS for m in FIGURE_METHODS if m not in ON_DEMAND]


def test_our_table4_beside_the_papers(seeds, tmp_path):
    from ddmr_cli.plots.common import StyleBook
    from ddmr_cli.report import tables as T
    from ddmr_cli.report.data import load
    from ddmr_cli.report.figures import fig_table4

    data = load(seeds)
    t4 = T.table4_frame(T.stats_frame(data))
    figure = fig_table4(t4, tmp_path, StyleBook(CONTROLLERS, data.displays()), data.displays())
    assert figure is not None and figure.path.read_bytes()[:4] == b"\x89PNG"
    assert max(_png_size(figure.path)) <= MAX_PX
    assert fig_table4(t4[t4["scenario"] != "paper_1"], tmp_path, StyleBook(CONTROLLERS), data.displays()) is None


@pytest.mark.slow
def test_all_figures_draw_every_job_of_a_sweep_in_bounded_small_multiples(realism_sweep, tmp_path, monkeypatch):
    from ddmr_cli.report.figures import MULTIPLES

    monkeypatch.setattr("ddmr_cli.report.realism.cost_rows", lambda controllers: [])
    monkeypatch.setenv("DDMR_REPORT_WORKERS", "1")
    from ddmr_cli.report import build_report

    out = build_report(realism_sweep, tmp_path / "report", all_figures=True)
    pages = sorted((out / "figures").glob("paper_1_multiples_*.png"))
    assert [p.name for p in pages] == [f"paper_1_multiples_{c}_{i}.png" for c in sorted(CONTROLLERS)
                                       for i in (1, 2)]  # 25 jobs each: pages of 24 and 1
    assert MULTIPLES == 24
    assert all(max(_png_size(p)) <= MAX_PX for p in pages)


@pytest.mark.slow
def test_ddmr_run_says_the_steady_state_window_is_empty(tmp_path):
    from conftest import run_ddmr

    proc = run_ddmr(["run", "controller=pid", "simulation.duration=0.5", "run.n_runs=2", "run.plots=false",
                     f"hydra.run.dir={tmp_path / 'r'}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stderr.count("ddmr: warning: metrics.settle_time=3 s is not below simulation.duration=0.5 s") == 1
