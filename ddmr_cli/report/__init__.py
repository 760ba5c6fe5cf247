"""``ddmr report``: the paper's tables and figures from a sweep (or a single run dir), beside its numbers.

Writes ``report.md``, ``tables/*.csv`` and ``figures/*.png`` under the output dir (default ``PATH/report``):
Table 3 (parameters), Table 4 (tracking statistics, with the paper's numbers and the ratio ours/paper),
verdicts on the paper's claims (paired by seed: bootstrap CI and Wilcoxon test), chattering, energy,
saturation, disturbance estimation, per-zone and per-phase tables, and the paper's figures per scenario.
pandas and matplotlib are imported only when a report is built.
"""

from __future__ import annotations

from pathlib import Path


def build_report(path, out=None, margin=None, figures: bool = True, progress: bool = True,
                 all_figures: bool = False, on_verdicts=None) -> Path:
    """Build the report of a sweep dir or a run dir; returns the output dir.

    ``margin`` is the practical margin of the verdicts (a tie when the 95 % CI of a paired difference lies inside
    it): a :class:`~ddmr_cli.report.stats.Margin`, a length in metres (``1e-4``), or text (``"0.1mm"``, ``"5%"``);
    default 0.1 mm for the metrics in metres and 5 % of the reference's mean for the others. ``figures=False``
    writes the markdown and every table without drawing a figure (seconds instead of tens of seconds). A scenario
    on a reference other than the paper's line gets its summary figures only, unless ``all_figures``.
    ``progress``: a bar with an ETA on stderr (a plain line every 10 s when stderr is not a terminal).
    ``on_verdicts``: called with the verdicts on the paper's claims in plain text, one line per claim, scenario and
    reading, then one line counting the comparisons against baseline controllers by verdict, as soon as they are
    known (before the figures are drawn; not called when no claim could be checked).

    Raises
    ------
    ddmr_cli.errors.DDMRError
        ``path`` is not a dir, holds no job, or no job completed.
    ValueError
        ``margin`` cannot be read.
    """
    from ddmr_cli.report.build import build

    return build(path, out, margin, figures, progress, all_figures, on_verdicts)


__all__ = ["build_report"]
