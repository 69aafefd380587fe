"""Rule policies: tau-independent (random) and rank rules (static, greedy), with the static
assignments of ``docs/policies.md``."""
from __future__ import annotations

import itertools
from abc import abstractmethod
from typing import Sequence

import numpy as np

from ..errors import PolicyError
from ..mdp import MDP
from ..models import MODELS
from ..models.system import System
from ..scenario import Scenario
from .base import Policy, as_rng

__all__ = [
    "TauIndependentPolicy",
    "RandomPolicy",
    "RankRulePolicy",
    "StaticPolicy",
    "GreedyPolicy",
    "default_assignment",
    "static_assignments",
]


#: Most (configuration, ranking) actions a rank rule keeps cached (about 200 bytes each).
CACHE_MAX = 1_000_000


class TauIndependentPolicy(Policy):
    """A policy whose action distribution depends on the configuration C only.

    Parameters
    ----------
    system : System
    probs : sequence of arrays
        ``probs[c]`` is a probability vector over the local actions of configuration c.
    name : str
    """

    randomised = True
    aoi_free = True

    def __init__(self, system: System, probs: Sequence[np.ndarray], name: str = "tau-independent"):
        super().__init__(system)
        if len(probs) != system.n_configs:
            raise PolicyError(f"expected one distribution per configuration ({system.n_configs}), got {len(probs)}")
        P = np.zeros((system.n_configs, system.max_actions))
        for c, p in enumerate(probs):
            p = np.asarray(p, dtype=float)
            if p.shape != (system.n_actions[c],) or np.any(p < 0) or abs(p.sum() - 1.0) > 1e-9:
                raise PolicyError(
                    f"probs[{c}] must be a probability vector over the {system.n_actions[c]} actions of configuration {c}"
                )
            P[c, : p.size] = p
        self.probs = P
        cum = np.cumsum(P, axis=1)
        cum[np.arange(system.n_configs), system.n_actions - 1] = np.inf
        cum[~system.action_valid] = np.inf
        self._cum = cum
        self.name = name
        self.randomised = bool(np.any((P > 0) & (P < 1)))

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        u = as_rng(rng).random(c.size)
        return (u[:, None] >= self._cum[c]).sum(axis=1).astype(np.int64)

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        """(L,) pair probabilities ``probs[C(s)][j]``."""
        self.system.check_mdp(mdp)
        local = np.arange(mdp.n_pairs) - mdp.pair_ptr[mdp.s_indices]
        return self.probs[np.asarray(mdp.states.config)[mdp.s_indices], local].astype(float)


class RandomPolicy(TauIndependentPolicy):
    """Uniformly random over the feasible actions of the configuration (the paper's random policy)."""

    def __init__(self, system: System):
        self.refuse_lazy(system)
        super().__init__(system, [np.full(n, 1.0 / n) for n in system.n_actions], name="random")
        self.randomised = True

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        n = self.system.n_actions[c]
        j = np.floor(as_rng(rng).random(c.size) * n).astype(np.int64)
        return np.minimum(j, n - 1)


# ============================================================================ rank rules
class RankRulePolicy(Policy):
    """A deterministic policy whose action depends on C and on the ranking of the processes.

    The ranking is by current cost q_k(tau_k), descending, ties towards the lower index. The
    action of each (C, ranking) met is computed once by :meth:`rule` and cached. It works on a
    lazily explored system (it reads only the configurations it is shown).
    """

    aoi_free = True
    explores_lazily = True

    def __init__(self, system: System):
        super().__init__(system)
        self._cache: dict[int, int] = {}
        N = system.n_processes
        self._pow = np.array([N**i for i in range(N)], dtype=object if N > 12 else np.int64)
        self._base = N**N

    @abstractmethod
    def rule(self, c: int, order: tuple[int, ...]) -> tuple[int, ...]:
        """The action label for configuration c and ranking ``order`` (0-based processes)."""

    def ranking(self, tau: np.ndarray) -> np.ndarray:
        """(R, N) 0-based process indices by q_k(tau_k) descending, ties to the lower index."""
        qv = np.stack([self.system.q[k][tau[:, k] - 1] for k in range(self.system.n_processes)], axis=1)
        return np.argsort(-qv, axis=1, kind="stable")

    def _local(self, c: int, order: tuple[int, ...]) -> int:
        label = tuple(int(x) for x in self.rule(c, order))
        j = self.system.label_index[c].get(label)
        if j is None:
            raise PolicyError(
                f"policy {self.name} chose action {label}, infeasible in configuration {c} "
                f"({self.system.automaton.configs[c]!r}); feasible: {self.system.automaton.actions[c]}"
            )
        return j

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        self.system.expand(c)
        order = self.ranking(tau)
        keys = c.astype(object if self._pow.dtype == object else np.int64) * self._base + order @ self._pow
        uniq, first, inv = np.unique(keys, return_index=True, return_inverse=True)  # first: a row of each key
        out = np.empty(uniq.size, dtype=np.int64)
        for i, key in enumerate(uniq.tolist()):
            j = self._cache.get(key)
            if j is None:
                if len(self._cache) >= CACHE_MAX:  # tens of processes: rankings rarely repeat; memory stays bounded
                    self._cache.clear()
                r = int(first[i])
                j = self._cache[key] = self._local(int(c[r]), tuple(int(x) for x in order[r]))
            out[i] = j
        return out[inv.reshape(-1)]


