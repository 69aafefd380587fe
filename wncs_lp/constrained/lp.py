r"""The constrained occupation-measure LP, solved with Clarabel (directly or through cvxpy).

.. math::

    g^*_C = \min_x c^T x \quad\text{s.t.}\quad (E - P^T) x = 0,\; 1^T x = 1,\; D x \le b,\; x \ge 0,

the unconstrained LP of :mod:`wncs_lp.solvers.lp` (same scaling: ``y = n x``, costs
``c / c_s``) plus one row per bound in the max form of :mod:`~wncs_lp.constrained.problem`,
each row scaled by :math:`s_j = \max_l |D_{jl}|`: :math:`(D_j / s_j)\, y \le n b_j / s_j`.

Duals. With Clarabel's convention (``A y + s = b``, stationarity ``q + A^T z = 0``) the
reduced cost of pair l is

.. math:: \mu_l = q_l + z_{bal}(s_l) - (P z_{bal})_l + z_{norm} + \sum_j z_j D_{jl} / s_j \ge 0,

so :math:`\lambda_j = c_s z_j / s_j \ge 0` are the multipliers of the rows in the units of the
problem, and ``-c_s z_norm`` is the gain of the Lagrangian MDP with cost :math:`c + \lambda^T D`
(its bias ``-c_s z_bal`` warm-starts the value iteration of the certificate).

Crossover. An interior-point method returns a point in the *relative interior* of the optimal
face: where several policies are optimal it mixes them all, and its "zeros" are 1e-9..1e-6.
A *basic* optimal solution randomises in at most as many states as there are active bounds
(Altman, *Constrained Markov Decision Processes*, Thm. 3.8). So, by default, the LP is solved
again on the pairs the interior point leaves in play (reduced cost within a tolerance of 0, or
visibly positive x) with HiGHS's dual simplex (``scipy.optimize.linprog``), whose answer is a
vertex; it is kept when its objective agrees with Clarabel's. Clarabel's answer is used as it is
when the crossover is off or fails (``stats["crossover"]`` says which).

Trade-off curves re-solve this LP for many bounds from the previous basis instead
(:mod:`~wncs_lp.constrained.warm`); both routes end in :func:`certify_lp_solution`.
"""
from __future__ import annotations

import time
import warnings
from typing import Any, Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import InfeasibleConstraintsError, SolverError
from ..mdp import MDP
from ..solvers.certify import greedy_first
from ..solvers.lp import (LPData, build_lp, clarabel_settings, clarabel_solve, clarabel_stats, clarabel_status,
                          cvxpy_status)
from ..status import FAILED, INFEASIBLE
from .certify import CERT_RTOL, certify, policy_from_occupation
from .problem import LinearConstraint, Rows, max_form, with_cost
from .result import ConstrainedSolution

__all__ = ["solve_constrained_lp", "reachable_range", "check_reachable", "basic_solution", "scaled_rows",
           "certify_lp_solution", "RC_TOL"]

#: Crossover: a pair stays in play when its scaled reduced cost is at most RC_TOL * (1 + max|q|).
RC_TOL = 1e-6

#: Each backend's status table, kept in one place (:mod:`wncs_lp.solvers.lp`).
_STATUS_OF = {"clarabel": clarabel_status, "cvxpy": cvxpy_status}


def scaled_rows(lp: LPData, rows: Rows) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """The bound rows as the LP carries them: ``(D / s) y <= n b / s`` with ``s_j = max|D_j|``
    (1 for an all-zero row).

    Returns
    -------
    G : (K, L) CSR matrix
    h : (K,) array
    s : (K,) array
        The row scales (a row dual z_j is the multiplier ``c_s z_j / s_j`` in problem units).
    """
    s = np.max(np.abs(rows.D), axis=1) if rows.n_rows else np.zeros(0)
    s = np.where(s > 0, s, 1.0)
    G = sp.csr_matrix(rows.D / s[:, None])
    G.eliminate_zeros()
    h = lp.x_scale * rows.b / s
    return G, h, s


