"""A plain reference builder for the Section II model with per-link success probabilities, cost
families and random arrivals, written from ``docs/model.md`` ("Beyond the paper") alone.

It shares no code with ``wncs_lp/models`` (it reads only the validated scenario's fields) and keeps
its own representation, so that it checks the package's lumping too:

* a state is ``(tau, alpha, servers)``: ``alpha[k]`` the age of the update at sensor k, lumped at
  tau_hat_k - 1 (an update that old cannot bring tau_k below the cap, every loop being >= 1 slot)
  -- a coarser rule than the package's a_k, so the state sets differ and only gains compare;
* a server is ``(up, job, down)``: ``up`` a tuple of U - 1 places, each ``None`` or ``(k, age)``
  (``up[i]`` sent i + 1 slots ago); ``job`` ``None`` or ``(k, age, d)``; ``down`` D places, each
  ``None`` or ``(k, age)`` (``down[-1]`` delivered this slot). ``age`` is the update's age at send.

Everything is per state and per action with Python loops: slow, easy to check against the text.
"""
from __future__ import annotations

from itertools import product

import numpy as np
import scipy.sparse as sp

from .wncs import explore  # the breadth-first search only: the model's rules are all written here

__all__ = ["cost_table", "build", "to_arrays", "small_scenario", "FIELDS"]


def cost_table(pr):
    """q(1..tau_hat) of one process from its family, computed directly from the definitions."""
    cap, w, cost = pr.tau_cap, pr.weight, pr.cost
    out = []
    for tau in range(1, cap + 1):
        if cost.family == "mse":
            total = 0.0
            for i in range(tau):
                Ai = np.linalg.matrix_power(pr.A, i)
                total += float(np.trace(Ai @ pr.R @ Ai.T))
            out.append(w * total)
        elif cost.family == "aoi":
            out.append(w * tau)
        elif cost.family == "power":
            out.append(w * tau ** cost.power)
        else:
            out.append(w * cost.table[tau - 1])
    return out


def _busy_until(srv, sstate):
    """The acceptance rule: busy = d, and j + T for each update in the uplink starting in j slots."""
    up, job, down = sstate
    U = srv.uplink_delay
    busy = job[2] if job else 0
    for i, x in enumerate(up):
        if x is not None:
            busy = max(busy, (U - 1 - i) + srv.processing_time[x[0] - 1])
    return busy <= U if U else busy == 0


def _actions(scenario, servers):
    N = scenario.n_processes
    acc = [_busy_until(s, st) for s, st in zip(scenario.servers, servers)]
    idle_ok = scenario.model.allow_idle or sum(acc) > N
    choices = [(([0] if idle_ok else []) + list(range(1, N + 1))) if a else [0] for a in acc]
    out = []
    for a in product(*choices):
        sent = [x for x in a if x]
        if scenario.model.distinct and len(sent) != len(set(sent)):
            continue
        out.append(tuple(a))
    return out


def _slot(srv, sstate, sent):
    """One server, uplink outcome applied (``sent`` = (k, age) or None): (new state, delivered
    (k, age) or None)."""
    up, job, down = sstate
    U, D, T = srv.uplink_delay, srv.downlink_delay, srv.processing_time
    if U == 0 and sent is not None:
        assert job is None
        job = (sent[0], sent[1], T[sent[0] - 1])
    completed = None
    if job is not None:
        k, age, d = job
        d -= 1
        job = (k, age, d) if d else None
        if not d:
            completed = (k, age)
    if D == 0:
        delivered, new_down = completed, ()
    else:
        delivered, new_down = down[-1], (completed,) + down[:-1]
    new_up = up
    if U >= 1:
        if U == 1:
            leaving = sent
        else:
            leaving, new_up = up[-1], (sent,) + up[:-1]
        if leaving is not None:
            assert job is None
            job = (leaving[0], leaving[1], T[leaving[0] - 1])
    return (new_up, job, new_down), delivered


