r"""From an occupation measure to a certified randomised policy: the one place every route ends.

Three steps, shared by the LP, the Lagrangian route and the convex front end:

1. :func:`policy_from_occupation`: :math:`\pi(a \mid s) = x(s, a) / \sum_a x(s, a)` where the
   measure visits s; elsewhere one deterministic action per state, chosen backwards from the
   visited set so that every state drains into it (the same rule as the unconstrained LP's
   :func:`~wncs_lp.solvers.lp.extract_policy`), so every start state has the same averages.
2. :func:`evaluate_rows`: the exact long-run averages of that policy on its own Markov chain
   (:class:`~wncs_lp.chain.PolicyChain`): the gain and every constrained quantity.
3. :func:`lagrangian_bound`: weak duality. For any :math:`\lambda \ge 0` and any policy
   meeting :math:`D x \le b`,

   .. math:: c^T x \;\ge\; (c + \lambda^T D)^T x - \lambda^T b \;\ge\; \underline g_\lambda - \lambda^T b,

   where :math:`\underline g_\lambda` is the lower end of a certified Bellman bracket of the
   unconstrained MDP with cost :math:`c + \lambda^T D` (certified value iteration). So
   :math:`L(\lambda) = \underline g_\lambda - \lambda^T b \le g^*_C`, whatever produced
   :math:`\lambda`.

:func:`certify` puts the three together into a :class:`ConstrainedSolution` whose bracket
``[L(lambda), exact cost of the returned feasible policy]`` does not trust any solver's status.
"""
from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from ..chain import PolicyChain
from ..errors import PolicyError
from ..mdp import MDP
from ..solvers.certify import certificate_closed
from ..status import CERTIFICATE, INFEASIBLE_POLICY, status_from
from .problem import LinearConstraint, Rows, max_form, with_cost
from .result import ConstrainedSolution, ConstraintReport

__all__ = ["policy_from_occupation", "evaluate_rows", "lagrangian_bound", "certify", "MIX_TOL", "FEAS_RTOL",
           "CERT_RTOL"]

#: A pair probability below this (relative to 1) is set to 0: interior-point "zeros".
MIX_TOL = 1e-9
#: A returned policy meets a bound when its exact value is within FEAS_RTOL * max(1, |bound|).
FEAS_RTOL = 1e-7
#: ``status == "optimal"`` needs (hi - lo) <= CERT_RTOL * |gain| (default of :func:`certify`).
CERT_RTOL = 1e-6


def policy_from_occupation(mdp: MDP, x: np.ndarray, h: np.ndarray | None = None,
                           visit_tol: float = 1e-9, mix_tol: float = MIX_TOL) -> tuple[np.ndarray, np.ndarray]:
    """The randomised stationary policy of an occupation measure.

    Parameters
    ----------
    mdp : MDP
    x : (L,) array
        An occupation measure (sum 1; small negative round-off is clipped).
    h : (n,) array, optional
        A bias used to break ties among the draining actions of unvisited states (the
        solver's dual bias); default 0.
    visit_tol : float
        A state is visited when ``n * sum_a x(s, a) > visit_tol``.
    mix_tol : float
        Probabilities below it are dropped (and the rest renormalised).

    Returns
    -------
    probs : (L,) float array
        ``probs[l]`` = probability of pair l in its state.
    randomized : (r,) int array
        The states where two or more pairs keep a positive probability.
    """
    from ..solvers.lp import extract_policy

    n, L = mdp.n_states, mdp.n_pairs
    starts = mdp.pair_ptr[:-1]
    xc = np.maximum(np.asarray(x, dtype=float), 0.0)
    h = np.zeros(n) if h is None else np.asarray(h, dtype=float)
    det, visited = extract_policy(mdp, xc, h, visit_tol)
    xs = np.add.reduceat(xc, starts)
    probs = np.zeros(L)
    vis_pairs = visited[mdp.s_indices]
    probs[vis_pairs] = xc[vis_pairs] / xs[mdp.s_indices[vis_pairs]]
    probs[probs < mix_tol] = 0.0
    sums = np.add.reduceat(probs, starts)
    ok = visited & (sums > 0)
    probs[ok[mdp.s_indices]] /= sums[mdp.s_indices[ok[mdp.s_indices]]]
    fallback = ~ok
    probs[fallback[mdp.s_indices]] = 0.0
    probs[det[fallback]] = 1.0
    counts = np.add.reduceat((probs > 0).astype(np.int64), starts)
    return probs, np.flatnonzero(counts > 1)