class StaticPolicy(RankRulePolicy):
    """Each process k has a fixed server ``assignment[k]`` (0-based), ``wncs`` model only.

    When server m accepts, it is sent, among the processes assigned to it, the one with the
    largest current cost q_k(tau_k) (ties: lower index). If none is assigned to m and m may not
    idle (idling is allowed iff ``allow_idle`` or more servers accept than there are
    processes), it is sent the largest-cost process not already sent this slot; servers with
    assigned processes are served first, in server order.

    Parameters
    ----------
    system : System
    assignment : sequence of int
        ``assignment[k]`` in 0..M-1, one entry per process.
    """

    def __init__(self, system: System, assignment: Sequence[int]):
        if not system.model.has_static_policy:
            kinds = " or ".join(k for k, m in MODELS.items() if m.has_static_policy)
            raise PolicyError(f"the static policy is defined for the {kinds} model, not {system.model.kind!r}")
        super().__init__(system)
        a = tuple(int(x) for x in assignment)
        M, N = system.n_servers, system.n_processes
        if len(a) != N or any(not 0 <= m < M for m in a):
            raise PolicyError(f"a static assignment needs one server index in 0..{M - 1} per process ({N}), got {a}")
        self.assignment = a
        names = [system.scenario.servers[m].name for m in a]
        self.name = "static[" + ",".join(names) + "]"
        self.gain_search: dict[tuple[int, ...], float] | None = None

    def rule(self, c, order):
        sc = self.system.scenario
        acc = self.system.accepts[c]
        M, N = sc.n_servers, sc.n_processes
        idle_ok = sc.model.allow_idle or int(acc.sum()) > N
        label = [0] * M
        sent: set[int] = set()
        for m in range(M):
            if acc[m]:
                for k in order:
                    if self.assignment[k] == m:
                        label[m] = k + 1
                        sent.add(k)
                        break
        for m in range(M):
            if acc[m] and label[m] == 0 and not idle_ok:
                for k in order:
                    if k not in sent:
                        label[m] = k + 1
                        sent.add(k)
                        break
        return tuple(label)

    def describe(self):
        out = {**super().describe(), "assignment": [self.system.scenario.servers[m].name for m in self.assignment]}
        if self.gain_search is not None:
            out["search"] = {",".join(self.system.scenario.servers[m].name for m in a): g
                             for a, g in self.gain_search.items()}
        return out


class GreedyPolicy(RankRulePolicy):
    """The greedy baseline: each model's :meth:`~wncs_lp.models.base.Model.greedy_label`.

    Section II model (the paper's greedy baseline): processes ranked by q_k(tau_k) (descending, ties: lower index); walking down the
    ranking while accepting servers remain, each process takes, among the accepting servers not
    yet taken this slot, the one with the smallest loop U_m + T_{m,k} + D_m (ties: lower server
    index). Accepting servers left over (more servers than processes) get nothing. Updates in
    flight are ignored.

    Preemption model: when the server is idle, start the arrived update of largest cost
    q_k(tau_k) (ties: lower index); when it is busy, keep going (never preempt). This is a
    baseline of our own (the paper's Section IV compares against the non-preemptive optimum).
    """

    name = "greedy"

    def rule(self, c, order):
        return self.system.model.greedy_label(self.system.automaton.configs[c], order)


def default_assignment(scenario: Scenario) -> tuple[int, ...]:
    """The paper's default static assignment (``docs/policies.md``), 0-based server indices.

    The process of largest dimension n_k (ties: lower index) goes to the server with the
    shortest loop U_m + T_{m,k} + D_m for it (ties: lower server index); every other process,
    in decreasing n_k, goes to the shortest-loop server for it *among the other servers* (never
    the first process's server, unless there is only one server). With two servers every other
    process goes to the other server: for the paper's processes 1, 2, 3 that is (remote, edge,
    edge), and for processes 1, 2 (remote, edge).
    """
    M, N = scenario.n_servers, scenario.n_processes
    order = sorted(range(N), key=lambda k: (-scenario.processes[k].dim, k))
    out = [0] * N
    first = order[0]
    out[first] = min(range(M), key=lambda m: (scenario.servers[m].loop[first], m))
    others = [m for m in range(M) if m != out[first]] or [out[first]]
    for k in order[1:]:
        out[k] = min(others, key=lambda m: (scenario.servers[m].loop[k], m))
    return tuple(out)


def static_assignments(scenario: Scenario) -> list[tuple[int, ...]]:
    """All assignments process -> server (0-based) that give every server at least one process.

    With N < M there are none; then all M^N assignments are returned instead.
    """
    M, N = scenario.n_servers, scenario.n_processes
    every = [a for a in itertools.product(range(M), repeat=N)]
    onto = [a for a in every if len(set(a)) == M]
    return onto or every
