r"""The rollout policy: a greedy policy on value tables, improved by simulating it a few slots ahead.

A greedy policy on a value function h (a bound's tables, the paper's separable tables) picks
:math:`\arg\min_a \mathrm{E}[h(s') \mid s, a]`. Rollout (Bertsekas) scores each candidate action a
by the cost of taking it and then following that base policy :math:`\pi` for H - 1 more slots, with
h as the terminal value:

.. math:: Q_H(s, a) = \mathrm{E}\Bigl[\sum_{t=0}^{H-1} c(s_t) + h(s_H) \Bigm| s_0 = s, a_0 = a,
          a_t = \pi(s_t)\Bigr].

Written with the base policy's own one-step values :math:`V(s_t) = \min_{a'} \mathrm{E}[h(s_{t+1})
\mid s_t, a']` (what the greedy policy computes anyway), the sum telescopes into

.. math:: Q_H(s, a) = c(s) + \mathrm{E}[h(s_1) \mid s, a] + \sum_{t=1}^{H-1}
          \mathrm{E}\bigl[c(s_t) + V(s_t) - h(s_t)\bigr],

the first expectation exact (the greedy value of a) and the rest a sum of the base policy's
**Bellman residuals** of h along the path: the approximating-martingale control variate of the
Monte Carlo estimator (:mod:`wncs_lp.simulate`) applied inside the decision, so only the
residuals, not the costs, carry sampling noise. They are averaged over S sampled paths, each
driven by a fixed row of uniforms drawn once from ``seed`` (the same rows for every candidate and
every state: common random numbers), so the policy is a deterministic function of the state --
exactly evaluable like any stationary policy -- and H = 1 is the greedy policy itself, H = 2 a
sampled two-step lookahead. Where h is the base policy's relative value function every residual is
its gain and the rollout ranks the actions as the greedy policy does; where h is a relaxation's
approximation the H - 1 simulated slots correct it with the real system's coupling (servers busy,
pipelines, the other processes' deliveries) that h only prices.

Only the ``candidates`` actions of least greedy value are rolled out (the greedy's own choice is
always the first): each decision costs candidates x samples x (H - 1) evaluations of the base
policy, run for all states of a call at once in blocks of :data:`BLOCK_ENTRIES` values.
"""
from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from ..errors import PolicyError
from .base import Policy

__all__ = ["RolloutPolicy", "check_rollout", "rollout_uniforms", "BLOCK_ENTRIES", "TIE", "ROLLOUT_CANDIDATES",
           "ROLLOUT_HORIZON", "ROLLOUT_SAMPLES"]

#: The rollout's defaults, here and in its numba twin (:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`,
#: the rollout by name): candidates, horizon (slots simulated, the candidate's included) and paths per
#: candidate. Measured (docs/bounds.md, "Rollout"): a horizon of 8 instead of 4 raised the sixteen-process
#: upper limit by 1% (beyond a few slots the base policy's own losses enter the score), and 16
#: candidates did no better than 8 where 240 actions compete.
ROLLOUT_CANDIDATES, ROLLOUT_HORIZON, ROLLOUT_SAMPLES = 4, 4, 8

#: Values of the base policy (rows x A_max) computed at once: the states of a call are rolled out in
#: blocks of about this many numbers.
BLOCK_ENTRIES = 4_000_000
#: Relative width within which two candidates' scores tie (the first in candidate order is taken):
#: paths that coincide under two actions give scores equal but for the order of their sums.
TIE = 1e-12


def check_rollout(candidates: Any, horizon: Any, samples: Any, seed: Any) -> None:
    """Refuse (:class:`PolicyError`, naming the parameter) a count below 1 or a negative seed."""
    for what, x in (("candidates", candidates), ("horizon", horizon), ("samples", samples)):
        if not (isinstance(x, (int, np.integer)) and x >= 1):
            raise PolicyError(f"{what} must be a whole number >= 1, got {x!r}")
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise PolicyError(f"seed must be a whole number >= 0, got {seed!r}")


