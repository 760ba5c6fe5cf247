"""The paper's published numbers and its claims, the one place either is written (issue 27).

:func:`numbers` reads ``ddmr_cli/data/paper_numbers.json`` (Tables 1, 3 and 4, the estimation MAEs, what the
text says of each figure; docs/model.md §8); :mod:`.claims` defines each claim the report's verdicts and the
sensitivity study judge (``report/verdicts.py``, ``study/claims.py``). Nothing here imports the rest of the
package: the report, the study and the command line all sit above it.
"""

from __future__ import annotations

import json
from importlib import resources

#: The scenario the paper's Table 4 is compared against (the paper does not say which one it is).
PAPER_SCENARIO = "paper_1"

#: Table 4's columns: (our metric, statistic, paper column, header).
TABLE4_COLUMNS = (
    ("deviation_mae", "mean", "deviation_mean", "Deviation mean (m)"),
    ("deviation_mae", "sd", "deviation_sd", "Deviation SD (m)"),
    ("e_x_mae", "mean", "e_x_mae", "e_x MAE (m)"),
    ("e_y_mae", "mean", "e_y_mae", "e_y MAE (m)"),
    ("e_theta_mae", "mean", "e_theta_mae", "e_θ MAE (rad)"),
)


def numbers() -> dict:
    """The paper's published numbers, shipped as ``ddmr_cli/data/paper_numbers.json``."""
    text = resources.files("ddmr_cli.data").joinpath("paper_numbers.json").read_text(encoding="utf-8")
    return json.loads(text)


__all__ = ["numbers", "PAPER_SCENARIO", "TABLE4_COLUMNS"]