def evaluate_rows(mdp: MDP, probs: np.ndarray, constraints: Sequence[LinearConstraint]) -> dict[str, Any]:
    """Exact long-run averages of a randomised policy: gain and each constraint's quantity.

    Returns
    -------
    dict
        ``gain``, ``values`` ((K,) array, one per constraint), ``occupation`` ((L,) array
        ``pi(s_l) probs[l]``), ``residual`` (of the stationary law), ``classes`` (number of
        recurrent classes).

    Raises
    ------
    PolicyError
        The policy is malformed or its chain has several recurrent classes (then the averages
        depend on the start state).
    """
    chain = PolicyChain(mdp, np.asarray(probs, dtype=float))
    if not chain.is_unichain:
        a, b = chain.recurrent_classes[:2]
        raise PolicyError(
            f"the randomised policy's chain has {chain.n_classes} recurrent classes (e.g. state "
            f"{mdp.state_label(int(a[0]))} and state {mdp.state_label(int(b[0]))}); its averages depend on the start state"
        )
    pi = chain.stationary
    occ = pi[mdp.s_indices] * np.asarray(probs, dtype=float)
    values = np.array([float(c.values @ occ) for c in constraints])
    return {"gain": float(mdp.cost @ occ), "values": values, "occupation": occ, "residual": float(chain.residual),
            "classes": chain.n_classes}


def lagrangian_bound(mdp: MDP, rows: Rows, lam: np.ndarray, *, h0: np.ndarray | None = None,
                     tol: float = 1e-10, **vi_kw: Any) -> tuple[float, Any]:
    r"""The weak-duality bound :math:`L(\lambda) = \underline g_\lambda - \lambda^T b \le g^*_C`.

    Parameters
    ----------
    mdp : MDP
    rows : Rows
        The max form of the constraints.
    lam : (K,) array
        One multiplier per row; negative entries are clipped to 0 (the bound needs lambda >= 0).
    h0 : (n,) array, optional
        Warm start of value iteration (e.g. the LP's dual bias).
    tol : float
        Relative width of the value-iteration bracket.

    Returns
    -------
    bound : float
    vi : Solution
        The certified value-iteration solution of the Lagrangian MDP (its ``gain_lower`` is
        :math:`\underline g_\lambda`).
    """
    from ..solvers.dp import value_iteration

    lam = np.maximum(np.asarray(lam, dtype=float), 0.0)
    cost = mdp.cost + (lam @ rows.D if rows.n_rows else 0.0)
    scale = float(np.max(np.abs(cost))) if cost.size else 1.0
    vi = value_iteration(with_cost(mdp, cost), tol=tol, atol=1e-12 * max(scale, 1e-300), h0=h0, **vi_kw)
    return float(vi.gain_lower - (lam @ rows.b if rows.n_rows else 0.0)), vi


