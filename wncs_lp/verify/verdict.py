"""One verdict rule for a structural check, shared by ``wncs-lp verify`` and the reproduction.

A structural claim (Theorems 1-3, the switching curves of Figs. 11-12) is decided from the counts
of its check, never from a bare flag:

* **HOLDS** -- no violation beyond the tie tolerance;
* **FAILS** -- some violation lies where the optimal policy's chain lives in the long run
  (every state involved is recurrent) *and* away from the AoI cap (no state involved has some
  tau at its cap): observable, and not a truncation artefact;
* **DEPENDS** -- violations exist, but each involves a transient state (never revisited in the long
  run, so it cannot change the average cost) or touches the cap (where the truncation, not the
  paper's model, decides).

Across several instances (caps, scenarios) of one claim, :func:`combine` gives FAILS when one
instance FAILS (a counterexample is decisive), HOLDS when all hold, DEPENDS otherwise.
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping

__all__ = ["HOLDS", "FAILS", "DEPENDS", "ERROR", "VERDICTS", "RULE", "structural_verdict", "verdict_of", "combine"]

HOLDS = "HOLDS"
FAILS = "FAILS"
DEPENDS = "DEPENDS"
#: Not a verdict: the claim could not be computed.
ERROR = "ERROR"
VERDICTS = (HOLDS, DEPENDS, FAILS)

#: The rule in one sentence (printed by ``wncs-lp verify`` and in the report).
RULE = ("HOLDS: no violation; FAILS: a violation whose states are all recurrent and none at the AoI cap; "
        "DEPENDS: violations only in transient states or touching the cap")


def structural_verdict(holds: bool, recurrent_below_cap: int) -> str:
    """The verdict of one check from its numbers.

    Parameters
    ----------
    holds : bool
        No violation beyond the tolerance.
    recurrent_below_cap : int
        Violations whose states are all recurrent and none at the cap.
    """
    if holds:
        return HOLDS
    return FAILS if int(recurrent_below_cap) > 0 else DEPENDS


def verdict_of(report: Any) -> str:
    """:func:`structural_verdict` of a :class:`~wncs_lp.verify.CheckReport` or of its JSON dict
    (or any mapping with ``holds`` and ``split["recurrent_below_cap"]``)."""
    if isinstance(report, Mapping):
        holds, split = report["holds"], report.get("split") or {}
    else:
        holds, split = report.holds, report.split or {}
    return structural_verdict(bool(holds), int(split.get("recurrent_below_cap", 0)))


def combine(verdicts: Iterable[str]) -> str:
    """One verdict over several instances: any FAILS -> FAILS; all HOLDS -> HOLDS; else DEPENDS.

    An ERROR among them makes the result ERROR (an instance that could not be computed is not
    evidence either way). No instance at all is an ERROR too.
    """
    vs = list(verdicts)
    if not vs or ERROR in vs:
        return ERROR
    if FAILS in vs:
        return FAILS
    if all(v == HOLDS for v in vs):
        return HOLDS
    return DEPENDS
