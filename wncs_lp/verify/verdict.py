"""The rules of the verdicts, in one place: structural checks, claims made of sub-claims, descriptive claims.

Every verdict of ``wncs-lp verify`` and of the reproduction is one of these rules applied to the
numbers printed beside it.

**Structural claims** (Theorems 1-3, the switching curves of Figs. 11-12, the policy maps) are
decided from the counts of their check, never from a bare flag:

* **HOLDS** -- no violation beyond the tie tolerance;
* **FAILS** -- some violation has a *witness* (the states that show it) that is *observable*
  (every state of it recurrent, with stationary probability at least :data:`NEGLIGIBLE` under
  the optimal policy) *and* away from the AoI cap (no state of the witness has some tau at its
  cap): seen in the long run, and not a truncation artefact;
* **DEPENDS** -- violations exist, but every witness of each involves a transient state (never
  revisited in the long run, so it cannot change the average cost), a state of negligible
  weight (recurrent but visited less than :data:`NEGLIGIBLE` of the time: a caveat, not a
  counterexample) or touches the cap (where the truncation, not the paper's model, decides).

A violation can have several witnesses (a line-gap: any two states choosing the action with a
state between them that strictly prefers another; an order reversal: any line of the majority
order). It is judged by its best witness, :func:`witness_class`: observable and below the cap
first, then recurrent and below the cap, then below the cap, then recurrent, then any; so a
violation is filed *at the cap* only when every witness touches the cap. Among the violations of
one class the reports show first the witnesses *farthest from the cap* (:func:`cap_distance`:
the smallest distance ``tau_hat_k - tau_k`` over the witness's states and processes), each with
the stationary probability of its states (the weight of the counterexample).

**Where a verdict is decided** (:func:`decide`). The cap truncates the paper's unbounded AoI, and
the *least truncated* instance computed decides: for each scenario (and plane, p, ...: each
group of instances that differ only by their cap) the instance of the largest cap. A more
truncated instance that disagrees with it can only add a *caveat*, printed beside the verdict,
never change it. Across the deciding instances of several scenarios, :func:`combine` gives
FAILS when one FAILS (a counterexample is decisive), HOLDS when all hold, DEPENDS otherwise.

**Claims made of sub-claims** (:func:`subclaims_verdict`): each sub-claim is decided at the
largest cap where it is checked; HOLDS when every sub-claim holds there, FAILS when one fails
there (a smaller cap that disagrees is a caveat, :func:`subclaim_caveats`). A sub-claim
the truncation cannot decide (e.g. a trend smaller than the change from one cap to the next) is
not checked (``None``) and said in words. The words of the paper are read with fixed bars:
"much better" / "vastly improved" = at least :data:`MUCH` above, "close" = within :data:`CLOSE`,
"not significant" = below :data:`SIGNIFICANT`, "equal" = within :data:`EQ_RTOL`. "Shrinks as p
grows" is judged by :func:`nonincreasing`: a bump counts only beyond the certificates of the two
numbers compared.

**Descriptive claims** (the maps of Figs. 4 and 6-7): one verdict per instance, decided by the
least truncated instances; :func:`across` them (e.g. several planes at one cap) DEPENDS when they
disagree.

**Static** has two readings, kept apart: *destinations fixed* (:func:`destinations_fixed`, the
paper's "each process will only transmit the status information to the corresponding
controller") and *equal to a static rule* (the same average cost as the best static policy,
which also fixes the order in which processes sharing a server are sent).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

__all__ = ["HOLDS", "FAILS", "DEPENDS", "ERROR", "VERDICTS", "RULE", "MUCH", "CLOSE", "SIGNIFICANT", "EQ_RTOL",
           "NEGLIGIBLE", "structural_verdict", "verdict_of", "combine", "across", "subclaims_verdict",
           "subclaim_caveats", "decide", "Decision", "witness_class", "witness_rank", "cap_distance",
           "nonincreasing", "destinations", "destinations_fixed", "static_reading", "STATIC_RULE",
           "FIXED_DESTINATIONS_ONLY", "NOT_STATIC"]

HOLDS = "HOLDS"
FAILS = "FAILS"
DEPENDS = "DEPENDS"
#: Not a verdict: the claim could not be computed.
ERROR = "ERROR"
VERDICTS = (HOLDS, DEPENDS, FAILS)

#: "Much better" (and the paper's "vastly improved", "greatly improved"): the other policy costs at
#: least this much more, relative.
MUCH = 0.10
#: "Close to optimal": within this relative distance.
CLOSE = 0.05
#: An improvement below this relative size is "not significant".
SIGNIFICANT = 0.01
#: Relative tolerance for "equal" average costs (the exact evaluations are certified far below).
EQ_RTOL = 1e-7
#: A recurrent state visited less than this share of the time is *negligible*: a violation whose
#: every witness has such a state is a caveat (DEPENDS), not a counterexample (FAILS). 1e-9 of the
#: time is one slot in 10^9 (more than 30 years of 1 ms slots), and far below what any average
#: cost of the report resolves.
NEGLIGIBLE = 1e-9

#: The rule in one sentence (printed by ``wncs-lp verify`` and in the report).
RULE = (f"HOLDS: no violation; FAILS: a violation with a witness whose states are all recurrent, each with "
        f"stationary probability >= {NEGLIGIBLE:g}, and none at the AoI cap; DEPENDS: violations only in transient "
        f"states, in states of negligible weight (< {NEGLIGIBLE:g}) or touching the cap")


def structural_verdict(holds: bool, recurrent_below_cap: int, observable_below_cap: int | None = None) -> str:
    """The verdict of one check from its numbers.

    Parameters
    ----------
    holds : bool
        No violation beyond the tolerance.
    recurrent_below_cap : int
        Violations with a witness whose states are all recurrent and none at the cap.
    observable_below_cap : int, optional
        Among those, the violations whose witness is also of weight: every state visited at
        least :data:`NEGLIGIBLE` of the time. Default: all of them (no stationary law known).
    """
    if holds:
        return HOLDS
    decisive = recurrent_below_cap if observable_below_cap is None else observable_below_cap
    return FAILS if int(decisive) > 0 else DEPENDS


def verdict_of(report: Any) -> str:
    """:func:`structural_verdict` of a :class:`~wncs_lp.verify.CheckReport` or of its JSON dict
    (or any mapping with ``holds`` and ``split["recurrent_below_cap"]``, ``split["observable_below_cap"]``)."""
    if isinstance(report, Mapping):
        holds, split = report["holds"], report.get("split") or {}
    else:
        holds, split = report.holds, report.split or {}
    obs = split.get("observable_below_cap")
    return structural_verdict(bool(holds), int(split.get("recurrent_below_cap", 0)),
                              None if obs is None else int(obs))


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


def _deciding_values(per: Mapping[Any, bool | None]) -> tuple[Any, bool] | None:
    """``(cap, value)`` of a sub-claim at the largest cap where it is checked (None: nowhere)."""
    vals = [(c, v) for c, v in per.items() if v is not None]
    return max(vals, key=lambda cv: cv[0]) if vals else None


def subclaims_verdict(results: dict[str, dict[Any, bool | None]]) -> str:
    """The verdict of a claim made of sub-claims, each checked at several caps.

    Each sub-claim is decided at the largest (least truncated) cap where it is checked: HOLDS when
    every sub-claim holds there, FAILS when one fails there. A smaller cap that disagrees is a
    caveat (:func:`subclaim_caveats`), never the verdict. ``None`` marks a sub-claim not checked
    (or not decidable) at a cap; a claim with no sub-claim checked anywhere is DEPENDS.
    """
    decided = [d for d in (_deciding_values(per) for per in results.values()) if d is not None]
    if not decided:
        return DEPENDS
    return HOLDS if all(v for _, v in decided) else FAILS


def subclaim_caveats(results: dict[str, dict[Any, bool | None]]) -> list[str]:
    """The sub-claims whose value at a more truncated cap differs from the deciding one, in words
    ("'x' fails at cap 12 (holds at cap 30, which decides)")."""
    out = []
    for name, per in results.items():
        d = _deciding_values(per)
        if d is None:
            continue
        cap, v = d
        other = sorted(c for c, x in per.items() if x is not None and x != v)
        if other:
            out.append(f"'{name}' {'fails' if v else 'holds'} at cap {', '.join(map(str, other))} "
                       f"({'holds' if v else 'fails'} at cap {cap}, which decides)")
    return out


@dataclass(frozen=True)
class Decision:
    """Where a verdict over several instances was decided (:func:`decide`).

    Attributes
    ----------
    verdict : str
    deciding : tuple of int
        Indices (into the instances given) of the deciding instances: the least truncated one
        of each group.
    caveats : tuple of int
        Indices of the more truncated instances whose own verdict differs from their group's
        deciding one (a caveat beside the verdict, never the verdict).
    """

    verdict: str
    deciding: tuple[int, ...]
    caveats: tuple[int, ...]


def decide(instances: Sequence[tuple[Any, float, str]], how: str = "structural") -> Decision:
    """The verdict of a claim over instances ``(group, truncation, verdict)``, decided by the least
    truncated instance of each group.

    Parameters
    ----------
    instances : sequence of (group, truncation, verdict)
        ``group``: what the instance is of apart from its cap (a scenario; a scenario and a plane);
        ``truncation``: orders the instances of a group, the largest the least truncated (the
        cap); ``verdict``: the instance's own verdict.
    how : {"structural", "descriptive"}
        How the deciding instances of several groups are combined: :func:`combine` (any FAILS
        decides) or :func:`across` (DEPENDS when they differ).

    Returns
    -------
    Decision
        ERROR when an instance is an ERROR or there is none.
    """
    inst = list(instances)
    if not inst or any(v == ERROR for _, _, v in inst):
        return Decision(ERROR, (), ())
    best: dict[Any, int] = {}
    for i, (g, t, _) in enumerate(inst):
        if g not in best or t > inst[best[g]][1]:
            best[g] = i
    deciding = tuple(sorted(best.values()))
    verdicts = [inst[i][2] for i in deciding]
    verdict = combine(verdicts) if how == "structural" else across(verdicts)
    caveats = tuple(i for i, (g, _, v) in enumerate(inst) if i not in deciding and v != inst[best[g]][2])
    return Decision(verdict, deciding, caveats)


#: The classes of a witness in the order :func:`witness_class` prefers them: (observable, recurrent, at the cap).
WITNESS_ORDER = ((True, True, False), (False, True, False), (False, False, False), (False, True, True),
                 (False, False, True))


def witness_class(recurrent: np.ndarray, at_cap: np.ndarray, observable: np.ndarray | None = None
                  ) -> list[np.ndarray]:
    """The state masks of :data:`WITNESS_ORDER`: a witness is of class k when all its states lie
    in mask k (observable and below the cap; recurrent and below the cap; below the cap; recurrent;
    any state). A violation is filed in the first class that holds one of its witnesses.
    ``observable``: recurrent with stationary probability >= :data:`NEGLIGIBLE` (default: recurrent)."""
    rec = np.asarray(recurrent, bool)
    below = ~np.asarray(at_cap, bool)
    obs = rec if observable is None else np.asarray(observable, bool)
    return [obs & below, rec & below, below, rec, np.ones_like(rec)]


def witness_rank(recurrent: np.ndarray, at_cap: np.ndarray, observable: np.ndarray | None = None) -> np.ndarray:
    """Per violation, the index of its class in :data:`WITNESS_ORDER` (0: observable and below the cap)."""
    rec = np.asarray(recurrent, bool)
    cap = np.asarray(at_cap, bool)
    obs = rec if observable is None else np.asarray(observable, bool) & rec
    return np.select([obs & ~cap, rec & ~cap, ~cap, rec], [0, 1, 2, 3], 4)


def cap_distance(tau: np.ndarray, caps: Sequence[int]) -> np.ndarray:
    """How far each state lies from the cap: ``min_k (tau_hat_k - tau_k)`` (0: some AoI at its cap).

    ``tau`` is an (n, N) array of AoI vectors; a witness's distance is the smallest over its states.
    """
    t = np.atleast_2d(np.asarray(tau, np.int64))
    return (np.asarray(caps, np.int64)[None, :] - t).min(axis=1)


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
