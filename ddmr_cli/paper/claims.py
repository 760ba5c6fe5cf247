"""The paper's claims, each written once (issue 27): what the paper says and where, the controllers it compares,
the metrics we judge it on, the claimed reduction and its band.

Two consumers read these definitions and nothing else: the report's verdicts (``report/verdicts.py``: every
comparison paired by seed, a verdict on each of :attr:`Claim.metrics`, the overall one on the first) and the
sensitivity study (``study/claims.py``: each claim's statistic at every reading of the box, on the first metric,
and whether it lies in :meth:`Claim.bounds`). A *reduction* of a candidate against a reference is
``1 - candidate / reference`` of a metric's mean over paired seeds, a fraction here (the study prints percent).

Kinds (:data:`KINDS`):

- ``improvement``: the candidate's metric is lower than the reference's by the claimed reduction, "about"
  ``value`` (``value ± band``) or "at least" ``value`` (no band). No practical difference refutes it.
- ``ranking``: a chain of improvements, :attr:`Claim.controllers` from the largest metric to the smallest.
- ``baseline``: not a paper claim: SMC-NDO-NNO (candidate) against another controller (:func:`baseline`), where
  equality in practice (a tie) is an outcome.

The metrics are columns of a job's ``metrics.csv`` (docs/model.md §7): the deviation claims rest on the
steady-state deviation (``deviation_mae_ss``, the start-up transient from the offset pose left out), with the
paper's own whole-run deviation (its Table 4) beside it; the chattering claim on the share of var(u) above the
high-pass cutoff (``hf_fraction``, which isolates switching), with the total variation of u (``chattering``, the
field's common measure, which also counts the compensation of the terrain) beside it; the estimation claim on
the whole-run estimation MAE, as the paper's. A consumer whose jobs lack a steady-state metric reads its
whole-run twin (:func:`available`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable

from ddmr_cli.engine.catalog import STEADY
from ddmr_cli.paper import numbers

IMPROVEMENT, RANKING, BASELINE = "improvement", "ranking", "baseline"
KINDS = (IMPROVEMENT, RANKING, BASELINE)
#: The paper's SMC-NDO-NNO: its Table 3 reading, and the text's reading of the NN parameters (docs/model.md §6);
#: the report judges every claim on each reading it has jobs for, the study on the first.
NNO_READINGS = ("smc_ndo_nno", "smc_ndo_nno_text")
NNO = NNO_READINGS[0]
#: Half-width of the paper's "about" / "approximately" (a fraction of the reference: 40 % is 30-50 %).
ABOUT_BAND = 0.10

DEVIATION = ("deviation_mae" + STEADY, "deviation_mae")
CHATTERING = ("hf_fraction", "chattering")
ESTIMATION = ("d_est_mae",)


@dataclass(frozen=True)
class Claim:
    """One claim of the paper (or a baseline comparison).

    Attributes
    ----------
    id : str
        The claim's name in every table (``verdicts.csv``'s ``claim``, the study's columns).
    title : str
        The claim in our words, as the report heads it.
    text : str
        The claim as the paper states it (quoted).
    source : str
        Where the paper states it.
    kind : str
        ``improvement``, ``ranking`` or ``baseline`` (:data:`KINDS`).
    controllers : tuple of str
        ``(reference, candidate)``; for a ranking, the claimed order, largest metric first.
    metrics : tuple of str
        The metrics it is judged on; the verdict (and the study's statistic) rests on the first.
    value : float
        The claimed reduction (a fraction of the reference); 0 for a ranking or a baseline (any reduction).
    band : float or None
        Half-width of an "about" claim (``value ± band``); None: a reduction of at least ``value``.
    reading : str
        How the claim is read where the paper leaves it open (empty when it does not).
    """

    id: str
    title: str
    text: str
    source: str
    kind: str
    controllers: tuple[str, ...]
    metrics: tuple[str, ...]
    value: float = 0.0
    band: float | None = None
    reading: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"claim {self.id}: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if len(self.controllers) < 2 or (self.kind != RANKING and len(self.controllers) != 2):
            raise ValueError(f"claim {self.id}: controllers {self.controllers} (a pair, or a ranking of 2 or more)")

    @property
    def reference(self) -> str:
        return self.controllers[0]

    @property
    def candidate(self) -> str:
        return self.controllers[-1]

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The (reference, candidate) comparisons the claim makes: each adjacent pair of a ranking."""
        return list(zip(self.controllers, self.controllers[1:]))

    @property
    def about(self) -> bool:
        return self.band is not None

    def bounds(self, scale: float = 1.0) -> tuple[float, float]:
        """The range of the reduction the claim asserts, ``(low, high)`` times ``scale`` (100: percent)."""
        if self.band is None:
            return scale * self.value, math.inf
        return scale * (self.value - self.band), scale * (self.value + self.band)

    @property
    def claimed(self) -> str:
        """The claimed reduction as a sentence ("a reduction of 40 ± 10 %")."""
        if self.kind == RANKING:
            return "each adjacent pair lower"
        if self.kind == BASELINE:
            return "lower"
        if self.about:
            return f"a reduction of {100 * self.value:.0f} ± {100 * self.band:.0f} %"
        return f"a reduction of at least {100 * self.value:.0f} %"


def estimation_reduction() -> float:
    """The reduction of the estimation MAE the paper reports: 1 - NDO+NNO / NDO (48.3152 -> 15.9876: 0.669)."""
    est = numbers()["claims"]["estimation"]
    return 1.0 - est["ndo_nno"] / est["ndo"]


def claims() -> tuple[Claim, ...]:
    """The paper's claims, in the report's order."""
    est = numbers()["claims"]["estimation"]
    est_reduction = estimation_reduction()
    return (
        Claim("ranking", "Ranking PID > SMC > SMC-NDO > SMC-NDO-NNO (deviation, largest first)",
              "The proposed controller achieved the lowest MAE for trajectory tracking [...] significantly improved "
              "performance compared to classical controllers such as PID, SMC, and even the improved SMC-NDO "
              "version", "section 5 (conclusion); the order of Table 4's deviation means", RANKING,
              ("pid", "smc", "smc_ndo", NNO), DEVIATION),
        Claim("vs_smc_ndo", "SMC-NDO-NNO: about 40 % lower deviation than SMC-NDO",
              "the SMC-NDO-NNO reduces the trajectory tracking Mean Absolute Error (MAE) by approximately 40% "
              "compared to the SMC-NDO", "section 1 (contributions), from Table 1 (tracking accuracy 0.0035 -> "
              "0.0021 m); its Table 4 gives 18.8 %", IMPROVEMENT, ("smc_ndo", NNO), DEVIATION,
              value=0.40, band=ABOUT_BAND),
        Claim("vs_smc", "SMC-NDO-NNO: over 60 % lower deviation than SMC",
              "[reduces the trajectory tracking MAE] over 60% compared to the standalone SMC",
              "section 1 (contributions), from Table 1 (tracking accuracy 0.0055 -> 0.0021 m); its Table 4 gives "
              "50 %", IMPROVEMENT, ("smc", NNO), DEVIATION, value=0.60),
        Claim("chattering", "SMC-NDO-NNO: near-complete elimination of chattering (vs SMC-NDO)",
              "Near-complete elimination, generating smooth control signals", "Table 1 (Chattering); section 5",
              IMPROVEMENT, ("smc_ndo", NNO), CHATTERING, value=0.90,
              reading="read as a reduction of at least 90 %"),
        Claim("estimation", f"Disturbance-estimation MAE: NDO {est['ndo']:.1f} vs NDO+NNO {est['ndo_nno']:.1f} "
                            f"(a {100 * est_reduction:.0f} % reduction, 'three times lower')",
              f"the average estimation error of the NDO-NNO is {est['ndo_nno']}, which is three times lower than "
              f"that of the standalone NDO ({est['ndo']})", "section 4, scenario 1 (Fig. 7)", IMPROVEMENT,
              ("smc_ndo", NNO), ESTIMATION, value=est_reduction, band=ABOUT_BAND,
              reading="our d_est_mae of SMC-NDO (NDO estimate) vs SMC-NDO-NNO (NDO + NN estimate)"),
    )


#: What SMC-NDO-NNO is compared with a baseline on: (aspect, metrics).
BASELINE_METRICS = (("deviation", DEVIATION[:1]), ("chattering", ("chattering",)))


def baseline(controller: str) -> tuple[Claim, ...]:
    """SMC-NDO-NNO against ``controller``, a controller no claim of the paper names (not a paper claim): one
    comparison per aspect of :data:`BASELINE_METRICS`."""
    return tuple(Claim(f"{controller}:{aspect}", f"SMC-NDO-NNO vs {controller}: {aspect}", "", "not a paper claim",
                       BASELINE, (controller, NNO), metrics) for aspect, metrics in BASELINE_METRICS)


def paper_controllers() -> frozenset[str]:
    """The controllers the paper's claims name, the other NNO reading and the ablations of SMC-NDO-NNO; any
    other controller of a report is a baseline (:func:`baseline`)."""
    named = {c for claim in claims() for c in claim.controllers}
    return frozenset(named | set(NNO_READINGS) | {"smc_nno", "open_loop"})


def available(metrics: Iterable[str], has: Callable[[str], bool]) -> tuple[str, ...]:
    """``metrics`` as a consumer can read them: a steady-state metric its jobs lack (``has(metric)`` false) is
    replaced by its whole-run twin, and a metric named twice is kept once."""
    out = [m[:-len(STEADY)] if m.endswith(STEADY) and not has(m) else m for m in metrics]
    return tuple(dict.fromkeys(out))


def by_id() -> dict[str, Claim]:
    return {c.id: c for c in claims()}


__all__ = ["Claim", "claims", "by_id", "baseline", "available", "paper_controllers", "estimation_reduction",
           "KINDS", "IMPROVEMENT", "RANKING", "BASELINE", "NNO", "NNO_READINGS", "ABOUT_BAND",
           "DEVIATION", "CHATTERING", "ESTIMATION", "BASELINE_METRICS"]
