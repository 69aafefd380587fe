"""Cross-check of ``build_wncs`` against an independent, plain reference (tests/reference/wncs.py).

The reference was written from the model's specification (now ``docs/model.md``) alone, without
reading the package's builder.  For every scenario below we compare

1. the numbers of states and state-action pairs;
2. the multiset of (tau, number of feasible actions) over states, and the multiset of actions;
3. the optimal gain (policy iteration on each side's own arrays) to 1e-9 relative;
4. the transition rows, pair by pair, under an explicit state mapping: the package's
   per-server configs (up, job, d, down) are mapped to the reference's, with the pipeline
   orientation (newest-first or oldest-first) detected once per scenario, and every row
   P(. | s, a) must agree to 1e-12.

The scenarios cover U = 0..3, D = 0..2, 1-3 servers, allow_idle and distinct both ways,
per-server p_up / p_down different from p, p = 1 (zero-probability outcomes dropped) and
processing times 1..4 given as lists (and once via slots_per_dimension), and per-link
probabilities (a list of one per process).
"""
from __future__ import annotations

from collections import Counter
from itertools import product

import numpy as np
import pytest

import reference.wncs as ref
from wncs_lp import scenario_path
from wncs_lp.models.wncs import build_wncs
from wncs_lp.scenario import load_scenario, scenario_from_dict


def srv(U, D, T, **kw):
    out = {"uplink_delay": U, "downlink_delay": D}
    if isinstance(T, int):
        out["slots_per_dimension"] = T
    else:
        out["processing_time"] = list(T)
    out.update(kw)
    return out


def scen(procs, servers, p=0.9, allow_idle=False, distinct=True):
    return {
        "model": {"kind": "wncs", "allow_idle": allow_idle, "distinct": distinct},
        "channel": {"success_probability": p},
        "process": procs,
        "server": servers,
    }


A2 = [[1.05, 0.3], [0.0, 0.9]]

SCENARIOS = {
    # U = 0, D = 0, one server, scalar A
    "one-server-U0D0": scen([{"A": [[1.2]], "tau_cap": 6}], [srv(0, 0, [2])], p=0.8),
    # remote + edge, 2x2 A, edge with its own p_up
    "remote-edge-2proc": scen(
        [{"A": [[1.1]], "tau_cap": 4}, {"A": A2, "tau_cap": 5, "weight": 2.0}],
        [srv(1, 1, [1, 2], name="remote"), srv(0, 0, [2, 4], name="edge", p_up=0.7)],
        p=0.9,
    ),
    # U = 2, D = 2, p = 1 (outcomes of probability zero dropped), idling allowed
    "U2D2-p1-idle": scen([{"A": [[1.1]], "tau_cap": 6}], [srv(2, 2, [3])], p=1.0, allow_idle=True),
    # U = 3, D = 1, own p_down, two processes on one server
    "U3D1-2proc": scen(
        [{"A": [[1.02]], "tau_cap": 4}, {"A": A2, "tau_cap": 4}],
        [srv(3, 1, [1, 2], p_down=0.6)],
        p=0.85,
    ),
    # three servers, two processes: more accepting servers than processes -> 0 allowed
    "3srv-2proc-distinct": scen(
        [{"A": [[1.1]], "tau_cap": 3}, {"A": [[1.0]], "tau_cap": 4}],
        [srv(0, 0, [1, 2]), srv(1, 1, [2, 1], p_up=0.5), srv(0, 2, [1, 1], p_down=0.75)],
        p=0.9,
    ),
    # distinct = false, p = 1, T up to 4
    "2srv-nondistinct-p1": scen(
        [{"A": [[1.1]], "tau_cap": 5}, {"A": A2, "tau_cap": 5}],
        [srv(2, 0, [1, 4]), srv(1, 2, [3, 2])],
        p=1.0,
        distinct=False,
    ),
    # U = 3, D = 2, T = 4 on one server, an edge server with U = 0, D = 1; idling allowed
    "2srv-idle-U3D2": scen(
        [{"A": A2, "tau_cap": 6}],
        [srv(3, 2, [4], p_up=0.6, p_down=0.8), srv(0, 1, [1], p_up=0.95, p_down=0.5)],
        p=0.9,
        allow_idle=True,
    ),
    # three processes on three servers, distinct = false, idling allowed, slots_per_dimension
    "3srv-3proc-nondistinct-idle": scen(
        [{"A": [[1.1]], "tau_cap": 3}, {"A": [[1.0]], "tau_cap": 3}, {"A": A2, "tau_cap": 3}],
        [srv(0, 0, 1), srv(1, 0, [1, 2, 1], p_up=0.7), srv(0, 1, [2, 1, 1], p_down=0.8)],
        p=0.9,
        allow_idle=True,
        distinct=False,
    ),
    # three processes, two servers, distinct, no idling, U = 2 uplink with T = 1
    "2srv-3proc-U2": scen(
        [{"A": [[1.1]], "tau_cap": 3}, {"A": [[1.05]], "tau_cap": 4}, {"A": [[0.9]], "tau_cap": 3}],
        [srv(2, 1, [1, 1, 2]), srv(0, 0, [3, 1, 2], p_up=0.8)],
        p=0.9,
    ),
    # per-link probabilities: every (process, server) its own uplink and downlink (docs/model.md)
    "2srv-2proc-per-link": scen(
        [{"A": [[1.1]], "tau_cap": 5}, {"A": A2, "tau_cap": 4}],
        [srv(1, 1, [1, 2], p_up=[0.95, 0.6], p_down=[0.9, 0.7]), srv(0, 0, [2, 1], p_up=[0.5, 0.99])],
        p=0.9,
    ),
    # distinct = false, no idling, more servers than processes: 0 is allowed only when both
    # servers accept (more accepting servers than processes), otherwise the process is sent
    "2srv-1proc-nondistinct": scen(
        [{"A": [[1.15]], "tau_cap": 6}],
        [srv(0, 0, [2]), srv(1, 1, [1], p_down=0.7)],
        p=0.9,
        distinct=False,
    ),
}


