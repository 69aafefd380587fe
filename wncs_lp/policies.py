"""Scheduling policies as first-class objects, usable with or without an enumerated MDP.

Every model of this toolkit has states s = (tau, C): the AoI vector tau in the box
1..tau_hat and a configuration C of a small automaton (:mod:`wncs_lp.models.space`). A
:class:`System` holds that automaton, the cost tables q_k and padded per-(C, action) outcome
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

Policies (``make_policy`` builds them by name):

``optimal``      :class:`OptimalPolicy`, the policy of a :class:`~wncs_lp.solvers.result.Solution`;
``suboptimal``   :class:`SuboptimalPolicy`, the separable one-step improvement of paper Section III;
``static``       :class:`StaticPolicy` with :func:`default_assignment`;
``best_static``  :func:`best_static`, the static assignment of least exact average cost;
``greedy``       :class:`GreedyPolicy`, the paper's greedy baseline;
``random``       :class:`RandomPolicy`, uniform over the feasible actions (tau-independent).

The exact rules are those of ``shared/spec/policies.md``.
"""
from __future__ import annotations

import itertools
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Sequence

import numpy as np
import scipy.sparse as sp

from .cost import cost_tables
from .errors import PolicyError
from .mdp import MDP
from .models.space import ConfigAutomaton
from .scenario import Scenario

__all__ = [
    "POLICY_NAMES",
    "System",
    "Policy",
    "OptimalPolicy",
    "TauIndependentPolicy",
    "RandomPolicy",
    "StaticPolicy",
    "GreedyPolicy",
    "SuboptimalPolicy",
    "default_assignment",
    "static_assignments",
    "best_static",
    "make_policy",
    "solve_optimal",
    "parse_policy_names",
]

#: Policy names understood by :func:`make_policy` and the command line.
POLICY_NAMES = ("optimal", "suboptimal", "static", "best_static", "greedy", "random")


