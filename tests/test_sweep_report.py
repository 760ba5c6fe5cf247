"""From sweep to report in one step: ``report=true``, ``report.margin`` passed through only when the report takes
it, ``ddmr report`` without a path; and the one-line message for a launcher whose plugin is missing."""

from __future__ import annotations

import importlib.util

import pytest

import ddmr_cli.report
from ddmr_cli.cli import args, run
from ddmr_cli.cli import main as cli


def _fake_report(calls: list):
    def build_report(path, out=None, margin=None, figures=True, progress=True, all_figures=False, on_verdicts=None):
        calls.append((path, out, margin, figures))
        return path
    return build_report


def test_report_shorthand_is_the_auto_key():
    assert args.normalise(["-m", "report=true", "report=False", "report.margin=0.1", "x.report=true"]) == [
        "-m", "report.auto=true", "report.auto=false", "report.margin=0.1", "x.report=true"]


def test_a_bad_margin_is_refused_before_running(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "report=true", "report.margin=wide", "run.n_runs=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ddmr: error: report.margin=wide:")
    assert list(tmp_path.iterdir()) == []
    assert cli.main(["report", str(tmp_path), "--margin=-3%"]) == 2


@pytest.mark.parametrize("bare", ["5", "0.05", "1e-4"])
def test_a_margin_without_a_unit_is_refused_in_one_line(tmp_path, bare, capsys):
    """``--margin 5`` once meant 5 m and made every verdict a tie; a bare number is refused, exit 2, one line."""
    assert cli.main(["report", str(tmp_path), "--margin", bare]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"ddmr: error: --margin={bare}:") and "unit" in err[0]
    assert list(tmp_path.iterdir()) == []


def test_margin_is_passed_through_when_the_report_takes_one(tmp_path, monkeypatch, capsys):
    calls: list = []
    monkeypatch.setattr(ddmr_cli.report, "build_report", _fake_report(calls))
    assert cli.main(["report", str(tmp_path), "--margin", "0.05mm"]) == 0
    assert calls == [(tmp_path, None, "0.05mm", True)]
    assert cli.main(["report", str(tmp_path)]) == 0  # no margin given: the report's own default
    assert calls[-1][2] is None
    assert cli.main(["report", str(tmp_path), "--no-figures"]) == 0  # tables and text only
    assert calls[-1] == (tmp_path, None, None, False)
    launch = run.prepare(["report.margin=0.05mm"], ["report.margin=0.05mm", "run.n_runs=1"], multirun=False)
    assert launch.margin == "0.05mm" and launch.report is False


@pytest.mark.skipif(importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is not None,
                    reason="the ray extra is installed")
def test_ray_launcher_missing_names_the_ray_extra(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "-m", "+experiment=smoke", "launcher=ray"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "ddmr: error: launcher=ray: Hydra's ray launcher plugin is not installed; pip install 'ddmr-cli[ray]' "
        "(or pip install -e '.[ray]' in a checkout)"]
    assert list(tmp_path.iterdir()) == []
