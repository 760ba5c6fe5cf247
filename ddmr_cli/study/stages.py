"""The stages of the sensitivity study (docs/model.md §11), the one list of them (issue 27).

Each stage is one sweep, ``ddmr run -m +experiment=sensitivity_<stage>`` (``conf/experiment/sensitivity_<stage>.yaml``
sets ``study.stage``), written into ``OUT/<stage>``; ``ddmr sensitivity`` runs them in this order (Morris before
Sobol, which takes Morris's top parameters; lhs before the calibration, which it warm-starts; the calibration
before the points, which rerun its best reading), its report reads them. No imports: the command line reads
this before anything heavy is loaded.
"""

from __future__ import annotations

#: every stage, in the order ``ddmr sensitivity`` runs them
STAGES = ("oat", "morris", "sobol", "map", "lhs", "calibration", "points")


__all__ = ["STAGES"]
