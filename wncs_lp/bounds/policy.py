r"""The policy of a bound: greedy on the relaxation's separable value function.

With the value tables :math:`h_k` of a relaxation (:class:`~wncs_lp.bounds.ValueTables`),

.. math:: \pi(\tau, C) = \arg\min_a \sum_o P(o \mid C, a) \sum_k h_k(\tau'_k, \mathrm{column}_k(C'_o)),

the paper's Section III rule (:class:`~wncs_lp.policies.suboptimal.SuboptimalPolicy`) with the
relaxation's tables instead of the random base policy's. For the private-servers relaxation
:math:`h_k` is process k's bias at the multipliers, read on k's projection of C; the price term
:math:`\sum_m \lambda_m \sum_k \text{claim}_m` of the relaxation is left out (it is the
constant :math:`\sum_m \lambda_m` whenever the claims sum to 1). Nothing of the size of the tau
box is formed: it works with :func:`wncs_lp.evaluate`, the matrix-free evaluation,
:func:`wncs_lp.simulate` and the maps like any :class:`~wncs_lp.policies.Policy`.
"""
from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from ..errors import PolicyError
from ..models.system import System
from ..policies.base import Policy
from ..policies.suboptimal import SeparableGreedyPolicy
from .projected import ProjectedBoundPolicy, lookahead_table, projected_tables
from .result import BoundResult, GroupTables

__all__ = ["BoundPolicy", "GroupBoundPolicy", "bound_policy", "group_lookahead"]

#: Lookahead entries (states x A_max x O_max) per block of :meth:`GroupBoundPolicy.act` for groups
#: without a precomputed table: a few arrays of this many numbers at a time.
ACT_BLOCK_ENTRIES = 2_000_000
#: Largest precomputed lookahead table of one group (valid pairs x the group's AoI vectors, 8 bytes
#: each: 39 MB for a pair of processes at cap 20 among 8 processes); a larger group computes its
#: lookahead per state.
TABLE_MAX_BYTES = 256 * 2**20


class BoundPolicy(SeparableGreedyPolicy):
    """The greedy policy on the value tables of a :class:`BoundResult`.

    Parameters
    ----------
    result : BoundResult
    system : System
        The system the bound was computed on (its configurations are the ones
        ``result.tables.column`` indexes).

    Attributes
    ----------
    result : BoundResult
    build_seconds : float
    """

    name = "bound"

    def __init__(self, result: BoundResult, system: System):
        t0 = time.perf_counter()
        cols = result.tables.column
        if len(cols) != system.n_processes or any(np.shape(c) != (system.n_configs,) for c in cols):
            raise PolicyError(f"the {result.relaxation} bound's tables belong to another system "
                              f"({len(cols)} processes, column maps of shape "
                              f"{sorted({np.shape(c) for c in cols})}; this system has {system.n_processes} "
                              f"processes and {system.n_configs} configurations)")
        super().__init__(system, result.tables.h, cols)
        self.result = result
        self.name = f"bound[{result.relaxation}]"
        self.build_seconds = time.perf_counter() - t0

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "relaxation": self.result.relaxation,
                "lower_bound": self.result.lower_bound, "build_seconds": self.build_seconds}