def _run_clarabel(lp: LPData, G, h, tol, max_iter, verbose, settings):
    import clarabel

    L, m, K = lp.n_pairs, lp.n_eq, G.shape[0]
    A = sp.vstack([lp.A_eq, G, -sp.identity(L, format="csc")], format="csc")
    b = np.concatenate([lp.b_eq, h, np.zeros(L)])
    st = clarabel_settings(tol, max_iter, verbose, settings)
    cones = [clarabel.ZeroConeT(m)] + ([clarabel.NonnegativeConeT(K)] if K else []) + [clarabel.NonnegativeConeT(L)]
    solver = clarabel.DefaultSolver(sp.csc_matrix((L, L)), lp.q, A, b, cones, st)
    sol = clarabel_solve(solver)
    info = solver.get_info()
    z = np.asarray(sol.z, float)
    stats = {**clarabel_stats(sol, info), "obj_scaled": float(sol.obj_val)}
    status = str(sol.status)
    return status, status == "Solved", np.asarray(sol.x, float), z[:m], z[m:m + K], z[m + K:], stats


def _run_cvxpy(lp: LPData, G, h, tol, max_iter, verbose, settings):
    import cvxpy as cp

    L = lp.n_pairs
    y = cp.Variable(L, nonneg=True)
    eq = lp.A_eq @ y == lp.b_eq
    cons = [eq]
    ineq = None
    if G.shape[0]:
        ineq = G @ y <= h
        cons.append(ineq)
    prob = cp.Problem(cp.Minimize(lp.q @ y), cons)
    opts: dict[str, Any] = {"tol_gap_abs": float(tol), "tol_gap_rel": float(tol), "tol_feas": float(tol),
                            "max_iter": int(max_iter)}
    opts.update(settings or {})
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=cp.CLARABEL, verbose=bool(verbose), **opts)
    except cp.error.SolverError as exc:
        raise SolverError(f"cvxpy/Clarabel failed: {exc}") from exc
    status = str(prob.status)
    if cvxpy_status(status).code is INFEASIBLE:
        return status, False, None, None, None, None, {"solver": "cvxpy+clarabel", "solver_status": status}
    if y.value is None or eq.dual_value is None:
        raise SolverError(f"cvxpy/Clarabel returned no solution (status {status})")
    yv = np.asarray(y.value, float)
    z_eq = np.asarray(eq.dual_value, float).ravel()
    z_in = np.asarray(ineq.dual_value, float).ravel() if ineq is not None else np.zeros(0)
    mu = lp.q + lp.A_eq.T @ z_eq + (G.T @ z_in if G.shape[0] else 0.0)
    ss = prob.solver_stats
    stats = {"solver": "cvxpy+clarabel", "solver_status": status, "solver_iterations": int(ss.num_iters or 0),
             "solve_time": float(ss.solve_time or 0.0), "obj_scaled": float(prob.value)}
    return status, status == "optimal", yv, z_eq, z_in, mu, stats


def basic_solution(mdp: MDP, A_eq, b_eq: np.ndarray, q: np.ndarray, G, h: np.ndarray, y: np.ndarray, mu: np.ndarray,
              ref_obj: float) -> tuple[np.ndarray | None, dict]:
    """A basic optimal solution of ``min q^T y  s.t.  A_eq y = b_eq, G y <= h, y >= 0`` on the
    pairs an interior point ``(y, mu)`` leaves in play (HiGHS dual simplex).

    In play: the interior point treats the pair as basic (``y > mu``) or its reduced cost is
    ~0 (``mu <= RC_TOL (1 + max|q|)``); and every state keeps its pair of least reduced cost,
    so that mass reaching a state can leave it. The vertex is kept when its objective agrees
    with ``ref_obj`` (the interior point's) to 1e-6 relative; else None.

    Returns
    -------
    y : (L,) array or None
    info : dict
        ``crossover_pairs``, ``crossover_seconds``, ``crossover_status`` and, when solved,
        ``crossover_objective_rel_diff``.
    """
    from scipy.optimize import linprog

    t0 = time.perf_counter()
    qmax = float(np.max(np.abs(q))) if q.size else 1.0
    keep = (mu <= RC_TOL * (1.0 + qmax)) | (y > mu)
    keep[greedy_first(mdp, mu)] = True
    cols = np.flatnonzero(keep)
    Gk = sp.csr_matrix(G)[:, cols] if G is not None and G.shape[0] else None
    res = linprog(q[cols], A_ub=Gk, b_ub=h if Gk is not None else None, A_eq=sp.csc_matrix(A_eq)[:, cols],
                  b_eq=b_eq, bounds=(0, None), method="highs-ds")
    info = {"crossover_pairs": int(cols.size), "crossover_seconds": time.perf_counter() - t0,
            "crossover_status": str(res.message)}
    if res.status != 0 or res.x is None:
        return None, info
    info["crossover_objective_rel_diff"] = abs(float(res.fun) - ref_obj) / max(1.0, abs(ref_obj))
    if info["crossover_objective_rel_diff"] > 1e-6:
        return None, info
    out = np.zeros(mdp.n_pairs)
    out[cols] = np.maximum(res.x, 0.0)
    return out, info


