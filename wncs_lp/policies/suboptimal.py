"""Greedy policies on separable value functions: the paper's Section III suboptimal policy, and
the mechanism it shares with the policies of the lower bounds (:mod:`wncs_lp.bounds`)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import PolicyError
from ..mdp import MDP
from ..models.guard import memory_budget, require_memory
from ..models.system import System
from ..solvers.dp import evaluate_policy
from .base import Policy
from .rules import RandomPolicy, TauIndependentPolicy

__all__ = ["ProcessPoisson", "SeparableGreedyPolicy", "SuboptimalPolicy", "separable_table", "table_bytes",
           "pair_values", "chain_bytes"]

#: Elements of the (configurations, actions, outcomes, tau) block one step of a table builds.
TABLE_BLOCK = 1 << 22
#: Entries (states x actions x outcomes x processes) of one block of the per-state lookahead.
STATE_BLOCK = 1 << 22


@dataclass(frozen=True, eq=False)
class ProcessPoisson:
    """The Poisson equation of one process's chain (tau_k, C) under a tau-independent policy.

    g_k + h_k(tau, C) = q_k(tau) + sum_{C', delta} P(C', delta | C) h_k(min(tau + 1, delta, cap), C')

    Attributes
    ----------
    gain : float
        g_k, the long-run average of q_k(tau_k).
    h : (|C|, tau_hat_k) array
        h_k[c, tau - 1], normalised so that h_k at (tau = 1, C = 0) is 0.
    residual : float
        Residual of the sparse solve.
    size : int
        tau_hat_k * |C|, the number of unknowns.
    """

    gain: float
    h: np.ndarray
    residual: float
    size: int


def separable_table(system: System, k: int, h: np.ndarray, column: np.ndarray | None = None) -> np.ndarray:
    """W_k[p, tau_k] = sum_o P(o | p) h_k(tau'_k, column_k(C'_o)) for every feasible pair p of
    :attr:`System.pairs` (local action j of configuration c is pair ``pairs.first[c] + j``),
    tau'_k the AoI after outcome o (:meth:`System.next_tau`).

    Parameters
    ----------
    system : System
    k : int
        The process (0-based).
    h : (n_cols, tau_hat_k) array
        Process k's value table.
    column : (|C|,) int array, optional
        The column of ``h`` each configuration reads (default: the identity, n_cols = |C|).

    Returns
    -------
    (P, tau_hat_k) float array
        One row per feasible pair (no padding to the largest action set: :func:`table_bytes`).

    Only the outcomes of positive probability are visited, in blocks of at most
    :data:`TABLE_BLOCK` (outcome, tau) entries, so the memory is the table itself.
    """
    pt = system.pairs
    K = int(system.caps[k])
    P, O = pt.prob.shape
    col = np.arange(system.n_configs) if column is None else np.asarray(column, dtype=np.int64)
    t_next0 = np.minimum(np.arange(1, K + 1) + 1, K)
    real = np.flatnonzero(pt.prob.reshape(-1) > 0)  # sorted: a pair's outcomes stay contiguous
    dk_all = pt.deltas[:, k]
    W = np.zeros((P, K))
    step = max(1, TABLE_BLOCK // K)
    for i0 in range(0, real.size, step):
        idx = real[i0:i0 + step]
        dk = dk_all[pt.delta.reshape(-1)[idx]][:, None]
        t_next = np.where(dk > 0, np.minimum(t_next0, dk), t_next0)
        vals = h[col[pt.nxt.reshape(-1)[idx]][:, None], t_next - 1] * pt.prob.reshape(-1)[idx][:, None]
        rows = idx // O
        starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
        W[rows[starts]] += np.add.reduceat(vals, starts, axis=0)
    return W


def table_bytes(system: System, processes: Sequence[int] | None = None) -> int:
    """Bytes of the tables :func:`separable_table` builds for ``processes`` (default all):
    8 P tau_hat_k each, P the feasible pairs (no padding). Python integers: no overflow."""
    ks = range(system.n_processes) if processes is None else processes
    return 8 * int(system.pairs.n_pairs) * sum(int(system.caps[k]) for k in ks)


def pair_values(system: System, tables: Sequence[np.ndarray], tau: np.ndarray, c: np.ndarray,
                members: Sequence[Sequence[int]] | None = None) -> np.ndarray:
    """(R, A_max) sum_i tables[i][p, tau_{G_i}] over the pairs p of each state's configuration
    (+inf on actions a configuration lacks); ``members[i]`` the processes table i is indexed by
    (default: table k by process k alone, flat AoI index of the group otherwise)."""
    pt = system.pairs
    p, valid = pt.padded(c, system.max_actions)
    v = np.zeros(p.shape)
    for i, W in enumerate(tables):
        g = (i,) if members is None else tuple(members[i])
        if len(g) == 1:
            t = tau[:, g[0]] - 1
        else:
            t = np.ravel_multi_index(tuple(tau[:, k] - 1 for k in g), tuple(int(system.caps[k]) for k in g))
        v += W[p, t[:, None]]
    v[~valid] = np.inf
    return v


class SeparableGreedyPolicy(Policy):
    """The one-step greedy policy on a separable value function h(tau, C) ~ sum_k h_k(tau_k, column_k(C)):

    .. math::

        \\pi(\\tau, C) = \\arg\\min_a \\sum_{C', \\delta} P(C', \\delta \\mid C, a)
            \\sum_k h_k(\\tau'_k, \\mathrm{column}_k(C')), \\qquad
        \\tau'_k = \\min(\\tau_k + 1, \\delta_k \\text{ if } \\delta_k > 0, \\hat\\tau_k),

    ties to the first action of the configuration (exact comparison). The expectation is
    separable, so it is precomputed as tables W_k[p, tau_k] over the feasible pairs p
    (:func:`separable_table`) and the value of action a in state (tau, C) is
    ``sum_k W_k[p(C, a), tau_k]``: nothing proportional to the tau box is ever formed.

    The tables take 8 P sum_k tau_hat_k bytes (:func:`table_bytes`; P the feasible pairs: 700
    MB for the paper's four processes four times at cap 40). When that exceeds the memory budget
    (:func:`wncs_lp.models.guard.memory_budget`) the policy computes the same expectation state
    by state instead (``lookahead == "per-state"``: R x A_max x O_max x N lookups a call, in
    blocks of :data:`STATE_BLOCK` entries; slower, nothing stored).

    Parameters
    ----------
    system : System
    h : sequence of arrays
        ``h[k]``, shape (n_cols_k, tau_hat_k): process k's value table.
    column : sequence of int arrays, optional
        ``column[k]``, shape (|C|,): the column of ``h[k]`` each configuration reads (default:
        the identity). Anything with attributes ``h`` and ``column`` (a
        :class:`wncs_lp.bounds.ValueTables`) may be passed as ``h`` alone.
    lookahead : {"auto", "tables", "per-state"}
        ``"auto"``: the tables when they fit the budget, else per state; ``"tables"`` refuses
        (:class:`~wncs_lp.errors.SizeLimitError`) when they do not fit.

    Attributes
    ----------
    tables : tuple of arrays or None
        W_k, shape (P, tau_hat_k) (None per state).
    lookahead : str
        ``"tables"`` or ``"per-state"``.
    """

    name = "separable-greedy"

    def __init__(self, system: System, h, column=None, *, lookahead: str = "auto"):
        super().__init__(system)
        if hasattr(h, "h") and hasattr(h, "column") and column is None:
            h, column = h.h, h.column
        N = system.n_processes
        cols = [None] * N if column is None else list(column)
        if len(h) != N or len(cols) != N:
            raise PolicyError(f"expected one value table and one column map per process ({N}), "
                              f"found {len(h)} and {len(cols)}")
        if lookahead not in ("auto", "tables", "per-state"):
            raise PolicyError(f"lookahead must be 'auto', 'tables' or 'per-state', got {lookahead!r}")
        for k in range(N):
            self._check_table(k, np.asarray(h[k]), cols[k])
        self._h = tuple(np.asarray(hk, float) for hk in h)
        self._cols = tuple(np.arange(system.n_configs) if c is None else np.asarray(c, np.int64) for c in cols)
        need = table_bytes(system)
        if lookahead == "tables":
            require_memory(need, f"the greedy policy's lookahead tables ({N} processes x {system.pairs.n_pairs:,} "
                           "feasible pairs x tau_hat)", ["lookahead='per-state' (nothing stored, slower)"])
        elif lookahead == "auto":
            lookahead = "tables" if need <= memory_budget() else "per-state"
        self.lookahead = lookahead
        self.tables = (tuple(separable_table(system, k, self._h[k], self._cols[k]) for k in range(N))
                       if lookahead == "tables" else None)

    def _check_table(self, k: int, h: np.ndarray, col) -> None:
        n_cols = self.system.n_configs if col is None else int(np.max(col)) + 1
        if col is not None and np.shape(col) != (self.system.n_configs,):
            raise PolicyError(f"process {k + 1}: the column map has shape {np.shape(col)}, expected "
                              f"({self.system.n_configs},) (one entry per configuration of the system)")
        if h.ndim != 2 or h.shape[1] != int(self.system.caps[k]) or h.shape[0] < n_cols:
            raise PolicyError(f"process {k + 1}: value table of shape {h.shape}, expected "
                              f"(>= {n_cols}, {int(self.system.caps[k])}) (columns, tau_hat)")
        if not np.all(np.isfinite(h)):
            raise PolicyError(f"process {k + 1}: the value table has non-finite entries")

    def values(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A_max) greedy values sum_k W_k[p(C, a), tau_k] (+inf on infeasible actions)."""
        tau, c = self._check_inputs(tau, config_ids)
        if self.tables is not None:
            return pair_values(self.system, self.tables, tau, c)
        s = self.system
        pt = s.pairs
        out = np.empty((c.size, s.max_actions))
        block = max(1, STATE_BLOCK // (s.max_actions * pt.n_outcomes * s.n_processes))
        for i in range(0, c.size, block):
            p, valid = pt.padded(c[i:i + block], s.max_actions)
            prob, nxt, did = pt.prob[p], pt.nxt[p], pt.delta[p]  # (R, A, O)
            v = np.zeros(prob.shape)
            for k in range(s.n_processes):
                dk = pt.deltas[did, k]
                t = np.minimum(tau[i:i + block, k] + 1, int(s.caps[k]))[:, None, None]
                v += self._h[k][self._cols[k][nxt], np.where(dk > 0, np.minimum(t, dk), t) - 1]
            w = (prob * v).sum(axis=-1)
            w[~valid] = np.inf
            out[i:i + block] = w
        return out

    def act(self, tau, config_ids, rng=None):
        return np.argmin(self.values(tau, config_ids), axis=1).astype(np.int64)

    def describe(self):
        return {**super().describe(), "lookahead": self.lookahead}


#: Bytes a transition of a process chain (tau_k, C) costs at the peak of its Poisson solve: its
#: triplets, the CSR matrix, the chain's copy, I - P with a column replaced and the solver's copy
#: (measured: 16 sensors at cap 20, 21 million transitions a chain, ~1.2 GB above the system's own
#: 0.9 GB with the tables; BiCGSTAB answered, no LU).
CHAIN_BYTES_PER_NNZ = 64


def chain_bytes(system: System) -> int:
    """Peak bytes of :class:`SuboptimalPolicy`'s construction: the largest process chain's Poisson
    solve (one at a time; :data:`CHAIN_BYTES_PER_NNZ` a transition, |C| tau_hat_k rows of
    (pairs x outcomes) transitions) plus the greedy tables kept (:func:`table_bytes`)."""
    nnz = int(np.count_nonzero(system.pairs.prob)) * int(system.caps.max())
    return CHAIN_BYTES_PER_NNZ * nnz + table_bytes(system)


def _solve_process(system: System, k: int, w: np.ndarray) -> ProcessPoisson:
    """The Poisson equation of (tau_k, C) under pair-outcome weights w[p, o] (pairs of :attr:`System.pairs`)."""
    pt = system.pairs
    K = int(system.caps[k])
    nC = system.n_configs
    p_idx, o_idx = np.nonzero(w > 0)
    c_idx = pt.config_of[p_idx]
    wt = w[p_idx, o_idx]
    nxt = pt.nxt[p_idx, o_idx]
    dk = pt.deltas[pt.delta[p_idx, o_idx], k]
    t = np.arange(1, K + 1)
    t_next = np.minimum(t[None, :] + 1, K)
    t_next = np.where(dk[:, None] > 0, np.minimum(t_next, dk[:, None]), t_next)
    rows = (c_idx[:, None] * K + (t[None, :] - 1)).ravel()
    cols = (nxt[:, None] * K + (t_next - 1)).ravel()
    vals = np.repeat(wt, K)
    n = nC * K
    P = sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
    P.sum_duplicates()
    cost = np.tile(system.q[k], nC)
    chain = MDP.from_arrays(np.arange(n), np.zeros(n, dtype=np.int64), cost, P, n, check=False,
                            name=f"process-{k + 1} chain")
    try:
        # g_k and h_k only: the stationary solve would cost as much again (LU fill-in at many configurations)
        ev = evaluate_policy(chain, np.arange(n, dtype=np.int64), stationary=False)
    except PolicyError as exc:
        raise PolicyError(f"process {k + 1}: the chain (tau_{k + 1}, C) under the base policy: {exc}") from None
    return ProcessPoisson(gain=float(ev.gain), h=ev.bias.reshape(nC, K), residual=float(ev.residual), size=n)


class SuboptimalPolicy(SeparableGreedyPolicy):
    """The separable suboptimal policy of paper Section III (one policy-improvement step).

    Under a base policy whose action distribution beta(a | C) depends on C only, every pair
    (tau_k, C) is a Markov chain with cost q_k(tau_k). Its Poisson equation (size
    tau_hat_k * |C|, solved sparse by :func:`wncs_lp.solvers.dp.evaluate_policy` on the
    single-action chain) gives g_k and h_k; by the paper's Lemma 2 the base policy's gain is
    sum_k g_k and its relative value sum_k h_k(tau_k, C). The policy is the greedy policy on
    sum_k h_k (:class:`SeparableGreedyPolicy`, column maps the identity).

    Parameters
    ----------
    system : System
    base : TauIndependentPolicy, optional
        Default :class:`RandomPolicy`.

    Attributes
    ----------
    poisson : tuple of ProcessPoisson
    base_gain : float
        sum_k g_k, the exact gain of the base policy (Lemma 2).
    tables : tuple of arrays or None
        W_k, shape (P, tau_hat_k) over the feasible pairs (None when computed per state).
    build_seconds : float

    Raises
    ------
    PolicyError
        A lazily explored system (the chains need every configuration).
    SizeLimitError
        The chains would not fit the memory budget (:func:`chain_bytes`).
    """

    name = "suboptimal"

    def __init__(self, system: System, base: TauIndependentPolicy | None = None):
        t0 = time.perf_counter()
        self.refuse_lazy(system)
        K, nnz = int(system.caps.max()), int(np.count_nonzero(system.pairs.prob))
        require_memory(chain_bytes(system), f"the suboptimal policy's Poisson chains (tau_k, C) over the "
                       f"{system.n_configs:,} joint configurations (up to {K * system.n_configs:,} unknowns and "
                       f"{K * nnz:,} transitions each)",
                       ["the bound's policy (wncs-lp bound --policy; its lookahead lives on private "
                        "configurations)", "a smaller cap (--set tau_cap=...)"])
        base = base if base is not None else RandomPolicy(system)
        if base.system is not system:
            raise PolicyError("the base policy belongs to another system")
        pt = system.pairs
        c_of = pt.config_of
        w = base.probs[c_of, np.arange(pt.n_pairs) - pt.first[c_of]][:, None] * pt.prob  # (P, O): action and outcome
        poisson = tuple(_solve_process(system, k, w) for k in range(system.n_processes))
        super().__init__(system, [p.h for p in poisson])
        self.base = base
        self.poisson = poisson
        self.base_gain = float(sum(p.gain for p in poisson))
        self.build_seconds = time.perf_counter() - t0

    @property
    def table_sizes(self) -> tuple[int, ...]:
        """tau_hat_k * |C| per process (unknowns of each Poisson equation)."""
        return tuple(p.size for p in self.poisson)

    def describe(self):
        return {
            **super().describe(),
            "base": self.base.name,
            "base_gain": self.base_gain,
            "process_gains": [p.gain for p in self.poisson],
            "table_sizes": list(self.table_sizes),
            "build_seconds": self.build_seconds,
        }
