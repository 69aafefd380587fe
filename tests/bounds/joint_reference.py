"""Independent references for relaxation 2 (joint configuration, separable value functions),
written from docs/model.md and docs/bounds.md without the package's relaxation-2 code:

* ``box_gain(system, tables)``: the Bellman sub-solution test of separable tables state by state
  over the whole AoI box, min over (tau, C, a) of c(tau) + E h(tau', C') - h(tau, C), with
  h(tau, C) = sum_k h_k(tau_k, C), the successor rule written out here and the automaton's
  per-configuration outcome lists (not the flat arrays relaxation 2 reads);
* ``mdp_gain(mdp, tables)``: the same test over the enumerated MDP's reachable pairs;
* ``box_alp(system)``: relaxation 2's approximate LP written out whole over the box, one
  constraint per (tau, C, a) (no separation into per-process maxima), solved by HiGHS.
"""
from __future__ import annotations

from itertools import product

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog


def _successor(tau: np.ndarray, delta: tuple, caps: np.ndarray) -> np.ndarray:
    """tau'_k = min(tau_k + 1, delta_k if delta_k > 0, tau_hat_k), rows of tau one AoI vector each."""
    out = np.minimum(tau + 1, caps[None, :])
    d = np.asarray(delta)[None, :]
    return np.where(d > 0, np.minimum(out, d), out)


def _box(caps: np.ndarray) -> np.ndarray:
    return np.array(list(product(*[range(1, int(c) + 1) for c in caps])), dtype=np.int64)


def _h(tables, tau: np.ndarray, c) -> np.ndarray:
    c = np.broadcast_to(np.asarray(c), tau.shape[:1])
    return sum(np.asarray(t)[c, tau[:, k] - 1] for k, t in enumerate(tables))


def box_gain(system, tables) -> float:
    """min over the box of c(tau) + sum_o P(o) h(tau', C') - h(tau, C): the largest g making
    (g, h) a Bellman sub-solution on every (tau, C, a)."""
    caps = np.asarray(system.caps)
    tau = _box(caps)
    cost = sum(np.asarray(system.q[k])[tau[:, k] - 1] for k in range(caps.size))
    best = np.inf
    for c, per_action in enumerate(system.automaton.outcomes):
        here = _h(tables, tau, c)
        for outcomes in per_action:
            ahead = sum(p * _h(tables, _successor(tau, delta, caps), nxt) for nxt, delta, p in outcomes)
            best = min(best, float((cost + ahead - here).min()))
    return best


def _state_values(mdp, tables) -> np.ndarray:
    st = mdp.states
    return _h(tables, np.asarray(st.tau, dtype=np.int64), np.asarray(st.config, dtype=np.int64))


def mdp_gain(mdp, tables) -> float:
    """min over the enumerated MDP's pairs (s, a) of c(s) + E h(s') - h(s)."""
    h = _state_values(mdp, tables)
    return float((mdp.cost + mdp.P @ h - h[mdp.s_indices]).min())


def box_alp(system) -> float:
    """max g s.t. g + sum_k h_k(tau_k, C) - sum_o P(o) sum_k h_k(tau'_k, C') <= c(tau) for every
    (tau, C, a) of the box: relaxation 2's optimum, by HiGHS."""
    caps = np.asarray(system.caps)
    n_c = system.n_configs
    offs = np.r_[0, np.cumsum(caps * n_c)] + 1  # column 0 is g
    tau = _box(caps)
    cost = sum(np.asarray(system.q[k])[tau[:, k] - 1] for k in range(caps.size))
    rows, cols, vals, rhs = [], [], [], []
    r0 = 0
    idx = np.arange(tau.shape[0])
    for c, per_action in enumerate(system.automaton.outcomes):
        for outcomes in per_action:
            rr = r0 + idx
            rows.append(rr)
            cols.append(np.zeros_like(rr))
            vals.append(np.ones(rr.size))
            for k in range(caps.size):
                rows.append(rr)
                cols.append(offs[k] + c * caps[k] + tau[:, k] - 1)
                vals.append(np.ones(rr.size))
                for nxt, delta, p in outcomes:
                    t2 = _successor(tau, delta, caps)
                    rows.append(rr)
                    cols.append(offs[k] + nxt * caps[k] + t2[:, k] - 1)
                    vals.append(np.full(rr.size, -p))
            rhs.append(cost)
            r0 += idx.size
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r0, offs[-1]))
    obj = np.zeros(offs[-1])
    obj[0] = -1.0
    res = linprog(obj, A_ub=A, b_ub=np.concatenate(rhs), bounds=(None, None), method="highs-ipm")
    assert res.status == 0, res.message
    return -float(res.fun)


def box_value_iteration(system, sweeps: int = 20_000, tol: float = 1e-11) -> tuple[float, float, np.ndarray]:
    """Relative value iteration of one process's MDP over the whole box (tau, C) (every (tau, C),
    reachable or not): (gain lower, gain upper, bias table (|C|, tau_hat))."""
    assert system.n_processes == 1
    cap = int(system.caps[0])
    tau = np.arange(1, cap + 1)[:, None]
    q = np.asarray(system.q[0])
    h = np.zeros((system.n_configs, cap))
    for _ in range(sweeps):
        th = np.empty_like(h)
        for c, per_action in enumerate(system.automaton.outcomes):
            vals = [sum(p * h[nxt, _successor(tau, delta, system.caps)[:, 0] - 1] for nxt, delta, p in outs)
                    for outs in per_action]
            th[c] = q + np.min(vals, axis=0)
        d = th - h
        if d.max() - d.min() <= tol * abs(d.min()):
            break
        h = h + 0.5 * d  # damped: the chain may be periodic
        h -= h[0, 0]
    return float(d.min()), float(d.max()), h


def three_processes(tau_cap: int = 5):
    """Three processes on an edge (U = 0) and a remote (U = 1) server: a joint configuration small
    enough (30 configurations) for the box tests, with unequal processing times and weights."""
    from wncs_lp.scenario import scenario_from_dict

    return scenario_from_dict({
        "model": {"kind": "wncs", "tau_cap": tau_cap}, "channel": {"success_probability": 0.9},
        "process": [{"A": [[1.1]]}, {"A": [[1.05]]}, {"A": [[1.2]], "weight": 2.0}],
        "server": [{"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [1, 2, 1]},
                   {"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "processing_time": [1, 1, 2]}],
    }, source="<three processes>")
