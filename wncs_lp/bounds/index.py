r"""The index policy: Whittle-type indices from relaxation 1's priced private chains.

Relaxation 1 (:mod:`~wncs_lp.bounds.private`) prices each server's capacity at lambda* and lets
every process k solve its private MDP (state :math:`s_k = (\tau_k, C_k)`, its own copy of the
servers, idling allowed) with cost :math:`q_k + \sum_m \lambda_m \text{claim}_m`. Move the price
of server m alone, the other servers' at lambda*:

.. math:: \lambda(x) = (\lambda^*_1, \dots, x, \dots, \lambda^*_M) \quad (x \text{ in position } m).

With :math:`Q_x(s, a)` the Q-factor of the optimal bias of the chain priced at
:math:`\lambda(x)`, the **advantage of sending to m** is

.. math:: D_m(s, x) = \min_{a:\, a_m = 0} Q_x(s, a) - \min_{a:\, a_m = k} Q_x(s, a)

(the best action that does not send k to m, idling included, against the best that does), and
the **index** of server m in state s is the price at which the two are indifferent,

.. math:: I_m(s) = \sup\{x : D_m(s, x) \ge 0\}:

the most a slot of server m may cost for sending k there to still pay, the Whittle index of
the arm k with m's price as the subsidy. The chain is **indexable** for m (Whittle's
condition) when the set of states where sending to m is optimal shrinks as x grows, i.e. each
:math:`D_m(s, \cdot)` changes sign once, from + to -; :func:`whittle_indices` counts the states
where it does not (``reversals``), and the index is then still defined by the supremum above.

**How the indices are computed (exactly).** Sending costs the claim now and holds server m
longer, so D_m falls to -inf as x grows and rises to +inf as x falls: a price bracket
[x_lo, x_hi] where every state sends at x_lo and none at x_hi is found by doubling. The optimal
policy is piecewise constant in x: a policy pi solved at x (policy iteration) stays optimal
while every reduced cost :math:`r_\pi(s, a; x') = r_0 + x' r_1` stays >= 0, and r_0, r_1 come from
two exact evaluations of pi (cost :math:`q + \sum_{m' \ne m} \lambda^*_{m'} \text{claim}_{m'}`
and cost :math:`\text{claim}_m`); its upper end is :math:`\min_{r_1 < 0} -r_0 / r_1`. On that
interval :math:`D_m(s, x') = \min_{a_m = 0} r - \min_{a_m = k} r` is known in closed form, and its
last nonnegative point is found by bisection on the closed form. The walk solves one policy per
breakpoint of the optimal policy in x (a few dozen to a few hundred per chain), so the indices
are exact up to the bisection's width (``tol`` of the price scale), not a grid's.

**The policy.** In state (tau, C) of the real system, among the feasible actions a, choose

.. math:: \pi(\tau, C) = \arg\max_a \sum_{m:\, a_m = k \ne 0} \bigl(I_{k,m}(\tau_k, C_k) - \lambda^*_m\bigr),

:math:`C_k` process k's projection of C (ties to the first action). Without idling every
accepting server is used, so the offsets lambda*_m only matter where idling is allowed: a
server is left idle when no candidate's index exceeds its market price. An action's value is a
sum over the (at most M) processes it sends, so the policy reads M small index tables per
state: nothing of the size of the tau box or of the (C, a, tau) tables of the greedy policies.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..errors import PolicyError, SolverError
from ..models.system import System
from ..policies.base import Policy
from ..progress import as_progress
from ..scenario import Scenario
from ..solvers import policy_iteration
from ..solvers.dp import evaluate_policy
from .private import PrivateChain, private_bound, private_chains
from .result import BoundResult

__all__ = ["ChainIndex", "IndexTables", "IndexPolicy", "whittle_indices", "chain_index", "index_policy"]

#: Relative width (of the chain's price scale) to which each index is bisected.
INDEX_TOL = 1e-9
#: Doublings of the price bracket before the indices outside it are clipped to its ends.
MAX_DOUBLINGS = 60
#: Policies solved per (chain, server) at most on the walk over the price bracket.
MAX_SOLVES = 5000


@dataclass(frozen=True, eq=False)
class ChainIndex:
    """The indices of one private chain (shared by identical processes).

    Attributes
    ----------
    processes : tuple of int
        The (0-based) processes whose private chain this is.
    index : (M, n_configs, tau_hat) array
        ``index[m, c, tau - 1]`` = I_m(tau, c) for private configuration c; NaN where c cannot
        send to server m. Entries at private states not reachable from the idle configuration take
        the value of the nearest reachable AoI of the same configuration.
    indexable : (M,) bool array
        Whittle's condition held for server m: no state where sending to m stops being optimal
        and becomes optimal again as the price rises (``reversals[m] == 0``), and no index clipped.
    reversals : (M,) int array
        Private states whose advantage D_m changes sign from - to + somewhere as the price rises.
    clipped : (M,) int array
        States whose index lies outside the price bracket (set to its end).
    bracket : (M, 2) array
        [x_lo, x_hi] of each server's walk.
    solves : (M,) int array
        Policies solved on each walk (breakpoints of the optimal policy in the price, plus the
        bracket search).
    """

    processes: tuple
    index: np.ndarray
    indexable: np.ndarray
    reversals: np.ndarray
    clipped: np.ndarray
    bracket: np.ndarray
    solves: np.ndarray


@dataclass(frozen=True, eq=False)
class IndexTables:
    """Whittle-type indices of every process (:func:`whittle_indices`).

    Attributes
    ----------
    multipliers : (M,) array
        lambda*, the prices of relaxation 1 at which the other servers are held.
    chains : tuple of ChainIndex
    which : (N,) int array
        The chain of each process.
    column : tuple of int arrays
        ``column[k][c]``: process k's private configuration in joint configuration c.
    lower_bound : float
        Relaxation 1's certified bound at lambda* (what the indices were priced from).
    seconds : float
    """

    multipliers: np.ndarray
    chains: tuple
    which: np.ndarray
    column: tuple
    lower_bound: float
    seconds: float

    @property
    def indexable(self) -> bool:
        """Every chain indexable for every server."""
        return bool(all(np.all(ch.indexable) for ch in self.chains))

    def index(self, k: int, m: int) -> np.ndarray:
        """(n_configs_k, tau_hat_k) table of process k's index for server m (NaN: cannot send)."""
        return self.chains[int(self.which[k])].index[m]

    def summary(self) -> dict[str, Any]:
        return {"multipliers": np.asarray(self.multipliers, float).tolist(), "lower_bound": float(self.lower_bound),
                "indexable": self.indexable,
                "chains": [{"processes": [k + 1 for k in ch.processes], "indexable": ch.indexable.tolist(),
                            "reversals": ch.reversals.tolist(), "clipped": ch.clipped.tolist(),
                            "solves": ch.solves.tolist(), "bracket": ch.bracket.tolist()} for ch in self.chains],
                "seconds": float(self.seconds)}

    def __repr__(self) -> str:
        solves = sum(int(ch.solves.sum()) for ch in self.chains)
        return (f"IndexTables({len(self.which)} processes, {len(self.chains)} chains, "
                f"{'indexable' if self.indexable else 'not indexable everywhere'}, {solves} priced solves, "
                f"{self.seconds:.2f} s)")


