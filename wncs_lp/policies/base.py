"""The policy interface: one ``act`` over (tau, configuration) arrays, one ``on_mdp``; and the
policies of one's own: from a function of (tau, configuration) (:meth:`Policy.from_function`),
from an action per state or pair indices on an enumerated MDP (:meth:`Policy.from_sigma`,
:meth:`Policy.from_pairs`).

See :mod:`wncs_lp.policies` for the two uses of a policy, and :mod:`wncs_lp.policy_forms` for the
array forms (``policy`` = pair indices, ``sigma`` = action per state).
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

import numpy as np

from ..errors import PolicyError
from ..mdp import MDP
from ..models.system import System
from ..policy_forms import check_pairs, policy_array, sigma_to_pairs

__all__ = ["Policy", "as_rng", "Configuration", "FunctionPolicy", "MemoryPolicy", "TablePolicy", "system_of"]


def as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    """A ``numpy.random.Generator`` from a generator, a seed or None."""
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


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
    #: The rule reads the AoI only through the system's cost tables (or not at all), so it is
    #: defined for any AoI, also past the cap: :meth:`on_system` moves it to another system.
    aoi_free: bool = False
    #: Whether the policy works on a lazily explored system (:meth:`System.expand`): it asks for
    #: nothing but the configurations it is shown. Others need the whole automaton and refuse one.
    explores_lazily: bool = False

    def __init__(self, system: System):
        self.refuse_lazy(system)
        self.system = system

    def on_system(self, system: System) -> "Policy":
        """The same rule on another system with the same configurations (larger caps, or the
        uncapped system of :mod:`wncs_lp.untruncated`); only for an :attr:`aoi_free` rule.

        Raises
        ------
        PolicyError
            The policy is a table over its own AoI box (optimal, suboptimal, ...): clip its AoI
            instead (:class:`~wncs_lp.policies.ClippedPolicy`).
        """
        if not self.aoi_free:
            raise PolicyError(f"policy {self.name} is defined on its own AoI box only: clip the AoI instead "
                              "(ClippedPolicy)")
        import copy

        other = copy.copy(self)
        other.system = system
        if isinstance(getattr(other, "_cache", None), dict):
            other._cache = {}
        return other

    @classmethod
    def refuse_lazy(cls, system: System) -> None:
        """Raise :class:`PolicyError` when ``system`` is explored lazily and this policy needs its
        whole automaton (:attr:`explores_lazily` false), naming the policies that run there."""
        if getattr(system, "is_lazy", False) and not cls.explores_lazily:
            raise PolicyError(
                f"{cls.__name__} needs the whole configuration automaton, which {system.scenario.source} has too many "
                "configurations to enumerate (it is explored lazily, configuration by configuration as a simulation "
                "meets them); policies that run there: the bound's policy (relaxations 1 and 3), greedy, static")

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

    # policies of one's own -------------------------------------------------------
    @classmethod
    def from_function(cls, system: Any, f: Callable[[tuple, "Configuration"], Any],
                      name: str = "custom") -> "FunctionPolicy":
        """A deterministic policy from a function ``f(tau, configuration) -> action label``.

        Parameters
        ----------
        system : System, Scenario or MDP
            The scenario's system (an MDP built from a scenario, or the scenario, gives it).
        f : callable
            Called as ``f(tau, configuration)`` with ``tau`` a tuple of ints (the AoI of each
            process, 1..tau_hat_k) and ``configuration`` a :class:`Configuration` (its model's
            readable ``description``, ``idle``, per-server ``accepts``, the allowed ``actions``).
            Returns an action label: a tuple of per-server process indices as in
            ``system.automaton.actions[c]`` (for the wncs model ``(a_1, ..., a_M)``, ``a_m = k``
            sends process k to server m, 0 sends nothing); one of ``configuration.actions``.
        name : str

        Returns
        -------
        FunctionPolicy
            ``f`` is called once per distinct state the policy is asked about (cached).
        """
        return FunctionPolicy(system_of(system), f, name=name)

    @classmethod
    def from_sigma(cls, mdp: MDP, sigma: Any, name: str = "sigma") -> "TablePolicy":
        """A deterministic policy from an action per state of an enumerated MDP (``sigma[s]``: a
        row of ``mdp.action_table``, as :attr:`Solution.sigma`), e.g. to simulate it."""
        return TablePolicy(system_of(mdp), mdp, sigma_to_pairs(mdp, sigma), name=name)

    @classmethod
    def from_pairs(cls, mdp: MDP, policy: Any, name: str = "pairs") -> "TablePolicy":
        """A deterministic policy from pair indices of an enumerated MDP (:attr:`Solution.policy`)."""
        return TablePolicy(system_of(mdp), mdp, check_pairs(mdp, policy), name=name)

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


def system_of(obj: Any) -> System:
    """The :class:`System` of a system, a scenario or an MDP built from a scenario."""
    if isinstance(obj, System):
        return obj
    from ..scenario import Scenario

    if isinstance(obj, Scenario):
        return System.from_scenario(obj)
    if isinstance(obj, MDP):
        model = getattr(obj.states, "model", None)
        if model is None:
            raise PolicyError(f"{obj!r} carries no model (read back from a file, or made by hand): give the "
                              "scenario's System instead (System.from_scenario(scenario))")
        return System.from_scenario(model.scenario, model)
    raise PolicyError(f"expected a System, a Scenario or an MDP built from a scenario; got {type(obj).__name__}")


@dataclass(frozen=True)
class Configuration:
    """A configuration of the automaton as a policy of one's own sees it (:meth:`Policy.from_function`).

    Everything is asked of the scenario's model, so a function written against these fields works
    for every model kind.

    Attributes
    ----------
    id : int
        The automaton's configuration id (``system.automaton.configs[id]``).
    description : str
        The model's readable one-line form (``"remote: idle; edge: job 1 d=2"``); also ``str()``.
    idle : bool
        Every server idle and every pipeline empty.
    accepts : tuple of bool
        Per server (in the scenario's order): whether a new update may be sent to it now.
    servers : tuple of str
        The server names, in the order of ``accepts`` and of an action label's entries.
    actions : tuple of tuple of int
        The allowed action labels, in the MDP's action order.
    raw : object
        The model's own configuration object (its layout is the model's business).
    """

    id: int
    description: str
    idle: bool
    accepts: tuple[bool, ...]
    servers: tuple[str, ...]
    actions: tuple[tuple[int, ...], ...]
    raw: Hashable = field(repr=False, default=None)

    def __str__(self) -> str:
        return self.description

    @classmethod
    def of(cls, system: System, c: int) -> "Configuration":
        model, raw = system.model, system.automaton.configs[c]
        return cls(id=int(c), description=model.describe(raw), idle=bool(model.is_idle(raw)),
                   accepts=tuple(bool(x) for x in model.accepts(raw)),
                   servers=tuple(s.name for s in system.scenario.servers),
                   actions=tuple(tuple(int(x) for x in a) for a in system.automaton.actions[c]), raw=raw)


def _label(value: Any) -> tuple[int, ...] | None:
    """An action label as a tuple of ints (a bare int for a one-entry label), or None."""
    try:
        if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
            return (int(value),)
        items = tuple(value)
        if all(isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_)) for x in items):
            return tuple(int(x) for x in items)
    except TypeError:
        pass
    return None


class FunctionPolicy(Policy):
    """A deterministic policy given by a function of (tau, configuration): :meth:`Policy.from_function`.

    ``act`` calls the function once per distinct state it has not seen yet and remembers the
    answer, so a simulation (R states a slot, mostly revisited) or ``on_mdp`` (every state once)
    costs one call per distinct state.
    """

    def __init__(self, system: System, f: Callable[[tuple, Configuration], Any], name: str = "custom"):
        super().__init__(system)
        if not callable(f):
            raise PolicyError(f"Policy.from_function needs a function of (tau, configuration); got {type(f).__name__}")
        self.f = f
        self.name = name
        self._configs: dict[int, Configuration] = {}
        self._cache: dict[int, int] = {}
        caps = [int(c) for c in system.caps]
        self._box = math.prod(caps)
        self._strides = np.array([math.prod(caps[k + 1:]) for k in range(len(caps))], dtype=np.int64)
        if self._box * max(system.n_configs, 1) >= 2 ** 62:  # pragma: no cover - boxes beyond int64
            raise PolicyError(f"policy {name}: the AoI box of {self._box} vectors is too large to index")

    def configuration(self, c: int) -> Configuration:
        """The :class:`Configuration` the function is shown for configuration id ``c``."""
        if c not in self._configs:
            self._configs[c] = Configuration.of(self.system, c)
        return self._configs[c]

    def _decide(self, tau: np.ndarray, c: int) -> int:
        conf = self.configuration(c)
        t = tuple(int(x) for x in tau)
        value = self.f(t, conf)
        label = _label(value)
        j = self.system.label_index[c].get(label) if label is not None else None
        if j is None:
            allowed = ", ".join(str(a) for a in conf.actions)
            raise PolicyError(f"policy {self.name}: the function returned {value!r} in state tau={t}, configuration "
                              f"{c} [{conf.description}]; the action labels allowed there are {allowed}")
        return int(j)

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        if tau.shape[1] != self._strides.size or np.any(tau < 1) or np.any(tau > self.system.caps):
            raise PolicyError(f"policy {self.name}: tau must have {self._strides.size} columns in 1..tau_hat = "
                              f"{self.system.caps.tolist()}")
        keys = c * self._box + (tau - 1) @ self._strides
        uniq, first, inv = np.unique(keys, return_index=True, return_inverse=True)
        out = np.empty(uniq.size, dtype=np.int64)
        for i, (key, r) in enumerate(zip(uniq.tolist(), first.tolist())):
            j = self._cache.get(key)
            if j is None:
                j = self._cache[key] = self._decide(tau[r], int(c[r]))
            out[i] = j
        return out[inv.reshape(-1)]

    def describe(self) -> dict[str, Any]:
        return {"policy": self.name, "randomised": False, "kind": "function",
                "function": getattr(self.f, "__qualname__", repr(self.f)), "states_decided": len(self._cache)}


class TablePolicy(Policy):
    """A deterministic policy stored as one pair per state of an enumerated MDP
    (:meth:`Policy.from_sigma`, :meth:`Policy.from_pairs`); ``act`` looks states up in the MDP."""

    def __init__(self, system: System, mdp: MDP, pairs: np.ndarray, name: str = "table"):
        super().__init__(system)
        system.check_mdp(mdp)
        self.mdp = mdp
        self.pairs = check_pairs(mdp, pairs)
        self.name = name
        self._local = self.pairs - mdp.pair_ptr[:-1]

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        s = self.mdp.states.ids(tau, c)
        if np.any(s < 0):
            r = int(np.flatnonzero(s < 0)[0])
            raise PolicyError(f"policy {self.name}: state tau={tau[r].tolist()}, configuration {int(c[r])} is not in "
                              "the MDP")
        return self._local[s]

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        if mdp is self.mdp:
            return self.pairs.copy()
        return super().on_mdp(mdp)



class MemoryPolicy(Policy):
    r"""A deterministic policy with a finite memory: the action depends on the state (tau, C) and
    on a memory value m in 0..``memory_size`` - 1, which moves deterministically with the action
    taken: m' = :meth:`next_memory` (m, C, j). Round robin's pointer is one
    (:class:`~wncs_lp.policies.baselines.RoundRobinPolicy`).

    Such a policy is not a stationary policy of the MDP, so ``act`` and ``on_mdp`` refuse (one
    :class:`~wncs_lp.errors.PolicyError` saying where it is evaluated instead). It is evaluated
    exactly on the augmented chain over (s, m) (:func:`wncs_lp.evaluate.evaluate`: n x
    ``memory_size`` states), and simulated with its memory carried along
    (:func:`wncs_lp.simulate.simulate`, from :attr:`initial_memory` in every replication).
    """

    memory_size: int = 1
    initial_memory: int = 0

    @abstractmethod
    def act_memory(self, tau: np.ndarray, config_ids: np.ndarray, memory: np.ndarray,
                   rng: np.random.Generator | None = None) -> np.ndarray:
        """Local action indices for R states with their memory values ``memory`` ((R,) ints)."""

    @abstractmethod
    def next_memory(self, memory: np.ndarray, config_ids: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(R,) memory values after local actions ``actions`` were taken in configurations ``config_ids``."""

    def start_memory(self, reps: int) -> np.ndarray:
        """(R,) memory values of R fresh replications (all :attr:`initial_memory`)."""
        return np.full(int(reps), int(self.initial_memory), dtype=np.int64)

    def _refuse(self, what: str) -> PolicyError:
        return PolicyError(f"policy {self.name} has a memory ({self.memory_size} values): it is no stationary policy "
                           f"of (tau, C), so {what}; evaluate it exactly with wncs_lp.evaluate.evaluate (its "
                           "augmented chain) or simulate it")

    def act(self, tau, config_ids, rng=None):
        raise self._refuse("act() needs its memory (act_memory)")

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        raise self._refuse("it has no single action per state of the MDP")

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "memory_size": int(self.memory_size)}
