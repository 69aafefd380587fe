"""Theorem 1 (claim C7): the bias is nondecreasing in each AoI with the configuration fixed."""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..mdp import MDP
from ..solvers.result import Solution
from .context import DEFAULT_EXAMPLES, PolicyContext, make_report, use_context
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
    caps = tuple(int(c) for c in space.caps)
    N = len(caps)
    nC = len(space.configs)
    grids = np.stack([space.lookup_grid(c) for c in range(nC)])  # (nC, *caps)
    tol = ctx.tol

    lows, highs, axes = [], [], []
    checked = 0
    per_axis = {}
    for k in range(N):
        if caps[k] < 2:
            per_axis[f"tau_{k + 1}"] = {"checked": 0, "violations": 0}
            continue
        lo = np.take(grids, np.arange(caps[k] - 1), axis=k + 1)
        hi = np.take(grids, np.arange(1, caps[k]), axis=k + 1)
        m = (lo >= 0) & (hi >= 0)
        s1, s2 = lo[m], hi[m]
        checked += s1.size
        bad = V[s1] - V[s2] > tol
        per_axis[f"tau_{k + 1}"] = {"checked": int(s1.size), "violations": int(np.count_nonzero(bad))}
        lows.append(s1[bad])
        highs.append(s2[bad])
        axes.append(np.full(int(np.count_nonzero(bad)), k))
    s1 = np.concatenate(lows) if lows else np.zeros(0, np.int64)
    s2 = np.concatenate(highs) if highs else np.zeros(0, np.int64)
    ax = np.concatenate(axes) if axes else np.zeros(0, np.int64)
    size = V[s1] - V[s2]
    rec = ctx.recurrent[s1] & ctx.recurrent[s2]
    any_rec = int(np.count_nonzero(ctx.recurrent[s1] | ctx.recurrent[s2]))
    cap = ctx.at_cap[s1] | ctx.at_cap[s2]

    def make(i: int) -> Violation:
        a, b = int(s1[i]), int(s2[i])
        return ctx.violation(
            "adjacent", size[i], (a, b), rec[i], cap[i],
            {"axis": int(ax[i]) + 1, "V_low_tau": float(V[a]), "V_high_tau": float(V[b]),
             "recurrent_each": [bool(ctx.recurrent[a]), bool(ctx.recurrent[b])]},
        )

    ex = [make(int(i)) for i in pick_examples(rec, cap, size, examples)]
    worst = make(int(np.argmax(size))) if size.size else None

    # every comparable pair, through the prefix maximum
    W = np.where(grids >= 0, V[np.maximum(grids, 0)], -np.inf)
    M = W
    for k in range(N):
        M = np.maximum.accumulate(M, axis=k + 1)
    with np.errstate(invalid="ignore"):
        gap = np.where(grids >= 0, M - W, 0.0)
    dom_bad = gap > tol
    n_dom = int(np.count_nonzero(dom_bad))
    dom: dict[str, Any] = {
        "states_checked": int(np.count_nonzero(grids >= 0)),
        "violating_states": n_dom,
        "note": "a state violates dominance when some reachable state of its configuration with "
                "componentwise smaller or equal tau has a larger V (beyond tol)",
    }
    if n_dom:
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
    details = {"per_axis": per_axis, "dominance": dom, "configurations": nC,
               "violations_with_some_recurrent_state": any_rec}
    notes = (
        "Adjacent pairs (s, s+e_k) in one configuration; by transitivity they cover every comparable pair "
        "joined by a monotone path of reachable states. The dominance sub-check covers all comparable pairs, "
        "also across unreachable cells; 'holds' requires both to be free of violations."
    )
    return make_report(
        "monotonicity", "Theorem 1 (C7): V nondecreasing in each tau_k, configuration fixed", ctx,
        holds=(size.size == 0 and n_dom == 0), checked=checked, violations=size.size, rec=rec, cap=cap,
        ties=0, unit="adjacent comparable pairs", worst=worst, examples=ex, details=details, notes=notes, t0=t0,
    )