#: the spec's table (model.md section 5): processes 1, 4 on remote + edge, tau_hat = 12, p = 0.9
PAPER_P14 = ("paper_p14.toml", 7340, 12181, 432.180362984)


# ----------------------------------------------------------------------------- helpers
_CACHE: dict = {}


def built(name):
    if name not in _CACHE:
        if name == "paper-p14":
            sc = load_scenario(scenario_path(PAPER_P14[0]))
        else:
            sc = scenario_from_dict(SCENARIOS[name])
        m = build_wncs(sc)
        states, model = ref.build_reference(sc)
        _CACHE[name] = (sc, m, states, model)
    return _CACHE[name]


def pkg_state_key(m, s, rev_up, rev_down):
    """The package's state s as a reference state (tau, servers)."""
    tau = tuple(int(x) for x in m.states.tau[s])
    cfg = m.states.configs[int(m.states.config[s])]
    servers = []
    for up, job, d, down in cfg:
        up = tuple(int(x) for x in up)
        down = tuple(int(x) for x in down)
        if rev_up:
            up = up[::-1]
        if rev_down:
            down = down[::-1]
        servers.append((up, int(job), int(d), down))
    return tau, tuple(servers)


def state_mapping(m, states):
    """Find the pipeline orientation under which the package's states are exactly the
    reference's; return the list package state -> reference state."""
    target = set(states)
    for rev_up, rev_down in product((False, True), repeat=2):
        keys = [pkg_state_key(m, s, rev_up, rev_down) for s in range(m.n_states)]
        if set(keys) == target and len(set(keys)) == len(keys):
            return keys
    return None


def pkg_action(m, l):
    return tuple(int(x) for x in np.atleast_1d(m.action_table[int(m.a_indices[l])]))


# ----------------------------------------------------------------------------- tests
NAMES = sorted(SCENARIOS) + ["paper-p14"]


def test_reference_closed_forms():
    """The reference itself reproduces the spec's checks (model.md sections 2 and 5)."""
    # U = D = 0, T = 1: an update sent in slot t resets tau to 1 at t+1 (p = 1)
    sc = scenario_from_dict(scen([{"A": [[1.1]], "tau_cap": 4}], [srv(0, 0, [1])], p=1.0))
    s0 = ((4,), (((), 0, 0, ()),))
    assert ref.feasible_actions(sc, s0) == [(1,)]
    assert ref.step(sc, s0, (1,)) == {((1,), (((), 0, 0, ()),)): 1.0}
    # U = D = 1, T = 3, p = 1, A = [[1.1]]: gain (q(5) + q(6) + q(7)) / 3 = 10.3645542423
    sc = scenario_from_dict(scen([{"A": [[1.1]], "tau_cap": 10}], [srv(1, 1, [3])], p=1.0))
    g, _ = ref.reference_gain(sc)
    assert g == pytest.approx(10.3645542423, rel=1e-10)
    # U = D = 0, T = 1, pd = 1: gain -> r / (1 - (1 - p) a^2) as tau_hat grows
    sc = scenario_from_dict(
        scen([{"A": [[1.1]], "tau_cap": 60}], [srv(0, 0, [1], p_down=1.0)], p=0.7)
    )
    g, _ = ref.reference_gain(sc)
    assert g == pytest.approx(1.0 / (1.0 - 0.3 * 1.21), rel=1e-9)


