"""The rules of the verdicts, in one place: structural checks, claims made of sub-claims, descriptive claims.

Every verdict of ``wncs-lp verify`` and of the reproduction is one of these rules applied to the
numbers printed beside it.

**Structural claims** (Theorems 1-3, the switching curves of Figs. 11-12, the policy maps) are
decided from the counts of their check, never from a bare flag:

* **HOLDS** -- no violation beyond the tie tolerance;
* **FAILS** -- some violation has a *witness* (the states that show it) lying where the optimal
  policy's chain lives in the long run (every state of the witness recurrent) *and* away from
  the AoI cap (no state of the witness has some tau at its cap): observable, and not a
  truncation artefact;
* **DEPENDS** -- violations exist, but every witness of each involves a transient state (never
  revisited in the long run, so it cannot change the average cost) or touches the cap (where
  the truncation, not the paper's model, decides).

A violation can have several witnesses (a line-gap: any two states choosing the action with a
state between them that strictly prefers another; an order reversal: any line of the majority
order). It is judged by its best witness, :func:`witness_class`: recurrent and below the cap
first, then below the cap, then recurrent, then any; so a violation is filed *at the cap* only
when every witness touches the cap. Beside each structural verdict the reports give the
stationary probability of the violating states (the weight of the counterexample).

Across several instances (caps, scenarios) of one claim, :func:`combine` gives FAILS when one
instance FAILS (a counterexample is decisive), HOLDS when all hold, DEPENDS otherwise.

**Claims made of sub-claims** (:func:`subclaims_verdict`): HOLDS when every sub-claim holds at
every instance; FAILS when one sub-claim fails at every instance where it is checked (false
whatever the truncation); DEPENDS otherwise. The words of the paper are read with fixed bars:
"much better" / "vastly improved" = at least :data:`MUCH` above, "close" = within :data:`CLOSE`,
"not significant" = below :data:`SIGNIFICANT`, "equal" = within :data:`EQ_RTOL`. "Shrinks as p
grows" is judged by :func:`nonincreasing`: a bump counts only beyond the certificates of the two
numbers compared.

**Descriptive claims** (the maps of Figs. 4 and 6-7): one verdict per instance, :func:`across`
instances DEPENDS when they disagree.

**Static** has two readings, kept apart: *destinations fixed* (:func:`destinations_fixed`, the
paper's "each process will only transmit the status information to the corresponding
controller") and *equal to a static rule* (the same average cost as the best static policy,
which also fixes the order in which processes sharing a server are sent).
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping, Sequence

import numpy as np

__all__ = ["HOLDS", "FAILS", "DEPENDS", "ERROR", "VERDICTS", "RULE", "MUCH", "CLOSE", "SIGNIFICANT", "EQ_RTOL",
           "structural_verdict", "verdict_of", "combine", "across", "subclaims_verdict", "witness_class",
           "nonincreasing", "destinations", "destinations_fixed", "static_reading", "STATIC_RULE",
           "FIXED_DESTINATIONS_ONLY", "NOT_STATIC"]

HOLDS = "HOLDS"
FAILS = "FAILS"
DEPENDS = "DEPENDS"
#: Not a verdict: the claim could not be computed.
ERROR = "ERROR"
VERDICTS = (HOLDS, DEPENDS, FAILS)

#: The rule in one sentence (printed by ``wncs-lp verify`` and in the report).
RULE = ("HOLDS: no violation; FAILS: a violation with a witness whose states are all recurrent and none at the "
        "AoI cap; DEPENDS: violations only in transient states or touching the cap")

#: "Much better" (and the paper's "vastly improved", "greatly improved"): the other policy costs at
#: least this much more, relative.
MUCH = 0.10
#: "Close to optimal": within this relative distance.
CLOSE = 0.05
#: An improvement below this relative size is "not significant".
SIGNIFICANT = 0.01
#: Relative tolerance for "equal" average costs (the exact evaluations are certified far below).
EQ_RTOL = 1e-7


def structural_verdict(holds: bool, recurrent_below_cap: int) -> str:
    """The verdict of one check from its numbers.

    Parameters
    ----------
    holds : bool
        No violation beyond the tolerance.
    recurrent_below_cap : int
        Violations with a witness whose states are all recurrent and none at the cap.
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


def across(verdicts: Sequence[str]) -> str:
    """A descriptive claim over several instances: the common verdict, or DEPENDS when they differ."""
    vs = list(verdicts)
    return vs[0] if vs and all(v == vs[0] for v in vs) else DEPENDS


