"""A scenario's configuration automaton and cost tables: all a policy or a simulator needs.

A :class:`System` never holds the tau box, so it exists for systems far too large to enumerate
(all four paper processes with caps of 30 or more). What it knows of the configurations comes
from the scenario's :class:`~wncs_lp.models.base.Model`.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import PolicyError
from ..mdp import MDP
from ..scenario import Scenario
from .automaton import ConfigAutomaton
from .base import Model
from .cost import cost_tables

__all__ = ["System", "OutcomeTables"]


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
    model : Model
        The scenario's model: what the system knows of its configurations comes from it.
    """

    scenario: Scenario
    automaton: ConfigAutomaton
    caps: np.ndarray
    q: tuple
    n_actions: np.ndarray
    model: Model

    # ---------------------------------------------------------------- construction
    @classmethod
    def from_scenario(cls, scenario: Scenario, model: Model | None = None) -> "System":
        """Explore the scenario's configuration automaton (through its :class:`Model`)."""
        from . import model_for

        model = model if model is not None else model_for(scenario)
        return cls.from_automaton(scenario, model.automaton, model)

    @classmethod
    def from_automaton(cls, scenario: Scenario, auto: ConfigAutomaton, model: Model | None = None) -> "System":
        if model is None:
            from . import model_for

            model = model_for(scenario)
        caps = np.array(scenario.tau_caps, dtype=np.int64)
        q = tuple(np.asarray(t, dtype=float) for t in cost_tables(scenario))
        n_actions = np.array([len(a) for a in auto.actions], dtype=np.int64)
        return cls(scenario, auto, caps, q, n_actions, model)

    # ---------------------------------------------------------------- basic facts
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
        """(|C|, M) bool: server m accepts a new update in configuration c (:meth:`Model.accepts`)."""
        return np.array([self.model.accepts(cfg) for cfg in self.automaton.configs], dtype=bool)

    @cached_property
    def busy(self) -> np.ndarray:
        """(|C|, A_max, M): probability that server m performs a service step in the slot
        (:meth:`Model.busy`; 0 on padding)."""
        out = np.zeros((self.n_configs, self.max_actions, self.n_servers))
        for c, cfg in enumerate(self.automaton.configs):
            out[c] = self.model.busy(cfg, self.labels[c])
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
