"""The self-documenting config: schema metadata on every field, ``ddmr run --help`` and ``ddmr explain KEY``."""

from __future__ import annotations

import dataclasses
import inspect
import re

import pytest

from ddmr_cli.config import compose_config, iter_keys, key_doc, key_docs, schema
from ddmr_cli.cli.main import main

SCHEMAS = [c for _, c in inspect.getmembers(schema, inspect.isclass)
           if dataclasses.is_dataclass(c) and c.__module__ == schema.__name__]


def test_every_schema_field_has_a_unit_and_a_meaning():
    from pathlib import Path

    model_doc = (Path(__file__).resolve().parents[1] / "docs" / "model.md").read_text(encoding="utf-8")
    sections = {int(n) for n in re.findall(r"^## (\d+)\. ", model_doc, re.MULTILINE)}
    assert len(SCHEMAS) >= 18  # robot, terrain, scenario, controllers, observers, trajectories, run, report, ...
    for cls in SCHEMAS:
        for f in dataclasses.fields(cls):
            meta = f.metadata
            assert {"unit", "help", "range", "model", "paper"} <= set(meta), f"{cls.__name__}.{f.name}"
            assert meta["help"].strip() and "\n" not in meta["help"], f"{cls.__name__}.{f.name}"
            assert meta["model"] is None or meta["model"] in sections, f"{cls.__name__}.{f.name}"


@pytest.mark.parametrize("overrides", [[], ["controller=pid", "trajectory=circle", "scenario=paper_2"],
                                       ["controller=open_loop", "trajectory=figure_eight", "launcher=slurm"]])
def test_every_key_of_a_composed_config_is_documented(overrides):
    cfg = compose_config(overrides)
    docs = key_docs(cfg)
    assert len(docs) == len(list(iter_keys(cfg))) > 40
    for doc in docs:
        assert doc.help, doc.key
    numbers = {d.key: d for d in docs if isinstance(d.value, (int, float)) and not isinstance(d.value, bool)}
    assert all(d.unit for d in numbers.values()), [k for k, d in numbers.items() if not d.unit]


def test_key_doc_follows_the_composed_schema():
    smc = compose_config(["controller=smc_ndo"])
    assert key_doc(smc, "controller.ndo.gain").unit == "1/s"
    assert key_doc(smc, "controller.switching_gain").reference == ("docs/model.md §6 (Controllers and observers); paper 3.1, "
                                                                         "eq. (17), Table 3")
    assert key_doc(compose_config(["controller=pid"]), "controller.kp").unit == "V s/rad"
    zone = key_doc(smc, "terrain.zones.very_rough.roughness")
    assert (zone.unit, zone.value, zone.model) == ("rad/s^2", 100.0, 5)
    assert key_doc(smc, "simulation.initial_pose.2").unit == "m, m, rad"
    with pytest.raises(KeyError):
        key_doc(smc, "controller.kp")


def test_explain_prints_meaning_unit_default_range_and_reference(capsys):
    assert main(["explain", "controller.switching_gain"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0] == "controller.switching_gain = 12.0"
    assert re.search(r"unit:\s+rad/s\^2", out) and re.search(r"default:\s+12\.0", out)
    assert re.search(r"range:\s+>= 0", out) and "docs/model.md §6" in out and "meaning:" in out


def test_explain_uses_the_overrides_and_finds_keys_of_other_options(capsys):
    assert main(["explain", "controller.switching_gain", "controller.switching_gain=7"]) == 0
    assert re.search(r"value:\s+7\b", capsys.readouterr().out)
    assert main(["explain", "controller.kp"]) == 0
    out = capsys.readouterr().out
    assert "V s/rad" in out and "controller=pid" in out


def test_explain_unknown_key_is_one_line_exit_2(capsys):
    assert main(["explain", "robot.masss"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ddmr: error: key=robot.masss: ")
    assert "did you mean robot.mass?" in lines[0] and captured.out == ""


def test_run_help_lists_every_key_with_value_unit_and_meaning(capsys):
    assert main(["run", "--help", "controller=pid"]) == 0
    out = capsys.readouterr().out
    assert "controller: adaptive_smc, adaptive_smc_ndo, adrc, open_loop, pid*," in out and ", sta, sta_ndo" in out
    line = next(line for line in out.splitlines() if line.strip().startswith("controller.kp "))
    assert re.match(r"\s+controller\.kp\s+5\.0\s+\[V s/rad\]\s+proportional gain", line), line
    line = next(line for line in out.splitlines() if line.strip().startswith("robot.mass "))
    assert re.match(r"\s+robot\.mass\s+15\.0\s+\[kg\]\s+robot mass", line), line
    for key in iter_keys(compose_config(["controller=pid"])):
        assert re.search(rf"^\s+{re.escape(key)}\s", out, re.M), key
