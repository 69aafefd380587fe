"""The workflow floor: the jobs that join the rooms below it, each importing what it calls.

It stands above the solvers, the constrained solvers, the bounds and the policies, and below the
studies, the reproduction and the command line:

* :func:`solve` (:mod:`~wncs_lp.workflow.route`) -- ``wncs_lp.solve``, the one public solve: an
  MDP or a scenario, ``method=``, ``criterion=`` (average, constrained, discounted);
* :func:`run_scenario` -- its route from a scenario to a solution: size guard, build, solve (the
  step of the criterion: :func:`~wncs_lp.solvers.registry.run_average`,
  :func:`~wncs_lp.constrained.registry.run_constrained`,
  :func:`~wncs_lp.solvers.discounted.run_discounted`), and ``auto``'s fallback to the
  matrix-free solver when the stored matrix would not fit; it hands back what was built and
  why (:class:`ScenarioSolve`), which the command line and the studies read;
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

from .. import moved
from ..solvers.route import ScenarioSolve, WarmStart, as_scenario, build_scenario
from .policies import make_policy, policy_for
from .route import run_scenario, solve

__all__ = ["solve", "run_scenario", "make_policy", "policy_for", "ScenarioSolve", "WarmStart", "as_scenario",
           "build_scenario"]


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