# ============================================================================ one chain
class _Walk:
    """The reduced costs of one private chain along the price of one server."""

    def __init__(self, chain: PrivateChain, lam: np.ndarray, m: int):
        self.chain, self.lam, self.m = chain, np.asarray(lam, float), m
        mdp = chain.mdp
        others = np.delete(np.arange(self.lam.size), m)
        self.c0 = chain.aoi_cost + chain.claims[:, others] @ self.lam[others]
        self.c1 = np.asarray(chain.claims[:, m], float)
        self.s = np.asarray(mdp.s_indices)
        self.ptr = np.asarray(mdp.pair_ptr)
        acts = chain.model.automaton.actions
        cfg = np.asarray(mdp.states.config)
        local = np.arange(mdp.n_pairs) - self.ptr[self.s]
        labels = np.array([acts[cfg[s]][j] for s, j in zip(self.s, local)], dtype=np.int64)
        proj = chain.model.project_labels(labels, 0)  # the private chain's process is its 0th
        sends = proj[:, m] > 0
        self.sends = sends
        self.idle = ~np.any(proj > 0, axis=1)  # pairs sending nothing (idling is allowed in a private chain)
        self.can_send = np.zeros(mdp.n_states, dtype=bool)
        self.can_send[self.s[sends]] = True
        self.scale = float(max(1.0, np.max(np.abs(chain.aoi_cost))))
        self.solves = 0

    def solve(self, x: float, policy0: np.ndarray | None) -> np.ndarray:
        lam = self.lam.copy()
        lam[self.m] = x
        self.solves += 1
        sol = policy_iteration(self.chain.priced(lam), policy0=policy0, tol=1e-12)
        return np.asarray(sol.policy)

    def reduced(self, policy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(r0, r1) per pair: the reduced cost of the pair under ``policy`` at price x is r0 + x r1."""
        mdp = self.chain.mdp
        out = []
        for cost in (self.c0, self.c1):
            try:
                ev = evaluate_policy(replace(mdp, cost=cost), policy, stationary=False)
            except PolicyError as exc:  # a multichain optimal policy: no single bias to read Q from
                raise SolverError(f"index of process {self.chain.processes[0] + 1}: {exc}") from None
            out.append(cost + mdp.P @ ev.bias - ev.gain - ev.bias[self.s])
        return out[0], out[1]

    def advantage(self, r0: np.ndarray, r1: np.ndarray, x: np.ndarray) -> np.ndarray:
        """D_m(s, x) for every state (x a scalar or one price per state); NaN where s cannot send."""
        r = r0 + np.asarray(x)[self.s] * r1 if np.ndim(x) else r0 + x * r1
        keep = np.where(self.idle, r, np.inf)
        send = np.where(self.sends, r, np.inf)
        d = np.minimum.reduceat(keep, self.ptr[:-1]) - np.minimum.reduceat(send, self.ptr[:-1])
        return np.where(self.can_send, d, np.nan)


def chain_index(chain: PrivateChain, lam: np.ndarray, m: int, *, tol: float = INDEX_TOL,
                max_solves: int = MAX_SOLVES) -> dict:
    """The index I_m(s) of every state of one private chain (module docstring), with its
    indexability check: ``{"index", "reversals", "clipped", "bracket", "solves"}``, ``index`` over
    the chain's states (NaN where s cannot send to m)."""
    w = _Walk(chain, lam, m)
    n = chain.mdp.n_states
    base = float(np.asarray(lam, float)[m])
    # the bracket: nobody sends at x_hi, everybody who can sends at x_lo
    width, pol_hi, pol_lo = w.scale, None, None
    for _ in range(MAX_DOUBLINGS):
        pol_hi = w.solve(base + width, pol_hi)
        d_hi = w.advantage(*w.reduced(pol_hi), base + width)
        if not np.any(d_hi[w.can_send] >= 0):
            break
        width *= 2
    x_hi = base + width
    width = w.scale
    for _ in range(MAX_DOUBLINGS):
        pol_lo = w.solve(base - width, pol_lo)
        d_lo = w.advantage(*w.reduced(pol_lo), base - width)
        if np.all(d_lo[w.can_send] >= 0):
            break
        width *= 2
    x_lo = base - width
    eps = tol * max(w.scale, abs(x_lo), abs(x_hi))
    last = np.full(n, np.nan)  # sup{x : D >= 0} so far
    clipped_lo = int(np.sum(w.can_send & ~(d_lo >= 0)))
    sign = w.can_send & (d_lo >= 0)  # D >= 0 at the end of the walk so far
    reversals = np.zeros(n, dtype=bool)
    x, policy = x_lo, pol_lo
    while True:
        r0, r1 = w.reduced(policy)
        off = np.ones(r1.size, dtype=bool)
        off[policy] = False  # the policy's own pairs have r = 0 at every price
        falling = off & (r1 < -1e-12 * np.maximum(1.0, np.abs(r0)))
        u = float(np.min(np.minimum(-r0[falling] / r1[falling], x_hi))) if np.any(falling) else x_hi
        u = min(max(u, x), x_hi)
        # the sign of D at probe points of [x, u] (D is piecewise linear there), then the last
        # nonnegative point by bisection on the closed form
        probes = np.linspace(x, u, 9)
        pos = np.stack([w.advantage(r0, r1, p) >= 0 for p in probes])  # NaN (cannot send) is False
        reversals |= ~sign & pos[0]  # from - at the previous segment's end to + here
        reversals |= np.any(~pos[:-1] & pos[1:], axis=0)
        has = np.any(pos, axis=0)
        i_last = probes.size - 1 - np.argmax(pos[::-1], axis=0)
        last[has & (i_last == probes.size - 1)] = u
        inner = has & (i_last < probes.size - 1)
        lo, hi = probes[i_last], probes[np.minimum(i_last + 1, probes.size - 1)]
        while np.any(inner & (hi - lo > eps)):
            mid = 0.5 * (lo + hi)
            ok = w.advantage(r0, r1, mid) >= 0
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        last[inner] = lo[inner]
        sign = pos[-1]
        if u >= x_hi or w.solves >= max_solves:
            break
        nxt = u + max(eps, 1e-12 * abs(u))
        new = w.solve(nxt, policy)
        step = eps
        while np.array_equal(new, policy) and nxt < x_hi and w.solves < max_solves:
            # the policy is still optimal past u (round-off in its validity end): step further
            step *= 16
            nxt = min(u + step, x_hi)
            new = w.solve(nxt, policy)
        x, policy = nxt, new
    if w.solves >= max_solves and x < x_hi:
        raise SolverError(f"the index walk of process {chain.processes[0] + 1} on server {m + 1} needed more than "
                          f"{max_solves} priced solves (at price {x:.6g} of [{x_lo:.6g}, {x_hi:.6g}])")
    clipped_hi = int(np.sum(w.can_send & sign))  # still sending at x_hi
    last[w.can_send & np.isnan(last)] = x_lo
    return {"index": last, "reversals": int(reversals.sum()), "reversal_states": np.flatnonzero(reversals),
            "clipped": clipped_lo + clipped_hi,
            "bracket": (x_lo, x_hi), "solves": w.solves}


def _table(chain: PrivateChain, values: np.ndarray) -> np.ndarray:
    """(n_configs, tau_hat) table of per-state values; unreachable AoI values of a configuration
    take the nearest reachable one's; configurations where every value is NaN stay NaN."""
    st = chain.mdp.states
    out = np.full((chain.n_configs, chain.cap), np.nan)
    out[np.asarray(st.config), np.asarray(st.tau)[:, 0] - 1] = values
    for row in out:
        known = np.flatnonzero(~np.isnan(row))
        if 0 < known.size < row.size:
            row[:] = row[known[np.abs(np.arange(row.size)[:, None] - known[None, :]).argmin(axis=1)]]
    return out


# ============================================================================ all processes
def whittle_indices(
    scenario_or_system: Scenario | System,
    bound: BoundResult | None = None,
    *,
    tol: float = INDEX_TOL,
    progress: Any = False,
) -> IndexTables:
    """The Whittle-type indices of every process and server, from relaxation 1's priced chains.

    Parameters
    ----------
    scenario_or_system : Scenario or System
        A Section II scenario (the model must have the private-servers relaxation).
    bound : BoundResult, optional
        Relaxation 1's result on this system (its multipliers lambda* and column maps); computed
        when not given.
    tol : float
        Width of each index's bisection, relative to the chain's price scale.
    progress : bool or Progress

    Returns
    -------
    IndexTables

    Raises
    ------
    ModelError
        A model without the private-servers relaxation (the preemption model).
    SolverError
        A priced chain whose optimal policy is multichain (no bias to read the indices from).
    """
    t0 = time.perf_counter()
    prog = as_progress(progress)
    system = scenario_or_system if isinstance(scenario_or_system, System) else System.from_scenario(scenario_or_system)
    if bound is None:
        prog.phase("relaxation 1 (private servers): the multipliers the indices are priced from")
        bound = private_bound(system, progress=prog)
    elif bound.relaxation != "private-servers":
        raise SolverError(f"the indices are priced from relaxation 1 (private-servers), got a {bound.relaxation} bound")
    chains, which = private_chains(system.model)
    lam = np.asarray(bound.multipliers, float)
    out = []
    for i, ch in enumerate(chains):
        per_m = []
        for m in range(system.n_servers):
            prog.tick(f"[index] chain {i + 1}/{len(chains)} (process {ch.processes[0] + 1}), server {m + 1}",
                      force=True)
            per_m.append(chain_index(ch, lam, m, tol=tol))
        rev = np.array([r["reversals"] for r in per_m])
        clip = np.array([r["clipped"] for r in per_m])
        out.append(ChainIndex(ch.processes, np.stack([_table(ch, r["index"]) for r in per_m]),
                              (rev == 0) & (clip == 0), rev, clip, np.array([r["bracket"] for r in per_m]),
                              np.array([r["solves"] for r in per_m])))
    return IndexTables(lam, tuple(out), np.asarray(which), tuple(bound.tables.column), float(bound.lower_bound),
                       time.perf_counter() - t0)


# ============================================================================ the policy
class IndexPolicy(Policy):
    r"""The index policy: argmax over feasible actions of
    :math:`\sum_{m: a_m = k} (I_{k,m}(\tau_k, C_k) - \lambda^*_m)` (module docstring); ties to the
    first action.

    Parameters
    ----------
    system : System
    indices : IndexTables, optional
        Computed by :func:`whittle_indices` when not given.
    """

    name = "index"

    def __init__(self, system: System, indices: IndexTables | None = None):
        super().__init__(system)
        t0 = time.perf_counter()
        self.indices = indices if indices is not None else whittle_indices(system)
        ix = self.indices
        N, M = system.n_processes, system.n_servers
        if len(ix.which) != N or any(np.shape(c) != (system.n_configs,) for c in ix.column):
            raise PolicyError(f"the index tables belong to another system ({len(ix.which)} processes; this system has "
                              f"{N} processes and {system.n_configs} configurations)")
        n_cols = max(ch.index.shape[1] for ch in ix.chains)
        cap = int(system.caps.max())
        # I[k, m, col, tau - 1] - lambda*_m, padded; +inf-free (NaN -> 0: never read for a feasible action)
        table = np.zeros((N, M, n_cols, cap))
        for k in range(N):
            t = ix.chains[int(ix.which[k])].index
            table[k, :, : t.shape[1], : t.shape[2]] = np.nan_to_num(t - ix.multipliers[:, None, None], nan=0.0)
        self.table = table
        self.column = np.stack([np.asarray(c, np.int64) for c in ix.column])  # (N, |C|)
        sent = np.zeros(system.labels.shape, dtype=np.int64)  # (C, A, M): 1 + the process sent to m, 0 none
        for k in range(N):
            sent += (k + 1) * system.model.project_labels(system.labels, k)
        sent[~system.action_valid] = 0
        self.sent = sent
        self.build_seconds = time.perf_counter() - t0

    def values(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """(R, A_max) minus the summed index advantage of each action (+inf on infeasible ones)."""
        tau, c = self._check_inputs(tau, config_ids)
        R = c.size
        out = np.zeros((R, self.system.max_actions))
        rows = np.arange(R)[:, None]
        for m in range(self.system.n_servers):
            k1 = self.sent[c, :, m]  # (R, A)
            k = np.maximum(k1 - 1, 0)
            v = self.table[k, m, self.column[k, c[:, None]], tau[rows, k] - 1]
            out -= np.where(k1 > 0, v, 0.0)
        out[~self.system.action_valid[c]] = np.inf
        return out

    def act(self, tau, config_ids, rng=None):
        return np.argmin(self.values(tau, config_ids), axis=1).astype(np.int64)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "indexable": self.indices.indexable,
                "multipliers": np.asarray(self.indices.multipliers, float).tolist(),
                "build_seconds": self.build_seconds}


def index_policy(system: System, bound: BoundResult | None = None) -> IndexPolicy:
    """The index policy of a system (relaxation 1 computed unless ``bound`` is given)."""
    return IndexPolicy(system, whittle_indices(system, bound))
