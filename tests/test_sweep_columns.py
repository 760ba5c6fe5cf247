"""Swept keys as typed columns: sweep_jobs.csv, sweep_metrics.csv, sweep_segments.csv, the terminal summary and
``ddmr_cli.load_sweep`` (unit tests on hand-made sweep dirs, then one real sweep through the console script)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from conftest import run_ddmr


import ddmr_cli
from ddmr_cli.storage import io, sweep
from ddmr_cli.config import plan as sweep_plan


def _fake_job(sweep_dir: Path, overrides: list[str], seeds=(0, 1), status="complete", value=0.0) -> str:
    """A job dir as a finished job leaves it: summary.json, metrics.csv and segments.csv."""
    name = sweep_plan.job_dirname(overrides, exclude_keys=[])
    job = sweep_dir / name
    job.mkdir(parents=True)
    rows = [{"controller": "smc", "scenario": "paper_1", "seed": s, "status": "ok", "deviation_mae": value + s}
            for s in seeds]
    io.write_csv(job / io.METRICS_CSV, rows)
    io.write_csv(job / io.SEGMENTS_CSV, [{**r, "segment": seg} for r in rows for seg in ("total", "zone:flat")])
    stats = {"runs": len(seeds), "diverged": 0, **{f"{m}_mean": value for m in io.HEADLINE},
             **{f"{m}_sd": 0.1 for m in io.HEADLINE}}
    io.write_json(job / io.SUMMARY, {"status": status, "controller": "smc", "scenario": "paper_1",
                                     "overrides": overrides, "statistics": stats, "wall_time": 0.1})
    return name


@pytest.fixture
def gain_sweep(tmp_path) -> Path:
    """Three jobs differing by controller.switching_gain, made in the order 12, 4, 8 (dir names sort 12, 4, 8)."""
    sweep_dir = tmp_path / "sweep"
    plan = []
    for gain in (12, 4, 8):
        overrides = ["controller=smc", f"controller.switching_gain={gain}", "run.n_runs=2"]
        plan.append({"dir": _fake_job(sweep_dir, overrides, value=float(gain)), "overrides": overrides})
    io.write_json(sweep_dir / sweep.PLAN, {"jobs": plan})
    return sweep_dir


def test_swept_values_are_the_keys_that_vary_typed():
    keys, values = sweep.swept_values({
        "a": ["controller=smc", "controller.switching_gain=4", "run.n_runs=3", "controller.lam=2.5"],
        "b": ["controller=smc_ndo", "controller.switching_gain=12", "run.n_runs=3", "controller.lam=2.5"],
        "c": ["controller=smc", "controller.switching_gain=[1,2]", "run.n_runs=3", "hydra.sweep.dir=x"],
    })
    assert keys == ["controller", "controller.switching_gain", "controller.lam"]  # lam unset in c: it varies
    assert values["a"]["controller.switching_gain"] == 4 and isinstance(values["a"]["controller.switching_gain"], int)
    assert values["b"]["controller"] == "smc_ndo" and values["c"]["controller.switching_gain"] == [1, 2]
    assert values["c"]["controller.lam"] is None and "run.n_runs" not in values["a"]


def test_swept_values_parse_each_distinct_override_once(monkeypatch):
    """A sweep's jobs share most of their override lines: each distinct line is parsed once (Hydra's parser), not
    once a job (200 one-seed jobs: 151 -> 33 ms at the sweep's end), with the same typed values."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parsed_lines: list[str] = []
    original = OverridesParser.parse_overrides
    monkeypatch.setattr(OverridesParser, "parse_overrides",
                        lambda self, lines: (parsed_lines.extend(lines), original(self, lines))[1])
    jobs = {f"j{i}": ["run.n_runs=1", f"run.base_seed={i}", "controller.lam=[25,30]", "hydra.job.chdir=false"]
            for i in range(50)}
    keys, values = sweep.swept_values(jobs)
    assert keys == ["run.base_seed"] and values["j7"] == {"run.base_seed": 7}
    assert sorted(parsed_lines) == sorted({line for job in jobs.values() for line in job if not line.startswith("hydra.")})


def test_load_sweep_has_typed_swept_columns_sorted_numerically(gain_sweep):
    table = ddmr_cli.load_sweep(gain_sweep)
    assert pd.api.types.is_integer_dtype(table["controller.switching_gain"])
    assert list(table["controller.switching_gain"]) == [4, 4, 8, 8, 12, 12]  # numbers, not "12" < "4" < "8"
    assert list(table.seed) == [0, 1] * 3
    assert "run.n_runs" not in table.columns  # the same in every job: not a column
    np.testing.assert_allclose(table.deviation_mae, [4, 5, 8, 9, 12, 13])  # each job's own rows
    segments = ddmr_cli.load_sweep(gain_sweep, segments=True)
    assert len(segments) == 12 and list(segments["controller.switching_gain"].unique()) == [4, 8, 12]


def test_aggregate_writes_the_swept_columns_in_every_table_and_the_summary(gain_sweep, capsys):
    state = sweep.aggregate(gain_sweep)
    assert state.ok
    out = capsys.readouterr().out
    for name in (sweep.JOBS_CSV, sweep.SWEEP_METRICS_CSV, sweep.SWEEP_SEGMENTS_CSV):
        frame = pd.read_csv(gain_sweep / name)
        assert pd.api.types.is_integer_dtype(frame["controller.switching_gain"]), name
        gains = list(frame["controller.switching_gain"])
        assert gains == sorted(gains) and set(gains) == {4, 8, 12}, name
    jobs = pd.read_csv(gain_sweep / sweep.JOBS_CSV)
    assert {f"{m}_{s}" for m in io.HEADLINE for s in ("mean", "sd")} <= set(jobs.columns)
    rows = [line for line in out.splitlines() if line.strip().startswith("smc ")]
    assert [int(line.split()[2]) for line in rows] == [4, 8, 12]
    assert "deviation_mae [m]" in out and "e_theta_mae [rad]" in out and "chattering [V/s]" in out


def test_the_tables_are_written_inside_while_writing_and_the_summary_printed_after_it(gain_sweep, capsys):
    """``aggregate``'s ``while_writing`` (the sweep callback's status line) is entered before the jobs are read and
    left once every table is in place, before the summary is printed (a status line and the summary never mix)."""
    import contextlib

    seen = []

    @contextlib.contextmanager
    def writing():
        seen.append([(gain_sweep / name).is_file() for name in (sweep.JOBS_CSV, sweep.SWEEP_METRICS_CSV)])
        print("<writing>")
        yield
        seen.append([(gain_sweep / name).is_file() for name in (sweep.JOBS_CSV, sweep.SWEEP_METRICS_CSV)])
        print("</writing>")

    assert sweep.aggregate(gain_sweep, while_writing=writing).ok
    assert seen == [[False, False], [True, True]]
    out = capsys.readouterr().out
    assert out.index("</writing>") < out.index("ddmr sweep: 3 complete")


def test_pivot_of_load_sweep(gain_sweep):
    table = ddmr_cli.load_sweep(gain_sweep)
    pivot = table.pivot_table(index="controller.switching_gain", values="deviation_mae", aggfunc="mean")
    assert list(pivot.index) == [4, 8, 12]
    np.testing.assert_allclose(pivot.deviation_mae, [4.5, 8.5, 12.5])


def test_missing_and_failed_jobs_keep_their_swept_values(gain_sweep):
    plan = json.loads((gain_sweep / sweep.PLAN).read_text())["jobs"]
    plan.append({"dir": "controller.switching_gain=16,controller=smc,run.n_runs=2",
                 "overrides": ["controller=smc", "controller.switching_gain=16", "run.n_runs=2"]})
    io.write_json(gain_sweep / sweep.PLAN, {"jobs": plan})
    failed = _fake_job(gain_sweep, ["controller=smc", "controller.switching_gain=2", "run.n_runs=2"], status="failed")
    plan.append({"dir": failed, "overrides": ["controller=smc", "controller.switching_gain=2", "run.n_runs=2"]})
    io.write_json(gain_sweep / sweep.PLAN, {"jobs": plan})
    state = sweep.aggregate(gain_sweep)
    assert not state.ok and len(state.missing) == 1 and len(state.failed) == 1
    jobs = pd.read_csv(gain_sweep / sweep.JOBS_CSV)
    assert list(jobs["controller.switching_gain"]) == [2, 4, 8, 12, 16]
    assert list(jobs.status) == ["failed", "complete", "complete", "complete", "missing"]
    assert list(ddmr_cli.load_sweep(gain_sweep)["controller.switching_gain"].unique()) == [4, 8, 12]


@pytest.mark.slow
def test_gain_sweep_end_to_end(tmp_path):
    """The README's example, shortened: 2 controllers x 3 gains, rows differing by switching_gain."""
    sweep_dir = tmp_path / "gains"
    proc = run_ddmr(["run", "-m", "controller=smc,smc_ndo", "controller.switching_gain=4,8,12", "run.n_runs=2",
                     "simulation.duration=0.3", "run.plots=false", "run.progress=false",
                     f"hydra.sweep.dir={sweep_dir}"], cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    jobs = pd.read_csv(sweep_dir / sweep.JOBS_CSV)
    assert len(jobs) == 6 and set(jobs.status) == {"complete"}
    assert list(zip(jobs.controller, jobs["controller.switching_gain"])) == [
        ("smc", 4), ("smc", 8), ("smc", 12), ("smc_ndo", 4), ("smc_ndo", 8), ("smc_ndo", 12)]
    table = ddmr_cli.load_sweep(sweep_dir)
    assert len(table) == 12 and pd.api.types.is_integer_dtype(table["controller.switching_gain"])
    # the table is the jobs' own per-seed rows, with their gain
    for _, job in jobs.iterrows():
        own = pd.read_csv(sweep_dir / job.job / io.METRICS_CSV)
        rows = table[table.job == job.job]
        assert set(rows["controller.switching_gain"]) == {job["controller.switching_gain"]}
        np.testing.assert_allclose(rows.deviation_mae.to_numpy(), own.deviation_mae.to_numpy(), rtol=1e-12)
    assert "controller.switching_gain [rad/s^2]" in proc.stdout
    summary = [line.split() for line in proc.stdout.splitlines() if re.match(r"\s+smc(_ndo)?\s+paper_1\s", line)]
    assert [(row[0], int(row[2])) for row in summary] == [("smc", 4), ("smc", 8), ("smc", 12), ("smc_ndo", 4),
                                                          ("smc_ndo", 8), ("smc_ndo", 12)]


def _both_ways(sweep_dir: Path, name: str):
    """The per-seed table as one parse of every job's rows makes it (None: refused) and as job-by-job reads do."""
    state = sweep.read_state(sweep_dir)
    keys, values = sweep.swept_values(sweep._job_overrides(state))
    return (sweep._read_together(state, keys, values, name), sweep._read_each(state, keys, values, name))


@pytest.mark.parametrize("group_bytes", [1, 300, 2**20], ids=["a parse a job", "parses of two jobs", "one parse"])
@pytest.mark.parametrize("name", [io.METRICS_CSV, io.SEGMENTS_CSV])
def test_one_parse_of_every_job_is_the_table_of_job_by_job_reads(tmp_path, monkeypatch, name, group_bytes):
    """Keys of mixed types (an int and a float, a number unset in one job, a text, a bool, a list), jobs of one and
    of three seeds, parsed in groups of jobs of every size: the same columns, types and values as reading the jobs
    one by one."""
    monkeypatch.setattr(sweep, "READ_TOGETHER_BYTES", group_bytes)
    sweep_dir = tmp_path / "sweep"
    plan = []
    for i, extra in enumerate([["controller.switching_gain=4", "controller.lam=2.5", "tags.fast=true"],
                               ["controller.switching_gain=4.5", "tags.fast=false", "controller.ndo.gain=[1,2]"],
                               ["controller.switching_gain=12", "controller.lam=3", "scenario=paper_2"]]):
        overrides = ["controller=smc", *extra]
        plan.append({"dir": _fake_job(sweep_dir, overrides, seeds=(0,) if i == 1 else (0, 1, 2), value=float(i)),
                     "overrides": overrides})
    io.write_json(sweep_dir / sweep.PLAN, {"jobs": plan})
    together, each = _both_ways(sweep_dir, name)
    assert together is not None
    pd.testing.assert_frame_equal(together, each)
    assert together["controller.lam"].isna().sum() == (1 if name == io.METRICS_CSV else 2)  # unset in one job


def test_jobs_with_different_headers_or_a_row_over_two_lines_are_read_one_by_one(gain_sweep):
    state = sweep.read_state(gain_sweep)
    first, second = (d for d, _ in state.complete[:2])
    assert _both_ways(gain_sweep, io.METRICS_CSV)[0] is not None
    io.write_csv(first / io.METRICS_CSV, [{"controller": "smc", "scenario": "paper_1", "seed": 0, "status": "ok",
                                          "deviation_mae": 1.0, "extra": 2.0}])
    assert _both_ways(gain_sweep, io.METRICS_CSV)[0] is None  # its header differs
    io.write_csv(first / io.METRICS_CSV, [{"controller": "smc", "scenario": "a\nb", "seed": 0, "status": "ok",
                                          "deviation_mae": 1.0}])
    assert _both_ways(gain_sweep, io.METRICS_CSV)[0] is None  # a quoted line break: rows are not lines
    io.write_csv(second / io.METRICS_CSV, [{"controller": "smc", "scenario": "", "seed": 0, "status": "ok",
                                           "deviation_mae": 1.0}])
    io.write_csv(first / io.METRICS_CSV, [{"controller": "smc", "scenario": "paper_1", "seed": 0, "status": "ok",
                                          "deviation_mae": 1.0}])
    assert _both_ways(gain_sweep, io.METRICS_CSV)[0] is None  # an empty cell: typed within its job alone
    table = sweep.load_table(gain_sweep)  # and the table is still made, job by job
    assert len(table) == 4 and set(table["deviation_mae"]) >= {1.0}
