"""Certified lower bounds on the optimal gain g*, for any number of processes, and the policies
they give (relaxations of the joint MDP built on :class:`~wncs_lp.models.system.System`, never on
the enumerated MDP).

* :func:`lower_bound` -- the entry point: a :class:`BoundResult` from the relaxation asked for
  (``"private-servers"`` = 1, ``"joint-configuration"`` = 2, ``"grouped-private-servers"`` = 3,
  ``"joint-pairs"`` = 4, ``"joint-all-pairs"`` = 5, or ``"auto"``);
* :func:`~wncs_lp.bounds.private.private_bound` -- relaxation 1, private servers with averaged
  capacity (:mod:`wncs_lp.bounds.private`);
* :func:`~wncs_lp.bounds.grouped.grouped_bound` -- relaxation 3, relaxation 1 with groups of
  processes sharing their private servers (:mod:`wncs_lp.bounds.grouped`);
* relaxation 2, the joint configuration with separable value functions, lives in
  :mod:`wncs_lp.bounds.joint`: ``joint_bound(system, **options)`` (the command
  line passes ``tol`` and ``progress``; a :class:`~wncs_lp.errors.WncsError` it raises makes
  ``auto`` fall back to relaxation 1) and optionally ``joint_reach(system)``, ``None`` when the
  instance is within its reach, else the reason in words;
* relaxation 4 (``"joint-pairs"``), relaxation 2 with pairs of processes' ages kept jointly in
  its tables (tighter, never looser than relaxation 2): :func:`~wncs_lp.bounds.pairs.pairs_bound`
  (:mod:`wncs_lp.bounds.pairs`), greedy and lookahead policies on its :class:`GroupTables`;
* relaxation 5 (``"joint-all-pairs"``), every pair's ages kept jointly at once (the level-2 LP of
  :mod:`wncs_lp.bounds.level2`, solved whole, certified by a check of its size):
  :func:`~wncs_lp.bounds.all_pairs.all_pairs_bound` (:mod:`wncs_lp.bounds.all_pairs`), its tables a
  :class:`GroupTables` cover of every pair; small systems only (its size is checked first; ``"auto"``
  runs it where its LP is predicted to fit a CPU budget: :func:`~wncs_lp.bounds.lower.all_pairs_plan`);
* :func:`bound_policy` / :class:`BoundPolicy` / :class:`GroupBoundPolicy` -- the greedy policy on a
  bound's value tables; for relaxations 1 and 3 :class:`ProjectedBoundPolicy`, the same lookahead
  read through the projections on the private systems (:mod:`wncs_lp.bounds.projected`: memory
  linear in the number of processes);
* :class:`LookaheadPolicy` -- the two-step lookahead on a greedy policy's tables (greedy on T h);
* :class:`TableRolloutPolicy` -- the rollout of a bound's greedy policy (a few simulated slots ahead of
  each candidate action, the tables as terminal value and control variate), in a numba kernel;
* :func:`~wncs_lp.bounds.tuned.tune_tables` / :func:`~wncs_lp.bounds.tuned.tuned_policy` -- a bound's
  tables reweighted per class of processes by a seeded simulation of the policy built on them
  (:mod:`wncs_lp.bounds.tuned`; the names ``tuned``, ``tuned_lookahead``, ``tuned_rollout``);
* :func:`whittle_indices` / :class:`IndexPolicy` -- Whittle-type indices of relaxation 1's priced
  chains and the index policy;
* :func:`~wncs_lp.bounds.gaps.policy_gaps` -- policies evaluated against a bound: the certified
  optimality gap of each.

Every bound is certified by the Bellman brackets of the chains it solves (relaxation 5: by its
tables' and prices' residuals on every (C, a)), never by an LP solver's status; the result type of every relaxation is :class:`BoundResult`, whose value
tables (:class:`ValueTables`, or :class:`GroupTables` for relaxations 3, 4 and 5) drive the greedy policy
of the bound.
"""
from __future__ import annotations

from .gaps import GapReport, PolicyGap, policy_gaps
from .lower import AUTO_SEARCH, RELAXATIONS, lower_bound, parse_relaxation
from .grouped import grouped_bound
from .index import IndexPolicy, IndexTables, whittle_indices
from .lookahead import LookaheadPolicy, TableRolloutPolicy
from .policy import BoundPolicy, GroupBoundPolicy, bound_policy
from .private import private_bound
from .projected import ProjectedBoundPolicy
from .result import BoundResult, GroupTables, ValueTables
from .tuned import TunedTables, tune_tables, tuned_policy

__all__ = ["BoundResult", "ValueTables", "GroupTables", "BoundPolicy", "GroupBoundPolicy", "ProjectedBoundPolicy",
           "GapReport", "PolicyGap",
           "RELAXATIONS", "lower_bound", "bound_policy", "policy_gaps", "private_bound", "grouped_bound",
           "parse_relaxation", "AUTO_SEARCH", "LookaheadPolicy", "TableRolloutPolicy", "IndexPolicy", "IndexTables", "whittle_indices",
           "TunedTables", "tune_tables", "tuned_policy"]
