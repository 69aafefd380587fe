r"""The constrained LP kept in one HiGHS model, re-solved from the previous basis as bounds change.

A trade-off curve solves

.. math:: \min_y q^T y \quad\text{s.t.}\quad A_{eq} y = b_{eq},\; G y \le h(b),\; y \ge 0

for many bounds b; only the right-hand side h of the bound rows moves (the scaled LP of
:mod:`~wncs_lp.constrained.lp`, rows ``(D / s) y <= n b / s``). Changing a right-hand side
keeps the optimal basis of the previous bound *dual* feasible, so the dual simplex method
restarts from it (a "hot start": no presolve, no new factorisation of the whole problem) and
pivots only as far as the optimal policy changes. Between two kinks of the curve it does 0
pivots; across kinks, a few per state whose action changes.

Clarabel has no such restart: its iterate always starts from its own initial point (Clarabel.jl
issue #173, "The solver does not allow for user-specified starting values"; Clarabel.rs issue
#206, still planned in October 2025; the 0.11 Python ``DefaultSolver.update`` replaces data and
keeps the symbolic factorisation, not the iterate). Hence HiGHS (``highspy``).

:class:`WarmConstrainedLP` solves

* the first bound (and any bound after a failed restart) *cold*: HiGHS's interior point with
  crossover, which ends on a basis (method ``"lp-highs"``);
* every later bound *warm*: new row bounds, then the dual simplex from the kept basis (method
  ``"lp-warm"``). A restart that has not finished within ``budget`` seconds (default: the last
  cold solve's time, at least :data:`WARM_MIN_SECONDS`) is abandoned for a cold solve, so a
  warm point never costs more than about two cold ones.

Every point is certified exactly as the Clarabel route's
(:func:`~wncs_lp.constrained.lp.certify_lp_solution`): the basic x gives a policy that
randomises in at most as many states as there are bound rows; it is evaluated exactly, and the
Lagrangian bound uses the row duals as multipliers. Duals: HiGHS reports ``row_dual`` with
``col_dual = q - A^T row_dual``; Clarabel's ``z`` (``q + A^T z >= 0``) is ``-row_dual``.
A bound HiGHS finds infeasible raises :class:`~wncs_lp.errors.InfeasibleConstraintsError` like
the cold route; the basis stays for the next bound.
"""
from __future__ import annotations

import time
from typing import Any, Iterable, Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..mdp import MDP
from ..solvers.highs import new_highs, run_highs
from ..solvers.lp import build_lp
from .certify import CERT_RTOL
from .lp import certify_lp_solution, check_reachable, scaled_rows
from .problem import LinearConstraint, constraints_for, max_form
from .result import ConstrainedSolution

__all__ = ["WarmConstrainedLP", "WARM_MIN_SECONDS", "solve_constrained_highs"]

#: A warm restart is always allowed at least this many seconds before it is abandoned.
WARM_MIN_SECONDS = 1.0