def reachable_range(mdp: MDP, constraint: LinearConstraint, side: str) -> float:
    """The least (``side="max"``) or largest (``side="min"``) long-run average of a
    constraint's quantity any stationary policy reaches, by certified value iteration."""
    from ..solvers.dp import value_iteration

    d = constraint.values if side == "max" else -constraint.values
    scale = max(float(np.max(np.abs(d))) if d.size else 0.0, 1e-300)
    vi = value_iteration(with_cost(mdp, d), tol=1e-10, atol=1e-10 * scale)
    g = vi.gain_lower if side == "max" else vi.gain_lower
    return float(g if side == "max" else -g)


def check_reachable(mdp: MDP, constraints: Sequence[LinearConstraint], *, joint_status: str | None = None) -> None:
    """Raise :class:`InfeasibleConstraintsError` naming the bounds no policy reaches.

    Every bound is first checked alone (its quantity's least or largest average); if all are
    reachable alone and ``joint_status`` says the solver found the whole set infeasible, the
    error says so and lists them all.
    """
    bad, bounds, reach, sides = [], [], [], []
    for c in constraints:
        for side in ("max", "min"):
            b = getattr(c, side)
            if b is None:
                continue
            r = reachable_range(mdp, c, side)
            tol = 1e-9 * max(1.0, abs(b))
            if (side == "max" and r > b + tol) or (side == "min" and r < b - tol):
                bad.append(c.label), bounds.append(b), reach.append(r), sides.append(side)
    if bad:
        parts = [f"{lab}: {'least' if s == 'max' else 'largest'} value any policy reaches is {r:.10g}"
                 for lab, s, r in zip(bad, sides, reach)]
        raise InfeasibleConstraintsError("infeasible constraint(s): " + "; ".join(parts), bad, bounds, reach, sides)
    if joint_status is not None:
        labels = [c.label for c in constraints]
        raise InfeasibleConstraintsError(
            f"infeasible constraints: each bound is reachable alone but not all together ({'; '.join(labels)}; "
            f"solver status {joint_status})", labels, [], [], [], jointly=True)


