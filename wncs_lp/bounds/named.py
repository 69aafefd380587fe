"""The policies the bounds room makes by name (:data:`~wncs_lp.policies.factory.BOUND_POLICY_NAMES`):
``relaxation``, the greedy policy of the best certified bound (:func:`~wncs_lp.bounds.lower_bound`
with ``"auto"``, then :func:`~wncs_lp.bounds.bound_policy`); ``lookahead``, the two-step lookahead
on the same tables, ``lookahead3`` one step deeper (the 2 best actions at the intermediate state),
``rollout`` the greedy policy simulated a few slots ahead of each candidate action
(:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`); ``index``, the Whittle-type index policy of relaxation 1's priced chains;
``tuned``, ``tuned_lookahead``, ``tuned_rollout``, those three on the tables reweighted per class of
processes by simulation (:mod:`~wncs_lp.bounds.tuned`).

The policy factory (:func:`wncs_lp.workflow.make_policy`, on the floor above) and the gap
reports (:func:`~wncs_lp.bounds.gaps.policy_by_name`) take them from here.
"""
from __future__ import annotations

from ..models.system import System
from ..policies import Policy
from .index import index_policy
from .lookahead import LookaheadPolicy, TableRolloutPolicy, auto_candidates
from .lower import lower_bound
from .policy import bound_policy
from .tuned import TUNED_NAMES, tune_tables, tuned_policy

__all__ = ["named_policy"]


def named_policy(name: str, system: System) -> Policy:
    """The policy ``name`` of :data:`~wncs_lp.policies.factory.BOUND_POLICY_NAMES` on ``system``
    (no enumerated MDP: any number of processes)."""
    if name == "index":
        return index_policy(system)
    bound = lower_bound(system, "auto")
    if name in TUNED_NAMES:  # tuned on the default tuning seed (bounds.tuned.TUNE_SEED_OFFSET)
        return tuned_policy(tune_tables(bound, system, TUNED_NAMES[name]), system)
    greedy = bound_policy(bound, system)
    if name == "rollout":
        return TableRolloutPolicy(greedy)
    if name in ("lookahead", "lookahead3"):
        return LookaheadPolicy(greedy, auto_candidates(system), depth=2 if name == "lookahead" else 3, middle=2)
    return greedy
