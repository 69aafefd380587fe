r"""An MDP in the forms two other Python toolkits take: QuantEcon's ``DiscreteDP`` and
pymdptoolbox's ``(P, R)`` (this module was ``wncs_lp.interop``).

Both toolkits *maximise* rewards, so the reward is minus the toolkit's cost, :math:`r = -c`, and
their values and average rewards are minus ours. Actions keep the toolkit's numbering: action
``a`` is row ``a`` of ``mdp.action_table`` in every state (``mdp.a_indices``), which is what the
toolkit's ``Solution.sigma`` holds.

QuantEcon (:func:`to_quantecon`)
--------------------------------
``quantecon.markov.DiscreteDP(R, Q, beta, s_indices, a_indices)`` in its *state-action pair*
form: one row per feasible pair, ``R = -mdp.cost``, ``Q = mdp.P`` (the sparse L x n matrix),
``s_indices = mdp.s_indices``, ``a_indices = mdp.a_indices``. Its criterion is the discounted
value :math:`v_\beta(s) = \max_\pi E[\sum_t \beta^t r(s_t, a_t)]` with :math:`0 \le \beta < 1`;
``res.sigma[s]`` is an action index as above. As :math:`\beta \to 1`,
:math:`(1 - \beta) v_\beta(s) \to -g^*` (the toolkit's optimal average cost), and
:math:`v_\beta(s) + g^*/(1 - \beta)` tends to minus the bias :math:`-h(s)` up to a constant.

pymdptoolbox (:func:`to_mdptoolbox`)
------------------------------------
``mdptoolbox.mdp.RelativeValueIteration(P, R)``, ``ValueIteration(P, R, discount)``, ... take
``P`` as a list of A sparse n x n matrices, one per action, and ``R`` as an (n, A) array, so
every action must exist in every state. **Padding convention** (exact): where action ``a`` is not
feasible in state ``s``, its row of ``P[a]`` and its reward ``R[s, a]`` repeat those of the
state's *first* feasible pair (``mdp.pair_ptr[s]``). A padded action is a duplicate of a
feasible one, so the padded MDP has exactly the original's set of achievable behaviours: the
same optimal gain, discounted values and optimal policies (up to which duplicate is named).
:func:`from_mdptoolbox_policy` maps a policy of the padded MDP back to the toolkit's pairs (a
padded action to the first pair it duplicates).

pymdptoolbox 4.0b3's input check builds dense n x n temporaries from sparse input with scipy
>= 1.15 (its ``isStochastic`` broadcasts the row sums); that is harmless on small models and
slow on large ones (its cost is measured in ``docs/interop.md``).
"""
from __future__ import annotations

import importlib
from types import ModuleType
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import WncsError
from ..mdp import MDP

__all__ = ["InteropError", "to_quantecon", "to_mdptoolbox", "from_mdptoolbox_policy", "n_action_labels",
           "require_package"]


class InteropError(WncsError):
    """An MDP or a policy cannot be handed to, or taken back from, another toolkit."""


