"""Randomised stationary policies given on an enumerated MDP: :class:`MixedPolicy`.

A randomised policy is an (L,) float array of pair probabilities ``probs[l] = pi(a_l | s_l)``
(nonnegative, summing to 1 over the pairs of each state), the form a constrained solve returns
(:class:`~wncs_lp.constrained.result.ConstrainedSolution` ``.policy``). :class:`MixedPolicy`
makes it a :class:`~wncs_lp.policies.base.Policy` like any other:

* exact evaluation: ``on_mdp(mdp)`` returns the probabilities (``wncs_lp.evaluate.evaluate``);
* simulation: ``act(tau, config_ids, rng)`` looks every state up in the MDP and draws one
  uniform u per row from ``rng``; the action is the first local index whose cumulative
  probability exceeds u (pairs of probability 0 are never drawn);
* maps and export: ``policy`` (= ``probs``) lets it stand where a solution does.

:func:`pair_probabilities` is the one normaliser of "a policy on an MDP" to pair probabilities
(used by the maps and the export); :func:`check_probabilities` the one validator, whose
:class:`~wncs_lp.errors.PolicyError` names the first bad state.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..chain import PROB_SUM_TOL
from ..errors import PolicyError
from ..mdp import MDP
from ..models.system import System
from .base import Policy, as_rng

__all__ = ["MixedPolicy", "check_probabilities", "pair_probabilities", "randomised_states"]


def _state_text(mdp: MDP, s: int) -> str:
    return f"state {s} ({mdp.state_label(s)})"


def check_probabilities(mdp: MDP, probs: Any, what: str = "randomised policy") -> np.ndarray:
    """Validate (L,) pair probabilities on ``mdp``; return them as a float64 array (a copy).

    Raises
    ------
    PolicyError
        Wrong shape or dtype, a negative or non-finite probability, or a state whose
        probabilities do not sum to 1 within :data:`wncs_lp.chain.PROB_SUM_TOL`. One error,
        naming the first bad state (and how many others are bad).
    """
    p = np.asarray(probs)
    L = mdp.n_pairs
    if p.dtype == object or not (np.issubdtype(p.dtype, np.floating) or np.issubdtype(p.dtype, np.integer)) \
            or np.issubdtype(p.dtype, np.bool_):
        raise PolicyError(f"{what}: pair probabilities must be a float array of shape ({L},), got dtype {p.dtype}")
    if p.shape != (L,):
        raise PolicyError(f"{what}: pair probabilities must have shape ({L},) (one per state-action pair of "
                          f"{mdp.name}), got {p.shape}")
    p = p.astype(np.float64)
    bad_pair = ~np.isfinite(p) | (p < 0)
    if bad_pair.any():
        l = int(np.flatnonzero(bad_pair)[0])
        s = int(mdp.s_indices[l])
        others = int(np.unique(mdp.s_indices[bad_pair]).size) - 1
        more = f" (and {others} more state(s))" if others else ""
        raise PolicyError(f"{what}: {_state_text(mdp, s)} has probability {float(p[l])!r} on action "
                          f"{mdp.action_label(l)} (pair {l}); probabilities must be finite and >= 0{more}")
    sums = np.add.reduceat(p, mdp.pair_ptr[:-1]) if L else np.zeros(0)
    off = np.abs(sums - 1.0) > PROB_SUM_TOL
    if off.any():
        s = int(np.flatnonzero(off)[0])
        others = int(off.sum()) - 1
        more = f" (and {others} more state(s))" if others else ""
        raise PolicyError(f"{what}: the probabilities of {_state_text(mdp, s)} sum to {sums[s]:.12g}, "
                          f"expected 1 (within {PROB_SUM_TOL:g}){more}")
    return p


def _one_hot(mdp: MDP, pol: np.ndarray, what: str) -> np.ndarray:
    n, L = mdp.n_states, mdp.n_pairs
    if pol.shape != (n,):
        raise PolicyError(f"{what}: a deterministic policy must have shape ({n},) (one pair per state), "
                          f"got {pol.shape}")
    pol = pol.astype(np.int64)
    bad = (pol < 0) | (pol >= L)
    if not bad.any():
        bad = mdp.s_indices[pol] != np.arange(n)
    if bad.any():
        s = int(np.flatnonzero(bad)[0])
        raise PolicyError(f"{what}: pair {int(pol[s])} chosen in {_state_text(mdp, s)} is not one of its pairs "
                          f"({int(mdp.pair_ptr[s])}..{int(mdp.pair_ptr[s + 1]) - 1})")
    out = np.zeros(L)
    out[pol] = 1.0
    return out


def pair_probabilities(mdp: MDP, policy: Any, what: str = "policy") -> np.ndarray:
    """Any stationary policy on ``mdp`` as validated (L,) pair probabilities (float64).

    ``policy`` may be a :class:`~wncs_lp.policies.base.Policy` (mapped with ``on_mdp``), an
    object with a ``.policy`` array (a ``Solution``, a ``ConstrainedSolution``, a
    :class:`MixedPolicy`), an (n,) integer array of pair indices (made one-hot) or an (L,)
    float array of pair probabilities.
    """
    if isinstance(policy, Policy):
        arr = policy.on_mdp(mdp)
    else:
        arr = getattr(policy, "policy", policy)
    arr = np.asarray(arr)
    if np.issubdtype(arr.dtype, np.integer) and not np.issubdtype(arr.dtype, np.bool_):
        return _one_hot(mdp, arr, what)
    return check_probabilities(mdp, arr, what)


def randomised_states(mdp: MDP, probs: np.ndarray) -> np.ndarray:
    """The states where two or more pairs have positive probability (sorted int array)."""
    counts = np.add.reduceat((np.asarray(probs) > 0).astype(np.int64), mdp.pair_ptr[:-1])
    return np.flatnonzero(counts > 1)


class MixedPolicy(Policy):
    """A stationary randomised policy given by pair probabilities on an enumerated MDP.

    Parameters
    ----------
    system : System
        The scenario's system; ``mdp`` must have been built from it.
    mdp : MDP
        The enumerated MDP the probabilities live on.
    probs : (L,) float array
        ``probs[l]`` = probability of pair l in its state (nonnegative, sum 1 per state);
        an (n,) integer array of pair indices is accepted too (made one-hot).
    name : str, optional
        Default ``"mixed"``.

    Attributes
    ----------
    probs : (L,) float array (read-only)
    policy : the same array, so the policy stands where a solution does (maps, export)
    randomised_states : (r,) int array
        The states where it mixes two or more actions.

    Raises
    ------
    PolicyError
        ``mdp`` not built from ``system``, or bad probabilities (the message names the state).
    """

    name = "mixed"
    randomised = True

    def __init__(self, system: System, mdp: MDP, probs: Any, name: str | None = None):
        super().__init__(system)
        system.check_mdp(mdp)
        p = np.asarray(probs)
        if np.issubdtype(p.dtype, np.integer) and not np.issubdtype(p.dtype, np.bool_):
            p = _one_hot(mdp, p, "MixedPolicy")
        else:
            p = check_probabilities(mdp, p, "MixedPolicy")
        n_pairs = np.diff(mdp.pair_ptr)
        cfg = np.asarray(mdp.states.config, dtype=np.int64)
        if np.any(n_pairs != system.n_actions[cfg]):
            s = int(np.flatnonzero(n_pairs != system.n_actions[cfg])[0])
            raise PolicyError(f"MixedPolicy: {_state_text(mdp, s)} has {int(n_pairs[s])} pairs in the MDP but its "
                              f"configuration has {int(system.n_actions[cfg[s]])} actions")
        p.setflags(write=False)
        self.mdp = mdp
        self.probs = p
        if name is not None:
            self.name = name
        self.randomised_states = randomised_states(mdp, p)
        self.randomised_states.setflags(write=False)
        # (n, A) cumulative probabilities by local action; from the last action of positive
        # probability on, +inf, so round-off never draws a pair of probability 0
        n, A = mdp.n_states, int(n_pairs.max()) if n_pairs.size else 1
        local = np.arange(mdp.n_pairs) - mdp.pair_ptr[mdp.s_indices]
        table = np.zeros((n, A))
        table[mdp.s_indices, local] = p
        table.setflags(write=False)
        self._table = table
        cum = np.cumsum(table, axis=1)
        pos = table > 0
        last = A - 1 - np.argmax(pos[:, ::-1], axis=1)
        cum[np.arange(A)[None, :] >= last[:, None]] = np.inf
        self._cum = cum

    @classmethod
    def from_solution(cls, system: System, mdp: MDP, solution: Any, name: str | None = None) -> "MixedPolicy":
        """Wrap a solution's policy: a ``ConstrainedSolution`` (or anything with a float ``.policy``
        of pair probabilities), or a deterministic ``Solution`` (int ``.policy``: made one-hot).

        The name defaults to ``"mixed[<method>]"`` when the solution has a ``method``.
        """
        if not hasattr(solution, "policy"):
            raise PolicyError("MixedPolicy.from_solution needs an object with a .policy array, "
                              f"got {type(solution).__name__}")
        method = getattr(solution, "method", None)
        return cls(system, mdp, solution.policy, name=name or (f"mixed[{method}]" if method else None))

    # ------------------------------------------------------------------ properties
    @property
    def policy(self) -> np.ndarray:
        """The (L,) pair probabilities (same array as ``probs``)."""
        return self.probs

    @property
    def n_randomised(self) -> int:
        return int(self.randomised_states.size)

    # ------------------------------------------------------------------ acting
    def states_of(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """MDP state ids of (tau, C) (raises :class:`PolicyError` for a state not in the MDP)."""
        tau, c = self._check_inputs(tau, config_ids)
        caps = np.asarray(self.mdp.states.caps, dtype=np.int64)
        n_cfg = len(self.mdp.states.configs)
        bad = ((tau < 1) | (tau > caps)).any(axis=1) | (c < 0) | (c >= n_cfg)
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise PolicyError(f"policy {self.name}: state tau={tau[r].tolist()}, configuration {int(c[r])} is outside "
                              f"the MDP's box (caps {caps.tolist()}, {n_cfg} configurations)")
        s = self.mdp.states.ids(tau, c)
        if np.any(s < 0):
            r = int(np.flatnonzero(s < 0)[0])
            raise PolicyError(f"policy {self.name}: state tau={tau[r].tolist()}, configuration {int(c[r])} "
                              "is not in the MDP")
        return s

    def probabilities(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A) probabilities of the local actions in R states (0 beyond a state's actions)."""
        return self._table[self.states_of(tau, config_ids)]

    def act(self, tau, config_ids, rng=None):
        s = self.states_of(tau, config_ids)
        u = as_rng(rng).random(s.size)
        return (u[:, None] >= self._cum[s]).sum(axis=1).astype(np.int64)

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        """The (L,) pair probabilities (a copy), on this MDP or one built identically.

        Raises
        ------
        PolicyError
            ``mdp`` is of another scenario, or numbers its states and pairs differently.
        """
        if mdp is not self.mdp:
            self.system.check_mdp(mdp)
            same = (mdp.n_states == self.mdp.n_states and mdp.n_pairs == self.mdp.n_pairs
                    and np.array_equal(mdp.pair_ptr, self.mdp.pair_ptr)
                    and np.array_equal(mdp.a_indices, self.mdp.a_indices)
                    and np.array_equal(mdp.states.tau, self.mdp.states.tau)
                    and np.array_equal(mdp.states.config, self.mdp.states.config))
            if not same:
                raise PolicyError(
                    f"policy {self.name}: the MDP ({mdp.n_states} states, {mdp.n_pairs} pairs) is not the one its "
                    f"probabilities were given on ({self.mdp.n_states} states, {self.mdp.n_pairs} pairs)")
        return self.probs.copy()

    # ------------------------------------------------------------------ reports
    def mixes(self, limit: int | None = None) -> list[dict[str, Any]]:
        """The randomised states with their mix (actions of positive probability only).

        Actions are named as on policy maps (:func:`wncs_lp.policy_grids.action_name`), as in
        :meth:`ConstrainedSolution.mixes <wncs_lp.constrained.result.ConstrainedSolution.mixes>`.

        Returns
        -------
        list of ``{"state": s, "label": str, "tau": [...], "config": c, "mix": {action name: prob}}``
        in state order (the first ``limit`` when given).
        """
        from ..policy_grids import action_name, map_names

        names = map_names(self.mdp, self.system.scenario)
        out = []
        st = self.mdp.states
        for s in self.randomised_states[:limit]:
            s = int(s)
            c = int(st.config[s])
            mix = {action_name(self.mdp, int(self.mdp.a_indices[l]), c, names=names): float(self.probs[l])
                   for l in self.mdp.pairs_of(s) if self.probs[l] > 0}
            out.append({"state": s, "label": self.mdp.state_label(s), "tau": [int(x) for x in st.tau[s]],
                        "config": int(st.config[s]), "mix": mix})
        return out

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "randomised_states": self.n_randomised, "mixes": self.mixes(limit=20)}

    def __repr__(self) -> str:
        return f"MixedPolicy({self.name!r}, randomised_states={self.n_randomised})"
