"""The sensitivity study's stages are listed once (issue 27): ``ddmr_cli.study.stages.STAGES``, which the designs,
the calibration search, the driver and the report read, and one experiment preset per stage."""

from __future__ import annotations

from importlib import resources

import yaml

from ddmr_cli.cli import sensitivity as driver
from ddmr_cli.report import sensitivity as report
from ddmr_cli.study import design, search
from ddmr_cli.study.stages import STAGES


def _presets() -> dict[str, dict]:
    folder = resources.files("ddmr_cli.conf").joinpath("experiment")
    return {p.name[:-len(".yaml")]: yaml.safe_load(p.read_text(encoding="utf-8")) for p in folder.iterdir()
            if p.name.startswith("sensitivity_") and p.name.endswith(".yaml")}


def test_every_stage_has_its_preset_and_every_preset_is_a_stage():
    presets = _presets()
    assert set(presets) == {f"sensitivity_{s}" for s in STAGES}
    for stage in STAGES:
        assert presets[f"sensitivity_{stage}"]["study"]["stage"] == stage


def test_the_consumers_read_the_one_list():
    assert driver.STAGES is STAGES and design.STAGES is STAGES
    assert set(search.OTHER_STAGES) >= set(STAGES) - {search.STAGE} and search.STAGE in STAGES
    assert search.STAGE not in search.OTHER_STAGES


def test_the_report_reads_every_stage(tmp_path, monkeypatch):
    """A stage the report did not know would be silently left out of it: every stage's study.csv is read."""
    seen = []
    monkeypatch.setattr(report, "_read_csv", lambda path: seen.append(path.relative_to(tmp_path).as_posix()))
    report.write_report(tmp_path)
    assert {f"{s}/study.csv" for s in STAGES} <= set(seen)
