"""A deliberately plain reference builder for the Section II "wncs" model.

Written straight from the model's specification (now ``docs/model.md``, Section II), independently of
``wncs_lp/models/wncs.py`` and ``space.py`` (which the author did not read), so that the two
can be cross-checked by ``tests/test_wncs_reference.py``.  Everything here is per state and
per action, with Python loops and dictionaries: slow, but easy to check against that text.

Representation
--------------
A full state is the hashable tuple ``(tau, servers)``:

* ``tau`` -- tuple of the AoI values tau_1..tau_N (1-based, 1..tau_hat_k);
* ``servers`` -- one tuple ``(up, job, d, down)`` per server m, where

  - ``up`` has ``max(U_m - 1, 0)`` places; ``up[i]`` is the process (1..N, 0 = empty or lost)
    of the update sent ``i + 1`` slots ago.  It starts service ``j = U_m - 1 - i`` slots from
    now, and ``up[-1]`` is the one that leaves the uplink in this slot's step 5;
  - ``job`` is the process in service (0 = none) and ``d`` its remaining slots (0 when idle);
  - ``down`` has ``D_m`` places; ``down[i]`` is the process whose job completed ``i + 1`` slots
    ago (0 = empty).  ``down[-1]`` (completed D_m slots ago) leaves in this slot's step 4.

The age a delivered command carries is fixed, U_m + T_{m,k} + D_m, so the pipelines need only
hold process indices.
"""
from __future__ import annotations

from collections import deque
from itertools import product

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve

from wncs_lp.models.cost import cost_tables

__all__ = [
    "initial_states",
    "accepts",
    "feasible_actions",
    "step",
    "build_reference",
    "explore",
    "to_pair_arrays",
    "policy_iteration",
    "reference_gain",
]


# ----------------------------------------------------------------------------- the spec's rules
def idle_server(srv):
    """An idle server with empty pipelines."""
    U, D = srv.uplink_delay, srv.downlink_delay
    return (tuple([0] * max(U - 1, 0)), 0, 0, tuple([0] * D))


def initial_states(scenario):
    """Every tau in the box 1..tau_hat, every server idle, empty pipelines."""
    caps = [pr.tau_cap for pr in scenario.processes]
    servers = tuple(idle_server(s) for s in scenario.servers)
    return [(tuple(tau), servers) for tau in product(*[range(1, c + 1) for c in caps])]


def accepts(srv, sstate):
    """Accepting rule: busy = d and, for each update still in the uplink that starts service in
    j slots, busy = j + T_{m,k}; accept iff busy <= U (for U = 0: iff d = 0)."""
    up, job, d, down = sstate
    U = srv.uplink_delay
    if U == 0:
        return d == 0
    busy = d
    for i, k in enumerate(up):
        if k:
            j = U - 1 - i
            busy = max(busy, j + srv.processing_time[k - 1])
    return busy <= U


def feasible_actions(scenario, state):
    """All action tuples (a_1..a_M) allowed in ``state`` (spec: Actions)."""
    N = scenario.n_processes
    _, servers = state
    acc = [accepts(srv, ss) for srv, ss in zip(scenario.servers, servers)]
    n_acc = sum(acc)
    idle_ok = scenario.model.allow_idle or n_acc > N
    choices = []
    for a in acc:
        if not a:
            choices.append((0,))
        else:
            choices.append(tuple(([0] if idle_ok else []) + list(range(1, N + 1))))
    out = []
    for a in product(*choices):
        if scenario.model.distinct:
            sent = [x for x in a if x]
            if len(sent) != len(set(sent)):
                continue
        out.append(tuple(a))
    return out


def _server_slot(srv, sstate, k_sent, up_ok):
    """Steps 1-5 for one server given the uplink outcome.  Returns (new server state,
    delivered process or 0)."""
    up, job, d, down = sstate
    U, D = srv.uplink_delay, srv.downlink_delay
    T = srv.processing_time
    # 1. the update sent now survives with pu (decided by up_ok); a lost update is gone
    arriving = k_sent if (k_sent and up_ok) else 0
    # 2. U = 0: a surviving update starts service at once
    if U == 0 and arriving:
        assert d == 0 and job == 0, "U = 0 server got an update while busy"
        job, d = arriving, T[arriving - 1]
    # 3. service
    completed = 0
    if d > 0:
        d -= 1
        if d == 0:
            completed = job
            job = 0
    # 4. downlink
    if D == 0:
        delivered = completed
        new_down = ()
    else:
        delivered = down[-1]
        new_down = (completed,) + tuple(down[:-1])
    # 5. U >= 1: the update leaving the uplink starts service from the next slot
    if U >= 1:
        if U == 1:
            leaving = arriving
            new_up = ()
        else:
            leaving = up[-1]
            new_up = (arriving,) + tuple(up[:-1])
        if leaving:
            assert d == 0 and job == 0, "update leaving the uplink found the server busy"
            job, d = leaving, T[leaving - 1]
    else:
        new_up = ()
    return (tuple(new_up), job, d, tuple(new_down)), delivered


