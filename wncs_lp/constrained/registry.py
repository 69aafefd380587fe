"""The functions of the constrained methods, imported normally: one :class:`~wncs_lp.methods.Entry`
per row of :data:`wncs_lp.methods.CONSTRAINED` (the average-cost ones are in
:mod:`wncs_lp.solvers.registry`). :func:`run_constrained` (the constrained step of
:func:`wncs_lp.solve`) dispatches through :data:`CONSTRAINED_ENTRIES`; ``auto`` runs the method its
``choose`` rule names.
"""
from __future__ import annotations

from typing import Any, Iterable

from ..errors import SolverError
from ..mdp import MDP
from ..methods import CONSTRAINED, DEFAULT_METHOD, Entry, Method, method
from .lagrangian import auto_method, solve_lagrangian
from .lp import solve_constrained_lp
from .problem import constraints_for
from .result import ConstrainedSolution
from .warm import solve_constrained_highs

__all__ = ["CONSTRAINED_ENTRIES", "constrained_entry", "row_that_runs", "run_constrained"]

#: Method name -> its entry (the row and the function that runs it).
CONSTRAINED_ENTRIES: dict[str, Entry] = {
    "auto": Entry(CONSTRAINED["auto"], None, choose=auto_method),
    "lp": Entry(CONSTRAINED["lp"], solve_constrained_lp),
    "lp-highs": Entry(CONSTRAINED["lp-highs"], solve_constrained_highs),
    "lp-cvxpy": Entry(CONSTRAINED["lp-cvxpy"], solve_constrained_lp),
    "lagrangian": Entry(CONSTRAINED["lagrangian"], solve_lagrangian),
}


def constrained_entry(name: str, problem: str | None = None) -> Entry:
    """The entry of ``name`` after the one validator (:func:`wncs_lp.methods.method`)."""
    return CONSTRAINED_ENTRIES[method(name, constrained=True, problem=problem).name]


def row_that_runs(name: str, mdp: Any, constraints: Any) -> Method:
    """The row of the method that would solve these constraints: ``name``'s, or the one ``auto``'s
    rule picks for them (``constraints`` as :func:`~wncs_lp.constrained.constraints_for` gives them)."""
    found = constrained_entry(name)
    return CONSTRAINED[found.choose(mdp, constraints)] if found.choose is not None else found.row


def run_constrained(mdp: MDP, constraints: Iterable[Any], method: str = DEFAULT_METHOD,
                    **kw: Any) -> ConstrainedSolution:
    """The constrained step of :func:`wncs_lp.solve` (``constraints=``) on an MDP: ``min g`` subject to
    the constraints' bounds.

    Parameters
    ----------
    mdp : MDP
        (A scenario is solved with its ``[[constraint]]`` tables by :func:`wncs_lp.solve`.)
    constraints : iterable of ConstraintSpec or LinearConstraint
        ``scenario.constraints`` or your own :class:`LinearConstraint` objects.
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian"}
        A row of :data:`wncs_lp.methods.CONSTRAINED` (run by its entry in
        :data:`CONSTRAINED_ENTRIES`). ``"lp"``: the occupation-measure LP on
        Clarabel, then a crossover to a basic solution; ``"lp-highs"``: the same LP on HiGHS
        (interior point + crossover, ending on a basis:
        :class:`~wncs_lp.constrained.warm.WarmConstrainedLP`); ``"lp-cvxpy"``: the Clarabel LP
        through cvxpy; ``"lagrangian"``: search on the multiplier with certified value iteration
        and a one-state mix (one constraint); ``"auto"``: ``"lp-highs"`` up to ``LP_MAX_PAIRS``
        pairs or with several constraints, the Lagrangian route beyond (one constraint only).
        Every route ends with the same certificate.
    **kw
        Passed to :func:`~wncs_lp.constrained.lp.solve_constrained_lp`,
        :func:`~wncs_lp.constrained.warm.solve_constrained_highs` or
        :func:`~wncs_lp.constrained.lagrangian.solve_lagrangian`.
    """
    if not isinstance(mdp, MDP):
        raise SolverError(f"a constrained solve takes an MDP (wncs_lp.build(scenario)); got {type(mdp).__name__} "
                          "(wncs_lp.solve(scenario) solves a scenario with its [[constraint]] tables)")
    found = constrained_entry(method)
    cons = constraints_for(mdp, constraints)
    if not cons:
        raise SolverError("a constrained solve needs at least one constraint (use wncs_lp.solve for the unconstrained "
                          "problem)")
    if found.choose is not None:  # auto: the method its rule picks, recorded as asked for
        sol = run_constrained(mdp, cons, found.choose(mdp, cons), **kw)
        sol.stats["method_requested"] = found.row.name
        return sol
    return found.call(mdp, cons, **kw)