def require_package(module: str, pip_name: str, purpose: str) -> ModuleType:
    """Import an optional package, or raise one ImportError saying what needs it and how to
    install it (``pip install 'wncs_lp[interop]'``)."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise ImportError(f"{purpose} needs the optional package {pip_name!r}, which is not installed "
                          f"({exc}); install it with: pip install 'wncs_lp[interop]' (or pip install {pip_name})"
                          ) from exc


def _check_mdp(mdp: Any) -> MDP:
    if not isinstance(mdp, MDP):
        raise InteropError(f"expected a wncs_lp MDP (wncs_lp.build(scenario)), got {type(mdp).__name__}")
    return mdp


def n_action_labels(mdp: MDP) -> int:
    """A, the number of action indices: the rows of ``mdp.action_table`` (else max action + 1)."""
    table = mdp.action_table
    return int(len(table)) if table is not None else int(mdp.a_indices.max()) + 1


def to_quantecon(mdp: MDP, beta: float) -> Any:
    """The MDP as a ``quantecon.markov.DiscreteDP`` in state-action pair form (module docstring).

    Parameters
    ----------
    mdp : MDP
    beta : float
        The discount factor, 0 <= beta < 1.

    Returns
    -------
    quantecon.markov.DiscreteDP
        ``R = -mdp.cost`` (QuantEcon maximises), ``Q = mdp.P`` (CSR), ``s_indices``,
        ``a_indices`` of the MDP. ``ddp.solve("policy_iteration")`` gives ``v`` (minus the
        discounted cost) and ``sigma`` (an action index per state).

    Raises
    ------
    InteropError
        ``beta`` outside [0, 1), or not an MDP.
    ImportError
        QuantEcon is not installed (``pip install 'wncs_lp[interop]'``).
    """
    mdp = _check_mdp(mdp)
    if not (isinstance(beta, (int, float, np.floating)) and 0.0 <= float(beta) < 1.0):
        raise InteropError(f"beta must be a number in [0, 1) (a discounted problem), got {beta!r}")
    DiscreteDP = require_package("quantecon.markov", "quantecon", "to_quantecon").DiscreteDP
    return DiscreteDP(-np.asarray(mdp.cost, dtype=np.float64), mdp.P.tocsr(), float(beta),
                      np.asarray(mdp.s_indices), np.asarray(mdp.a_indices))


def _pair_table(mdp: MDP) -> np.ndarray:
    """(n, A) pair of every (state, action index), padded with the state's first pair."""
    A = n_action_labels(mdp)
    table = np.repeat(np.asarray(mdp.pair_ptr[:-1], dtype=np.int64)[:, None], A, axis=1)
    table[mdp.s_indices, mdp.a_indices] = np.arange(mdp.n_pairs)
    return table


def to_mdptoolbox(mdp: MDP) -> tuple[list[sp.csr_matrix], np.ndarray]:
    """The ``(P, R)`` pymdptoolbox's solvers take, padded by the exact convention of the module
    docstring.

    Returns
    -------
    P : list of A scipy.sparse.csr_matrix, each (n, n)
        ``P[a][s]`` is the transition row of action ``a`` in state ``s``.
    R : (n, A) float array
        ``R[s, a] = -c(s, a)`` (pymdptoolbox maximises).

    Examples
    --------
    >>> import mdptoolbox.mdp                                      # doctest: +SKIP
    >>> P, R = to_mdptoolbox(mdp)                                  # doctest: +SKIP
    >>> rvi = mdptoolbox.mdp.RelativeValueIteration(P, R, epsilon=1e-6); rvi.run()  # doctest: +SKIP
    >>> -rvi.average_reward                                        # doctest: +SKIP  (the optimal gain g*)
    """
    mdp = _check_mdp(mdp)
    table = _pair_table(mdp)
    P = mdp.P.tocsr()
    cost = np.asarray(mdp.cost, dtype=np.float64)
    return [P[table[:, a]].tocsr() for a in range(table.shape[1])], -cost[table]


def from_mdptoolbox_policy(mdp: MDP, policy: Any) -> np.ndarray:
    """The (n,) pair indices of a pymdptoolbox policy (an action index per state, e.g.
    ``rvi.policy``) on the MDP given to :func:`to_mdptoolbox`; a padded action maps to the first
    pair of its state, which it duplicates.

    Raises
    ------
    InteropError
        Not one action index in 0..A-1 per state.
    """
    mdp = _check_mdp(mdp)
    table = _pair_table(mdp)
    a = np.asarray(policy)
    if a.shape != (mdp.n_states,) or not np.issubdtype(a.dtype, np.integer) or a.min() < 0 or a.max() >= table.shape[1]:
        raise InteropError(f"expected one action index in 0..{table.shape[1] - 1} per state ({mdp.n_states}), "
                           f"got an array of shape {a.shape} and dtype {a.dtype}")
    return table[np.arange(mdp.n_states), a]
