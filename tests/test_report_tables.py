"""The report's table formatting on constructed numbers."""

from __future__ import annotations

import math
import re

import pytest

from ddmr_cli.report.tables import fmt, pm


@pytest.mark.parametrize("mean, sd, expected", [
    (0.0008, 1.1e-19, "0.0008 ± 0"),             # rounding noise of identical runs
    (0.003214, 0.000412, "0.00321 ± 0.00041"),
    (0.0018, 1.433e-05, "0.001800 ± 0.000014"),
    (0.0008, 0.00011, "0.00080 ± 0.00011"),
    (12.345, 0.0001, "12.3450 ± 0.00010"),
    (21.08, 0.4637, "21.08 ± 0.46"),
    (48.3, 3.1, "48.3 ± 3.1"),
    (5.0, 12.0, "5 ± 12"),
    (-0.5, 0.01, "-0.500 ± 0.010"),
    (1e-5, 3e-7, "(1.000 ± 0.030)e-05"),
    (123456.0, 789.0, "(1.2346 ± 0.0079)e+05"),
    (3.0, math.nan, "3"),
    (math.nan, 1.0, "–"),
])
def test_pm(mean, sd, expected):
    assert pm(mean, sd) == expected


def test_fmt():
    assert fmt(0.0187) == "0.0187" and fmt(math.nan) == "–" and fmt(0) == "0" and fmt(2.5e-5) == "2.500e-05"


def test_md_table_right_aligns_numbers_in_shared_exponent_form():
    from ddmr_cli.report.tables import md_table

    table = md_table(["Controller", "slightly_rough (m)"], [["SMC", pm(0.00038, 0.00013)],
                                                            ["SMC-NDO", pm(2.25e-5, 0.94e-5)]])
    lines = table.splitlines()
    assert re.fullmatch(r"\|:-+\|-+:\|", lines[1])  # text left, numbers right
    assert [c.strip() for c in lines[3].strip("|").split("|")] == ["SMC-NDO", "(2.25 ± 0.94)e-05"]


def test_md_table_is_pandas_to_markdown_with_the_cells_as_given():
    from ddmr_cli.report.tables import md_table

    table = md_table(["Controller", "Runs", "Note"], [["pid", "050", "a|b"], ["smc", "1e3", "two\nlines"]])
    assert table.splitlines() == ["| Controller   |   Runs | Note      |",
                                  "|:-------------|-------:|:----------|",
                                  "| pid          |    050 | a\\|b      |",
                                  "| smc          |    1e3 | two lines |"]