def rollout_uniforms(samples: int, horizon: int, seed: int) -> np.ndarray:
    """The (samples, horizon - 1) uniforms that drive the rollout's paths, drawn once from ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed))).random((int(samples), int(horizon) - 1))


class RolloutPolicy(Policy):
    """Rollout of a greedy policy on a value function, with the Bellman residual as control variate
    (module docstring).

    Parameters
    ----------
    base : Policy
        A greedy policy with ``values(tau, config_ids)`` -> (R, A_max) array of E[h(s') | s, a]
        (+inf on infeasible actions) and the action of least value as its choice:
        :class:`~wncs_lp.policies.suboptimal.SeparableGreedyPolicy`, a bound's greedy policy.
    value : callable
        h(tau, config_ids) -> (R,) values of the same h (a bound's ``tables.value``).
    candidates : int
        Actions rolled out per state, those of least greedy value (default :data:`ROLLOUT_CANDIDATES`;
        1: the greedy policy).
    horizon : int
        H >= 1, slots simulated per path including the candidate's (default :data:`ROLLOUT_HORIZON`).
    samples : int
        S >= 1, paths per candidate (default :data:`ROLLOUT_SAMPLES`).
    seed : int
        Seed of the uniforms that drive the paths (one (S, H - 1) array, fixed).
    name : str, optional

    Attributes
    ----------
    uniforms : (S, H - 1) float array
    build_seconds : float
    """

    def __init__(self, base: Policy, value: Callable[[np.ndarray, np.ndarray], np.ndarray], *,
                 candidates: int = ROLLOUT_CANDIDATES, horizon: int = ROLLOUT_HORIZON,
                 samples: int = ROLLOUT_SAMPLES, seed: int = 0, name: str | None = None):
        if not callable(getattr(base, "values", None)):
            raise PolicyError(f"the rollout policy needs a greedy base policy with values(tau, config_ids) "
                              f"(a bound's greedy policy, SeparableGreedyPolicy); got {type(base).__name__}")
        if not callable(value):
            raise PolicyError(f"the rollout policy needs the value function h(tau, config_ids) of its base policy's "
                              f"tables; got {type(value).__name__}")
        check_rollout(candidates, horizon, samples, seed)
        super().__init__(base.system)
        t0 = time.perf_counter()
        if self.system.is_lazy:
            self.refuse_lazy(self.system)
        self.base, self.value = base, value
        self.candidates, self.horizon, self.samples, self.seed = int(candidates), int(horizon), int(samples), int(seed)
        self.uniforms = rollout_uniforms(self.samples, self.horizon, self.seed)
        self.name = name or f"rollout-k{self.candidates}-h{self.horizon}-s{self.samples}[{base.name}]"
        self.build_seconds = time.perf_counter() - t0 + getattr(base, "build_seconds", 0.0)

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        out = np.empty(c.size, dtype=np.int64)
        per_state = max(1, min(self.candidates, self.system.max_actions) * self.samples) * self.system.max_actions
        block = max(1, BLOCK_ENTRIES // per_state)
        for i in range(0, c.size, block):
            out[i:i + block] = self._act_block(tau[i:i + block], c[i:i + block])
        return out

    def _act_block(self, tau: np.ndarray, c: np.ndarray) -> np.ndarray:
        s = self.system
        pt = s.pairs
        v0 = np.asarray(self.base.values(tau, c), dtype=float)
        R, A = v0.shape
        K = min(self.candidates, A)
        first = np.asarray(self.base.act(tau, c), dtype=np.int64)  # the greedy's own choice (its tie rule)
        if K == 1 or self.horizon == 1:
            return first
        order = v0.copy()
        order[np.arange(R), first] = -np.inf
        cand = np.argsort(order, axis=1, kind="stable")[:, :K]  # the greedy's choice, then least greedy value
        q = np.take_along_axis(v0, cand, axis=1)  # E[h(s_1) | s, a]; +inf where a is not feasible
        S, H = self.samples, self.horizon
        n = s.n_actions[c]
        a = np.minimum(cand, n[:, None] - 1)  # an infeasible candidate (inf above) steps as a feasible one
        t_r = np.repeat(np.repeat(tau, K, axis=0), S, axis=0)  # rows (state, candidate, sample)
        c_r = np.repeat(c, K * S)
        a_r = np.repeat(a.reshape(-1), S)
        u = np.tile(self.uniforms, (R * K, 1))  # (rows, H - 1): sample i's uniforms in every (state, candidate)
        resid = np.zeros(c_r.size)
        rows = np.arange(c_r.size)
        for t in range(H - 1):
            p = pt.first[c_r] + a_r
            o = (u[:, t][:, None] >= pt.cum[p]).sum(axis=1)
            t_r, c_r = s.next_tau(t_r, pt.deltas[pt.delta[p, o]]), pt.nxt[p, o]
            v = np.asarray(self.base.values(t_r, c_r), dtype=float)
            a_r = np.argmin(v, axis=1)
            resid += s.state_cost(t_r) + v[rows, a_r] - np.asarray(self.value(t_r, c_r), dtype=float)
        q = q + resid.reshape(R, K, S).mean(axis=2)
        low = q.min(axis=1, keepdims=True)
        pick = np.argmax(q <= low + TIE * np.abs(low), axis=1)  # ties: the greedy's choice, then by greedy value
        return cand[np.arange(R), pick]

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "base": self.base.describe(), "candidates": self.candidates,
                "horizon": self.horizon, "samples": self.samples, "seed": self.seed,
                "build_seconds": self.build_seconds}