def solve_constrained_lp(
    mdp: MDP,
    constraints: Sequence[LinearConstraint],
    *,
    backend: str = "clarabel",
    tol: float = 1e-9,
    max_iter: int = 200,
    verbose: bool = False,
    settings: dict | None = None,
    crossover: bool = True,
    cert_rtol: float = CERT_RTOL,
) -> ConstrainedSolution:
    """Minimise the average cost subject to the bounds, on the occupation-measure LP.

    Parameters
    ----------
    mdp : MDP
    constraints : sequence of LinearConstraint
        (:func:`~wncs_lp.constrained.problem.constraints_for` makes them from a scenario.)
    backend : {"clarabel", "cvxpy"}
        Clarabel called directly, or the same LP built with cvxpy and solved by Clarabel.
    tol : float
        Clarabel's gap and feasibility tolerances (scaled problem).
    crossover : bool
        Look for a basic optimal solution on the interior point's optimal face (see the module
        docstring); it randomises in at most as many states as there are active bounds.
    cert_rtol : float
        Width of the certificate ``[L(lambda), exact cost]`` accepted as "optimal".

    Returns
    -------
    ConstrainedSolution

    Raises
    ------
    InfeasibleConstraintsError
        No policy meets the bounds (the message names them and what policies can reach).
    SolverError
        The solver failed outright (its status is in the message).
    """
    t0 = time.perf_counter()
    if backend not in ("clarabel", "cvxpy"):
        raise SolverError(f"unknown LP backend {backend!r}; expected 'clarabel' or 'cvxpy'")
    constraints = tuple(constraints)
    rows = max_form(constraints, mdp.n_pairs)
    lp = build_lp(mdp)
    G, h, s = scaled_rows(lp, rows)
    if backend == "clarabel":
        # iterative refinement stays on (Clarabel's default): the multipliers are an output here
        status, solved, y, z_eq, z_in, mu, stats = _run_clarabel(lp, G, h, tol, max_iter, verbose, settings)
    else:
        status, solved, y, z_eq, z_in, mu, stats = _run_cvxpy(lp, G, h, tol, max_iter, verbose, settings)
    method = "lp" if backend == "clarabel" else "lp-cvxpy"
    mapped = _STATUS_OF[backend](status)
    if mapped.code is INFEASIBLE:
        check_reachable(mdp, constraints, joint_status=status)
    if mapped.code is FAILED or y is None \
            or not (np.all(np.isfinite(y)) and np.all(np.isfinite(z_eq)) and np.all(np.isfinite(z_in))):
        raise SolverError(f"{method}: the constrained LP failed with status {status} "
                          f"(iterations={stats.get('solver_iterations')}); no usable solution")
    stats.update(lp_rows=int(lp.n_eq + rows.n_rows), lp_cols=int(lp.n_pairs))
    yb = y
    if crossover:
        yv, info = basic_solution(mdp, lp.A_eq, lp.b_eq, lp.q, G, h, y, mu, stats["obj_scaled"])
        stats.update(info)
        stats["crossover"] = "basic" if yv is not None else "failed: interior point kept"
        if yv is not None:
            yb = yv
    else:
        stats["crossover"] = "off"
    return certify_lp_solution(mdp, constraints, lp, s, yb, z_eq, z_in, method=method,
                               solver_status=mapped, stats=stats, t0=t0,
                               cert_rtol=cert_rtol)


def certify_lp_solution(mdp: MDP, constraints: Sequence[LinearConstraint], lp: LPData, s: np.ndarray, y: np.ndarray,
                        z_eq: np.ndarray, z_in: np.ndarray, *, method: str, solver_status: str, stats: dict,
                        t0: float, cert_rtol: float = CERT_RTOL) -> ConstrainedSolution:
    r"""From a solution of the scaled constrained LP to a certified :class:`ConstrainedSolution`.

    Shared by the Clarabel route and the warm-started HiGHS re-solves
    (:mod:`~wncs_lp.constrained.warm`).

    Parameters
    ----------
    lp : LPData
        The scaled unconstrained LP (:func:`~wncs_lp.solvers.lp.build_lp`).
    s : (K,) array
        Row scales of :func:`scaled_rows`.
    y : (L,) array
        The scaled occupation measure ``y = n x`` (a basic solution randomises in at most K states).
    z_eq, z_in : arrays
        Duals of the equality rows and of the bound rows in Clarabel's sign (``q + A^T z >= 0``,
        ``z_in >= 0``); :math:`\lambda_j = c_s z_j / s_j`, the Lagrangian gain is ``-c_s z_eq[-1]``.
    stats : dict
        Must hold ``obj_scaled`` (the LP's scaled objective); updated with the multipliers.
    solver_status : str
        ``"optimal"`` or the solver's word for what went wrong.
    """
    lam_rows = np.maximum(lp.cost_scale * np.asarray(z_in, float) / s, 0.0)
    g_lag = -lp.cost_scale * float(z_eq[-1])
    _, h_dual = lp.unscale_duals(z_eq)
    solver_gain = lp.objective(stats["obj_scaled"])
    stats.update(lagrangian_dual_gain=g_lag, row_multipliers=[float(v) for v in lam_rows])
    x = lp.unscale_x(np.maximum(y, 0.0))
    x = x / x.sum()
    lp_values = np.array([float(c.values @ x) for c in constraints])
    probs, randomized = policy_from_occupation(mdp, x, h_dual)
    return certify(mdp, constraints, probs, randomized, lam_rows, method=method, solver_status=solver_status,
                   solver_gain=solver_gain, lp_values=lp_values, h0=h_dual, cert_rtol=cert_rtol,
                   iterations=int(stats.get("solver_iterations", 0)), t0=t0, stats=stats)
