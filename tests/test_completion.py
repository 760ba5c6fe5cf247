"""Tab completion (issue 29): the subcommands first, paths after ``report``, topics after ``explain``, Hydra's
completion after ``run``; never a Hydra parse error."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from ddmr_cli.cli.main import main


def _query(line: str, monkeypatch, capsys) -> tuple[list[str], str]:
    monkeypatch.setenv("COMP_LINE", line)
    monkeypatch.setenv("COMP_POINT", str(len(line)))
    assert main(["-sc", "query=bash"]) == 0
    out = capsys.readouterr()
    return out.out.split(), out.err


@pytest.mark.parametrize("line, expected", [
    ("ddmr r", ["run", "report"]),
    ("ddmr ", ["run", "explain", "report", "bench", "sensitivity", "--help", "--version"]),
    ("ddmr ex", ["explain"]),
])
def test_the_first_word_completes_to_subcommands(line, expected, monkeypatch, capsys):
    words, err = _query(line, monkeypatch, capsys)
    assert words == expected and err == ""


@pytest.mark.parametrize("line", ["ddmr report ", "ddmr report outputs/ta", "ddmr bench --", "ddmr report x --out "])
def test_after_report_and_bench_nothing_is_offered_so_the_shell_offers_paths(line, monkeypatch, capsys):
    assert _query(line, monkeypatch, capsys) == ([], "")


def test_after_explain_the_topics_are_offered(monkeypatch, capsys):
    words, err = _query("ddmr explain controller.switching_g", monkeypatch, capsys)
    assert words == ["controller.switching_gain"] and err == ""
    words, _ = _query("ddmr explain controller.k", monkeypatch, capsys)
    assert "controller.kp" in words  # a key of another controller (pid)
    words, _ = _query("ddmr explain sen", monkeypatch, capsys)
    assert "sensor" in words


def _shell_query(line: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "COMP_LINE": line, "COMP_POINT": str(len(line))}
    return subprocess.run([sys.executable, "-m", "ddmr_cli.cli.main", "-sc", "query=bash"], env=env,
                          capture_output=True, text=True, timeout=120)


def test_after_run_and_after_an_explain_topic_hydra_completes_the_overrides():
    for line in ("ddmr run controller=sm", "ddmr explain controller.kp controller=sm"):
        p = _shell_query(line)
        assert p.returncode == 0 and "Error" not in p.stderr, p.stderr
        assert {"controller=smc", "controller=smc_ndo"} <= set(p.stdout.split()), line
