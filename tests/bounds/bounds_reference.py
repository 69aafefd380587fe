"""Independent references for the tests of the bounds, written from docs/model.md and docs/bounds.md
without the package's relaxation code:

* the claim of a server slot by walking the server's timeline with the plain reference builder
  (``tests/reference/wncs.py``): who is in service in slot t + U_m when nothing new is sent;
* relaxation 1's LP written out whole with ``scipy.optimize.linprog``: one occupation measure per
  process over its private chain (built by the reference builder from a 1-process scenario
  written here), all coupled by the averaged capacity of every server.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

import reference.wncs as ref
from wncs_lp.scenario import scenario_from_dict


def slot_holder(scenario, servers: tuple, m: int) -> int:
    """The process (1-based, 0 = none) served in slot t + U_m of server m if nothing new is sent:
    U_m slots of the reference automaton with no sends, then the job in service, if any."""
    state = (tuple(pr.tau_cap for pr in scenario.processes), servers)
    for _ in range(scenario.servers[m].uplink_delay):
        nxt = ref.step(scenario, state, (0,) * scenario.n_servers)
        state = next(iter(nxt))  # without sends only the downlink branches, and only in tau
    _, job, d, _ = state[1][m]
    return job if d > 0 else 0


def claims_brute(scenario, servers: tuple, action: tuple) -> np.ndarray:
    """(M, N) claim of slot t + U_m of server m by process k: held by k's job, or k sent to m now."""
    out = np.zeros((scenario.n_servers, scenario.n_processes))
    for m in range(scenario.n_servers):
        holder = slot_holder(scenario, servers, m)
        if holder:
            out[m, holder - 1] += 1
        if action[m]:
            out[m, action[m] - 1] += 1
    return out


def private_scenario(scenario, k: int):
    """Process k alone with its own copy of every server (idling allowed), written from the fields."""
    pr = scenario.processes[k]
    return scenario_from_dict({
        "model": {"kind": "wncs", "allow_idle": True, "distinct": scenario.model.distinct},
        "process": [{"A": pr.A.tolist(), "R": pr.R.tolist(), "weight": pr.weight, "tau_cap": pr.tau_cap}],
        "server": [{"name": s.name, "uplink_delay": s.uplink_delay, "downlink_delay": s.downlink_delay,
                    "processing_time": [s.processing_time[k]], "p_up": s.p_up[k], "p_down": s.p_down[k]}
                   for s in scenario.servers],
    }, source=f"<private {k}>")


def _private_blocks(scenario, k: int):
    """(balance matrix, cost, claims (L, M)) of process k's private chain (reference builder)."""
    priv = private_scenario(scenario, k)
    states, model = ref.build_reference(priv)
    s_idx, cost, P, ptr, actions = ref.to_pair_arrays(states, model)
    n, L = len(states), len(s_idx)
    E = sp.csr_matrix((np.ones(L), (s_idx, np.arange(L))), shape=(n, L))
    claims = np.array([claims_brute(priv, states[s][1], a)[:, 0] for s, a in zip(s_idx, actions)])
    return (E - P.T).tocsr(), cost, claims


def relaxation1_lp(scenario) -> float:
    """min sum_k <q_k, x_k> over stationary x_k of every private chain with
    sum_k E_{x_k}[claim_m] = 1 (no idling and N >= M) or <= 1 (otherwise), for every server m."""
    blocks = [_private_blocks(scenario, k) for k in range(scenario.n_processes)]
    sizes = [b[1].size for b in blocks]
    balance = sp.block_diag([b[0] for b in blocks])
    norm = sp.block_diag([np.ones((1, s)) for s in sizes])
    capacity = sp.csr_matrix(np.hstack([b[2].T for b in blocks]))
    cost = np.concatenate([b[1] for b in blocks])
    zero = np.zeros(balance.shape[0])
    equality = not scenario.model.allow_idle and scenario.n_processes >= scenario.n_servers
    M = scenario.n_servers
    if equality:
        res = linprog(cost, A_eq=sp.vstack([balance, norm, capacity]).tocsr(),
                      b_eq=np.concatenate([zero, np.ones(len(sizes)), np.ones(M)]), bounds=(0, None), method="highs")
    else:
        res = linprog(cost, A_ub=capacity, b_ub=np.ones(M), A_eq=sp.vstack([balance, norm]).tocsr(),
                      b_eq=np.concatenate([zero, np.ones(len(sizes))]), bounds=(0, None), method="highs")
    assert res.status == 0, res.message
    return float(res.fun)


