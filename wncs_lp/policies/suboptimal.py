"""The separable suboptimal policy of paper Section III (one policy-improvement step)."""
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

__all__ = ["ProcessPoisson", "SuboptimalPolicy"]


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


class SuboptimalPolicy(Policy):
    """The separable suboptimal policy of paper Section III (one policy-improvement step).

    Under a base policy whose action distribution beta(a | C) depends on C only, every pair
    (tau_k, C) is a Markov chain with cost q_k(tau_k). Its Poisson equation (size
    tau_hat_k * |C|, solved sparse by :func:`wncs_lp.solvers.dp.evaluate_policy` on the
    single-action chain) gives g_k and h_k; by the paper's Lemma 2 the base policy's gain is
    sum_k g_k and its relative value sum_k h_k(tau_k, C). The policy is

    .. math::

        \\pi(\\tau, C) = \\arg\\min_a \\sum_{C', \\delta} P(C', \\delta \\mid C, a)
            \\sum_k h_k(\\tau'_k, C'), \\qquad
        \\tau'_k = \\min(\\tau_k + 1, \\delta_k \\text{ if } \\delta_k > 0, \\hat\\tau_k),

    ties to the first action of the configuration (exact comparison). The expectation is
    separable, so it is precomputed as tables
    ``W_k[C, a, tau_k] = sum_o p_o h_k(tau'_k, C'_o)`` of size |C| * A_max * tau_hat_k and the
    value of action a in state (tau, C) is ``sum_k W_k[C, a, tau_k]``: nothing proportional to
    the tau box is ever formed.

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
        super().__init__(system)
        t0 = time.perf_counter()
        self.base = base if base is not None else RandomPolicy(system)
        if self.base.system is not system:
            raise PolicyError("the base policy belongs to another system")
        ot = system.outcome_tables
        w = self.base.probs[:, :, None] * ot.prob  # (C, A, O) probability of (action, outcome)
        poisson = []
        tables = []
        for k in range(system.n_processes):
            poisson.append(self._solve_process(k, w))
            tables.append(self._improvement_table(k, poisson[-1].h))
        self.poisson = tuple(poisson)
        self.tables = tuple(tables)
        self.base_gain = float(sum(p.gain for p in poisson))
        self.build_seconds = time.perf_counter() - t0

    # --- step 2: per-process Poisson equations -----------------------------------
    def _solve_process(self, k: int, w: np.ndarray) -> ProcessPoisson:
        sysm = self.system
        ot = sysm.outcome_tables
        K = int(sysm.caps[k])
        nC = sysm.n_configs
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
        cost = np.tile(sysm.q[k], nC)
        chain = MDP.from_arrays(np.arange(n), np.zeros(n, dtype=np.int64), cost, P, n, check=False,
                                name=f"process-{k + 1} chain")
        try:
            ev = evaluate_policy(chain, np.arange(n, dtype=np.int64))
        except PolicyError as exc:
            raise PolicyError(f"process {k + 1}: the chain (tau_{k + 1}, C) under the base policy: {exc}") from None
        return ProcessPoisson(gain=float(ev.gain), h=ev.bias.reshape(nC, K), residual=float(ev.residual), size=n)

    # --- step 3: improvement tables --------------------------------------------------
    def _improvement_table(self, k: int, h: np.ndarray) -> np.ndarray:
        sysm = self.system
        ot = sysm.outcome_tables
        K = int(sysm.caps[k])
        t = np.arange(1, K + 1)
        dk = ot.delta[..., k][..., None]  # (C, A, O, 1)
        t_next = np.minimum(t + 1, K)
        t_next = np.where(dk > 0, np.minimum(t_next, dk), t_next)  # (C, A, O, K)
        vals = h[ot.nxt[..., None], t_next - 1]  # (C, A, O, K)
        W = np.einsum("cao,caok->cak", ot.prob, vals)
        W[~sysm.action_valid] = np.inf
        return W

    # --- the policy --------------------------------------------------------------------
    def values(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A_max) improvement values sum_k W_k[C, a, tau_k] (+inf on infeasible actions)."""
        tau, c = self._check_inputs(tau, config_ids)
        v = self.tables[0][c, :, tau[:, 0] - 1].copy()
        for k in range(1, self.system.n_processes):
            v += self.tables[k][c, :, tau[:, k] - 1]
        return v

    def act(self, tau, config_ids, rng=None):
        return np.argmin(self.values(tau, config_ids), axis=1).astype(np.int64)

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