def step(scenario, state, action):
    """{next_state: probability} for one slot from ``state`` under ``action``.

    Every channel outcome (uplink of each server that sends, downlink of each server that
    delivers) is enumerated; zero-probability outcomes are dropped; equal next states merge.
    """
    tau, servers = state
    caps = [pr.tau_cap for pr in scenario.processes]
    # per server: list of (prob, new server state, delivered process or 0 if lost/none, age)
    per_server = []
    for srv, ss, a in zip(scenario.servers, servers, action):
        outs = []
        pu_a = srv.p_up[a - 1] if a else 1.0  # the link of the process sent
        up_opts = [(True, pu_a), (False, 1.0 - pu_a)] if a else [(True, 1.0)]
        for up_ok, pu in up_opts:
            if pu <= 0.0:
                continue
            new_ss, delivered = _server_slot(srv, ss, a, up_ok)
            if delivered:
                pd_k = srv.p_down[delivered - 1]  # the link of the process delivered
                dn_opts = [(True, pd_k), (False, 1.0 - pd_k)]
            else:
                dn_opts = [(False, 1.0)]
            for dn_ok, pd in dn_opts:
                if pd <= 0.0:
                    continue
                if dn_ok:
                    age = srv.uplink_delay + srv.processing_time[delivered - 1] + srv.downlink_delay
                    outs.append((pu * pd, new_ss, delivered, age))
                else:
                    outs.append((pu * pd, new_ss, 0, 0))
        per_server.append(outs)
    result = {}
    for combo in product(*per_server):
        prob = 1.0
        new_tau = [t + 1 for t in tau]
        for pr, _, k, age in combo:
            prob *= pr
            if k:
                new_tau[k - 1] = min(new_tau[k - 1], age)
        new_tau = tuple(min(t, c) for t, c in zip(new_tau, caps))
        nxt = (new_tau, tuple(c[1] for c in combo))
        result[nxt] = result.get(nxt, 0.0) + prob
    return result


def build_reference(scenario):
    """BFS from the initial states.

    Returns ``(states, model)``: ``states`` the reachable states in BFS order, ``model`` a dict
    state -> (cost, [(action tuple, {next_state: prob}), ...]).
    """
    q = cost_tables(scenario)
    return explore(initial_states(scenario), lambda s: feasible_actions(scenario, s),
                   lambda s, a: step(scenario, s, a),
                   lambda s: float(sum(q[k][t - 1] for k, t in enumerate(s[0]))))


def explore(start, actions, step, cost):
    """Breadth-first search from ``start``: ``(states in BFS order, {state: (cost, [(action,
    {next state: probability}), ...])})`` for the functions ``actions(s)``, ``step(s, a)`` and
    ``cost(s)`` of a model."""
    seen = set(start)
    order = list(start)
    queue = deque(start)
    model = {}
    while queue:
        s = queue.popleft()
        rows = []
        for a in actions(s):
            row = step(s, a)
            rows.append((a, row))
            for s2 in row:
                if s2 not in seen:
                    seen.add(s2)
                    order.append(s2)
                    queue.append(s2)
        model[s] = (cost(s), rows)
    return order, model


def to_pair_arrays(states, model):
    """Pair form: (s_indices, cost, P csr (pairs x states), pair_ptr, actions list)."""
    index = {s: i for i, s in enumerate(states)}
    s_idx, cost, actions = [], [], []
    rows, cols, vals = [], [], []
    ptr = [0]
    l = 0
    for i, s in enumerate(states):
        c, pairs = model[s]
        for a, row in pairs:
            s_idx.append(i)
            cost.append(c)
            actions.append(a)
            for s2, p in row.items():
                rows.append(l)
                cols.append(index[s2])
                vals.append(p)
            l += 1
        ptr.append(l)
    P = sp.csr_matrix((vals, (rows, cols)), shape=(l, len(states)))
    return np.array(s_idx), np.array(cost), P, np.array(ptr), actions


