r"""Transient cost: the expected cost over the first T slots from a given state or distribution.

The average cost says what a policy costs in the long run; a start far from the stationary law
(every AoI at its cap after an outage, say) costs more for a while. With V_0 = 0,

.. math::

    V_{t+1}(s) = c_\pi(s) + \sum_{s'} P_\pi(s, s')\, V_t(s')
    \qquad\text{(a fixed policy } \pi\text{)},

    V^*_{t+1}(s) = \min_a \Bigl[c(s, a) + \sum_{s'} P(s' \mid s, a)\, V^*_t(s')\Bigr]
    \qquad\text{(the optimum over all policies for T slots)},

V_T(s) is the expected cost of slots 0..T-1 from s, and mu . V_T from a start law mu. The
finite-horizon optimum is attained by a policy that changes with the slots left (finite-horizon
dynamic programming); a fixed stationary policy -- the average-cost optimum included -- costs
at least as much. For a fixed policy the expected cost of each slot, E[c(s_t)] = mu P^t c, is
given too (the forward recursion mu_{t+1} = mu_t P_pi), so one sees the curve approach the
average cost.

Both are exact recursions on the enumerated MDP: T products with its transition matrix (a
policy with memory, on its augmented chain, starting from its initial memory).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .chain import policy_matrices
from .errors import PolicyError
from .evaluate import memory_chain
from .mdp import MDP
from .policy_forms import policy_array

__all__ = ["TransientCost", "transient_cost", "start_law"]


@dataclass(frozen=True)
class TransientCost:
    """The expected cost over the first ``horizon`` slots.

    Attributes
    ----------
    policy : str
        The policy (``"finite-horizon optimum"`` for the optimum over all policies).
    horizon : int
    total : float
        Expected cost of slots 0..T-1 from the start (mu . V_T).
    per_slot : (T,) array or None
        E[c(s_t)], t = 0..T-1, for a fixed policy (None for the optimum, which changes with t).
    values : (n,) array
        V_T(s): the total from every state s of the MDP (a policy with memory: from s with its
        initial memory).
    start : str
        The start, in words.
    seconds : float
    """

    policy: str
    horizon: int
    total: float
    per_slot: np.ndarray | None
    values: np.ndarray
    start: str
    seconds: float

    @property
    def average(self) -> float:
        """total / T: the average cost per slot over the horizon."""
        return self.total / self.horizon

    def __repr__(self) -> str:
        return (f"TransientCost({self.policy}, T = {self.horizon}, from {self.start}: total {self.total:.10g}, "
                f"average {self.average:.10g})")

    def to_dict(self) -> dict[str, Any]:
        return {"policy": self.policy, "horizon": self.horizon, "total": self.total, "average": self.average,
                "start": self.start, "per_slot": None if self.per_slot is None else self.per_slot.tolist(),
                "seconds": self.seconds}


def start_law(mdp: MDP, start: Any = None) -> tuple[np.ndarray, str]:
    """A start law over the MDP's states and its description.

    ``start``: None (every AoI at its cap, first initial configuration: the start of
    :func:`wncs_lp.simulate.simulate`), a state index, a tau vector (in the first initial
    configuration), a pair ``(tau, configuration id)``, or an (n,) probability vector.
    """
    n = mdp.n_states
    st = mdp.states
    if isinstance(start, np.ndarray) and np.issubdtype(start.dtype, np.floating):
        mu = np.asarray(start, dtype=float)
        if mu.shape != (n,) or not np.all(np.isfinite(mu)) or mu.min() < 0 or abs(mu.sum() - 1.0) > 1e-9:
            raise PolicyError(f"a start law must be {n} nonnegative probabilities summing to 1")
        return mu, "a given law"
    if isinstance(start, (int, np.integer)):
        s = int(start)
        if not 0 <= s < n:
            raise PolicyError(f"start state {s} is not in 0..{n - 1}")
    else:
        from .models.system import System

        model = getattr(st, "model", None)
        if model is None:
            raise PolicyError("a start given by AoI needs an MDP built from a scenario (its state decoding)")
        system = System.from_scenario(model.scenario, model)
        if start is None:
            tau, c = system.caps, system.initial_config
        elif isinstance(start, tuple) and len(start) == 2 and not np.isscalar(start[0]):
            tau, c = np.asarray(start[0], dtype=np.int64), int(start[1])
        else:
            tau, c = np.asarray(start, dtype=np.int64), system.initial_config
        s = int(st.find(tau, c))
        if s < 0:
            raise PolicyError(f"the start (tau={np.asarray(tau).tolist()}, configuration {c}) is not a state of the MDP")
    mu = np.zeros(n)
    mu[s] = 1.0
    return mu, f"state {mdp.state_label(s)}"


def transient_cost(mdp: MDP, policy: Any = "optimal", horizon: int = 100, start: Any = None, *,
                   sigma: Any = None) -> TransientCost:
    r"""Expected cost over the first ``horizon`` slots (module docstring).

    Parameters
    ----------
    mdp : MDP
    policy : "optimal", Policy, Solution or array
        ``"optimal"``: the finite-horizon optimum over all policies (finite-horizon dynamic
        programming). Otherwise a fixed policy in any form :func:`wncs_lp.evaluate.evaluate`
        takes (a policy with memory on its augmented chain).
    horizon : int
        T >= 1 slots.
    start : optional
        See :func:`start_law` (default: every AoI at its cap, servers idle).
    sigma : (n,) int array, optional
        A fixed policy as an action per state instead.

    Returns
    -------
    TransientCost
    """
    T = int(horizon)
    if T < 1:
        raise PolicyError(f"the horizon must be at least 1 slot, got {horizon}")
    t0 = time.perf_counter()
    mu, where = start_law(mdp, start)
    n = mdp.n_states
    if isinstance(policy, str) and policy == "optimal" and sigma is None:
        V = _optimal_values(mdp, T)
        return TransientCost("finite-horizon optimum", T, float(mu @ V), None, V, where, time.perf_counter() - t0)
    if hasattr(policy, "act_memory") and sigma is None:
        P, pairs = memory_chain(mdp, policy)
        c = np.asarray(mdp.cost, dtype=float)[pairs.ravel()]
        m0 = int(policy.initial_memory)
        mu_aug = np.zeros(P.shape[0])
        mu_aug[m0 * n:(m0 + 1) * n] = mu
        V, per = _fixed(P, c, mu_aug, T)
        return TransientCost(policy.name, T, float(mu_aug @ V), per, V[m0 * n:(m0 + 1) * n], where,
                             time.perf_counter() - t0)
    if hasattr(policy, "on_mdp") and sigma is None:
        name, arr = policy.name, policy.on_mdp(mdp)
    else:
        name = "sigma" if sigma is not None else getattr(policy, "method", None) or "array"
        arr = policy_array(mdp, policy, sigma)
    P, c = policy_matrices(mdp, arr)
    V, per = _fixed(P, c, mu, T)
    return TransientCost(name, T, float(mu @ V), per, V, where, time.perf_counter() - t0)


def _fixed(P: Any, c: np.ndarray, mu: np.ndarray, T: int) -> tuple[np.ndarray, np.ndarray]:
    """(V_T, E[c(s_t)] for t < T) of the chain (P, c) from the law mu."""
    V = np.zeros(P.shape[0])
    PT = P.T.tocsr()
    per = np.empty(T)
    x = mu.copy()
    for t in range(T):
        V = c + P @ V
        per[t] = x @ c
        x = PT @ x
    return V, per


def _optimal_values(mdp: MDP, T: int) -> np.ndarray:
    """V*_T by T steps of finite-horizon dynamic programming over the state-action pairs."""
    cost = np.asarray(mdp.cost, dtype=float)
    V = np.zeros(mdp.n_states)
    for _ in range(T):
        V = np.minimum.reduceat(cost + mdp.P @ V, mdp.pair_ptr[:-1])
    return V