# ============================================================================ the system
@dataclass(frozen=True, eq=False)
class System:
    """A scenario's configuration automaton and cost tables: all a policy or simulator needs.

    Build it with :meth:`System.from_scenario`; nothing here is proportional to the size of the
    tau box, only to the number of configurations |C| and to sum_k tau_hat_k.

    Attributes
    ----------
    scenario : Scenario
    automaton : ConfigAutomaton
        ``configs``, ``actions[c]`` (labels in the MDP's action order), ``outcomes[c][j]`` =
        ``[(next_config_id, delta, prob), ...]``.
    caps : (N,) int array
        tau_hat_k.
    q : tuple of arrays
        ``q[k][tau - 1] = q_k(tau)``, tau = 1..tau_hat_k.
    n_actions : (|C|,) int array
        Number of feasible actions of each configuration.
    """

    scenario: Scenario
    automaton: ConfigAutomaton
    caps: np.ndarray
    q: tuple
    n_actions: np.ndarray

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_scenario(cls, scenario: Scenario) -> "System":
        """Explore the scenario's configuration automaton (``wncs`` or ``preemption`` kind)."""
        kind = scenario.model.kind
        if kind == "wncs":
            from .models.wncs import wncs_automaton

            auto = wncs_automaton(scenario)
        elif kind == "preemption":
            from .models.preemption import preemption_automaton

            auto = preemption_automaton(scenario)
        else:  # pragma: no cover - the scenario loader rejects other kinds
            raise PolicyError(f"{scenario.source}: no policies for model kind {kind!r}")
        return cls.from_automaton(scenario, auto)

    @classmethod
    def from_automaton(cls, scenario: Scenario, auto: ConfigAutomaton) -> "System":
        caps = np.array(scenario.tau_caps, dtype=np.int64)
        q = tuple(np.asarray(t, dtype=float) for t in cost_tables(scenario))
        n_actions = np.array([len(a) for a in auto.actions], dtype=np.int64)
        return cls(scenario, auto, caps, q, n_actions)

    # ---------------------------------------------------------------- basic facts
    @property
    def kind(self) -> str:
        return self.scenario.model.kind

    @property
    def n_processes(self) -> int:
        return int(self.caps.size)

    @property
    def n_servers(self) -> int:
        return self.scenario.n_servers

    @property
    def n_configs(self) -> int:
        return len(self.automaton.configs)

    @property
    def initial_config(self) -> int:
        """The first initial configuration (all servers idle, empty pipelines)."""
        return int(self.automaton.initial[0])

    def state_cost(self, tau: np.ndarray) -> np.ndarray:
        """c(s) = sum_k q_k(tau_k) for an (R, N) array of AoI vectors."""
        tau = np.asarray(tau)
        out = np.zeros(tau.shape[0])
        for k in range(self.n_processes):
            out += self.q[k][tau[:, k] - 1]
        return out

    def check_mdp(self, mdp: MDP) -> None:
        """Raise :class:`PolicyError` unless ``mdp`` was built from this system's automaton.

        The engine numbers the MDP's configurations in automaton order, so the check is that
        the configuration lists and the caps agree.
        """
        states = getattr(mdp, "states", None)
        if states is None or not hasattr(states, "configs") or not hasattr(states, "tau"):
            raise PolicyError(f"{mdp!r} has no decoded (tau, configuration) states; build it with wncs_lp.models.build")
        if tuple(states.caps) != tuple(int(c) for c in self.caps):
            raise PolicyError(f"MDP caps {tuple(states.caps)} differ from the scenario's {tuple(self.caps)}")
        if len(states.configs) != self.n_configs or any(
            a != b for a, b in zip(states.configs, self.automaton.configs)
        ):
            raise PolicyError(
                "the MDP's configurations differ from this scenario's automaton "
                "(was it built from another scenario or another parameter value?)"
            )

    # ---------------------------------------------------------------- padded tables
    @cached_property
    def max_actions(self) -> int:
        return int(self.n_actions.max())

    @cached_property
    def labels(self) -> np.ndarray:
        """(|C|, A_max, M) int array of action labels (padding: -1)."""
        M = len(self.automaton.actions[0][0])
        out = np.full((self.n_configs, self.max_actions, M), -1, dtype=np.int64)
        for c, acts in enumerate(self.automaton.actions):
            out[c, : len(acts)] = np.array(acts, dtype=np.int64)
        return out

    @cached_property
    def label_index(self) -> list[dict[tuple, int]]:
        """Per configuration: action label -> local index."""
        return [{tuple(a): j for j, a in enumerate(acts)} for acts in self.automaton.actions]

    @cached_property
    def action_valid(self) -> np.ndarray:
        """(|C|, A_max) bool: local index j is a feasible action of configuration c."""
        return np.arange(self.max_actions)[None, :] < self.n_actions[:, None]

    @cached_property
    def outcome_tables(self) -> "OutcomeTables":
        """Padded per-(configuration, action) outcome tables (see :class:`OutcomeTables`)."""
        auto = self.automaton
        nC, A, N = self.n_configs, self.max_actions, self.n_processes
        O = max(len(outs) for per_c in auto.outcomes for outs in per_c)
        nxt = np.zeros((nC, A, O), dtype=np.int64)
        delta = np.zeros((nC, A, O, N), dtype=np.int64)
        prob = np.zeros((nC, A, O))
        cum = np.full((nC, A, O), np.inf)
        for c, per_c in enumerate(auto.outcomes):
            for j, outs in enumerate(per_c):
                n_o = len(outs)
                nxt[c, j, :n_o] = [o[0] for o in outs]
                delta[c, j, :n_o] = [o[1] for o in outs]
                p = np.array([o[2] for o in outs], dtype=float)
                prob[c, j, :n_o] = p
                cs = np.cumsum(p)
                cs[-1] = np.inf  # u < 1 always lands on a real outcome, whatever the round-off
                cum[c, j, :n_o] = cs
                nxt[c, j, n_o:] = nxt[c, j, 0]
        return OutcomeTables(nxt=nxt, delta=delta, prob=prob, cum=cum)

    @cached_property
    def accepts(self) -> np.ndarray:
        """(|C|, M) bool, ``wncs`` only: server m accepts a new update in configuration c."""
        if self.kind != "wncs":
            raise PolicyError("server acceptance is defined for the wncs model only")
        from .models.wncs import server_accepts

        return np.array(
            [[server_accepts(s, st) for s, st in zip(self.scenario.servers, cfg)] for cfg in self.automaton.configs],
            dtype=bool,
        )

    @cached_property
    def busy(self) -> np.ndarray:
        """(|C|, A_max, M): probability that server m performs a service step in the slot.

        ``wncs``: the server has a job in service at the start of the slot (d > 0), or U_m = 0
        and an update is sent to it and survives the uplink (it is served in this same slot),
        which has probability ``pu_m``. ``preemption``: a job is in service at the start of the
        slot, or the action starts one (it is served in this slot).
        """
        nC, A, M = self.n_configs, self.max_actions, self.n_servers
        out = np.zeros((nC, A, M))
        labels = self.labels
        if self.kind == "wncs":
            for c, cfg in enumerate(self.automaton.configs):
                for m, (srv, st) in enumerate(zip(self.scenario.servers, cfg)):
                    base = 1.0 if st[2] > 0 else 0.0
                    out[c, :, m] = base
                    if srv.uplink_delay == 0 and base == 0.0:
                        out[c, :, m] = np.where(labels[c, :, m] > 0, srv.p_up, 0.0)
        else:
            for c, cfg in enumerate(self.automaton.configs):
                if cfg[1] is not None:
                    out[c] = 1.0
                else:
                    out[c, :, 0] = (labels[c, :, 0] > 0).astype(float)
        out[~self.action_valid] = 0.0
        return out

    def next_tau(self, tau: np.ndarray, delta: np.ndarray) -> np.ndarray:
        """tau'_k = min(tau_k + 1, delta_k if delta_k > 0, tau_hat_k), elementwise (broadcasts)."""
        t = np.minimum(tau + 1, self.caps)
        return np.where(delta > 0, np.minimum(t, delta), t)


