"""Theorem 1 (claim C7): the bias is nondecreasing in each AoI with the configuration fixed."""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..mdp import MDP
from ..solvers.result import Solution
from .context import DEFAULT_EXAMPLES, PolicyContext, make_report, use_context, witness_flags
from .report import CheckReport, Tolerance, Violation, pick_examples

__all__ = ["check_monotonicity"]


def check_monotonicity(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    ctx: PolicyContext | None = None,
) -> CheckReport:
    r"""Theorem 1 (claim C7): ``V`` is nondecreasing in each ``tau_k`` with the configuration fixed.

    For every configuration C, every reachable state ``s = (tau, C)`` and every k such that
    ``s + e_k = (tau + e_k, C)`` is reachable, the check is

    .. math:: V(s + e_k) \ge V(s) - \mathrm{tol}.

    A violation is a pair with ``V(s) - V(s + e_k) > tol``; its size is that difference.
    By transitivity these adjacent pairs imply ``V(s^1) >= V(s^2)`` for every comparable pair
    ``tau^1 >= tau^2`` joined by a monotone path of reachable states (up to ``tol`` per step).
    Reachable sets can have holes, so the check also tests *every* comparable pair at once:
    with ``M(tau) = max {V(tau', C) : tau' <= tau, (tau', C) reachable}`` (a prefix maximum
    over the box, one ``np.maximum.accumulate`` per axis), a state violates dominance when
    ``M(tau) - V(tau, C) > tol`` (``details["dominance"]``).

    Works for any model over an AoI state space (Section II or preemption).

    Parameters
    ----------
    mdp : MDP
    solution : Solution
    tolerance : Tolerance, optional
        Default ``Tolerance()`` (atol = rtol = 1e-9, rtol relative to span(V)).
    examples : int
        Number of example violations kept (K).
    stationary_tol : float
        See :func:`policy_context`.
    ctx : PolicyContext, optional
        Precomputed shared data (from :func:`policy_context`).

    Returns
    -------
    CheckReport
        ``checked`` = adjacent comparable pairs; ``violations`` = adjacent pairs violating;
        ``holds`` = no adjacent and no dominance violation. A pair is recurrent when both its
        states are, at the cap when one of them has some tau at its cap.
    """
    t0 = time.perf_counter()
    ctx = use_context(mdp, solution, tolerance, stationary_tol, ctx)
    space = mdp.states
    V = np.asarray(solution.bias, float)
    grids = np.stack([space.lookup_grid(c) for c in range(len(space.configs))])  # (nC, *caps)
    pairs = _adjacent_pairs(ctx, V, grids)
    s1, s2, ax = pairs["low"], pairs["high"], pairs["axis"]
    size = V[s1] - V[s2]
    rec = ctx.recurrent[s1] & ctx.recurrent[s2]
    cap = ctx.at_cap[s1] | ctx.at_cap[s2]

    def make(i: int) -> Violation:
        a, b = int(s1[i]), int(s2[i])
        return ctx.violation(
            "adjacent", size[i], (a, b), rec[i], cap[i],
            {"axis": int(ax[i]) + 1, "V_low_tau": float(V[a]), "V_high_tau": float(V[b]),
             "recurrent_each": [bool(ctx.recurrent[a]), bool(ctx.recurrent[b])]},
        )

    W = np.stack([s1, s2], axis=1)
    obs, dist = witness_flags(ctx, W, rec)
    ex = [make(int(i)) for i in pick_examples(rec, cap, size, examples, obs, dist)]
    worst = make(int(np.argmax(size))) if size.size else None
    dom = _dominance(ctx, V, grids)
    details = {"per_axis": pairs["per_axis"], "dominance": dom, "configurations": len(space.configs),
               "violations_with_some_recurrent_state": int(np.count_nonzero(ctx.recurrent[s1] | ctx.recurrent[s2]))}
    notes = (
        "Adjacent pairs (s, s+e_k) in one configuration; by transitivity they cover every comparable pair "
        "joined by a monotone path of reachable states. The dominance sub-check covers all comparable pairs, "
        "also across unreachable cells; 'holds' requires both to be free of violations."
    )
    return make_report(
        "monotonicity", "Theorem 1 (C7): V nondecreasing in each tau_k, configuration fixed", ctx,
        holds=(size.size == 0 and dom["violating_states"] == 0), checked=pairs["checked"], violations=size.size,
        rec=rec, cap=cap, ties=0, unit="adjacent comparable pairs", worst=worst, examples=ex, details=details,
        notes=notes, t0=t0, witnesses=W, obs=obs,
    )