class GroupBoundPolicy(Policy):
    r"""The greedy policy on the group tables of a grouped bound (:class:`GroupTables`):

    .. math:: \pi(\tau, C) = \arg\min_a \sum_o P(o \mid C, a) \sum_G h_G(\tau'_G, \mathrm{column}_G(C'_o)),

    ties to the first action. A group's table is not separable over its processes, so its
    expectation is precomputed per group over the valid pairs and the group's AoI vectors,
    W_G[(C, a), tau_G] (:func:`group_lookahead`, up to :data:`TABLE_MAX_BYTES`; the value of an
    action is then sum_G W_G[(C, a), tau_G]); a larger group computes its lookahead per state
    (R x A_max x O_max lookups, in blocks of :data:`ACT_BLOCK_ENTRIES` entries).

    Parameters
    ----------
    result : BoundResult
        With ``tables`` a :class:`GroupTables`.
    system : System
    """

    name = "bound"

    def __init__(self, result: BoundResult, system: System):
        super().__init__(system)
        t0 = time.perf_counter()
        tables = result.tables
        if not isinstance(tables, GroupTables):
            raise PolicyError(f"the {result.relaxation} bound has no group tables; use bound_policy")
        if tables.n_processes != system.n_processes or any(np.shape(c) != (system.n_configs,) for c in tables.column):
            raise PolicyError(f"the {result.relaxation} bound's tables belong to another system ({tables.n_processes} "
                              f"processes; this system has {system.n_processes} processes and "
                              f"{system.n_configs} configurations)")
        self.result = result
        self.tables = tables
        self.name = f"bound[{result.relaxation}]"
        valid = system.action_valid
        #: (C, a) -> its row in the W tables (-1: not a feasible action)
        self.pair_row = np.full(valid.shape, -1, dtype=np.int64)
        self.pair_row[valid] = np.arange(int(valid.sum()))
        self.lookahead = tuple(group_lookahead(system, g, h, col, TABLE_MAX_BYTES)
                               for g, h, col in zip(tables.groups, tables.h, tables.column))
        self.build_seconds = time.perf_counter() - t0

    def values(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A_max) lookahead values (+inf on infeasible actions)."""
        tau, c = self._check_inputs(tau, config_ids)
        s = self.system
        rows, valid = s.pairs.padded(c, s.max_actions)  # (C, a) -> its row in the W tables: the pair
        out = np.zeros(rows.shape)
        lazy = []
        for g, W, i in zip(self.tables.groups, self.lookahead, range(len(self.lookahead))):
            if W is None:
                lazy.append(i)
                continue
            t = np.ravel_multi_index(tuple(tau[:, k] - 1 for k in g), tuple(int(s.caps[k]) for k in g))
            out += W[rows, t[:, None]]
        if lazy:
            pt = s.pairs
            nxt, prob = pt.nxt[rows], pt.prob[rows]
            v = np.zeros(prob.shape)
            for i in lazy:
                g, h, col = self.tables.groups[i], self.tables.h[i], self.tables.column[i]
                v += h[(col[nxt],) + tuple(self._next_tau(tau, rows, k) - 1 for k in g)]
            out += np.where(prob > 0, prob * v, 0.0).sum(axis=-1)
        out[~valid] = np.inf
        return out

    def _next_tau(self, tau: np.ndarray, rows: np.ndarray, k: int) -> np.ndarray:
        """(R, A_max, O_max) AoI of process k after each outcome of the pairs ``rows``:
        min(tau_k + 1, delta_k if > 0, tau_hat_k)."""
        pt = self.system.pairs
        dk = pt.deltas[pt.delta[rows], k]
        t = np.minimum(tau[:, k] + 1, int(self.system.caps[k]))[:, None, None]
        return np.where(dk > 0, np.minimum(t, dk), t)

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        out = np.empty(c.size, dtype=np.int64)
        block = max(1, ACT_BLOCK_ENTRIES // (self.system.max_actions * self.system.pairs.n_outcomes))
        for i in range(0, c.size, block):
            out[i:i + block] = np.argmin(self.values(tau[i:i + block], c[i:i + block]), axis=1)
        return out

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "relaxation": self.result.relaxation, "lower_bound": self.result.lower_bound,
                "groups": [list(g) for g in self.tables.groups], "build_seconds": self.build_seconds}


def group_lookahead(system: System, group: tuple, h: np.ndarray, column: np.ndarray,
                    max_bytes: int | None = TABLE_MAX_BYTES) -> np.ndarray | None:
    """W[p, t] = sum_o P(o | pair p) h(column(C'_o), tau'_G) for every feasible pair p (of
    :attr:`System.pairs`) and every AoI vector of the group
    (t the flat index of tau_G - 1), tau'_k = min(tau_k + 1, delta_k if > 0, tau_hat_k); None when it
    would exceed ``max_bytes`` (default :data:`TABLE_MAX_BYTES`; None: no limit)."""
    n_t = math.prod(int(system.caps[k]) for k in group)
    if max_bytes is not None and system.pairs.n_pairs * n_t * 8 > max_bytes:
        return None
    return lookahead_table(system, group, h, column)


def bound_policy(result: BoundResult, system: System) -> Policy:
    """The greedy policy of a bound on its system: for relaxations 1 and 3 (tables over private
    configurations) :class:`~wncs_lp.bounds.projected.ProjectedBoundPolicy`, the same lookahead
    read through the projections in memory linear in N; else :class:`BoundPolicy` on per-process
    tables, :class:`GroupBoundPolicy` on group tables."""
    if projected_tables(result) is not None:
        return ProjectedBoundPolicy(result, system)
    if isinstance(result.tables, GroupTables):
        return GroupBoundPolicy(result, system)
    return BoundPolicy(result, system)
