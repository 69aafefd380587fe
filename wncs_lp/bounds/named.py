"""The policies the bounds room makes by name (:data:`~wncs_lp.policies.factory.BOUND_POLICY_NAMES`):
``relaxation``, the greedy policy of the best certified bound (:func:`~wncs_lp.bounds.lower_bound`
with ``"auto"``, then :func:`~wncs_lp.bounds.bound_policy`); ``lookahead``, the two-step lookahead
on the same tables, ``lookahead3`` one step deeper (the 2 best actions at the intermediate state),
``rollout`` the greedy policy simulated a few slots ahead of each candidate action
(:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`); ``index``, the Whittle-type index policy of relaxation 1's priced chains.

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

__all__ = ["named_policy"]


def named_policy(name: str, system: System) -> Policy:
    """The policy ``name`` of :data:`~wncs_lp.policies.factory.BOUND_POLICY_NAMES` on ``system``
    (no enumerated MDP: any number of processes)."""
    if name == "index":
        return index_policy(system)
    greedy = bound_policy(lower_bound(system, "auto"), system)
    if name == "rollout":
        return TableRolloutPolicy(greedy)
    if name in ("lookahead", "lookahead3"):
        return LookaheadPolicy(greedy, auto_candidates(system), depth=2 if name == "lookahead" else 3, middle=2)
    return greedy