def _adjacent_pairs(ctx: PolicyContext, V: np.ndarray, grids: np.ndarray) -> dict[str, Any]:
    """The adjacent pairs ``(s, s + e_k)`` with ``V(s) - V(s + e_k) > tol``: their low and high
    states and axis, the number of pairs checked, and the counts per axis."""
    caps = grids.shape[1:]
    lows, highs, axes = [], [], []
    checked = 0
    per_axis = {}
    for k in range(len(caps)):
        if caps[k] < 2:
            per_axis[f"tau_{k + 1}"] = {"checked": 0, "violations": 0}
            continue
        lo = np.take(grids, np.arange(caps[k] - 1), axis=k + 1)
        hi = np.take(grids, np.arange(1, caps[k]), axis=k + 1)
        m = (lo >= 0) & (hi >= 0)
        s1, s2 = lo[m], hi[m]
        checked += s1.size
        bad = V[s1] - V[s2] > ctx.tol
        per_axis[f"tau_{k + 1}"] = {"checked": int(s1.size), "violations": int(np.count_nonzero(bad))}
        lows.append(s1[bad])
        highs.append(s2[bad])
        axes.append(np.full(int(np.count_nonzero(bad)), k))
    empty = np.zeros(0, np.int64)
    return {"low": np.concatenate(lows) if lows else empty, "high": np.concatenate(highs) if highs else empty,
            "axis": np.concatenate(axes) if axes else empty, "checked": checked, "per_axis": per_axis}


def _dominance(ctx: PolicyContext, V: np.ndarray, grids: np.ndarray) -> dict[str, Any]:
    """Every comparable pair at once, through the prefix maximum ``M(tau)`` over the box: the
    states with ``M(tau) - V(tau, C) > tol``, with the worst one and its witness."""
    W = np.where(grids >= 0, V[np.maximum(grids, 0)], -np.inf)
    M = W
    for k in range(grids.ndim - 1):
        M = np.maximum.accumulate(M, axis=k + 1)
    with np.errstate(invalid="ignore"):
        gap = np.where(grids >= 0, M - W, 0.0)
    dom_bad = gap > ctx.tol
    n_dom = int(np.count_nonzero(dom_bad))
    dom: dict[str, Any] = {
        "states_checked": int(np.count_nonzero(grids >= 0)),
        "violating_states": n_dom,
        "note": "a state violates dominance when some reachable state of its configuration with "
                "componentwise smaller or equal tau has a larger V (beyond tol)",
    }
    if not n_dom:
        return dom
    flat = int(np.argmax(gap))
    c, *tau0 = np.unravel_index(flat, gap.shape)
    hi_state = int(grids[(c, *tau0)])
    sub = tuple(slice(0, t + 1) for t in tau0)
    block = np.where(grids[c][sub] >= 0, V[np.maximum(grids[c][sub], 0)], -np.inf)
    lo_state = int(grids[c][sub][np.unravel_index(int(np.argmax(block)), block.shape)])
    r = bool(ctx.recurrent[lo_state] and ctx.recurrent[hi_state])
    cp = bool(ctx.at_cap[lo_state] or ctx.at_cap[hi_state])
    dom["worst"] = ctx.violation("dominance", float(gap[(c, *tau0)]), (lo_state, hi_state), r, cp,
                                 {"V_low_tau": float(V[lo_state]), "V_high_tau": float(V[hi_state])}).to_json()
    dom_states = grids[dom_bad]
    dom["recurrent_states"] = int(np.count_nonzero(ctx.recurrent[dom_states]))
    dom["at_cap"] = int(np.count_nonzero(ctx.at_cap[dom_states]))
    return dom
