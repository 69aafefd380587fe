"""The functions of the constrained methods, imported normally: one :class:`~wncs_lp.methods.Entry`
per row of :data:`wncs_lp.methods.CONSTRAINED` (the average-cost ones are in
:mod:`wncs_lp.solvers.registry`). :func:`wncs_lp.constrained.solve_constrained` dispatches
through :data:`CONSTRAINED_ENTRIES`; ``auto`` runs the method its ``choose`` rule names.
"""
from __future__ import annotations

from typing import Any

from ..methods import CONSTRAINED, Entry, Method, method
from .lagrangian import auto_method, solve_lagrangian
from .lp import solve_constrained_lp
from .warm import solve_constrained_highs

__all__ = ["CONSTRAINED_ENTRIES", "constrained_entry", "row_that_runs"]

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