A1 = [[1.02, 1, 0, 1], [0, 1, 0.2, 0], [0, 0, 1, 0], [0, 0, 0, 1.01]]
A2 = [[1, 1, 0], [0, 1.02, 0], [0, 0, 1]]
REMOTE = {"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1}
EDGE = {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2}
FOG = {"name": "fog", "uplink_delay": 1, "downlink_delay": 0, "slots_per_dimension": 1}


def shape(name: str):
    """Small Section II scenarios of several shapes (processes 1, 2 of the paper unless said)."""
    procs = [{"A": A1}, {"A": A2}]
    model = {"kind": "wncs", "tau_cap": 8}
    servers = [REMOTE, EDGE]
    if name == "asymmetric":  # p_up != p_down on both servers
        servers = [{**REMOTE, "p_up": 0.7, "p_down": 0.95}, {**EDGE, "p_up": 0.95, "p_down": 0.8}]
    elif name == "three-servers":  # N = 2 < M = 3: an accepting server may be left unused
        servers, model = [REMOTE, EDGE, FOG], {"kind": "wncs", "tau_cap": 7}
    elif name == "idle":
        model = {**model, "allow_idle": True}
    elif name == "u2":  # an uplink place on the remote server
        servers = [{**REMOTE, "uplink_delay": 2}, EDGE]
    elif name == "u3":  # two uplink places, jobs shorter and longer than the places
        procs = [{"A": [[1.1]]}, {"A": [[1.02, 1], [0, 1]]}]
        servers = [{"name": "far", "uplink_delay": 3, "downlink_delay": 0, "processing_time": [2, 1]},
                   {"name": "near", "uplink_delay": 0, "downlink_delay": 1, "processing_time": [3, 2]}]
        model = {"kind": "wncs", "tau_cap": 9}
    elif name == "3x3":  # three processes on three servers with U = 0, 1, 2
        procs = [{"A": [[1.1]]}, {"A": [[1.02, 1], [0, 1]]}, {"A": [[1.05]], "weight": 2.0}]
        servers = [{"name": "a", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 1},
                   {"name": "b", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1},
                   {"name": "c", "uplink_delay": 2, "downlink_delay": 0, "processing_time": [1, 3, 2]}]
        model = {"kind": "wncs", "tau_cap": 5}
    elif name == "one-idle":  # one process on one server, idling allowed: relaxation 1 is the system
        procs = [{"A": [[1.1]]}]
        servers = [{"name": "edge", "uplink_delay": 1, "downlink_delay": 0, "processing_time": [2]}]
        model = {"kind": "wncs", "tau_cap": 12, "allow_idle": True}
    elif name != "paper":
        raise KeyError(name)
    return scenario_from_dict({"model": model, "channel": {"success_probability": 0.9}, "process": procs,
                               "server": servers}, source=f"<{name}>")


SHAPES = ("paper", "asymmetric", "three-servers", "idle", "u2", "u3", "3x3")


def brute_lookahead(system, groups, h, column, tau, c: int) -> np.ndarray:
    """sum_o P(o | C, a) sum_G h_G(tau'_G, column_G(C'_o)) per feasible action of configuration c,
    by loops over the automaton's outcome lists (per-process tables: groups of one process)."""
    out = []
    for outs in system.automaton.outcomes[c]:
        v = 0.0
        for nxt, delta, p in outs:
            nt = [min(tau[k] + 1, int(system.caps[k])) for k in range(system.n_processes)]
            nt = [min(t, delta[k]) if delta[k] > 0 else t for k, t in enumerate(nt)]
            for g, hg, col in zip(groups, h, column):
                v += p * hg[(col[nxt],) + tuple(nt[k] - 1 for k in g)]
        out.append(v)
    return np.array(out)
