r"""The field's baselines from the age-of-information literature (Kadota et al. 2018 and after),
on this toolkit's servers: max-age-first, max-weighted-cost-first and round robin.

All three choose *which processes* to send by a ranking of their own and then hand the ranked
processes to the accepting servers exactly as the paper's greedy policy does (the model's
:meth:`~wncs_lp.models.base.Model.greedy_label`: walking down the ranking, each process takes
the accepting server with its shortest loop among those not yet taken; leftover servers idle).
Updates in flight are ignored, as by the greedy policy. The exact rules, with their tie rules and
what they do with two servers and pipelines, are in ``docs/policies.md``.

* :class:`MaxAgePolicy` ranks by the AoI tau_k (descending, ties: lower index);
* :class:`MaxWeightPolicy` ranks by the expected cost reduction of an update sent now through
  the process's shortest-loop server m_k,
  :math:`v_k(\tau) = p^{up}_{m_k,k} p^{down}_{m_k,k}\,[q_k(\min(\tau + L_{m_k,k}, \hat\tau_k)) -
  q_k(\min(L_{m_k,k}, \hat\tau_k))]` (Kadota et al.'s Max-Weight index for this cost);
* :class:`RoundRobinPolicy` ranks cyclically from a pointer that moves past the processes sent:
  a policy with memory (:class:`~wncs_lp.policies.base.MemoryPolicy`).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import PolicyError
from ..models.system import System
from .base import MemoryPolicy
from .rules import GreedyPolicy

__all__ = ["MaxAgePolicy", "MaxWeightPolicy", "RoundRobinPolicy", "max_weight_index"]


class MaxAgePolicy(GreedyPolicy):
    """Max-age-first: the processes ranked by their AoI tau_k (descending, ties: lower index), then
    served as by the greedy policy (:meth:`~wncs_lp.models.base.Model.greedy_label`)."""

    name = "max_age"

    def ranking(self, tau: np.ndarray) -> np.ndarray:
        return np.argsort(-np.asarray(tau, dtype=np.int64), axis=1, kind="stable")


def _best_server(system: System, k: int) -> int:
    """The server with the shortest loop U + T_k + D for process k (ties: lower index)."""
    servers = system.scenario.servers
    return min(range(len(servers)), key=lambda m: (servers[m].loop[k], m))


def max_weight_index(system: System) -> tuple[np.ndarray, ...]:
    r"""Per process k, the table ``v[k][tau - 1]`` of the max-weight index of :class:`MaxWeightPolicy`:

    .. math:: v_k(\tau) = p^{up}_{m,k} p^{down}_{m,k}\,\bigl[q_k(\min(\tau + L_{m,k}, \hat\tau_k))
              - q_k(\min(L_{m,k}, \hat\tau_k))\bigr],

    m the shortest-loop server of process k (ties: lower index), L_{m,k} = U_m + T_{m,k} + D_m.
    The bracket is the cost the update removes when it lands L slots from now (the AoI is then
    L instead of tau + L, both within the cap); the factor is the chance that it lands, through
    process k's own links to m (``docs/model.md``: per-link success probabilities).
    """
    out = []
    for k, cap in enumerate(system.caps.tolist()):
        m = _best_server(system, k)
        srv = system.scenario.servers[m]
        L = int(srv.loop[k])
        tau = np.arange(1, cap + 1)
        q = system.q[k]
        out.append(srv.p_up[k] * srv.p_down[k] * (q[np.minimum(tau + L, cap) - 1] - q[min(L, cap) - 1]))
    return tuple(out)


class MaxWeightPolicy(GreedyPolicy):
    """Max-weighted-cost-first: the processes ranked by :func:`max_weight_index` (descending, ties:
    lower index), then served as by the greedy policy. The index is read from the system's cost
    tables at every call, so the rule acts on any AoI (:meth:`~wncs_lp.policies.Policy.on_system`)."""

    name = "max_weight"

    def __init__(self, system: System):
        super().__init__(system)
        sc = system.scenario
        best = [_best_server(system, k) for k in range(system.n_processes)]
        self._loop = np.array([sc.servers[m].loop[k] for k, m in enumerate(best)], dtype=np.int64)
        self._p = np.array([sc.servers[m].p_up[k] * sc.servers[m].p_down[k] for k, m in enumerate(best)])

    def ranking(self, tau: np.ndarray) -> np.ndarray:
        caps, q = self.system.caps, self.system.q
        v = np.stack([self._p[k] * (q[k][np.minimum(tau[:, k] + self._loop[k], caps[k]) - 1]
                                    - q[k][np.full(1, min(self._loop[k], caps[k])) - 1])
                      for k in range(self.system.n_processes)], axis=1)
        return np.argsort(-v, axis=1, kind="stable")


class RoundRobinPolicy(MemoryPolicy):
    """Round robin: a pointer r (a process, 0-based; 0 at the start) ranks the processes cyclically,
    r, r + 1, ..., N - 1, 0, ..., r - 1, and they are served as by the greedy policy; the pointer
    then moves to the process after the last one sent (in that cyclic order), and stays when none
    is sent. The action depends on (C, r) only, never on tau.

    Attributes
    ----------
    table : (|C|, N) int array
        The local action in configuration c with pointer r.
    moves : (|C|, N) int array
        The pointer after that action.
    """

    name = "round_robin"
    aoi_free = True

    def __init__(self, system: System):
        super().__init__(system)
        N, nC = system.n_processes, system.n_configs
        self.memory_size = N
        self.table = np.empty((nC, N), dtype=np.int64)
        self.moves = np.empty((nC, N), dtype=np.int64)
        model, configs = system.model, system.automaton.configs
        for c in range(nC):
            for r in range(N):
                order = [(r + i) % N for i in range(N)]
                label = tuple(int(x) for x in model.greedy_label(configs[c], order))
                j = system.label_index[c].get(label)
                if j is None:  # pragma: no cover - greedy labels are feasible in every model
                    raise PolicyError(f"policy {self.name} chose action {label}, infeasible in configuration {c}")
                sent = [(k - 1 - r) % N for k in label if k > 0]
                self.table[c, r] = j
                self.moves[c, r] = (r + max(sent) + 1) % N if sent else r

    def act_memory(self, tau, config_ids, memory, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        return self.table[c, self._memory(memory, c)]

    def next_memory(self, memory, config_ids, actions):
        c = np.asarray(config_ids, dtype=np.int64)
        m = self._memory(memory, c)
        j = np.asarray(actions, dtype=np.int64)
        if np.any(j != self.table[c, m]):
            raise PolicyError(f"policy {self.name}: next_memory was given an action the policy did not take")
        return self.moves[c, m]

    def separable_evaluation(self) -> Any:
        r"""The exact long-run averages of round robin at any number of processes, without the MDP.

        The action depends on (C, r) only, so (C, r) is a Markov chain of its own and, for every
        process k, so is (tau_k, C, r): tau'_k = min(tau_k + 1, delta_k if delta_k > 0, tau_hat_k)
        with the delivery ages delta of the outcome drawn. The stationary law of each such chain
        (tau_hat_k |C| N states: :func:`wncs_lp.chain.stationary_law`) gives
        g_k = E[q_k(tau_k)], and the gain is sum_k g_k -- the same numbers as
        :func:`wncs_lp.evaluate.evaluate` on the augmented chain of the enumerated MDP (tested),
        for a cost linear in N instead of a product of the caps.

        Returns
        -------
        Evaluation
            ``n_states`` counts the per-process chains' states, ``n_pairs`` is 0 (no MDP).

        Raises
        ------
        PolicyError
            Some (tau_k, C, r) chain has several recurrent classes.
        """
        import time

        from ..chain import recurrent_classes, stationary_law
        from ..evaluate import Evaluation

        t0 = time.perf_counter()
        sysm, pt = self.system, self.system.pairs  # one row per feasible (configuration, action) pair
        N, nC = sysm.n_processes, sysm.n_configs
        c_idx = np.repeat(np.arange(nC), N)
        r_idx = np.tile(np.arange(N), nC)
        j_idx = self.table[c_idx, r_idx]
        src = r_idx * nC + c_idx  # the (C, r) node, r-major
        pair = pt.first[c_idx] + j_idx
        prob = pt.prob[pair]  # (nC N, O)
        dst = self.moves[c_idx, r_idx][:, None] * nC + pt.nxt[pair]
        real = prob > 0
        mse, residual, size = [], 0.0, 0
        for k in range(N):
            K = int(sysm.caps[k])
            t = np.arange(1, K + 1)
            t1 = np.minimum(t + 1, K)
            dk = pt.deltas[pt.delta[pair], k]
            rows = (src[:, None, None] * K + t[None, None, :] - 1)
            t_next = np.where(dk[..., None] > 0, np.minimum(t1[None, None, :], dk[..., None]), t1[None, None, :])
            cols = dst[..., None] * K + t_next - 1
            vals = np.broadcast_to(prob[..., None], cols.shape)
            mask = np.broadcast_to(real[..., None], cols.shape)
            rows = np.broadcast_to(rows, cols.shape)
            n = nC * N * K
            P = sp.csr_matrix((vals[mask], (rows[mask], cols[mask])), shape=(n, n))
            classes = recurrent_classes(P)
            if len(classes) != 1:
                raise PolicyError(f"policy {self.name}: the chain of ({sysm.scenario.processes[k].name}'s AoI, "
                                  f"configuration, pointer) has {len(classes)} recurrent classes")
            pi, res = stationary_law(P, classes)
            residual, size = max(residual, res), size + n
            mse.append(float(pi @ np.tile(sysm.q[k], nC * N)))
            if k == 0:
                node = pi.reshape(nC * N, K).sum(axis=1)  # the law of (C, r), r-major
        r_of, c_of = np.divmod(np.arange(nC * N), nC)
        busy = sysm.busy[c_of, self.table[c_of, r_of]]  # (nC N, M)
        sc = sysm.scenario
        return Evaluation(policy=self.name, gain=float(sum(mse)), mse=tuple(mse),
                          utilisation=tuple(float(x) for x in node @ busy),
                          process_names=tuple(p.name for p in sc.processes),
                          server_names=tuple(s.name for s in sc.servers), randomised=False, residual=residual,
                          recurrent_classes=1, n_states=size, n_pairs=0, seconds=time.perf_counter() - t0)

    def _memory(self, memory: Any, c: np.ndarray) -> np.ndarray:
        m = np.asarray(memory, dtype=np.int64)
        if m.shape != c.shape or np.any(m < 0) or np.any(m >= self.memory_size):
            raise PolicyError(f"policy {self.name}: memory must be {c.size} pointers in 0..{self.memory_size - 1}")
        return m
