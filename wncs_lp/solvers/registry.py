"""The functions of the average-cost methods, imported normally: one :class:`~wncs_lp.methods.Entry`
per row of :data:`wncs_lp.methods.TABLE` (like cvxpy's solver map).

:func:`run_average` (the average-cost step of :func:`wncs_lp.solve` on an MDP) dispatches through
:data:`AVERAGE`; the scenario route (:func:`wncs_lp.workflow.route.run_scenario`) reads it for a
scenario method (``matrix-free`` on the AoI box) and for the keywords a method takes. The
constrained methods' functions are registered in :mod:`wncs_lp.constrained.registry`, beside
their step; the discounted ones in :data:`wncs_lp.solvers.discounted.DISCOUNTED_ENTRIES`, beside
theirs.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from ..errors import SolverError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD, SCENARIO_METHODS, TABLE, Entry, method
from .auto import solve_auto
from .dp import policy_iteration, relative_value_iteration, value_iteration
from .lp import solve_lp
from .matrix_free import matrix_free_value_iteration, run_on_mdp
from .result import Solution

__all__ = ["AVERAGE", "average_entry", "run_average"]

#: Method name -> its entry (the row and the function that runs it).
AVERAGE: dict[str, Entry] = {
    "auto": Entry(TABLE["auto"], solve_auto),
    "lp": Entry(TABLE["lp"], solve_lp),
    "lp-highs": Entry(TABLE["lp-highs"], solve_lp),
    "lp-cvxpy": Entry(TABLE["lp-cvxpy"], solve_lp),
    "vi": Entry(TABLE["vi"], value_iteration),
    "rvi": Entry(TABLE["rvi"], relative_value_iteration),
    "pi": Entry(TABLE["pi"], policy_iteration),
    "matrix-free": Entry(TABLE["matrix-free"], matrix_free_value_iteration, on_mdp=run_on_mdp),
}


def average_entry(name: str, allowed: tuple[str, ...] | None = None, problem: str | None = None) -> Entry:
    """The entry of ``name`` after the one validator (:func:`wncs_lp.methods.method`)."""
    return AVERAGE[method(name, allowed=allowed, problem=problem).name]


def run_average(mdp: MDP, method: str = DEFAULT_METHOD, **kw: Any) -> Solution:
    """The average-cost step of :func:`wncs_lp.solve` on an MDP: the named method's function (a row of
    :data:`wncs_lp.methods.TABLE`, run by its entry in :data:`AVERAGE`).

    Parameters
    ----------
    mdp : MDP
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "vi", "rvi", "pi", "matrix-free"}
    **kw
        The method's keywords: :func:`~wncs_lp.solvers.auto.solve_auto`,
        :func:`~wncs_lp.solvers.lp.solve_lp` (``backend`` is set by the method name),
        :func:`~wncs_lp.solvers.dp.value_iteration`, :func:`~wncs_lp.solvers.dp.relative_value_iteration`,
        :func:`~wncs_lp.solvers.dp.policy_iteration`, or the matrix-free solver's. A keyword the
        method does not take raises a :class:`SolverError` naming the ones it does.

    Returns
    -------
    Solution
        With ``pair_actions`` (so ``sigma`` and ``chain(mdp)`` work whichever solver ran).

    Raises
    ------
    SolverError
        Unknown method (the message lists the allowed ones), a keyword it does not take, or a
        solver failure.
    """
    if not isinstance(mdp, MDP):
        raise SolverError(f"solve takes an MDP (wncs_lp.build(scenario)); got {type(mdp).__name__} "
                          "(wncs_lp.solve takes a scenario)")
    sol = average_entry(method, allowed=SCENARIO_METHODS).call(mdp, on_mdp=True, **kw)
    if isinstance(sol, Solution) and sol.pair_actions is None:  # e.g. a matrix-free solve mapped onto the MDP
        sol = replace(sol, pair_actions=mdp.a_indices)
    return sol
