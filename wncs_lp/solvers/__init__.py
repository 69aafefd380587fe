"""Average-cost MDP solvers, each returning a certified :class:`Solution`.

``solve(mdp, method)`` dispatches to

Every method is a row of the one vocabulary, :data:`wncs_lp.methods.TABLE`, run by the function
registered for it in :data:`wncs_lp.solvers.registry.AVERAGE`:

* ``"lp"``       -- occupation-measure LP, Clarabel called directly (:func:`solve_lp`);
* ``"lp-highs"`` -- the same LP on HiGHS (:mod:`wncs_lp.solvers.highs`);
* ``"lp-cvxpy"`` -- the same LP built with cvxpy and solved by Clarabel;
* ``"rvi"``      -- relative value iteration with the aperiodicity transform;
* ``"vi"``       -- certified value iteration on the fused kernels (Gauss-Seidel modified
  policy iteration with numba, Jacobi RVI with scipy; :func:`value_iteration`);
* ``"pi"``       -- Howard policy iteration with exact evaluation (sparse LU; BiCGSTAB on large
  chains; falls back to value iteration on a multichain iterate);
* ``"auto"``     -- picks LP or value iteration by size and cross-checks them when both are
  cheap (:func:`solve_auto`);
* ``"matrix-free"`` -- certified value iteration without the transition matrix, on the MDP's
  scenario (:mod:`wncs_lp.solvers.matrix_free`; the answer is returned on the MDP).

From a scenario, :func:`wncs_lp.workflow.solve_scenario` (the workflow floor, above the solvers
and the constrained solvers) is the one route: size guard, build (:func:`build_scenario`),
solve, and ``auto``'s switch to the matrix-free solver when the stored matrix would not fit.

The discounted criterion (a discount factor beta, certified by MacQueen's bounds) is
:func:`solve_discounted` (:mod:`wncs_lp.solvers.discounted`).

Every solution carries the bracket ``gain_lower <= g* <= gain_upper`` from one Bellman
step on its bias (:func:`bracket`).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from .. import moved
from ..errors import SolverError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD, METHODS, SCENARIO_METHODS
from .certify import bellman_step, bracket, certificate_closed, greedy_first, q_values
from .auto import solve_auto
from .discounted import DiscountedSolution, discounted_value, laurent_terms, solve_discounted
from .dp import (
    MultichainPolicyError,
    PolicyEvaluation,
    evaluate_policy,
    policy_iteration,
    relative_value_iteration,
    value_iteration,
)
from .lp import LPData, build_lp, extract_policy, solve_lp
from .result import Solution
from .registry import AVERAGE, average_entry
from .route import ScenarioSolve, WarmStart, build_scenario

__all__ = [
    "METHODS",
    "solve",
    "Solution",
    "q_values",
    "bellman_step",
    "bracket",
    "greedy_first",
    "certificate_closed",
    "PolicyEvaluation",
    "evaluate_policy",
    "relative_value_iteration",
    "value_iteration",
    "policy_iteration",
    "MultichainPolicyError",
    "solve_auto",
    "LPData",
    "build_lp",
    "extract_policy",
    "solve_lp",
    "ScenarioSolve",
    "WarmStart",
    "build_scenario",
    "AVERAGE",
    "DiscountedSolution",
    "solve_discounted",
    "discounted_value",
    "laurent_terms",
]


def solve(mdp: MDP, method: str = DEFAULT_METHOD, **kw: Any) -> Solution:
    """Solve an average-cost MDP with the named method (a row of :data:`wncs_lp.methods.TABLE`).

    Parameters
    ----------
    mdp : MDP
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "vi", "rvi", "pi", "matrix-free"}
    **kw
        The method's keywords: :func:`solve_auto`, :func:`solve_lp` (``backend`` is set by the
        method name), :func:`value_iteration`, :func:`relative_value_iteration`,
        :func:`policy_iteration`, or the matrix-free solver's. A keyword the method does not take
        raises a :class:`SolverError` naming the ones it does.

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
                          "(wncs_lp.solve and wncs_lp.workflow.solve_scenario take a scenario)")
    sol = average_entry(method, allowed=SCENARIO_METHODS).call(mdp, on_mdp=True, **kw)
    if isinstance(sol, Solution) and sol.pair_actions is None:  # e.g. a matrix-free solve mapped onto the MDP
        sol = replace(sol, pair_actions=mdp.a_indices)
    return sol



def __getattr__(name: str) -> Any:
    """Names that moved to the workflow floor (:mod:`wncs_lp.moved`): still found here, with a warning."""
    return moved.old_name(__name__, name)
