"""Policies as tidy tables, state by state: what ``to_frame()`` of a solution shows.

One row per state (a deterministic policy) or per state and action played (a randomised one):
the decoded state (``tau_1`` ... ``tau_N`` and the configuration) where the MDP has decoded
states, the action by its name (as on policy maps, :func:`wncs_lp.policy_grids.action_name`), its index
(QuantEcon's ``sigma``), and the bias or the probability. The columns are built as whole arrays
(a name is computed once per distinct action and configuration), so a table of 10^5 states takes
a fraction of a second. The state columns and the action names are read through the one state-space
interface (:mod:`wncs_lp.spaces`), so an MDP's table and a matrix-free layout's table
(:func:`layout_columns`) are built by the same code.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from .errors import WncsError
from .spaces import BoxSpace, Space, space_of

__all__ = ["policy_columns", "mixed_policy_records", "layout_columns", "MAX_TABLE_ROWS"]

#: Largest table :func:`layout_columns` builds (a matrix-free layout can hold 10^8 states).
MAX_TABLE_ROWS = 5_000_000


def _decoded(mdp: Any) -> bool:
    st = getattr(mdp, "states", None)
    return st is not None and getattr(st, "configs", None) is not None and getattr(st, "tau", None) is not None


def _action_names(space: Space, actions: np.ndarray, configs: np.ndarray) -> np.ndarray:
    """The name of each (action index, configuration id), computed once per distinct pair."""
    names = space.names()
    key = np.stack([np.asarray(actions, np.int64), np.asarray(configs, np.int64)], axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    table = np.array([space.action_name(int(c), int(a), names) for a, c in uniq], dtype=object)
    return table[np.asarray(inv).ravel()]


def _space_columns(space: Space, states: np.ndarray, actions: np.ndarray | None) -> dict[str, Any]:
    """The columns every table of a state space has: ``state``, ``tau_k``, ``configuration`` and,
    given the action index per row, ``action`` (its name)."""
    cols: dict[str, Any] = {"state": states}
    tau = space.tau_of(states)
    for k in range(tau.shape[1]):
        cols[f"tau_{k + 1}"] = tau[:, k]
    cid = np.asarray(space.config_of(states))
    desc = np.array([space.describe(c) for c in range(len(space.configs))], dtype=object)
    cols["configuration"] = desc[cid]
    if actions is not None:
        cols["action"] = _action_names(space, actions, cid)
    return cols


def _state_part(mdp: Any, states: np.ndarray) -> tuple[list[str], dict[str, Any]]:
    """The state columns: ``state``, then ``tau_k`` and ``configuration`` (decoded MDPs) or ``label``."""
    if _decoded(mdp):
        cols = _space_columns(space_of(mdp), states, None)
    else:
        cols = {"state": states}
        if mdp is not None:
            cols["label"] = np.array([mdp.state_label(int(s)) for s in states], dtype=object)
    return list(cols), cols


def _action_part(mdp: Any, pairs: np.ndarray, states: np.ndarray) -> dict[str, Any]:
    a = np.asarray(mdp.a_indices)[pairs]
    if _decoded(mdp) and mdp.action_table is not None:
        space = space_of(mdp)
        return {"action": _action_names(space, a, space.config_of(states)), "sigma": a}
    return {"action": np.array([str(mdp.action_label(int(l))) for l in pairs], dtype=object), "sigma": a}


def policy_columns(mdp: Any, policy: np.ndarray, *, bias: np.ndarray | None = None,
                   sigma: np.ndarray | None = None) -> tuple[list[str], dict[str, Any]]:
    """The table of a deterministic policy (pair indices, one per state), as columns.

    Parameters
    ----------
    mdp : MDP or None
        With it: the decoded state and the action's name. Without it: the pair index and ``sigma``.
    policy : (n,) int array
        Pair index per state.
    bias : (n,) array, optional
    sigma : (n,) int array, optional
        The action index per state, when known without the MDP.

    Returns
    -------
    (columns, {column: array})
    """
    policy = np.asarray(policy, dtype=np.int64)
    n = policy.size
    states = np.arange(n, dtype=np.int64)
    if mdp is not None and mdp.n_states != n:
        raise WncsError(f"the policy has {n:,} states, the MDP {mdp.n_states:,}: not this MDP's solution")
    if mdp is None:
        names, cols = ["state", "pair"], {"state": states, "pair": policy}
        if sigma is not None:
            names.append("sigma")
            cols["sigma"] = np.asarray(sigma)
    else:
        names, cols = _state_part(mdp, states)
        cols.update(_action_part(mdp, policy, states))
        names += ["action", "sigma"]
    if bias is not None and np.asarray(bias).size == n:
        names.append("bias")
        cols["bias"] = np.asarray(bias, dtype=float)
    return names, cols


def mixed_policy_records(mdp: Any, probs: np.ndarray, *, tol: float = 0.0) -> tuple[list[str], dict[str, Any]]:
    """The table of a randomised policy (pair probabilities): one row per state and action played
    with probability above ``tol`` (``probability`` column; each state's rows sum to 1)."""
    probs = np.asarray(probs, dtype=float)
    if mdp is None:
        raise WncsError("the table of a randomised policy needs its MDP: to_frame(mdp)")
    if probs.shape != (mdp.n_pairs,):
        raise WncsError(f"the policy has {probs.size:,} pair probabilities, the MDP {mdp.n_pairs:,} pairs")
    pairs = np.flatnonzero(probs > tol)
    states = np.asarray(mdp.s_indices)[pairs]
    names, cols = _state_part(mdp, states)
    cols.update(_action_part(mdp, pairs, states))
    cols["probability"] = probs[pairs]
    return names + ["action", "sigma", "probability"], cols


def layout_columns(system: Any, layout: Any, local_actions: np.ndarray, bias: np.ndarray | None = None,
                   mask: np.ndarray | None = None) -> tuple[list[str], dict[str, Any]]:
    """The table of a matrix-free policy over a :class:`~wncs_lp.solvers.matrix_free.BoxLayout`:
    one row per layout state (``reachable`` says which are, when the solve knew), up to
    :data:`MAX_TABLE_ROWS` rows."""
    n = int(layout.n_states)
    if n > MAX_TABLE_ROWS:
        raise WncsError(f"a table of {n:,} layout states is too large (at most {MAX_TABLE_ROWS:,} rows): take "
                        "solution.on_mdp(mdp).to_frame(mdp) on a smaller cap, or the policy maps")
    local = np.asarray(local_actions, dtype=np.int64)
    cols = _space_columns(BoxSpace(system, layout), np.arange(n, dtype=np.int64), local)
    cols["local_action"] = local
    out = list(cols)
    if bias is not None and np.asarray(bias).size == n:
        cols["bias"] = np.asarray(bias, dtype=float)
        out.append("bias")
    if mask is not None:
        cols["reachable"] = np.asarray(mask, dtype=bool)
        out.append("reachable")
    return out, cols