def subclaims_verdict(results: dict[str, dict[Any, bool | None]]) -> str:
    """The verdict of a claim made of sub-claims, each checked at several instances (caps).

    HOLDS: every sub-claim holds at every instance; FAILS: some sub-claim fails at every instance
    where it is checked (it is false whatever the truncation); DEPENDS: otherwise (some sub-claim
    fails at some instances only). ``None`` marks a sub-claim not checked at an instance.
    """
    any_fail, everywhere = False, False
    for per in results.values():
        vals = [v for v in per.values() if v is not None]
        if not vals:
            continue
        if not all(vals):
            any_fail = True
        if not any(vals):
            everywhere = True
    return FAILS if everywhere else (DEPENDS if any_fail else HOLDS)


#: The classes of a witness in the order :func:`witness_class` prefers them: (recurrent, at the cap).
WITNESS_ORDER = ((True, False), (False, False), (True, True), (False, True))


def witness_class(recurrent: np.ndarray, at_cap: np.ndarray) -> list[np.ndarray]:
    """The state masks of :data:`WITNESS_ORDER`: a witness is of class k when all its states lie
    in mask k (recurrent and below the cap; below the cap; recurrent; any state). A violation is
    filed in the first class that holds one of its witnesses."""
    rec = np.asarray(recurrent, bool)
    below = ~np.asarray(at_cap, bool)
    return [rec & below, below, rec, np.ones_like(rec)]


def nonincreasing(values: Sequence[float], lower: Sequence[float] | None = None,
                  upper: Sequence[float] | None = None, atol: float = EQ_RTOL) -> bool:
    """Whether a sequence of relative quantities (gaps, improvements) does not grow, beyond its certificates.

    ``values[i + 1] > values[i]`` is a bump only when the certified intervals do not overlap,
    ``lower[i + 1] > upper[i] + atol`` (each number is known only to its interval; without
    intervals, to the value itself, and ``atol`` is the round-off of "equal").
    """
    v = np.asarray(values, float)
    lo = v if lower is None else np.asarray(lower, float)
    hi = v if upper is None else np.asarray(upper, float)
    return bool(v.size < 2 or np.all(lo[1:] - hi[:-1] <= atol))


def destinations(actions: Iterable[Sequence[int]], n_processes: int) -> list[dict[int, int]]:
    """How often each process is sent to each server along a sequence of actions.

    An action is ``(a_1, ..., a_M)`` with ``a_m`` the process (1-based) sent to server m, 0 for
    none. Returns ``counts[k - 1] = {m: sends of process k to server m}`` (0-based servers).
    """
    counts: list[dict[int, int]] = [{} for _ in range(n_processes)]
    for action in actions:
        for m, k in enumerate(action):
            if k:
                counts[int(k) - 1][m] = counts[int(k) - 1].get(m, 0) + 1
    return counts


def destinations_fixed(counts: Sequence[Mapping[int, int]]) -> bool:
    """Static in the paper's sense ("each process will only transmit the status information to the
    corresponding controller"): every process is sent to one server at most. The order in which
    the processes sharing a server are sent is not part of it."""
    return all(len(c) <= 1 for c in counts)


#: The three readings of "the optimal policy is static" (:func:`static_reading`).
STATIC_RULE = "static rule"
FIXED_DESTINATIONS_ONLY = "destinations fixed, another order"
NOT_STATIC = "destinations not fixed"


def static_reading(counts: Sequence[Mapping[int, int]], gap_to_static_rule: float, rtol: float = EQ_RTOL) -> str:
    """Which reading of "static" a policy meets: :data:`STATIC_RULE` (destinations fixed and the
    same average cost as the best static rule, within ``rtol``), :data:`FIXED_DESTINATIONS_ONLY`
    (each process to one server, but the order of the processes sharing a server is not a static
    rule's: it costs less or more) or :data:`NOT_STATIC` (some process goes to two servers).

    Parameters
    ----------
    counts : sequence of {server: sends}
        :func:`destinations` of the policy's cycle.
    gap_to_static_rule : float
        ``(g_static_rule - g_policy) / g_policy`` for the best static rule.
    """
    if not destinations_fixed(counts):
        return NOT_STATIC
    return STATIC_RULE if abs(gap_to_static_rule) <= rtol else FIXED_DESTINATIONS_ONLY
