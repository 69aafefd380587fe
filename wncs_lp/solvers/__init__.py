"""Average-cost MDP solvers, each returning a certified :class:`Solution`.

The one public entry point is :func:`wncs_lp.solve`; on an MDP its average-cost step is
:func:`~wncs_lp.solvers.registry.run_average`. Every method is a row of the one vocabulary,
:data:`wncs_lp.methods.TABLE`, run by the function registered for it in
:data:`wncs_lp.solvers.registry.AVERAGE`:

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

From a scenario, :func:`wncs_lp.workflow.route.run_scenario` (the workflow floor, above the
solvers and the constrained solvers) is the one route: size guard, build
(:func:`build_scenario`), solve, and ``auto``'s switch to the matrix-free solver when the stored
matrix would not fit.

The discounted criterion (a discount factor beta, certified by MacQueen's bounds:
``wncs_lp.solve(mdp, discount=beta)``) is solved by
:func:`~wncs_lp.solvers.discounted.run_discounted` (:mod:`wncs_lp.solvers.discounted`).

``solve``, ``solve_discounted`` and ``solve_scenario`` are still found here for one release, with
a :class:`DeprecationWarning` naming the call that replaces them (:mod:`wncs_lp.moved`).

Every solution carries the bracket ``gain_lower <= g* <= gain_upper`` from one Bellman
step on its bias (:func:`bracket`).
"""
from __future__ import annotations

from .. import moved
from ..methods import METHODS
from .certify import bellman_step, bracket, certificate_closed, greedy_first, q_values
from .auto import solve_auto
from .discounted import DiscountedSolution, discounted_value, laurent_terms
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
from .registry import AVERAGE
from .route import ScenarioSolve, WarmStart, build_scenario

__all__ = [
    "METHODS",
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
    "discounted_value",
    "laurent_terms",
]


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