def test_reference_reproduces_spec_table():
    """Processes 1, 4 on remote + edge: the spec's certified states / pairs / gain."""
    sc, m, states, model = built("paper-p14")
    _, n, L, gain = PAPER_P14
    assert len(states) == n and sum(len(model[s][1]) for s in states) == L
    g, (lo, hi) = ref.reference_gain(sc, (states, model))
    assert g == pytest.approx(gain, rel=1e-11)
    assert lo <= gain * (1 + 1e-11) and gain * (1 - 1e-11) <= hi


@pytest.mark.parametrize("name", NAMES)
def test_counts(name):
    sc, m, states, model = built(name)
    n_pairs = sum(len(model[s][1]) for s in states)
    assert (m.n_states, m.n_pairs) == (len(states), n_pairs)
    assert name == "paper-p14" or len(states) <= 5000  # keeps the file fast


@pytest.mark.parametrize("name", NAMES)
def test_tau_action_multisets(name):
    sc, m, states, model = built(name)
    n_act = np.diff(m.pair_ptr)
    pkg = Counter((tuple(int(x) for x in m.states.tau[s]), int(n_act[s])) for s in range(m.n_states))
    mine = Counter((s[0], len(model[s][1])) for s in states)
    assert pkg == mine
    pkg_a = Counter(pkg_action(m, l) for l in range(m.n_pairs))
    mine_a = Counter(a for s in states for a, _ in model[s][1])
    assert pkg_a == mine_a


@pytest.mark.parametrize("name", NAMES)
def test_no_zero_entries(name):
    """Outcomes of probability zero (p = 1 links) are dropped, not stored as explicit zeros."""
    sc, m, states, model = built(name)
    assert m.P.data.size == 0 or m.P.data.min() > 0.0


@pytest.mark.parametrize("name", NAMES)
def test_gain(name):
    sc, m, states, model = built(name)
    g_ref, (lo, hi) = ref.reference_gain(sc, (states, model))
    assert lo - 1e-9 * abs(g_ref) <= g_ref <= hi + 1e-9 * abs(g_ref)
    g, h, _ = ref.policy_iteration(m.s_indices, np.asarray(m.cost), m.P, np.asarray(m.pair_ptr))
    assert np.ptp(g) <= 1e-9 * abs(g).max()
    assert abs(g.mean() - g_ref) <= 1e-9 * abs(g_ref), (g.mean(), g_ref)


@pytest.mark.parametrize("name", NAMES)
def test_rows_exact(name):
    sc, m, states, model = built(name)
    keys = state_mapping(m, states)
    assert keys is not None, "no pipeline orientation maps the package's states onto the reference's"
    P = m.P.tocsr()
    for s in range(m.n_states):
        c_ref, rows = model[keys[s]]
        ref_rows = dict(rows)
        lo, hi = int(m.pair_ptr[s]), int(m.pair_ptr[s + 1])
        assert hi - lo == len(ref_rows), (keys[s], hi - lo, len(ref_rows))
        for l in range(lo, hi):
            assert int(m.s_indices[l]) == s
            a = pkg_action(m, l)
            assert a in ref_rows, (keys[s], a, list(ref_rows))
            assert m.cost[l] == pytest.approx(c_ref, rel=1e-12)
            start, end = P.indptr[l], P.indptr[l + 1]
            got = {}
            for j, v in zip(P.indices[start:end], P.data[start:end]):
                if v != 0.0:
                    got[keys[j]] = got.get(keys[j], 0.0) + float(v)
            want = ref_rows[a]
            assert set(got) == set(want), (name, keys[s], a, got, want)
            for k, v in want.items():
                assert got[k] == pytest.approx(v, rel=1e-12, abs=1e-15), (name, keys[s], a, k, got[k], v)
