"""The functions of the average-cost methods, imported normally: one :class:`~wncs_lp.methods.Entry`
per row of :data:`wncs_lp.methods.TABLE` (like cvxpy's solver map).

:func:`wncs_lp.solvers.solve` dispatches through :data:`AVERAGE`; the scenario route
(:func:`wncs_lp.workflow.solve_scenario`) reads it for a scenario method (``matrix-free`` on the
AoI box) and for the keywords a method takes. The constrained methods' functions are registered
in :mod:`wncs_lp.constrained.registry`, beside their dispatcher; the discounted ones in
:data:`wncs_lp.solvers.discounted.DISCOUNTED_ENTRIES`, beside theirs.
"""
from __future__ import annotations

from ..methods import TABLE, Entry, method
from .auto import solve_auto
from .dp import policy_iteration, relative_value_iteration, value_iteration
from .lp import solve_lp
from .matrix_free import matrix_free_value_iteration, solve_mdp

__all__ = ["AVERAGE", "average_entry"]

#: Method name -> its entry (the row and the function that runs it).
AVERAGE: dict[str, Entry] = {
    "auto": Entry(TABLE["auto"], solve_auto),
    "lp": Entry(TABLE["lp"], solve_lp),
    "lp-highs": Entry(TABLE["lp-highs"], solve_lp),
    "lp-cvxpy": Entry(TABLE["lp-cvxpy"], solve_lp),
    "vi": Entry(TABLE["vi"], value_iteration),
    "rvi": Entry(TABLE["rvi"], relative_value_iteration),
    "pi": Entry(TABLE["pi"], policy_iteration),
    "matrix-free": Entry(TABLE["matrix-free"], matrix_free_value_iteration, on_mdp=solve_mdp),
}


def average_entry(name: str, allowed: tuple[str, ...] | None = None, problem: str | None = None) -> Entry:
    """The entry of ``name`` after the one validator (:func:`wncs_lp.methods.method`)."""
    return AVERAGE[method(name, allowed=allowed, problem=problem).name]
