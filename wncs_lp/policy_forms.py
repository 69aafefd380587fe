r"""The forms a stationary policy takes on an enumerated MDP, and the one converter pair.

On an :class:`~wncs_lp.mdp.MDP` with n states and L state-action pairs a deterministic policy is
written two ways, both (n,) integer arrays, so they are told apart by **name**, never by shape:

``policy`` (pair indices)
    ``policy[s]`` is the chosen pair l of state s (``mdp.s_indices[l] == s``): the form of
    :attr:`Solution.policy <wncs_lp.solvers.result.Solution.policy>`, of the LP's occupation
    measure and of :func:`wncs_lp.chain.policy_matrices`. It indexes the per-pair arrays
    directly: ``mdp.cost[policy]``, ``mdp.P[policy]``.
``sigma`` (action per state)
    ``sigma[s]`` is the chosen **action** a of state s, a row of ``mdp.action_table`` (the value
    ``mdp.a_indices[l]`` of the chosen pair): :attr:`Solution.sigma
    <wncs_lp.solvers.result.Solution.sigma>`, QuantEcon's ``DiscreteDP`` ``sigma`` and the
    ``sigma`` entry of ``wncs-lp solve --out``. It reads as a decision:
    ``mdp.action_table[sigma[s]]`` is what every server is sent in state s.

    .. math:: \sigma(s) = a_{\pi(s)}, \qquad \pi(s) = \text{the pair } l \text{ of } s \text{ with } a_l = \sigma(s).

A randomised policy is an (L,) float array of pair probabilities (summing to one over the pairs of
each state). :func:`pairs_to_sigma` and :func:`sigma_to_pairs` convert between the two
deterministic forms; :func:`policy_array` turns any documented form (a ``Policy``, a solution,
``policy=`` or ``sigma=``) into the array the evaluators take. A bad shape, dtype or range is one
:class:`~wncs_lp.errors.PolicyError` naming what was expected.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .errors import PolicyError
from .mdp import MDP

__all__ = ["pairs_to_sigma", "sigma_to_pairs", "check_pairs", "policy_array"]


def _state(mdp: MDP, s: int) -> str:
    """State s as the MDP labels it (its decoded (tau, configuration) when it has one)."""
    return f"state {s} ({mdp.state_label(s)})" if mdp.states is not None else f"state {s}"


def _actions(mdp: MDP, s: int) -> str:
    """The actions of state s: their indices, with their labels when the MDP decodes them."""
    ls = mdp.pairs_of(s)
    if mdp.action_table is None:
        return ", ".join(str(int(mdp.a_indices[l])) for l in ls)
    return ", ".join(f"{int(mdp.a_indices[l])} = {mdp.action_label(l)}" for l in ls)


def _integers(a: Any, n: int, name: str, meaning: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.integer) or arr.dtype == np.bool_:
        raise PolicyError(f"{name} must be an integer array of shape ({n},) ({meaning}); got dtype {arr.dtype}")
    if arr.shape != (n,):
        raise PolicyError(f"{name} must have shape ({n},) ({meaning}); got shape {arr.shape}")
    return arr.astype(np.int64)


def pairs_to_sigma(mdp: MDP, policy: Any) -> np.ndarray:
    """The action per state (``sigma``) of a policy given as pair indices.

    Parameters
    ----------
    mdp : MDP
    policy : (n,) int array
        ``policy[s]`` = a pair of state s (:attr:`Solution.policy`).

    Returns
    -------
    (n,) int64 array
        ``sigma[s] = mdp.a_indices[policy[s]]``, a row of ``mdp.action_table``.

    Raises
    ------
    PolicyError
        Wrong shape or dtype, a pair index out of range, or a pair of another state.
    """
    pol = check_pairs(mdp, policy)
    return np.asarray(mdp.a_indices, dtype=np.int64)[pol]


def sigma_to_pairs(mdp: MDP, sigma: Any) -> np.ndarray:
    """The pair indices (``policy``) of a policy given as an action per state.

    Parameters
    ----------
    mdp : MDP
    sigma : (n,) int array
        ``sigma[s]`` = an action of state s, a row of ``mdp.action_table`` (:attr:`Solution.sigma`).

    Returns
    -------
    (n,) int64 array
        The pair l of state s with ``mdp.a_indices[l] == sigma[s]``.

    Raises
    ------
    PolicyError
        Wrong shape or dtype, or an action that is not one of its state's (the message names the
        state and the actions it has).
    """
    n, L = mdp.n_states, mdp.n_pairs
    sig = _integers(sigma, n, "sigma", "one action per state: a row of mdp.action_table")
    a = np.asarray(mdp.a_indices, dtype=np.int64)
    match = a == sig[np.asarray(mdp.s_indices, dtype=np.int64)]
    cand = np.where(match, np.arange(L, dtype=np.int64), np.int64(L))
    pairs = np.minimum.reduceat(cand, mdp.pair_ptr[:-1]) if n else cand[:0]
    bad = np.flatnonzero(pairs >= L)
    if bad.size:
        s = int(bad[0])
        raise PolicyError(f"sigma[{s}] = {int(sig[s])} is not an action of {_state(mdp, s)}; its actions (rows of "
                          f"mdp.action_table) are {_actions(mdp, s)}"
                          + (f" ({bad.size} such states in all)" if bad.size > 1 else ""))
    return pairs


def check_pairs(mdp: MDP, policy: Any) -> np.ndarray:
    """``policy`` as (n,) int64 pair indices, each a pair of its own state, else one
    :class:`PolicyError` (with a hint when the array reads as ``sigma`` instead)."""
    n, L = mdp.n_states, mdp.n_pairs
    pol = _integers(policy, n, "policy", "one pair index per state, as Solution.policy")
    out = (pol < 0) | (pol >= L)
    wrong = out.copy()
    wrong[~out] = np.asarray(mdp.s_indices)[pol[~out]] != np.flatnonzero(~out)
    if wrong.any():
        s = int(np.flatnonzero(wrong)[0])
        lo, hi = int(mdp.pair_ptr[s]), int(mdp.pair_ptr[s + 1])
        what = "out of range" if out[s] else f"a pair of state {int(mdp.s_indices[pol[s]])}"
        hint = ""
        try:
            sigma_to_pairs(mdp, pol)
            hint = "; it reads as an action per state: pass it as sigma= (or convert with sigma_to_pairs)"
        except PolicyError:
            pass
        raise PolicyError(f"policy[{s}] = {int(pol[s])} is {what}; expected a pair index of {_state(mdp, s)}, "
                          f"in {lo}..{hi - 1}{hint}")
    return pol


def policy_array(mdp: MDP, policy: Any = None, sigma: Any = None) -> np.ndarray:
    """The array form of a policy given in any documented form (module docstring).

    Parameters
    ----------
    mdp : MDP
    policy : Policy, Solution, array, optional
        A :class:`~wncs_lp.policies.Policy` (anything with ``on_mdp``), a solution (anything with
        a ``policy`` attribute: ``Solution``, ``ConstrainedSolution``), (n,) int pair indices or
        (L,) float pair probabilities.
    sigma : (n,) int array, optional
        The action per state instead.

    Returns
    -------
    (n,) int64 pair indices, or (L,) float64 pair probabilities.

    Raises
    ------
    PolicyError
        Neither or both given, or a malformed array (the message says what was expected).
    """
    if (policy is None) == (sigma is None):
        raise PolicyError("give the policy exactly one way: policy= (a Policy, a solution, pair indices or pair "
                          "probabilities) or sigma= (an action per state)")
    if sigma is not None:
        return sigma_to_pairs(mdp, sigma)
    if hasattr(policy, "on_mdp"):
        policy = policy.on_mdp(mdp)  # a Policy: an array; a matrix-free solution: a Solution
    if hasattr(policy, "policy") and not isinstance(policy, np.ndarray):
        policy = policy.policy
    arr = np.asarray(policy)
    if np.issubdtype(arr.dtype, np.floating):
        if arr.shape != (mdp.n_pairs,):
            raise PolicyError(f"a randomised policy must be ({mdp.n_pairs},) pair probabilities, one per "
                              f"state-action pair; got shape {arr.shape}")
        return arr.astype(np.float64)
    return check_pairs(mdp, arr)
