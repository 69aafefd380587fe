"""Greedy policies on separable value functions: the paper's Section III suboptimal policy, and
the mechanism it shares with the policies of the lower bounds (:mod:`wncs_lp.bounds`)."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import PolicyError
from ..mdp import MDP
from ..models.system import System
from ..solvers.dp import evaluate_policy
from .base import Policy
from .rules import RandomPolicy, TauIndependentPolicy

__all__ = ["ProcessPoisson", "SeparableGreedyPolicy", "SuboptimalPolicy", "separable_table"]

#: Elements of the (configurations, actions, outcomes, tau) block one step of a table builds.
TABLE_BLOCK = 1 << 22


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
    """W_k[C, a, tau_k] = sum_o P(o | C, a) h_k(tau'_k, column_k(C'_o)), tau'_k the AoI after
    outcome o (:meth:`System.next_tau`); +inf on infeasible actions.

    Parameters
    ----------
    system : System
    k : int
        The process (0-based).
    h : (n_cols, tau_hat_k) array
        Process k's value table.
    column : (|C|,) int array, optional
        The column of ``h`` each configuration reads (default: the identity, n_cols = |C|).

    Only the outcomes of positive probability are visited, in blocks of at most
    :data:`TABLE_BLOCK` (outcome, tau) entries, so the memory is the table itself,
    |C| * A_max * tau_hat_k floats.
    """
    ot = system.outcome_tables
    K = int(system.caps[k])
    nC, A, O = ot.nxt.shape
    col = np.arange(nC) if column is None else np.asarray(column, dtype=np.int64)
    t_next0 = np.minimum(np.arange(1, K + 1) + 1, K)
    real = np.flatnonzero(ot.prob.reshape(-1) > 0)  # sorted: (C, a) rows stay contiguous
    W = np.zeros((nC * A, K))
    step = max(1, TABLE_BLOCK // K)
    for i0 in range(0, real.size, step):
        idx = real[i0:i0 + step]
        dk = ot.delta.reshape(-1, ot.delta.shape[-1])[idx, k][:, None]
        t_next = np.where(dk > 0, np.minimum(t_next0, dk), t_next0)
        vals = h[col[ot.nxt.reshape(-1)[idx]][:, None], t_next - 1] * ot.prob.reshape(-1)[idx][:, None]
        rows = idx // O
        starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
        W[rows[starts]] += np.add.reduceat(vals, starts, axis=0)
    W = W.reshape(nC, A, K)
    W[~system.action_valid] = np.inf
    return W


class SeparableGreedyPolicy(Policy):
    """The one-step greedy policy on a separable value function h(tau, C) ~ sum_k h_k(tau_k, column_k(C)):

    .. math::

        \\pi(\\tau, C) = \\arg\\min_a \\sum_{C', \\delta} P(C', \\delta \\mid C, a)
            \\sum_k h_k(\\tau'_k, \\mathrm{column}_k(C')), \\qquad
        \\tau'_k = \\min(\\tau_k + 1, \\delta_k \\text{ if } \\delta_k > 0, \\hat\\tau_k),

    ties to the first action of the configuration (exact comparison). The expectation is
    separable, so it is precomputed as tables W_k[C, a, tau_k] (:func:`separable_table`) and the
    value of action a in state (tau, C) is ``sum_k W_k[C, a, tau_k]``: nothing proportional to
    the tau box is ever formed.

    Parameters
    ----------
    system : System
    h : sequence of arrays
        ``h[k]``, shape (n_cols_k, tau_hat_k): process k's value table.
    column : sequence of int arrays, optional
        ``column[k]``, shape (|C|,): the column of ``h[k]`` each configuration reads (default:
        the identity). Anything with attributes ``h`` and ``column`` (a
        :class:`wncs_lp.bounds.ValueTables`) may be passed as ``h`` alone.

    Attributes
    ----------
    tables : tuple of arrays
        W_k, shape (|C|, A_max, tau_hat_k); +inf on infeasible actions.
    """

    name = "separable-greedy"

    def __init__(self, system: System, h, column=None):
        super().__init__(system)
        if hasattr(h, "h") and hasattr(h, "column") and column is None:
            h, column = h.h, h.column
        N = system.n_processes
        cols = [None] * N if column is None else list(column)
        if len(h) != N or len(cols) != N:
            raise PolicyError(f"expected one value table and one column map per process ({N}), "
                              f"found {len(h)} and {len(cols)}")
        for k in range(N):
            self._check_table(k, np.asarray(h[k]), cols[k])
        self.tables = tuple(separable_table(system, k, np.asarray(h[k], float), cols[k]) for k in range(N))

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
        """(R, A_max) greedy values sum_k W_k[C, a, tau_k] (+inf on infeasible actions)."""
        tau, c = self._check_inputs(tau, config_ids)
        v = self.tables[0][c, :, tau[:, 0] - 1].copy()
        for k in range(1, self.system.n_processes):
            v += self.tables[k][c, :, tau[:, k] - 1]
        return v

    def act(self, tau, config_ids, rng=None):
        return np.argmin(self.values(tau, config_ids), axis=1).astype(np.int64)


def _solve_process(system: System, k: int, w: np.ndarray) -> ProcessPoisson:
    """The Poisson equation of (tau_k, C) under action-outcome weights w[C, a, o]."""
    ot = system.outcome_tables
    K = int(system.caps[k])
    nC = system.n_configs
    c_idx, j_idx, o_idx = np.nonzero(w > 0)
    wt = w[c_idx, j_idx, o_idx]
    nxt = ot.nxt[c_idx, j_idx, o_idx]
    dk = ot.delta[c_idx, j_idx, o_idx, k]
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
    tables : tuple of arrays
        W_k, shape (|C|, A_max, tau_hat_k); +inf on infeasible actions.
    build_seconds : float
    """

    name = "suboptimal"

    def __init__(self, system: System, base: TauIndependentPolicy | None = None):
        t0 = time.perf_counter()
        base = base if base is not None else RandomPolicy(system)
        if base.system is not system:
            raise PolicyError("the base policy belongs to another system")
        w = base.probs[:, :, None] * system.outcome_tables.prob  # (C, A, O) probability of (action, outcome)
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
