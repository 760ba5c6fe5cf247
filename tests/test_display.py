"""A controller's label, style and rank live in its YAML's ``display`` node (issue 27): the packaged ones set every
key, a bad value is refused with one line naming the key, and a controller without the keys (a user's YAML, or
one extending a packaged YAML) still gets a label, a style of its own and a place after the known ones."""

from __future__ import annotations

import re

import math

import pytest

from ddmr_cli.errors import ConfigError
from ddmr_cli import display
from ddmr_cli.plots import common as P

PACKAGED = display.packaged_all()


def test_every_packaged_controller_sets_every_key_once():
    assert len(PACKAGED) >= 12
    for name, node in PACKAGED.items():
        assert set(node) == set(display.RULES), name
        display.check(node)
    shown = [display.of(n) for n in PACKAGED]
    assert len({d.label for d in shown}) == len(shown)
    assert len({(d.colour, d.dash) for d in shown}) == len(shown)   # not told apart by a marker only
    assert len({d.rank for d in shown}) == len(shown)
    order = [d.name for d in sorted(shown, key=lambda d: d.order)]
    assert order[:4] == ["pid", "smc", "smc_ndo", "smc_ndo_nno"]       # the paper's order, largest deviation first
    assert display.label("smc_ndo_nno") == "SMC-NDO-NNO" and display.of("smc_ndo_nno").colour == "#000000"


def test_the_composed_config_carries_the_display_and_the_constructor_does_not():
    import ddmr_cli
    from ddmr_cli.config.build import config_hash, result_config

    cfg = ddmr_cli.compose_config(["controller=smc_ndo_nno_text"])
    assert cfg.controller.display.label == "SMC-NDO-NNO (text reading)"    # its own, over the one it extends
    assert "display" not in result_config(cfg)["controller"]
    assert result_config(cfg, display=True)["controller"]["display"]["rank"] == 5
    relabelled = ddmr_cli.compose_config(["controller=smc_ndo_nno_text", "controller.display.label=other"])
    assert config_hash(relabelled) == config_hash(cfg)                      # not the numbers: a sweep resumes
    ddmr_cli.paper_simulation("controller=smc_ndo_nno_text")                # the constructor never sees it


@pytest.mark.parametrize("override, key", [
    ("controller.display.colour=red", "controller.display.colour"),
    ("controller.display.dash=wavy", "controller.display.dash"),
    ("controller.display.rank=-1", "controller.display.rank"),
    ("controller.display.width=0", "controller.display.width"),
    ("controller.display.label=' '", "controller.display.label"),
])
def test_a_bad_value_is_refused_naming_the_key(override, key):
    import ddmr_cli
    from ddmr_cli.config.validate import validate_config

    with pytest.raises(ConfigError) as err:
        validate_config(ddmr_cli.compose_config(["controller=smc", override]))
    assert err.value.key == key


def test_the_cli_refuses_a_bad_colour_with_one_line(tmp_path, monkeypatch, capsys):
    from ddmr_cli.cli import main

    monkeypatch.chdir(tmp_path)
    assert main.main(["run", "controller.display.colour=reddish", "run.n_runs=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "controller.display.colour" in err[0] and "#rrggbb" in err[0], err


def test_a_controller_without_the_keys_gets_the_defaults():
    bare = display.of("computed_torque", None)
    assert (bare.label, bare.colour, bare.rank) == ("computed_torque", None, math.inf)
    # a user's YAML extending smc_ndo inherits its display through Hydra: read as absent, not as SMC-NDO's
    inherited = display.of("my_ndo", PACKAGED["smc_ndo"])
    assert (inherited.label, inherited.colour, inherited.dash, inherited.rank) == ("my_ndo", None, None, math.inf)
    # what the user sets over it is theirs
    own = display.of("my_ndo", {**PACKAGED["smc_ndo"], "label": "My NDO", "dash": "dotted", "rank": 0})
    assert (own.label, own.dash, own.rank, own.colour) == ("My NDO", "dotted", 0, None)
    # a job dir written before the node existed: the packaged YAML
    assert display.of_job("smc", {"controller": {"name": "smc"}}).label == "SMC"
    book = P.StyleBook(["smc_ndo", "my_ndo"], {"my_ndo": inherited})
    assert book["my_ndo"] != book["smc_ndo"] and book["smc_ndo"] == P.known_styles()["smc_ndo"]


def test_report_of_a_sweep_with_controllers_lacking_the_keys(tmp_path):
    """Two user controllers beside the paper's: one extending smc (it inherits smc's display), one with none at
    all. Each is labelled by its name, drawn in a style no other controller has, and listed after the known
    ones; the paper's controllers keep their labels."""
    from test_report import _md, _read, write_job

    from ddmr_cli.report import build_report
    from ddmr_cli.report.data import load

    sweep = tmp_path / "sweep"
    for controller in ("smc", "smc_ndo_nno"):
        write_job(sweep, controller, "paper_1")
    write_job(tmp_path / "a", "smc", "paper_1", ["controller.name=my_smc"]).rename(
        sweep / "controller=my_smc,scenario=paper_1")
    write_job(tmp_path / "b", "smc_ndo", "paper_1", ["controller.name=bare", "controller.display=null"]).rename(
        sweep / "controller=bare,scenario=paper_1")
    data = load(sweep)
    assert data.keys("paper_1") == ["smc", "smc_ndo_nno", "bare", "my_smc"]
    assert [data.label(k) for k in data.keys("paper_1")] == ["SMC", "SMC-NDO-NNO", "bare", "my_smc"]
    shown = data.displays()
    book = P.StyleBook(shown, shown)
    assert len({book[c] for c in shown}) == len(shown)
    out = build_report(sweep, tmp_path / "report", figures=False)
    t4 = _read(out / "tables" / "table4.csv")
    assert {"my_smc", "bare"} <= set(t4["controller"])
    md = _md(out)
    assert all(re.search(rf"^\| {name} +\|", md, re.MULTILINE) for name in ("my_smc", "bare", "SMC-NDO-NNO"))