@dataclass(frozen=True, eq=False)
class OutcomeTables:
    """Padded outcome tables of a :class:`System`, indexed ``[c, j, o]``.

    Attributes
    ----------
    nxt : (|C|, A, O) int array
        Next configuration id of outcome o of action j in configuration c.
    delta : (|C|, A, O, N) int array
        Delivery ages (0 = none).
    prob : (|C|, A, O) float array
        Outcome probabilities (0 on padding).
    cum : (|C|, A, O) float array
        Cumulative probabilities with the last real entry and the padding set to +inf: the
        outcome drawn by a uniform u in [0, 1) is ``sum(u >= cum[c, j])``.
    """

    nxt: np.ndarray
    delta: np.ndarray
    prob: np.ndarray
    cum: np.ndarray


def _as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


# ============================================================================ base class
class Policy(ABC):
    """A stationary scheduling policy over the states (tau, C) of a :class:`System`.

    Subclasses implement :meth:`act`; :meth:`on_mdp` derives the enumerated form from it
    (randomised policies override it).

    Attributes
    ----------
    name : str
        Short name (``"greedy"``, ``"static[remote,edge]"``, ...).
    system : System
    randomised : bool
        Whether :meth:`act` draws random numbers.
    """

    name: str = "policy"
    randomised: bool = False

    def __init__(self, system: System):
        self.system = system

    @abstractmethod
    def act(self, tau: np.ndarray, config_ids: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Local action indices for R states.

        Parameters
        ----------
        tau : (R, N) int array
            AoI values, 1 <= tau[r, k] <= tau_hat_k.
        config_ids : (R,) int array
            Configuration ids of the automaton.
        rng : numpy.random.Generator, optional
            Used by randomised policies only.

        Returns
        -------
        (R,) int64 array
            ``j[r]`` indexes ``system.automaton.actions[config_ids[r]]``.
        """

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        """The policy on an enumerated MDP of the same scenario: (n,) pair indices.

        Raises
        ------
        PolicyError
            The MDP was not built from this policy's scenario.
        """
        self.system.check_mdp(mdp)
        st = mdp.states
        j = np.asarray(self.act(np.asarray(st.tau, dtype=np.int64), np.asarray(st.config, dtype=np.int64),
                                np.random.default_rng(0)), dtype=np.int64)
        if np.any(j < 0) or np.any(j >= np.diff(mdp.pair_ptr)):
            raise PolicyError(f"policy {self.name}: a local action index is out of range")
        return mdp.pair_ptr[:-1] + j

    def describe(self) -> dict[str, Any]:
        """JSON-ready description."""
        return {"policy": self.name, "randomised": self.randomised}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"

    # helpers ------------------------------------------------------------------
    @staticmethod
    def _check_inputs(tau: np.ndarray, config_ids: np.ndarray) -> tuple:
        tau = np.asarray(tau, dtype=np.int64)
        c = np.asarray(config_ids, dtype=np.int64)
        if tau.ndim != 2 or c.shape != (tau.shape[0],):
            raise PolicyError(f"act expects tau of shape (R, N) and config_ids of shape (R,), got {tau.shape}, {c.shape}")
        return tau, c


# ============================================================================ optimal
class OptimalPolicy(Policy):
    """The deterministic policy of a solved MDP (``Solution.policy``, one pair per state).

    ``act`` looks the states up in the MDP (``mdp.states._lookup``), so it works for every
    state of the MDP's reachable set, which contains every state a simulation started in an
    initial configuration can visit.

    Parameters
    ----------
    mdp : MDP
        The enumerated MDP (from :func:`wncs_lp.models.build`).
    solution : Solution
        Any solution of ``mdp`` (``policy`` = pair indices).
    system : System
        The scenario's system (``mdp`` must have been built from it); :meth:`from_scenario`
        builds all three.
    """

    name = "optimal"

    def __init__(self, mdp: MDP, solution: Any, system: System):
        super().__init__(system)
        system.check_mdp(mdp)
        pol = np.asarray(solution.policy, dtype=np.int64)
        if pol.shape != (mdp.n_states,) or np.any(mdp.s_indices[pol] != np.arange(mdp.n_states)):
            raise PolicyError("solution.policy is not one pair index per state of this MDP")
        self.mdp = mdp
        self.solution = solution
        self._local = pol - mdp.pair_ptr[:-1]
        self._strides = np.array(
            [int(np.prod(system.caps[k + 1:])) for k in range(system.n_processes)], dtype=np.int64
        )

    @classmethod
    def from_scenario(cls, scenario: Scenario, method: str = "pi", system: System | None = None,
                      mdp: MDP | None = None, **solve_kw: Any) -> "OptimalPolicy":
        """Build the MDP (unless given), solve it with ``method`` and wrap the solution."""
        from .models import build

        system = system or System.from_scenario(scenario)
        mdp = mdp if mdp is not None else build(scenario)
        return cls(mdp, solve_optimal(mdp, method=method, **solve_kw), system)

    @property
    def gain(self) -> float:
        return float(self.solution.gain)

    def states_of(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """MDP state ids of (tau, C) (raises :class:`PolicyError` for a state not in the MDP)."""
        tau, c = self._check_inputs(tau, config_ids)
        flat = (tau - 1) @ self._strides
        s = self.mdp.states._lookup[c, flat]
        if np.any(s < 0):
            r = int(np.flatnonzero(s < 0)[0])
            raise PolicyError(f"state tau={tau[r].tolist()}, configuration {int(c[r])} is not in the MDP")
        return s

    def act(self, tau, config_ids, rng=None):
        return self._local[self.states_of(tau, config_ids)]

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        if mdp is self.mdp:
            return np.asarray(self.solution.policy, dtype=np.int64)
        return super().on_mdp(mdp)

    def describe(self):
        return {**super().describe(), "method": self.solution.method, "solver_gain": float(self.solution.gain)}


# ============================================================================ tau-independent
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
        u = _as_rng(rng).random(c.size)
        return (u[:, None] >= self._cum[c]).sum(axis=1).astype(np.int64)

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        """(L,) pair probabilities ``probs[C(s)][j]``."""
        self.system.check_mdp(mdp)
        local = np.arange(mdp.n_pairs) - mdp.pair_ptr[mdp.s_indices]
        return self.probs[np.asarray(mdp.states.config)[mdp.s_indices], local].astype(float)


class RandomPolicy(TauIndependentPolicy):
    """Uniformly random over the feasible actions of the configuration (the paper's random policy)."""

    def __init__(self, system: System):
        super().__init__(system, [np.full(n, 1.0 / n) for n in system.n_actions], name="random")
        self.randomised = True

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        n = self.system.n_actions[c]
        j = np.floor(_as_rng(rng).random(c.size) * n).astype(np.int64)
        return np.minimum(j, n - 1)


# ============================================================================ rank rules
class _RankRulePolicy(Policy):
    """A deterministic policy whose action depends on C and on the ranking of the processes.

    The ranking is by current cost q_k(tau_k), descending, ties towards the lower index. The
    action of each (C, ranking) met is computed once by :meth:`rule` and cached.
    """

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
        order = self.ranking(tau)
        keys = c.astype(object if self._pow.dtype == object else np.int64) * self._base + order @ self._pow
        uniq, inv = np.unique(keys, return_inverse=True)
        out = np.empty(uniq.size, dtype=np.int64)
        for i, key in enumerate(uniq.tolist()):
            j = self._cache.get(key)
            if j is None:
                r = int(np.flatnonzero(inv == i)[0])
                j = self._cache[key] = self._local(int(c[r]), tuple(int(x) for x in order[r]))
            out[i] = j
        return out[inv.reshape(-1)]


class StaticPolicy(_RankRulePolicy):
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
        if system.kind != "wncs":
            raise PolicyError(f"the static policy is defined for the wncs model, not {system.kind!r}")
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


class GreedyPolicy(_RankRulePolicy):
    """The paper's greedy baseline (``wncs``), and a greedy work-conserving rule (``preemption``).

    ``wncs``: processes ranked by q_k(tau_k) (descending, ties: lower index); walking down the
    ranking while accepting servers remain, each process takes, among the accepting servers not
    yet taken this slot, the one with the smallest loop U_m + T_{m,k} + D_m (ties: lower server
    index). Accepting servers left over (more servers than processes) get nothing. Updates in
    flight are ignored.

    ``preemption``: when the server is idle, start the arrived update of largest cost
    q_k(tau_k) (ties: lower index); when it is busy, keep going (never preempt). This is a
    baseline of our own (the paper's Section IV compares against the non-preemptive optimum).
    """

    name = "greedy"

    def rule(self, c, order):
        sc = self.system.scenario
        cfg = self.system.automaton.configs[c]
        if self.system.kind == "preemption":
            b, job = cfg[0], cfg[1]
            if job is None:
                for k in order:
                    if b[k]:
                        return (k + 1,)
            return (0,)
        acc = self.system.accepts[c]
        free = [m for m in range(sc.n_servers) if acc[m]]
        label = [0] * sc.n_servers
        for k in order:
            if not free:
                break
            m = min(free, key=lambda m: (sc.servers[m].loop[k], m))
            label[m] = k + 1
            free.remove(m)
        return tuple(label)


def default_assignment(scenario: Scenario) -> tuple[int, ...]:
    """The paper's default static assignment (``policies.md``), 0-based server indices.

    Processes are taken in decreasing dimension n_k (ties: lower index); each takes, among the
    servers that have no process yet (all servers, once every server has one), the server with
    the shortest loop U_m + T_{m,k} + D_m for it (ties: lower server index). For the paper's
    processes 1, 2 this sends process 1 to the remote server (loop 6 < 8) and process 2 to the
    edge server.
    """
    M, N = scenario.n_servers, scenario.n_processes
    order = sorted(range(N), key=lambda k: (-scenario.processes[k].dim, k))
    out = [0] * N
    used: set[int] = set()
    for k in order:
        pool = [m for m in range(M) if m not in used] or list(range(M))
        m = min(pool, key=lambda m: (scenario.servers[m].loop[k], m))
        out[k] = m
        used.add(m)
    return tuple(out)


def static_assignments(scenario: Scenario) -> list[tuple[int, ...]]:
    """All assignments process -> server (0-based) that give every server at least one process.

    With N < M there are none; then all M^N assignments are returned instead.
    """
    M, N = scenario.n_servers, scenario.n_processes
    every = [a for a in itertools.product(range(M), repeat=N)]
    onto = [a for a in every if len(set(a)) == M]
    return onto or every


def best_static(system: System | Scenario, mdp: MDP | None = None) -> StaticPolicy:
    """The static policy of least exact average cost over :func:`static_assignments`.

    Each candidate is evaluated exactly on ``mdp``; ties keep the first assignment in the
    lexicographic order. The returned policy's ``gain_search`` maps every assignment tried to
    its gain (``inf`` for one whose chain is multichain).

    Parameters
    ----------
    system : System or Scenario
        A scenario is turned into its system.
    mdp : MDP, optional
        The enumerated MDP (built from the scenario when omitted).
    """
    from .evaluate import evaluate

    if isinstance(system, Scenario):
        system = System.from_scenario(system)
    if mdp is None:
        from .models import build

        mdp = build(system.scenario)
    best: StaticPolicy | None = None
    best_gain = np.inf
    search: dict[tuple[int, ...], float] = {}
    for a in static_assignments(system.scenario):
        pol = StaticPolicy(system, a)
        try:
            g = float(evaluate(mdp, pol).gain)
        except PolicyError:
            g = np.inf
        search[a] = g
        if g < best_gain:
            best, best_gain = pol, g
    if best is None:
        raise PolicyError("every static assignment induces a multichain chain; no best static policy")
    best.gain_search = search
    best.name = "best_" + best.name
    return best


# ============================================================================ suboptimal
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
        from .solvers.dp import evaluate_policy

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


# ============================================================================ factory
def solve_optimal(mdp: MDP, method: str = "pi", **kw: Any) -> Any:
    """Solve ``mdp`` with ``method``; when policy iteration meets a multichain iterate, use RVI.

    Policy iteration needs every iterate to be unichain; at p = 1 (deterministic channels)
    deterministic policies can settle into several cycles, and PI stops with a
    :class:`PolicyError`. Relative value iteration (with the aperiodicity transform) only needs
    a constant optimal gain, so it is used instead; the returned solution's ``method`` is then
    ``"rvi"`` and ``stats["fallback_from"] = "pi"``. Keyword arguments of the other method are
    dropped on fallback except ``h0``.
    """
    from .solvers import solve

    try:
        return solve(mdp, method=method, **{k: v for k, v in kw.items() if k != "h0" or method == "rvi"})
    except PolicyError:
        if method != "pi":
            raise
        sol = solve(mdp, method="rvi", **({"h0": kw["h0"]} if "h0" in kw else {}))
        sol.stats["fallback_from"] = "pi"
        return sol


def make_policy(
    name: str,
    system: System,
    mdp: MDP | None = None,
    *,
    method: str = "pi",
    solution: Any = None,
    assignment: Sequence[int] | None = None,
) -> Policy:
    """Build a policy by name.

    Parameters
    ----------
    name : {"optimal", "suboptimal", "static", "best_static", "greedy", "random"}
    system : System
    mdp : MDP, optional
        Needed by ``optimal`` (solved with ``method`` unless ``solution`` is given) and
        ``best_static`` (exact evaluation of every assignment).
    method : str
        Solver method for ``optimal`` (default ``"pi"``).
    solution : Solution, optional
        A solution of ``mdp`` to wrap instead of solving.
    assignment : sequence of int, optional
        For ``static`` (0-based servers); default :func:`default_assignment`.

    Raises
    ------
    PolicyError
        Unknown name (the message lists the allowed ones), or a needed MDP missing.
    """
    if name not in POLICY_NAMES:
        raise PolicyError(f"unknown policy {name!r}; expected one of {', '.join(POLICY_NAMES)}")
    if name in ("optimal", "best_static") and mdp is None:
        raise PolicyError(f"policy {name!r} needs the enumerated MDP")
    if name == "optimal":
        if solution is None:
            solution = solve_optimal(mdp, method=method)
        return OptimalPolicy(mdp, solution, system)
    if name == "suboptimal":
        return SuboptimalPolicy(system)
    if name == "static":
        return StaticPolicy(system, default_assignment(system.scenario) if assignment is None else assignment)
    if name == "best_static":
        return best_static(system, mdp)
    if name == "greedy":
        return GreedyPolicy(system)
    return RandomPolicy(system)


def parse_policy_names(text: str | Sequence[str]) -> list[str]:
    """``"optimal,greedy"`` -> ``["optimal", "greedy"]``, checked against :data:`POLICY_NAMES`."""
    items = [s.strip() for s in (text.split(",") if isinstance(text, str) else text) if s.strip()]
    if not items:
        raise PolicyError(f"no policy given; expected names from {', '.join(POLICY_NAMES)}")
    for s in items:
        if s not in POLICY_NAMES:
            raise PolicyError(f"unknown policy {s!r}; expected one of {', '.join(POLICY_NAMES)}")
    return list(dict.fromkeys(items))
