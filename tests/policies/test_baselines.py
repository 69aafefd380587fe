"""The field's baselines (max-age-first, max-weighted-cost-first, round robin) against brute force.

Each baseline's rule is written out here again, plainly, from ``docs/policies.md``, and applied
state by state to the independent reference model of ``tests/reference/wncs.py`` (its own states,
accepting rule and transitions); the chain it induces is solved by the reference's own
evaluation. Round robin's chain is the hand-built augmented chain over (state, pointer). The
package's exact gains (``wncs_lp.evaluate.evaluate``) must agree to 1e-9 relative, and round
robin's simulation (its pointer carried along) must agree with its exact gain.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import reference.wncs as ref
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.cost import cost_tables
from wncs_lp.models.system import System
from wncs_lp.policies import POLICY_NAMES
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import scenario_from_dict
from wncs_lp.simulate import simulate

# three scalar processes of different growth and weight on a remote (U = D = 1) and an edge server
# (U = D = 0), the edge's uplinks per process (every process's shortest loop is the edge's, so the
# max-weight index reads pu_{edge,k}: one link for all would give 16.62 instead of 15.82): the
# rankings differ from one another
RAW = {
    "model": {"kind": "wncs", "allow_idle": False, "distinct": True},
    "channel": {"success_probability": 0.8},
    "process": [
        {"name": "a", "A": [[1.3]], "tau_cap": 4},
        {"name": "b", "A": [[1.1]], "tau_cap": 5, "weight": 2.0},
        {"name": "c", "A": [[1.2]], "tau_cap": 4, "weight": 0.5},
    ],
    "server": [
        {"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "processing_time": [1, 1, 2]},
        {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [2, 1, 2],
         "p_up": [0.6, 0.95, 0.5]},
    ],
}


@pytest.fixture(scope="module")
def case():
    sc = scenario_from_dict(RAW, source="baselines")
    states, model = ref.build_reference(sc)
    mdp = build(sc)
    return sc, states, model, System.from_scenario(sc), mdp


def loop(srv, k):
    return srv.uplink_delay + srv.processing_time[k] + srv.downlink_delay


def serve(sc, servers, order):
    """The greedy hand-out: down the ranking, each process to its shortest-loop accepting server
    not yet taken (ties: lower server index)."""
    free = [m for m, (srv, ss) in enumerate(zip(sc.servers, servers)) if ref.accepts(srv, ss)]
    label = [0] * len(sc.servers)
    for k in order:
        if not free:
            break
        m = min(free, key=lambda m: (loop(sc.servers[m], k), m))
        label[m] = k + 1
        free.remove(m)
    return tuple(label)


def max_age_order(sc, tau):
    return sorted(range(len(tau)), key=lambda k: (-tau[k], k))


def max_weight_order(sc, tau):
    q = cost_tables(sc)
    v = []
    for k, t in enumerate(tau):
        cap = sc.processes[k].tau_cap
        m = min(range(len(sc.servers)), key=lambda m: (loop(sc.servers[m], k), m))
        srv = sc.servers[m]
        L = loop(srv, k)
        v.append(srv.p_up[k] * srv.p_down[k] * (q[k][min(t + L, cap) - 1] - q[k][min(L, cap) - 1]))  # k's own links
    return sorted(range(len(tau)), key=lambda k: (-v[k], k))


def chain_gain(P, cost):
    g, _ = ref._evaluate(P, np.asarray(cost, float))
    assert np.ptp(g) <= 1e-9 * abs(g).max()
    return float(g.mean())


def brute_force_gain(sc, states, model, order_of):
    index = {s: i for i, s in enumerate(states)}
    rows, cols, vals, cost = [], [], [], []
    for i, s in enumerate(states):
        tau, servers = s
        c, pairs = model[s]
        want = serve(sc, servers, order_of(sc, tau))
        (row,) = [r for a, r in pairs if a == want]
        for s2, p in row.items():
            rows.append(i), cols.append(index[s2]), vals.append(p)
        cost.append(c)
    n = len(states)
    return chain_gain(sp.csr_matrix((vals, (rows, cols)), shape=(n, n)), cost)


def round_robin_gain(sc, states, model):
    """The augmented chain over (state, pointer), built by hand."""
    N, n = sc.n_processes, len(states)
    index = {s: i for i, s in enumerate(states)}
    rows, cols, vals, cost = [], [], [], []
    for r in range(N):
        for i, s in enumerate(states):
            tau, servers = s
            c, pairs = model[s]
            want = serve(sc, servers, [(r + d) % N for d in range(N)])
            sent = [(k - 1 - r) % N for k in want if k]
            r2 = (r + max(sent) + 1) % N if sent else r
            (row,) = [x for a, x in pairs if a == want]
            for s2, p in row.items():
                rows.append(r * n + i), cols.append(r2 * n + index[s2]), vals.append(p)
            cost.append(c)
    return chain_gain(sp.csr_matrix((vals, (rows, cols)), shape=(N * n, N * n)), cost)


def test_the_baselines_are_named():
    assert {"max_age", "max_weight", "round_robin"} <= set(POLICY_NAMES)


@pytest.mark.parametrize("name, order_of", [("max_age", max_age_order), ("max_weight", max_weight_order)])
def test_rank_baselines_against_brute_force(case, name, order_of):
    sc, states, model, system, mdp = case
    assert mdp.n_states == len(states)
    expected = brute_force_gain(sc, states, model, order_of)
    got = evaluate(mdp, make_policy(name, system, mdp)).gain
    assert got == pytest.approx(expected, rel=1e-9)


def test_rank_baselines_differ_from_greedy(case):
    sc, states, model, system, mdp = case
    gains = {name: evaluate(mdp, make_policy(name, system, mdp)).gain for name in ("greedy", "max_age", "max_weight")}
    assert len({round(g, 6) for g in gains.values()}) == 3, gains


def test_round_robin_against_the_augmented_chain(case):
    sc, states, model, system, mdp = case
    expected = round_robin_gain(sc, states, model)
    ev = evaluate(mdp, make_policy("round_robin", system, mdp))
    assert ev.gain == pytest.approx(expected, rel=1e-9)
    assert sum(ev.mse) == pytest.approx(ev.gain, rel=1e-12)
    assert ev.residual < 1e-10


def test_round_robin_simulated_with_its_pointer(case):
    sc, states, model, system, mdp = case
    rr = make_policy("round_robin", system, mdp)
    exact = evaluate(mdp, rr)
    sim = simulate(rr, slots=4000, reps=10, seed=3, burn_in=200, progress=False)
    assert abs(sim.mean - exact.gain) < 4 * sim.stderr
    assert np.allclose(sim.utilisation, exact.utilisation, atol=0.02)


def test_round_robin_is_no_stationary_policy(case):
    sc, states, model, system, mdp = case
    rr = make_policy("round_robin", system, mdp)
    with pytest.raises(PolicyError, match="memory"):
        rr.on_mdp(mdp)
    with pytest.raises(PolicyError, match="memory"):
        rr.act(np.ones((1, 3), dtype=np.int64), np.zeros(1, dtype=np.int64))


def test_round_robin_separable_evaluation_equals_the_augmented_chain(case):
    sc, states, model, system, mdp = case
    rr = make_policy("round_robin", system, mdp)
    full, sep = evaluate(mdp, rr), rr.separable_evaluation()
    assert sep.gain == pytest.approx(full.gain, rel=1e-10)
    assert np.allclose(sep.mse, full.mse, rtol=1e-10)
    assert np.allclose(sep.utilisation, full.utilisation, rtol=1e-10)
