"""Constrained and convex scheduling over the occupation measure (``docs/constraints.md``).

Minimise the average cost while bounding other long-run averages (a server's send rate, one
process's AoI or MSE, ...). The optimum is a *randomised* stationary policy, certified by
``[L(lambda), exact cost of the returned policy]``.

* :func:`solve_constrained` -- the entry point: ``method="lp"`` (Clarabel), ``"lp-highs"``,
  ``"lp-cvxpy"``, ``"lagrangian"`` (one constraint, beyond the LP's size) or ``"auto"``;
* :class:`OccupationProgram` -- convex programs over the occupation measure (cvxpy + Clarabel):
  the variable, the balance constraints and the quantities as expressions;
* :func:`tradeoff` -- the optimal cost against one bound (a trade-off curve), resumable;
* :func:`constraints_for` -- a scenario's ``[[constraint]]`` tables as :class:`LinearConstraint`;
* :class:`ConstrainedSolution` -- what every route returns.
"""
from __future__ import annotations

from typing import Any, Iterable

from ..mdp import MDP
from .convex import OccupationProgram
from .certify import certify, evaluate_rows, lagrangian_bound, policy_from_occupation
from .lp import check_reachable, reachable_range, solve_constrained_lp
from .problem import LinearConstraint, Rows, constraints_for, max_form, with_cost
from .result import ConstrainedSolution, ConstraintReport
from .tradeoff import TradeoffPoint, TradeoffResult, tradeoff

__all__ = [
    "solve_constrained",
    "solve_constrained_lp",
    "OccupationProgram",
    "tradeoff",
    "TradeoffResult",
    "TradeoffPoint",
    "constraints_for",
    "LinearConstraint",
    "ConstrainedSolution",
    "ConstraintReport",
    "Rows",
    "max_form",
    "with_cost",
    "certify",
    "evaluate_rows",
    "lagrangian_bound",
    "policy_from_occupation",
    "reachable_range",
    "check_reachable",
    "CONSTRAINED_METHODS",
]

from ..methods import CONSTRAINED_METHODS  # noqa: E402  (one vocabulary: wncs_lp.methods)


def solve_constrained(mdp: MDP, constraints: Iterable[Any], method: str = "auto", **kw: Any) -> ConstrainedSolution:
    """Solve ``min g`` subject to the constraints' bounds.

    Parameters
    ----------
    mdp : MDP
    constraints : iterable of ConstraintSpec or LinearConstraint
        ``scenario.constraints`` or your own :class:`LinearConstraint` objects.
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian"}
        ``"lp"``: the occupation-measure LP on Clarabel, then a crossover to a basic solution;
        ``"lp-highs"``: the same LP on HiGHS (interior point + crossover, ending on a basis:
        :class:`~wncs_lp.constrained.warm.WarmConstrainedLP`); ``"lp-cvxpy"``: the Clarabel LP
        through cvxpy; ``"lagrangian"``: search on the multiplier with certified value iteration
        and a one-state mix (one constraint); ``"auto"``: ``"lp-highs"`` up to ``LP_MAX_PAIRS``
        pairs or with several constraints, the Lagrangian route beyond (one constraint only).
        Every route ends with the same certificate.
    **kw
        Passed to :func:`solve_constrained_lp` or :func:`~wncs_lp.constrained.lagrangian.solve_lagrangian`.
    """
    from ..errors import SolverError

    cons = constraints_for(mdp, constraints)
    if not cons:
        raise SolverError("solve_constrained needs at least one constraint (use wncs_lp.solve for the unconstrained problem)")
    if method == "auto":
        from .lagrangian import auto_method

        method = auto_method(mdp, cons)
        sol = solve_constrained(mdp, cons, method, **kw)
        sol.stats["method_requested"] = "auto"
        return sol
    if method == "lp":
        return solve_constrained_lp(mdp, cons, backend="clarabel", **kw)
    if method == "lp-highs":
        from .warm import WarmConstrainedLP

        return WarmConstrainedLP(mdp, cons, **kw).solve(cons, warm=False)
    if method == "lp-cvxpy":
        return solve_constrained_lp(mdp, cons, backend="cvxpy", **kw)
    if method == "lagrangian":
        from .lagrangian import solve_lagrangian

        return solve_lagrangian(mdp, cons, **kw)
    raise SolverError(f"unknown constrained method {method!r}; expected one of {', '.join(map(repr, CONSTRAINED_METHODS))}")
