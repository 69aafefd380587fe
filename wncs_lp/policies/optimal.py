"""The deterministic policy of a solved MDP."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import PolicyError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD
from ..models import build
from ..models.system import System
from ..scenario import Scenario
from ..solvers.registry import run_average
from .base import Policy

__all__ = ["OptimalPolicy", "CappedPolicy", "ClippedPolicy"]


class OptimalPolicy(Policy):
    """The deterministic policy of a solved MDP (``Solution.policy``, one pair per state).

    ``act`` looks the states up in the MDP (``mdp.states.ids``), so it works for every
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
    outside : {"error", "first"}
        A state not in the MDP: a :class:`PolicyError` (default), or the configuration's first
        action. The MDP holds every state reachable from its initial states under any policy, so a
        state outside it is never entered from one inside and its action does not change the gain
        of any state of the MDP; ``"first"`` lets the policy act on a matrix-free layout, whose
        interval hull holds such states too.
    """

    name = "optimal"

    def __init__(self, mdp: MDP, solution: Any, system: System, outside: str = "error"):
        if outside not in ("error", "first"):
            raise PolicyError(f"outside must be 'error' or 'first', got {outside!r}")
        self.outside = outside
        super().__init__(system)
        system.check_mdp(mdp)
        pol = np.asarray(solution.policy, dtype=np.int64)
        if pol.shape != (mdp.n_states,) or np.any(mdp.s_indices[pol] != np.arange(mdp.n_states)):
            raise PolicyError("solution.policy is not one pair index per state of this MDP")
        self.mdp = mdp
        self.solution = solution
        self._local = pol - mdp.pair_ptr[:-1]

    @classmethod
    def from_scenario(cls, scenario: Scenario, method: str = DEFAULT_METHOD, system: System | None = None,
                      mdp: MDP | None = None, **solve_kw: Any) -> "OptimalPolicy":
        """Build the MDP (unless given; after the size guard, :func:`wncs_lp.build`), solve it with
        ``method`` (:data:`wncs_lp.methods.METHODS`, default ``"auto"``) and wrap the solution."""
        system = system or System.from_scenario(scenario)
        mdp = mdp if mdp is not None else build(scenario)
        return cls(mdp, run_average(mdp, method=method, **solve_kw), system)

    @property
    def gain(self) -> float:
        return float(self.solution.gain)

    def states_of(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """MDP state ids of (tau, C) (raises :class:`PolicyError` for a state not in the MDP)."""
        tau, c = self._check_inputs(tau, config_ids)
        s = self.mdp.states.ids(tau, c)
        if np.any(s < 0):
            r = int(np.flatnonzero(s < 0)[0])
            raise PolicyError(f"state tau={tau[r].tolist()}, configuration {int(c[r])} is not in the MDP")
        return s

    def act(self, tau, config_ids, rng=None):
        if self.outside == "error":
            return self._local[self.states_of(tau, config_ids)]
        tau, c = self._check_inputs(tau, config_ids)
        s = self.mdp.states.ids(tau, c)
        return np.where(s >= 0, self._local[np.maximum(s, 0)], 0)

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        if mdp is self.mdp:
            return np.asarray(self.solution.policy, dtype=np.int64)
        return super().on_mdp(mdp)

    def describe(self):
        return {**super().describe(), "method": self.solution.method, "solver_gain": float(self.solution.gain),
                "solve_status": str(self.solution.status)}


class CappedPolicy(Policy):
    """The policy of an MDP solved at a smaller AoI cap, applied at a larger one.

    A state (tau, C) of the larger model acts as the state (min(tau, cap), C) of the solved
    model: the AoI values the smaller model lumps at its cap get the cap's action. Used by the
    cap study (:func:`wncs_lp.capstudy.cap_study`) to say what a small model's answer is worth.

    Parameters
    ----------
    mdp : MDP
        The solved (smaller-cap) MDP.
    solution : Solution
        Its solution (one pair per state).
    system : System
        The system of the larger-cap scenario (same configurations, larger caps).

    Raises
    ------
    PolicyError
        The two models' configurations differ, or the solved caps exceed the larger ones.
    """

    name = "capped"

    def __init__(self, mdp: MDP, solution: Any, system: System):
        super().__init__(system)
        st = mdp.states
        if st is None or list(st.configs) != list(system.automaton.configs):
            raise PolicyError("the solved MDP's configurations differ from the scenario's: not the same model")
        self.caps = np.asarray(st.caps, dtype=np.int64)
        if np.any(self.caps > system.caps):
            raise PolicyError(f"the solved caps {self.caps.tolist()} exceed the scenario's {system.caps.tolist()}")
        pol = np.asarray(solution.policy, dtype=np.int64)
        if pol.shape != (mdp.n_states,):
            raise PolicyError("solution.policy is not one pair index per state of the solved MDP")
        self.mdp = mdp
        self._local = pol - mdp.pair_ptr[:-1]
        self.name = f"capped[{','.join(str(int(c)) for c in self.caps)}]"

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        s = self.mdp.states.ids(np.minimum(tau, self.caps[None, :]), c)
        if np.any(s < 0):
            r = int(np.flatnonzero(s < 0)[0])
            raise PolicyError(f"state tau={tau[r].tolist()}, configuration {int(c[r])} has no counterpart "
                              f"at caps {self.caps.tolist()}")
        return self._local[s]


class ClippedPolicy(Policy):
    """Any policy of a model with smaller AoI caps, acting on a system with larger ones (or none:
    :class:`wncs_lp.untruncated.UncappedPolicy`).

    A state (tau, C) acts as the state (min(tau, cap), C) of ``policy``'s own system, as
    :class:`CappedPolicy` does for a solved MDP; here for any policy (a matrix-free solution's,
    a rule, one with memory: ``act_memory`` and ``next_memory`` pass through).

    Parameters
    ----------
    policy : Policy
        The policy on the smaller caps.
    system : System
        The system it acts on: the same configurations, caps at least ``policy``'s.
    """

    def __init__(self, policy: Policy, system: System):
        super().__init__(system)
        inner = policy.system
        if inner.n_configs != system.n_configs or any(
                a != b for a, b in zip(inner.automaton.configs, system.automaton.configs)):
            raise PolicyError("the policy's configurations differ from the system's: not the same model")
        self.caps = np.asarray(inner.caps, dtype=np.int64)
        if np.any(self.caps > system.caps):
            raise PolicyError(f"the policy's caps {self.caps.tolist()} exceed the system's {system.caps.tolist()}")
        self.policy = policy
        self.name = policy.name
        self.randomised = policy.randomised
        if hasattr(policy, "act_memory"):
            self.act_memory = self._act_memory
            self.next_memory = policy.next_memory
            self.start_memory = policy.start_memory
            self.memory_size = policy.memory_size
            self.initial_memory = policy.initial_memory

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        return self.policy.act(np.minimum(tau, self.caps), c, rng)

    def _act_memory(self, tau, config_ids, memory, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        return self.policy.act_memory(np.minimum(tau, self.caps), c, memory, rng)

    def describe(self) -> dict[str, Any]:
        return {**self.policy.describe(), "clipped_at": self.caps.tolist()}