class WarmConstrainedLP:
    """One constrained LP in a ``highspy.Highs`` model, re-solved as the bounds change.

    Parameters
    ----------
    mdp : MDP
    constraints : sequence of LinearConstraint
        Fixes the rows (which constraints, their per-pair values, which sides are bounded);
        :meth:`solve` may then change the bounds only.
    budget : float, optional
        Seconds a warm restart may take before a cold solve replaces it; default the last cold
        solve's time (at least :data:`WARM_MIN_SECONDS`).
    cert_rtol : float
        Width of the certificate accepted as "optimal" (as in
        :func:`~wncs_lp.constrained.lp.solve_constrained_lp`).
    tol : float
        HiGHS's primal and dual feasibility tolerances (scaled problem).

    Examples
    --------
    >>> warm = WarmConstrainedLP(mdp, [c.with_bounds(max=0.1)])       # doctest: +SKIP
    >>> [warm.solve([c.with_bounds(max=b)]).gain for b in (0.1, 0.2)]  # doctest: +SKIP
    """

    def __init__(self, mdp: MDP, constraints: Sequence[LinearConstraint], *, budget: float | None = None,
                 cert_rtol: float = CERT_RTOL, tol: float = 1e-9):
        import highspy

        self.mdp = mdp
        self.cert_rtol = float(cert_rtol)
        self.budget = None if budget is None else float(budget)
        self.rows = max_form(tuple(constraints), mdp.n_pairs)
        self.lp = build_lp(mdp)
        G, h, self.scales = scaled_rows(self.lp, self.rows)
        A = sp.vstack([self.lp.A_eq, G], format="csc")
        A.sort_indices()
        self.n_eq, self.n_rows = self.lp.n_eq, int(G.shape[0])
        self._h = h.copy()  # the bound rows' right-hand sides the model holds now
        self.cold_seconds = 0.0  # the last cold solve's time
        self.solves = {"warm": 0, "cold": 0, "abandoned": 0}

        inf = highspy.kHighsInf
        m, L = A.shape
        model = highspy.HighsLp()
        model.num_col_, model.num_row_ = L, m
        model.col_cost_ = np.asarray(self.lp.q, float)
        model.col_lower_ = np.zeros(L)
        model.col_upper_ = np.full(L, inf)
        model.row_lower_ = np.concatenate([self.lp.b_eq, np.full(self.n_rows, -inf)])
        model.row_upper_ = np.concatenate([self.lp.b_eq, h])
        model.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        model.a_matrix_.num_col_, model.a_matrix_.num_row_ = L, m
        model.a_matrix_.start_ = A.indptr.astype(np.int32)
        model.a_matrix_.index_ = A.indices.astype(np.int32)
        model.a_matrix_.value_ = A.data.astype(float)
        self._hs = highspy
        self.highs = new_highs()  # without the banner that would corrupt --json output
        self.highs.setOptionValue("output_flag", False)
        self.highs.setOptionValue("primal_feasibility_tolerance", float(tol))
        self.highs.setOptionValue("dual_feasibility_tolerance", float(tol))
        if self.highs.passModel(model) != highspy.HighsStatus.kOk:
            raise SolverError("HiGHS refused the constrained LP (passModel failed)")

    # ------------------------------------------------------------------ internals
    def _run(self, warm: bool) -> tuple[str, dict]:
        """One HiGHS run: dual simplex from the kept basis (warm) or interior point + crossover."""
        hs, H = self._hs, self.highs
        inf = hs.kHighsInf
        if warm:
            budget = self.budget if self.budget is not None else max(WARM_MIN_SECONDS, self.cold_seconds)
            H.setOptionValue("solver", "simplex")
            H.setOptionValue("simplex_strategy", 1)  # dual: a new right-hand side keeps the basis dual feasible
            H.setOptionValue("time_limit", H.getRunTime() + budget)  # HiGHS's clock runs across runs
        else:
            H.clearSolver()
            H.setOptionValue("solver", "ipm")
            H.setOptionValue("run_crossover", "on")  # end on a basis: a vertex, and the next warm start
            H.setOptionValue("time_limit", inf)
        t0 = time.perf_counter()
        run_highs(H)
        dt = time.perf_counter() - t0
        info = H.getInfo()
        status = H.modelStatusToString(H.getModelStatus())
        st = {"solver": "highs", "highs_start": "basis" if warm else "cold (ipm+crossover)",
              "solver_status": status, "solve_time": dt,
              "simplex_iterations": int(info.simplex_iteration_count),
              "ipm_iterations": int(info.ipm_iteration_count),
              "crossover_iterations": int(info.crossover_iteration_count),
              "solver_iterations": int(info.simplex_iteration_count) + int(info.ipm_iteration_count)}
        if warm:
            st["warm_budget_seconds"] = float(budget)
        return status, st

    # ------------------------------------------------------------------ the solve
    def solve(self, constraints: Sequence[LinearConstraint], *, warm: bool = True) -> ConstrainedSolution:
        """Solve with new bounds on the same rows, from the previous basis when there is one.

        Parameters
        ----------
        constraints : sequence of LinearConstraint
            The constraints of the constructor with (possibly) other bounds.
        warm : bool
            False: a cold HiGHS solve even when a basis is kept (what the benchmark compares).

        Returns
        -------
        ConstrainedSolution
            ``method`` is ``"lp-warm"`` (re-solved from the previous basis) or ``"lp-highs"``
            (cold); ``stats`` says how (``highs_start``, iterations, ``solve_time`` of the run
            that produced it, and ``warm_abandoned`` / ``warm_abandoned_seconds`` when a restart
            ran out of budget first).

        Raises
        ------
        SolverError
            Other rows than the constructor's, or HiGHS failed (its status in the message).
        InfeasibleConstraintsError
            No policy meets the bounds.
        """
        t0 = time.perf_counter()
        hs, H = self._hs, self.highs
        constraints = tuple(constraints)
        rows = max_form(constraints, self.mdp.n_pairs)
        if rows.n_rows != self.n_rows or rows.side != self.rows.side or not np.array_equal(rows.owner, self.rows.owner) \
                or not np.array_equal(rows.D, self.rows.D):
            raise SolverError("a warm re-solve needs the constraints it was built with: only their bounds may change "
                              f"(built with {self.n_rows} bound row(s) {list(self.rows.side)}, got {rows.n_rows} "
                              f"{list(rows.side)} or other values)")
        h = self.lp.x_scale * rows.b / self.scales
        changed = np.flatnonzero(h != self._h)
        if changed.size:
            H.changeRowsBounds(int(changed.size), (self.n_eq + changed).astype(np.int32),
                               np.full(changed.size, -hs.kHighsInf), h[changed].astype(float))
            self._h = h.copy()
        hot = warm and H.getBasis().valid
        extra: dict = {}
        if hot:
            status, st = self._run(True)
            if status == "Time limit reached":
                self.solves["abandoned"] += 1
                extra = {"warm_abandoned": f"dual simplex restart stopped after {st['solve_time']:.3g} s "
                                           f"({st['simplex_iterations']} iterations); solved cold",
                         "warm_abandoned_seconds": st["solve_time"]}
                hot = False
        if not hot:
            status, st = self._run(False)
            self.cold_seconds = st["solve_time"]
        self.solves["warm" if hot else "cold"] += 1
        st.update(extra)
        method = "lp-warm" if hot else "lp-highs"
        if status in ("Infeasible", "Primal infeasible or unbounded"):
            # the feasible set is bounded (sum x = 1, x >= 0): "infeasible or unbounded" is infeasible
            check_reachable(self.mdp, constraints, joint_status=f"highs: {status}")
        sol = H.getSolution()
        if status != "Optimal" or not sol.value_valid or not sol.dual_valid:
            raise SolverError(f"{method}: HiGHS ended with status {status!r} (simplex iterations "
                              f"{st['simplex_iterations']}, interior-point iterations {st['ipm_iterations']}); "
                              "no usable solution")
        y = np.asarray(sol.col_value, float)
        z = -np.asarray(sol.row_dual, float)  # Clarabel's sign: q + A^T z = reduced costs >= 0
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(z))):
            raise SolverError(f"{method}: HiGHS returned non-finite values with status {status!r}")
        st.update(obj_scaled=float(H.getInfo().objective_function_value), lp_rows=int(self.n_eq + self.n_rows),
                  lp_cols=int(self.lp.n_pairs), crossover="basic (HiGHS basis)")
        return certify_lp_solution(self.mdp, constraints, self.lp, self.scales, y, z[:self.n_eq], z[self.n_eq:],
                                   method=method, solver_status="optimal", stats=st, t0=t0,
                                   cert_rtol=self.cert_rtol)


def solve_constrained_highs(mdp: MDP, constraints: Iterable[Any], *, budget: float | None = None,
                            cert_rtol: float = CERT_RTOL, tol: float = 1e-9) -> ConstrainedSolution:
    """The constrained LP on HiGHS from scratch (interior point + crossover, ending on a basis):
    method ``"lp-highs"`` (:class:`WarmConstrainedLP`, whose options these are)."""
    cons = constraints_for(mdp, constraints)
    return WarmConstrainedLP(mdp, cons, budget=budget, cert_rtol=cert_rtol, tol=tol).solve(cons, warm=False)
