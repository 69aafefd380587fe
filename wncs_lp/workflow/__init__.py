"""The workflow floor: the jobs that join the rooms below it, each importing what it calls.

It stands above the solvers, the constrained solvers, the bounds and the policies, and below the
studies, the reproduction and the command line:

* :func:`solve_any` -- what :func:`wncs_lp.solve` runs: an MDP by :func:`wncs_lp.solvers.solve`,
  anything else by :func:`solve_scenario`;
* :func:`solve_scenario` (:mod:`~wncs_lp.workflow.route`) -- the one route from a scenario to a
  solution: size guard, build, solve (:func:`wncs_lp.solvers.solve` or
  :func:`wncs_lp.constrained.solve_constrained`), and ``auto``'s fallback to the matrix-free
  solver when the stored matrix would not fit;
* :func:`make_policy` (:mod:`~wncs_lp.workflow.policies`) -- the policy factory: a policy by name,
  the policies room's own (:func:`~wncs_lp.policies.factory.make_basic_policy`) or the bounds
  room's (:func:`~wncs_lp.bounds.named.named_policy`: ``relaxation``, ``lookahead``, ``index``);
* :func:`policy_for` -- a policy by name on a scenario: its system, its MDP when needed,
  ``optimal`` solved by the route, then :func:`make_policy`.

The method registry's vocabulary is :mod:`wncs_lp.methods`; the functions of its rows are
registered beside their dispatchers (:mod:`wncs_lp.solvers.registry`,
:mod:`wncs_lp.constrained.registry`), imported normally.
"""
from __future__ import annotations

from ..solvers.route import ScenarioSolve, WarmStart, as_scenario, build_scenario
from .policies import make_policy, policy_for
from .route import solve_any, solve_scenario

__all__ = ["solve_any", "solve_scenario", "make_policy", "policy_for", "ScenarioSolve", "WarmStart", "as_scenario", "build_scenario"]
