"""Scheduling policies as first-class objects, usable with or without an enumerated MDP.

Every model of this toolkit has states s = (tau, C): the AoI vector tau in the box
1..tau_hat and a configuration C of a small automaton (:mod:`wncs_lp.models.automaton`). A
:class:`~wncs_lp.models.system.System` holds that automaton, the cost tables q_k and padded per-(C, action) outcome
tables, but never the tau box, so it exists for systems far too large to enumerate (all four
paper processes with caps of 30 or more).

A :class:`Policy` has one interface that serves both uses:

* ``policy.act(tau, config_ids, rng)`` -- vectorised over R replications: ``tau`` is an
  (R, N) integer array of AoI values (1-based), ``config_ids`` an (R,) array of automaton
  configuration ids; the result is the (R,) array of *local* action indices j, i.e. positions in
  ``system.automaton.actions[c]`` (the MDP's action order for that configuration);
* ``policy.on_mdp(mdp)`` -- the policy on an enumerated MDP built from the same scenario:
  an (n,) int array of chosen pair indices (deterministic policies) or an (L,) float array of
  pair probabilities (randomised ones), the two forms accepted by
  :func:`wncs_lp.solvers.dp.evaluate_policy`.

Policies (:func:`wncs_lp.workflow.make_policy` builds them by name):

``optimal``      :class:`OptimalPolicy`, the policy of a :class:`~wncs_lp.solvers.result.Solution`;
``suboptimal``   :class:`SuboptimalPolicy`, the separable one-step improvement of paper Section III;
``static``       :class:`StaticPolicy` with :func:`default_assignment`;
``best_static``  :func:`best_static`, the static assignment of least exact average cost;
``greedy``       :class:`GreedyPolicy`, the paper's greedy baseline;
``random``       :class:`RandomPolicy`, uniform over the feasible actions (tau-independent);
``max_age``      :class:`MaxAgePolicy`, max-age-first (the processes ranked by AoI);
``max_weight``   :class:`MaxWeightPolicy`, max-weighted-cost-first (ranked by the expected cost an
                 update removes);
``round_robin``  :class:`RoundRobinPolicy`, round robin (a :class:`MemoryPolicy`: its pointer);
``relaxation``   the greedy policy of the certified lower bound (:mod:`wncs_lp.bounds`), a
                 :class:`SeparableGreedyPolicy` on the relaxation's value tables;
``lookahead``    the two-step lookahead on the same tables (:class:`wncs_lp.bounds.LookaheadPolicy`);
``lookahead3``   the same, one step deeper (the 2 best actions at the intermediate state);
``rollout``      the greedy policy on the same tables simulated a few slots ahead of each candidate
                 action (:class:`wncs_lp.bounds.TableRolloutPolicy`; :class:`RolloutPolicy` for any
                 greedy policy with ``values``);
``index``        the Whittle-type index policy of relaxation 1's priced chains
                 (:class:`wncs_lp.bounds.IndexPolicy`).

Policies of one's own: :meth:`Policy.from_function` (a function of (tau, configuration) returning
an action label), :meth:`Policy.from_sigma` (an action per state of an enumerated MDP) and
:meth:`Policy.from_pairs` (pair indices); :func:`as_policy` makes a policy of any of these forms.
The two array forms and their converters (:func:`pairs_to_sigma`, :func:`sigma_to_pairs`) are
described in :mod:`wncs_lp.policy_forms`.

The exact rules are in ``docs/policies.md``.
"""
from __future__ import annotations

from .. import moved
from ..models.system import OutcomeTables, System
from ..policy_forms import pairs_to_sigma, policy_array, sigma_to_pairs
from .base import Configuration, FunctionPolicy, MemoryPolicy, Policy, TablePolicy, as_rng, system_of
from .baselines import MaxAgePolicy, MaxWeightPolicy, RoundRobinPolicy, max_weight_index
from .convert import as_policy
from .factory import POLICY_NAMES, PolicySetup, parse_assignment, parse_policy_names
from .matrix_free import MatrixFreePolicy
from .mixed import MixedPolicy
from .optimal import CappedPolicy, ClippedPolicy, OptimalPolicy
from .rules import (
    GreedyPolicy,
    RandomPolicy,
    RankRulePolicy,
    StaticPolicy,
    TauIndependentPolicy,
    default_assignment,
    static_assignments,
)
from .rollout import RolloutPolicy
from .search import best_static
from .suboptimal import ProcessPoisson, SeparableGreedyPolicy, SuboptimalPolicy

__all__ = [
    "POLICY_NAMES",
    "System",
    "OutcomeTables",
    "Policy",
    "as_rng",
    "as_policy",
    "system_of",
    "Configuration",
    "FunctionPolicy",
    "MemoryPolicy",
    "MaxAgePolicy",
    "MaxWeightPolicy",
    "RoundRobinPolicy",
    "max_weight_index",
    "TablePolicy",
    "pairs_to_sigma",
    "sigma_to_pairs",
    "policy_array",
    "OptimalPolicy",
    "CappedPolicy",
    "ClippedPolicy",
    "MixedPolicy",
    "RolloutPolicy",
    "MatrixFreePolicy",
    "TauIndependentPolicy",
    "RandomPolicy",
    "RankRulePolicy",
    "StaticPolicy",
    "GreedyPolicy",
    "SuboptimalPolicy",
    "SeparableGreedyPolicy",
    "ProcessPoisson",
    "default_assignment",
    "static_assignments",
    "best_static",
    "parse_policy_names",
    "parse_assignment",
    "PolicySetup",
]


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
