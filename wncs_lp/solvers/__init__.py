"""Average-cost MDP solvers, each returning a certified :class:`Solution`.

``solve(mdp, method)`` dispatches to

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
  scenario (:mod:`wncs_lp.solvers.matrix_free`; the answer is returned on the MDP). For systems
  too large to build, call :func:`solve_scenario` (``method="matrix-free"``) or
  :func:`wncs_lp.solvers.matrix_free.matrix_free_value_iteration` on the scenario.

Every solution carries the bracket ``gain_lower <= g* <= gain_upper`` from one Bellman
step on its bias (:func:`bracket`).
"""
from __future__ import annotations

from typing import Any

from ..errors import SolverError
from ..mdp import MDP
from .certify import bellman_step, bracket, certificate_closed, greedy_first, q_values
from .auto import solve_auto
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
    "MATRIX_FREE",
    "solve_scenario",
]

#: The method names accepted by :func:`solve` (and :data:`MATRIX_FREE`, which needs an MDP built
#: from a scenario, so it is not in this tuple of methods for any MDP).
METHODS = ("lp", "lp-highs", "lp-cvxpy", "rvi", "vi", "pi", "auto")
#: The matrix-free method (:mod:`wncs_lp.solvers.matrix_free`).
MATRIX_FREE = "matrix-free"


def solve(mdp: MDP, method: str = "auto", **kw: Any) -> Solution:
    """Solve an average-cost MDP with the named method.

    Parameters
    ----------
    mdp : MDP
    method : {"lp", "lp-highs", "lp-cvxpy", "rvi", "vi", "pi", "auto", "matrix-free"}
    **kw
        Passed to :func:`solve_lp` (``backend`` is set by the method name),
        :func:`relative_value_iteration`, :func:`value_iteration`, :func:`policy_iteration`
        or :func:`solve_auto`.

    Raises
    ------
    SolverError
        Unknown method (the message lists the allowed ones), or a solver failure.
    """
    if method == "lp":
        return solve_lp(mdp, backend="clarabel", **kw)
    if method == "lp-highs":
        return solve_lp(mdp, backend="highs", **kw)
    if method == "lp-cvxpy":
        return solve_lp(mdp, backend="cvxpy", **kw)
    if method == "rvi":
        return relative_value_iteration(mdp, **kw)
    if method == "vi":
        return value_iteration(mdp, **kw)
    if method == "pi":
        return policy_iteration(mdp, **kw)
    if method == "auto":
        return solve_auto(mdp, **kw)
    if method == MATRIX_FREE:
        from .matrix_free import solve_mdp

        return solve_mdp(mdp, **kw)
    raise SolverError(f"unknown solver method {method!r}; expected one of "
                      f"{', '.join(map(repr, METHODS + (MATRIX_FREE,)))}")


def solve_scenario(scenario: Any, method: str = MATRIX_FREE, **kw: Any) -> Solution:
    """Solve a scenario: ``"matrix-free"`` without building the MDP (a
    :class:`~wncs_lp.solvers.matrix_free.MatrixFreeSolution`); any other method builds the MDP
    after the size guard (``force=True`` skips it) and calls :func:`solve`."""
    from .matrix_free import solve_scenario as _solve_scenario

    return _solve_scenario(scenario, method, **kw)
