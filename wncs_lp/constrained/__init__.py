"""Constrained and convex scheduling over the occupation measure (``docs/constraints.md``).

Minimise the average cost while bounding other long-run averages (a server's send rate, one
process's AoI or MSE, ...). The optimum is a *randomised* stationary policy, certified by
``[L(lambda), exact cost of the returned policy]``.

* :func:`solve_constrained` -- the entry point: ``method="lp"`` (Clarabel), ``"lp-highs"``,
  ``"lp-cvxpy"``, ``"lagrangian"`` (one constraint, beyond the LP's size) or ``"auto"``;
* :class:`OccupationProgram` -- convex programs over the occupation measure (cvxpy + Clarabel):
  the variable, the balance constraints and the quantities as expressions;
* :func:`constraints_for` -- a scenario's ``[[constraint]]`` tables as :class:`LinearConstraint`;
* :class:`ConstrainedSolution` -- what every route returns.
"""
from __future__ import annotations

from typing import Any, Iterable

from ..errors import SolverError
from ..mdp import MDP
from ..methods import CONSTRAINED_METHODS, DEFAULT_METHOD  # one vocabulary: wncs_lp.methods
from .convex import OccupationProgram
from .certify import CERT_RTOL, certify, evaluate_rows, lagrangian_bound, policy_from_occupation
from .lp import check_reachable, reachable_range, solve_constrained_lp
from .warm import solve_constrained_highs
from .problem import LinearConstraint, Rows, constraints_for, max_form, with_cost
from .registry import CONSTRAINED_ENTRIES, constrained_entry
from .result import ConstrainedSolution, ConstraintReport

__all__ = [
    "solve_constrained",
    "solve_constrained_lp",
    "solve_constrained_highs",
    "OccupationProgram",
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
    "CONSTRAINED_ENTRIES",
]


def solve_constrained(mdp: MDP, constraints: Iterable[Any], method: str = DEFAULT_METHOD,
                      **kw: Any) -> ConstrainedSolution:
    """Solve ``min g`` subject to the constraints' bounds.

    Parameters
    ----------
    mdp : MDP
        (A scenario is solved with its ``[[constraint]]`` tables by :func:`wncs_lp.solve`.)
    constraints : iterable of ConstraintSpec or LinearConstraint
        ``scenario.constraints`` or your own :class:`LinearConstraint` objects.
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian"}
        A row of :data:`wncs_lp.methods.CONSTRAINED` (run by its entry in
        :data:`wncs_lp.constrained.registry.CONSTRAINED_ENTRIES`). ``"lp"``: the occupation-measure LP on
        Clarabel, then a crossover to a basic solution; ``"lp-highs"``: the same LP on HiGHS
        (interior point + crossover, ending on a basis:
        :class:`~wncs_lp.constrained.warm.WarmConstrainedLP`); ``"lp-cvxpy"``: the Clarabel LP
        through cvxpy; ``"lagrangian"``: search on the multiplier with certified value iteration
        and a one-state mix (one constraint); ``"auto"``: ``"lp-highs"`` up to ``LP_MAX_PAIRS``
        pairs or with several constraints, the Lagrangian route beyond (one constraint only).
        Every route ends with the same certificate.
    **kw
        Passed to :func:`solve_constrained_lp`, :func:`solve_constrained_highs` or
        :func:`~wncs_lp.constrained.lagrangian.solve_lagrangian`.
    """
    if not isinstance(mdp, MDP):
        raise SolverError(f"solve_constrained takes an MDP (wncs_lp.build(scenario)); got {type(mdp).__name__} "
                          "(wncs_lp.solve(scenario) solves a scenario with its [[constraint]] tables)")
    found = constrained_entry(method)
    cons = constraints_for(mdp, constraints)
    if not cons:
        raise SolverError("solve_constrained needs at least one constraint (use wncs_lp.solve for the unconstrained problem)")
    if found.choose is not None:  # auto: the method its rule picks, recorded as asked for
        sol = solve_constrained(mdp, cons, found.choose(mdp, cons), **kw)
        sol.stats["method_requested"] = found.row.name
        return sol
    return found.call(mdp, cons, **kw)