# ----------------------------------------------------------------------------- policy iteration
def _evaluate(Pd, c):
    """Gain vector g and bias h (with P* h = 0) of a stationary policy with matrix Pd, cost c.

    Multichain-safe: closed strongly connected components are the recurrent classes; each gets
    its stationary distribution; transient states are solved by absorption.
    """
    n = Pd.shape[0]
    Pd = sp.csr_matrix(Pd)
    ncomp, lab = connected_components(Pd, directed=True, connection="strong")
    # a component is closed iff no edge leaves it
    coo = Pd.tocoo()
    leaves = np.zeros(ncomp, bool)
    mask = lab[coo.row] != lab[coo.col]
    leaves[lab[coo.row[mask]]] = True
    g = np.zeros(n)
    h = np.zeros(n)
    rec = np.zeros(n, bool)
    for comp in np.flatnonzero(~leaves):
        idx = np.flatnonzero(lab == comp)
        rec[idx] = True
        Pc = Pd[idx][:, idx]
        m = idx.size
        I = sp.identity(m, format="lil")
        # stationary distribution: pi (I - Pc) = 0, sum pi = 1 (first equation replaced)
        M = sp.lil_matrix((I - Pc).T)
        M[0, :] = np.ones(m)
        rhs = np.zeros(m)
        rhs[0] = 1.0
        pi = np.atleast_1d(spsolve(M.tocsc(), rhs))
        gc = float(pi @ c[idx])
        # bias: (I - Pc) h = c - gc, pi h = 0  (pin h[0] = 0, then shift)
        B = sp.lil_matrix(I - Pc)
        B[0, :] = 0.0
        B[0, 0] = 1.0
        r = c[idx] - gc
        r[0] = 0.0
        hc = np.atleast_1d(spsolve(B.tocsc(), r))
        hc -= pi @ hc
        g[idx] = gc
        h[idx] = hc
    tr = np.flatnonzero(~rec)
    if tr.size:
        rc = np.flatnonzero(rec)
        Ptt = Pd[tr][:, tr]
        Ptr = Pd[tr][:, rc]
        A = (sp.identity(tr.size, format="csc") - Ptt).tocsc()
        g[tr] = np.atleast_1d(spsolve(A, Ptr @ g[rc]))
        h[tr] = np.atleast_1d(spsolve(A, c[tr] - g[tr] + Ptr @ h[rc]))
    return g, h


def policy_iteration(s_indices, cost, P, pair_ptr, max_iter=500):
    """Multichain policy iteration (Puterman, Alg. 9.2.1) on an MDP in pair form.

    Returns (g, h, policy) with ``policy[s]`` the chosen pair of state s.  Keeps the current
    action unless another one improves by more than a small tolerance.
    """
    n = pair_ptr.size - 1
    P = sp.csr_matrix(P)
    policy = pair_ptr[:-1].copy()
    for _ in range(max_iter):
        g, h = _evaluate(P[policy], cost[policy])
        tol = 1e-11 * max(1.0, np.abs(h).max(), np.abs(g).max())
        # gain improvement
        Pg = P @ g
        new = policy.copy()
        changed = False
        for s in range(n):
            lo, hi = pair_ptr[s], pair_ptr[s + 1]
            vals = Pg[lo:hi]
            best = lo + int(np.argmin(vals))
            if vals[best - lo] < Pg[policy[s]] - tol:
                new[s] = best
                changed = True
        if not changed:
            # bias improvement among the gain-minimising actions
            q = cost + P @ h
            for s in range(n):
                lo, hi = pair_ptr[s], pair_ptr[s + 1]
                ok = np.flatnonzero(Pg[lo:hi] <= Pg[lo:hi].min() + tol) + lo
                best = ok[int(np.argmin(q[ok]))]
                if q[best] < q[policy[s]] - tol:
                    new[s] = best
                    changed = True
        if not changed:
            return g, h, policy
        policy = new
    raise RuntimeError("policy iteration did not converge")


def certify(s_indices, cost, P, pair_ptr, h):
    """Bellman bracket on the optimal (constant) gain: min(Th - h) <= theta <= max(Th - h)."""
    q = cost + sp.csr_matrix(P) @ h
    Th = np.minimum.reduceat(q, pair_ptr[:-1])
    diff = Th - h
    return float(diff.min()), float(diff.max())


def reference_gain(scenario, built=None):
    """Optimal average cost of the reference model by policy iteration.

    Returns (gain, (lo, hi)) where (lo, hi) is the Bellman certificate bracket.  Raises if the
    optimal gain is not constant over the states.
    """
    states, model = built if built is not None else build_reference(scenario)
    s_idx, cost, P, ptr, _ = to_pair_arrays(states, model)
    g, h, _ = policy_iteration(s_idx, cost, P, ptr)
    if np.ptp(g) > 1e-9 * max(1.0, abs(g).max()):
        raise RuntimeError(f"optimal gain not constant: {g.min()} .. {g.max()}")
    return float(g.mean()), certify(s_idx, cost, P, ptr, h)