def certify(
    mdp: MDP,
    constraints: Sequence[LinearConstraint],
    probs: np.ndarray,
    randomized: np.ndarray,
    row_multipliers: np.ndarray,
    *,
    method: str,
    solver_status: str = "optimal",
    solver_gain: float = float("nan"),
    lp_values: np.ndarray | None = None,
    h0: np.ndarray | None = None,
    lower: tuple[float, Any] | None = None,
    cert_rtol: float = CERT_RTOL,
    feas_rtol: float = FEAS_RTOL,
    iterations: int = 0,
    t0: float | None = None,
    stats: dict | None = None,
) -> ConstrainedSolution:
    """Evaluate a randomised policy exactly, bound g*_C from below, and judge the result.

    Parameters
    ----------
    constraints : sequence of LinearConstraint
    probs, randomized
        The policy (:func:`policy_from_occupation`).
    row_multipliers : (K_rows,) array
        lambda >= 0 per row of :func:`max_form` (the solver's duals).
    solver_status : Status or str
        The backend's status mapped by its table (a :class:`~wncs_lp.status.Status`, e.g.
        ``max_iter:MaxIterations``, which stands as it is), or ``"optimal"``, or a word for what
        went wrong (becomes ``"inaccurate:<word>"``).
    lower : (bound, vi), optional
        An already computed :func:`lagrangian_bound` (the Lagrangian route has it).
    """
    t0 = time.perf_counter() if t0 is None else t0
    rows = max_form(constraints, mdp.n_pairs)
    lam_rows = np.maximum(np.asarray(row_multipliers, dtype=float).reshape(rows.n_rows), 0.0)
    ev = evaluate_rows(mdp, probs, constraints)
    if lower is None:
        lower = lagrangian_bound(mdp, rows, lam_rows, h0=h0)
    lo, vi = lower
    reports, mult, viol_max = _constraint_reports(constraints, rows, ev["values"], lam_rows, lp_values, feas_rtol)
    gain = ev["gain"]
    hi = gain
    closed = certificate_closed(mdp, lo, hi, gain, cert_rtol)
    status = status_from((None if solver_status == "optimal" else solver_status,
                          None if viol_max <= feas_rtol else INFEASIBLE_POLICY, None if closed else CERTIFICATE))
    st = dict(stats or {})
    st.update(
        evaluation_residual=ev["residual"],
        max_violation=float(viol_max),
        lagrangian_vi_sweeps=int(getattr(vi, "iterations", 0)),
        lagrangian_vi_status=getattr(vi, "status", None),
        lagrangian_gain_lower=float(getattr(vi, "gain_lower", np.nan)),
        lagrangian_gain_upper=float(getattr(vi, "gain_upper", np.nan)),
    )
    randomized = np.asarray(randomized, dtype=np.int64)
    for a in (probs, ev["occupation"], mult, randomized):
        a.setflags(write=False)
    return ConstrainedSolution(
        method=method,
        status=status,
        gain=float(gain),
        gain_lower=float(lo),
        gain_upper=float(hi),
        solver_gain=float(solver_gain),
        policy=probs,
        occupation=ev["occupation"],
        multipliers=mult,
        constraints=tuple(reports),
        randomized_states=randomized,
        iterations=int(iterations),
        seconds=time.perf_counter() - t0,
        stats=st,
    )


def _constraint_reports(constraints: Sequence[LinearConstraint], rows: Rows, values: np.ndarray, lam_rows: np.ndarray,
                        lp_values: np.ndarray | None, feas_rtol: float
                        ) -> tuple[list[ConstraintReport], np.ndarray, float]:
    """Each constraint's report from the exact values: whether it is active (on a bound, within
    ``feas_rtol``) and that side's multiplier; the multipliers; the largest relative violation."""
    reports, viol_max = [], 0.0
    mult = np.zeros(len(constraints))
    for j, c in enumerate(constraints):
        v = float(values[j])
        tol_j = {s: feas_rtol * max(1.0, abs(float(getattr(c, s)))) for s in ("max", "min") if getattr(c, s) is not None}
        over = max(0.0, v - c.max) if c.max is not None else 0.0
        under = max(0.0, c.min - v) if c.min is not None else 0.0
        viol = max(over, under)
        viol_max = max(viol_max, viol / max(1.0, abs(float(c.max if over > 0 else (c.min if under > 0 else 1.0)))))
        # active = the exact value sits on a bound; the multiplier is that side's. Off the
        # bounds complementary slackness makes it 0 exactly (the solver's ~1e-9 residue stays
        # in stats["row_multipliers"] and in the Lagrangian bound, valid for any lambda)
        side, lam_j = None, 0.0
        for r in np.flatnonzero(rows.owner == j):
            s_r = rows.side[r]
            if abs(v - float(getattr(c, s_r))) <= tol_j[s_r]:
                side, lam_j = s_r, float(lam_rows[r])
                break
        mult[j] = lam_j
        lpv = float(lp_values[j]) if lp_values is not None else float("nan")
        reports.append(ConstraintReport(c.label, c.quantity, c.max, c.min, v, lpv, side is not None, side, lam_j, viol))
    return reports, mult, viol_max