def _step(scenario, state, action):
    tau, alpha, servers = state
    caps = [pr.tau_cap for pr in scenario.processes]
    per_server = []
    for srv, st, a in zip(scenario.servers, servers, action):
        outs = []
        tries = [(True, srv.p_up[a - 1]), (False, 1.0 - srv.p_up[a - 1])] if a else [(False, 1.0)]
        for ok, p1 in tries:
            if p1 <= 0:
                continue
            new, delivered = _slot(srv, st, (a, alpha[a - 1]) if ok else None)
            if delivered is None:
                outs.append((p1, new, None))
                continue
            k, age = delivered
            for got, p2 in ((True, srv.p_down[k - 1]), (False, 1.0 - srv.p_down[k - 1])):
                if p2 > 0:
                    loop = srv.uplink_delay + srv.processing_time[k - 1] + srv.downlink_delay
                    outs.append((p1 * p2, new, (k, age + loop) if got else None))
        per_server.append(outs)
    gens = []
    for k, pr in enumerate(scenario.processes):
        lam = pr.arrival_probability
        gens.append([(0, 1.0)] if lam == 1.0 else [(0, lam), (min(alpha[k] + 1, caps[k] - 1), 1.0 - lam)])
    result = {}
    for combo in product(*per_server):
        prob = 1.0
        new_tau = [t + 1 for t in tau]
        for p, _, dl in combo:
            prob *= p
            if dl is not None:
                new_tau[dl[0] - 1] = min(new_tau[dl[0] - 1], dl[1])
        new_tau = tuple(min(t, c) for t, c in zip(new_tau, caps))
        new_servers = tuple(c[1] for c in combo)
        for g in product(*gens):
            pg = prob
            for _, p in g:
                pg *= p
            nxt = (new_tau, tuple(x for x, _ in g), new_servers)
            result[nxt] = result.get(nxt, 0.0) + pg
    return result


def build(scenario):
    """BFS from (every tau, every alpha = 0, idle servers): ``(states, {state: (cost, [(a, row)])})``."""
    caps = [pr.tau_cap for pr in scenario.processes]
    q = [cost_table(pr) for pr in scenario.processes]
    idle = tuple(((None,) * max(s.uplink_delay - 1, 0), None, (None,) * s.downlink_delay) for s in scenario.servers)
    start = [(tuple(t), (0,) * len(caps), idle) for t in product(*[range(1, c + 1) for c in caps])]
    return explore(start, lambda s: _actions(scenario, s[2]), lambda s, a: _step(scenario, s, a),
                   lambda s: sum(q[k][t - 1] for k, t in enumerate(s[0])))


def to_arrays(states, model):
    """``(s_indices, a_indices, cost, P, n_states)`` for ``MDP.from_arrays`` (pairs state-major,
    ``a_indices`` the action's position in the state's list)."""
    index = {s: i for i, s in enumerate(states)}
    s_idx, a_idx, cost, rows, cols, vals = [], [], [], [], [], []
    for i, s in enumerate(states):
        c, pairs = model[s]
        for j, (_, row) in enumerate(pairs):
            a_idx.append(j)
            for s2, p in row.items():
                rows.append(len(s_idx))
                cols.append(index[s2])
                vals.append(p)
            s_idx.append(i)
            cost.append(c)
    P = sp.csr_matrix((vals, (rows, cols)), shape=(len(s_idx), len(states)))
    return np.array(s_idx), np.array(a_idx), np.array(cost), P, len(states)


# ----------------------------------------------------------------------------- small systems, one per field
#: Two scalar processes on a cloud (U = D = 1) and an edge (U = D = 0) server, cap 5, and the
#: fields that make each test system (``small_scenario(name)``): none, per-link probabilities,
#: cost families, random arrivals.
SMALL = {"model": {"kind": "wncs"}, "channel": {"success_probability": 0.9},
         "process": [{"name": "a", "A": [[1.2]], "tau_cap": 5}, {"name": "b", "A": [[1.1]], "tau_cap": 5}],
         "server": [{"name": "cloud", "uplink_delay": 1, "downlink_delay": 1, "processing_time": [1, 1]},
                    {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [1, 2]}]}
FIELDS = {
    "none": {},
    "links": {"server": {0: {"p_up": [0.95, 0.6]}, 1: {"p_down": [0.6, 0.99]}}},
    "costs": {"process": {0: {"cost": {"power": 2.0}}, 1: {"cost": [1, 2, 4, 8, 16]}}},
    "arrivals": {"process": {0: {"arrival_probability": 0.5}}},
}


def small_scenario(field):
    """The small system with one field of ``FIELDS`` in use."""
    from copy import deepcopy

    from wncs_lp.scenario import scenario_from_dict

    raw = deepcopy(SMALL)
    for table, entries in FIELDS[field].items():
        for i, values in entries.items():
            raw[table][i].update(values)
    return scenario_from_dict(raw, source=f"<{field}>")
