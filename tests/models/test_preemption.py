"""Tests of the Section IV preemption model (``model.md`` section 3, ``wncs_lp/models/preemption.py``).

Gains are checked with a small certified relative value iteration written here (so these tests
do not depend on ``wncs_lp.solvers``), and additionally with ``wncs_lp.solvers.solve`` when that
package provides it.
"""
from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.models.cost import mse_table
from wncs_lp.errors import ModelError
from wncs_lp.models import build
from wncs_lp.models.preemption import (
    PreemptionConfig,
    build_preemption,
    describe_preemption_config,
    feasible_preemption_actions,
    initial_preemption_configs,
    preemption_automaton,
    preemption_step,
)
from wncs_lp.scenario import load_scenario, scenario_from_dict

PAPER = scenario_path("paper_preemption_p12.toml")
THREE = scenario_path("preemption_p123_u0d0.toml")
REF_STATES, REF_PAIRS, REF_GAIN = 23_268, 46_536, 1078.548921698

A1 = [[1.02, 1, 0, 1], [0, 1, 0.2, 0], [0, 0, 1, 0], [0, 0, 0, 1.01]]
A2 = [[1, 1, 0], [0, 1.02, 0], [0, 0, 1]]


# ----------------------------------------------------------------------------- helpers
def certified_gain(mdp, tol=1e-12, lam=0.5, max_iter=100_000):
    """Damped relative value iteration h <- lam h + (1 - lam) T h (the aperiodicity transform).

    Returns (lo, hi) with lo = min(Th - h) <= g* <= max(Th - h) = hi, valid for any h.
    """
    starts = mdp.pair_ptr[:-1]
    h = np.zeros(mdp.n_states)
    for _ in range(max_iter):
        Th = np.minimum.reduceat(mdp.cost + mdp.P @ h, starts)
        d = Th - h
        lo, hi = float(d.min()), float(d.max())
        if hi - lo <= tol * abs(hi):
            return lo, hi
        h = lam * h + (1.0 - lam) * Th
        h -= h[0]
    raise AssertionError(f"RVI did not close: [{lo}, {hi}]")


def gain(mdp):
    lo, hi = certified_gain(mdp)
    return 0.5 * (lo + hi)


def one_server(processes, *, U, D, T, p=0.9, pu=None, pd=None, preemptive=True, cap=12):
    server = {"name": "s", "uplink_delay": U, "downlink_delay": D, "processing_time": list(T)}
    if pu is not None:
        server["p_up"] = pu
    if pd is not None:
        server["p_down"] = pd
    raw = {
        "model": {"kind": "preemption", "preemptive": preemptive, "tau_cap": cap},
        "channel": {"success_probability": p},
        "process": [dict(pr) for pr in processes],
        "server": [server],
    }
    return scenario_from_dict(raw)


def paper(**overrides):
    return load_scenario(PAPER, overrides or None)


def outcomes(scenario, config, a):
    """{(next_config, delta): prob}, merged."""
    out = {}
    for nxt, delta, prob in preemption_step(scenario, config, a):
        out[(nxt, delta)] = out.get((nxt, delta), 0.0) + prob
    return out


def core(config):
    """(job, stack, down) of a configuration (the part the action/slot changes)."""
    return tuple(config[1:])


def next_cores(scenario, config, a):
    """The set of (job, stack, down, delta) after one slot, over all arrivals."""
    return {core(n) + (d,) for (n, d) in outcomes(scenario, config, a)}


def run(scenario, config, actions):
    """Follow a deterministic path: apply actions, keep b fixed to all-ones, return the
    configurations visited and the deliveries (as (slot, delta)) made on the success branch."""
    N = scenario.n_processes
    seen, deliveries = [config], []
    for t, a in enumerate(actions):
        res = outcomes(scenario, config, a)
        succ = [(n, d) for (n, d) in res if n.b == (1,) * N]
        with_delivery = [x for x in succ if any(x[1])]
        nxt, delta = with_delivery[0] if with_delivery else succ[0]
        if any(delta):
            deliveries.append((t, delta))
        config = nxt
        seen.append(config)
    return seen, deliveries


# ----------------------------------------------------------------------------- the file
def test_paper_file_loads():
    sc = paper()
    assert sc.model.kind == "preemption" and sc.model.preemptive
    assert sc.n_servers == 1 and sc.n_processes == 2
    s = sc.servers[0]
    assert (s.uplink_delay, s.downlink_delay, s.processing_time) == (1, 1, (4, 3))
    assert (s.p_up, s.p_down) == ((0.9, 0.9), (0.9, 0.9))
    assert sc.tau_caps == (12, 12)


def test_more_than_one_server_is_rejected():
    # the loader rejects it; the builder double-checks
    raw = copy.deepcopy(paper().to_dict())
    raw["server"].append(dict(raw["server"][0], name="edge"))
    with pytest.raises(Exception, match="exactly one server"):
        scenario_from_dict(raw)


def test_builder_refuses_a_wncs_scenario():
    sc = load_scenario(scenario_path("paper_p12.toml"))
    with pytest.raises(ModelError, match="preemption"):
        build_preemption(sc)


# ----------------------------------------------------------------------------- reference row
@pytest.fixture(scope="module")
def paper_mdp():
    return build(paper())


def test_reference_sizes(paper_mdp):
    assert paper_mdp.n_states == REF_STATES
    assert paper_mdp.n_pairs == REF_PAIRS
    paper_mdp.validate()
    assert paper_mdp.meta["kind"] == "preemption"


def test_reference_gain(paper_mdp):
    lo, hi = certified_gain(paper_mdp)
    assert (hi - lo) / hi < 1e-11
    assert abs(0.5 * (lo + hi) - REF_GAIN) <= 1e-9 * REF_GAIN


@pytest.mark.parametrize("method", ["pi", "rvi"])
def test_reference_gain_with_package_solvers(paper_mdp, method):
    from wncs_lp import solve

    sol = solve(paper_mdp, method=method)
    assert sol.gain_lower - 1e-9 * REF_GAIN <= REF_GAIN <= sol.gain_upper + 1e-9 * REF_GAIN
    assert abs(sol.gain - REF_GAIN) <= 1e-9 * REF_GAIN


def test_lp_gain_against_the_damped_rvi_here():
    """The LP on the preemption model (Clarabel; cap 8, 6k states: the reference row's 23k took
    30 s of the suite) against this file's own certified relative value iteration."""
    from wncs_lp import solve

    mdp = build(paper(**{"model.tau_cap": 8}))
    lo, hi = certified_gain(mdp)
    sol = solve(mdp, method="lp")
    assert sol.gain_lower - 1e-9 * hi <= lo and hi <= sol.gain_upper + 1e-9 * hi
    assert sol.gain == pytest.approx(0.5 * (lo + hi), rel=1e-9)


def test_action_labels_and_order(paper_mdp):
    st = paper_mdp.states
    for s in (0, 17, paper_mdp.n_states // 2, paper_mdp.n_states - 1):
        cfg = st.configs[st.config[s]]
        labels = [paper_mdp.action_label(l) for l in paper_mdp.pairs_of(s)]
        assert labels == [(0,)] + [(k,) for k in (1, 2) if cfg.b[k - 1]]
    assert sorted(tuple(r) for r in paper_mdp.action_table) == [(0,), (1,), (2,)]


# ----------------------------------------------------------------------------- hand traces
def test_preemption_pushes_the_running_job():
    sc = paper()  # U = D = 1, T = (4, 3), caps 12, p = 0.9
    cfg = PreemptionConfig((0, 1), (1, 3, 2), (), (None,))
    assert feasible_preemption_actions(sc, cfg) == [(0,), (2,)]
    res = outcomes(sc, cfg, 2)
    # job 2 starts with age U = 1 and is served at once: (2, 3 - 1, 1 + 1);
    # job 1 goes on the stack untouched in work, one slot older
    job, stack, down = (2, 2, 2), ((1, 3, 3),), (None,)
    expected = {
        (PreemptionConfig(b, job, stack, down), (0, 0)): {(0, 0): 0.01, (1, 0): 0.09, (0, 1): 0.09, (1, 1): 0.81}[b]
        for b in itertools.product((0, 1), repeat=2)
    }
    assert res.keys() == expected.keys()
    for key, prob in expected.items():
        assert res[key] == pytest.approx(prob, abs=1e-15)
    # keep going instead: job 1 is served
    assert next_cores(sc, cfg, 0) == {(((1, 2, 3)), (), (None,), (0, 0))}


def test_resumed_job_keeps_its_work_and_ages_while_waiting():
    sc = paper()
    # job 1 was served one slot (d = 3, g = 2), then preempted by job 2 (T_2 = 3)
    cfg = PreemptionConfig((0, 1), (1, 3, 2), (), (None,))
    seen, deliveries = run(sc, cfg, [2, 0, 0, 0, 0, 0, 0, 0])
    cores = [core(c) for c in seen]
    assert cores[1] == ((2, 2, 2), ((1, 3, 3),), (None,))
    assert cores[2] == ((2, 1, 3), ((1, 3, 4),), (None,))
    # job 2 completes (age U + T_2 = 4) and enters the downlink; in the same slot job 1,
    # one slot older again, resumes with its remaining work d = 3
    assert cores[3] == ((1, 3, 5), (), ((2, 4),))
    assert cores[4] == ((1, 2, 6), (), (None,))  # job 2's command left, aged to 5
    assert cores[5] == ((1, 1, 7), (), (None,))
    assert cores[6] == (None, (), ((1, 8),))
    assert cores[7] == (None, (), (None,))
    # deliveries: process 2 at age U + T_2 + D = 5; process 1 at U + T_1 + D + 3 waited = 9
    assert deliveries == [(3, (0, 5)), (6, (9, 0))]


def test_same_process_arrival_cancels_the_obsolete_job():
    sc = paper()
    cfg = PreemptionConfig((1, 0), (1, 2, 3), (), (None,))
    # restart: the old job of process 1 is cancelled, nothing is stacked
    assert next_cores(sc, cfg, 1) == {((1, 3, 2), (), (None,), (0, 0))}


def test_arrival_discards_a_stacked_job_of_its_process():
    sc = paper()
    cfg = PreemptionConfig((1, 0), (2, 2, 2), ((1, 1, 5),), (None,))
    # job 2 is pushed (one slot older), the stale stacked job 1 is discarded
    assert next_cores(sc, cfg, 1) == {((1, 3, 2), ((2, 2, 3),), (None,), (0, 0))}


def test_stack_order_last_preempted_resumes_first():
    procs = [{"A": [[1.02]]}, {"A": [[1.02]]}, {"A": [[1.02]]}]
    sc = one_server(procs, U=0, D=0, T=(3, 3, 1), p=1.0)
    cfg = PreemptionConfig((1, 1, 1), (1, 3, 0), (), ())
    seen, deliveries = run(sc, cfg, [0, 2, 3, 0])
    cores = [core(c) for c in seen]
    assert cores[1] == ((1, 2, 1), (), ())
    assert cores[2] == ((2, 2, 1), ((1, 2, 2),), ())
    # job 3 (T = 1) preempts job 2, completes in the same slot (D = 0: delivered at once, age 1),
    # and job 2 -- the top of the stack, not job 1 -- resumes
    assert cores[3] == ((2, 2, 2), ((1, 2, 3),), ())
    assert deliveries[0] == (2, (0, 0, 1))
    assert cores[4] == ((2, 1, 3), ((1, 2, 4),), ())


def test_uninterrupted_job_is_delivered_at_the_loop_age():
    procs = [{"A": [[1.02]]}, {"A": [[1.1]]}]
    for U, D in itertools.product((0, 1, 2), (0, 1, 3)):
        sc = one_server(procs, U=U, D=D, T=(2, 3), p=1.0)
        for k in (1, 2):
            cfg = PreemptionConfig((1, 1), None, (), (None,) * D)
            _, deliveries = run(sc, cfg, [k] + [0] * (sc.servers[0].processing_time[k - 1] + D + 1))
            loop = sc.servers[0].loop[k - 1]
            assert deliveries == [(loop - U - 1, tuple(loop if j == k else 0 for j in (1, 2)))], (U, D, k)


def test_delivery_sets_tau_to_the_job_age_in_the_mdp(paper_mdp):
    st = paper_mdp.states
    # an idle server whose downlink holds process 1's command (completed with age U + T_1 = 5)
    cfg = PreemptionConfig((0, 0), None, (), ((1, 5),))
    s = st.find((9, 5), cfg)
    assert s >= 0
    assert st.configs[st.config[s]] == cfg and tuple(st.tau[s]) == (9, 5)
    assert "down [1(g=5)]" in paper_mdp.state_label(s)
    (pair,) = list(paper_mdp.pairs_of(s))  # b = 00: only "keep going"
    assert paper_mdp.action_label(pair) == (0,)
    row = paper_mdp.P.getrow(pair)
    got = dict(zip(row.indices.tolist(), row.data.tolist()))
    pb = {(0, 0): 0.01, (1, 0): 0.09, (0, 1): 0.09, (1, 1): 0.81}
    expected = {}
    for b, p in pb.items():
        nxt = PreemptionConfig(b, None, (), (None,))
        ok = st.find((6, 6), nxt)  # delivered: tau_1 = min(9 + 1, 5 + 1) = 6
        lost = st.find((10, 6), nxt)  # downlink loss: tau_1 grows
        assert ok >= 0 and lost >= 0
        expected[ok] = expected.get(ok, 0.0) + 0.9 * p
        expected[lost] = expected.get(lost, 0.0) + 0.1 * p
    assert got.keys() == expected.keys()
    for j, p in expected.items():
        assert got[j] == pytest.approx(p, abs=1e-15)
    # fresher information wins: with tau_1 = 5 (reachable: the loop is 6 slots) a delivery of
    # age 6 changes nothing, tau_1 just grows
    assert st.find((4, 5), cfg) == -1  # not reachable: the command took 5 slots to make
    s2 = st.find((5, 5), cfg)
    assert s2 >= 0
    row = paper_mdp.P.getrow(paper_mdp.pair_ptr[s2])
    assert {tuple(st.tau[j]) for j in row.indices} == {(6, 6)}


def test_ages_saturate_at_the_cap():
    procs = [{"A": [[1.02]], "tau_cap": 4}, {"A": [[1.02]], "tau_cap": 12}]
    sc = one_server(procs, U=1, D=1, T=(3, 3))
    cfg = PreemptionConfig((0, 1), (1, 1, 4), ((2, 2, 11),), ((1, 4),))
    # job 1 completes with age min(5, 4) = 4; stacked job 2 caps at 12 and resumes; the leaving
    # command of process 1 is delivered (or lost) with age min(5, 4) = 4
    assert next_cores(sc, cfg, 0) == {
        ((2, 2, 12), (), ((1, 4),), (0, 0)),
        ((2, 2, 12), (), ((1, 4),), (4, 0)),
    }


# ----------------------------------------------------------------------------- invariants
@pytest.mark.parametrize("preemptive", [True, False])
def test_configuration_invariants(preemptive):
    sc = paper(**{"model.preemptive": preemptive})
    auto = preemption_automaton(sc)
    N, caps, T = sc.n_processes, sc.tau_caps, sc.servers[0].processing_time
    assert set(initial_preemption_configs(sc)) <= set(auto.configs)
    for cfg, acts in zip(auto.configs, auto.actions):
        b, job, stack, down = cfg
        jobs = ([job] if job else []) + list(stack)
        assert len({j[0] for j in jobs}) == len(jobs)  # one job per process at most
        assert job is not None or stack == ()  # the server never idles over a stacked job
        assert len(stack) <= N - 1
        if not preemptive:
            assert stack == ()
        for k, d, g in jobs:
            assert 1 <= d <= T[k - 1] and 1 <= g <= caps[k - 1]
        for c in down:
            assert c is None or 1 <= c[1] <= caps[c[0] - 1]
        allowed = [(0,)] + [(k,) for k in range(1, N + 1) if b[k - 1] and (preemptive or job is None)]
        assert acts == allowed


def test_describe_config():
    cfg = PreemptionConfig((1, 0), (2, 1, 3), ((1, 3, 4),), ((2, 5),))
    text = describe_preemption_config(cfg)
    assert text == "b=10 | serving 2(d=1,g=3) | stack [top 1(d=3,g=4)] | down [2(g=5)]"
    assert describe_preemption_config(((0, 0), None, (), (None,))) == "b=00 | idle | down [-]"
    three = PreemptionConfig((0, 0, 1), (3, 1, 1), ((1, 2, 4), (2, 1, 3)), ())
    assert "stack [top 2(d=1,g=3), 1(d=2,g=4)]" in describe_preemption_config(three)


# ----------------------------------------------------------------------------- preemption helps
def test_nonpreemptive_automaton_is_included():
    """Every non-preemptive configuration and (action, outcome) also exists with preemption."""
    pre = preemption_automaton(paper())
    non = preemption_automaton(paper(**{"model.preemptive": False}))
    idx = {c: i for i, c in enumerate(pre.configs)}
    for c, cfg in enumerate(non.configs):
        i = idx[cfg]
        for lab, outs in zip(non.actions[c], non.outcomes[c]):
            j = pre.actions[i].index(lab)
            mapped = sorted((pre.configs[idx[non.configs[n]]], d, p) for n, d, p in outs)
            assert mapped == sorted((pre.configs[n], d, p) for n, d, p in pre.outcomes[i][j])


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda pre: paper(**{"model.preemptive": pre}), id="paper-p0.9"),
        pytest.param(lambda pre: paper(**{"model.preemptive": pre, "p": 0.6, "tau_cap": 10}), id="paper-p0.6-cap10"),
        pytest.param(
            lambda pre: one_server(
                [{"A": A1, "weight": 0.5}, {"A": [[1.02, 1], [0, 1]], "weight": 3.0}],
                U=2, D=0, T=(5, 2), pu=0.7, pd=0.95, preemptive=pre, cap=10,
            ),
            id="U2-D0",
        ),
        pytest.param(lambda pre: load_scenario(THREE, {"model.preemptive": pre, "tau_cap": 5}), id="three-cap5"),
    ],
)
def test_preemption_never_hurts(make):
    g_pre, g_non = gain(build(make(True))), gain(build(make(False)))
    assert g_pre <= g_non * (1 + 1e-10)


# ----------------------------------------------------------------------------- other shapes
def test_three_processes_without_delays_builds_and_validates():
    sc = load_scenario(THREE, {"tau_cap": 5})
    s = sc.servers[0]
    assert (s.uplink_delay, s.downlink_delay, s.processing_time, s.p_up, s.p_down) == (0, 0, (4, 2, 3), (0.8,) * 3, (0.95,) * 3)
    mdp = build(sc)
    mdp.validate()
    st = mdp.states
    assert mdp.n_pairs > mdp.n_states > 0
    assert any(len(st.configs[c].stack) == 2 for c in np.unique(st.config))  # two jobs stacked
    # with D = 0 an arrival of process 2 (T = 2) is delivered two slots later with age 2
    cfg = PreemptionConfig((0, 1, 0), None, (), ())
    (c1,) = {n for (n, d) in outcomes(sc, cfg, 2) if n.b == (0, 0, 0)}
    assert core(c1) == ((2, 1, 1), (), ())
    assert {d for (_, d) in outcomes(sc, c1, 0)} == {(0, 2, 0), (0, 0, 0)}
    assert gain(mdp) > 0


def test_three_processes_state_space_is_the_reachable_set():
    """The three-process scenario (no delays, so stacks of preempted jobs form) at cap 8: the
    built states are exactly those reachable, under any actions and outcomes, from model.md's
    start set (any tau, any arrivals, idle server, empty stack): a breadth-first search by scipy
    on the built transition graph, independent of the builder's own vectorised search."""
    from scipy.sparse import csr_matrix, hstack, vstack
    from scipy.sparse.csgraph import breadth_first_order

    sc = load_scenario(THREE, {"tau_cap": 8})
    mdp = build(sc)
    mdp.validate()
    S, n = mdp.states, mdp.n_states
    start = np.flatnonzero(np.isin(S.config, [S.config_id(c) for c in initial_preemption_configs(sc)]))
    assert 0 < start.size < n
    P = mdp.P.tocsr()
    edges = csr_matrix((np.ones(P.nnz), P.indices, P.indptr), shape=P.shape)
    owner = csr_matrix((np.ones(mdp.n_pairs), (np.asarray(mdp.s_indices), np.arange(mdp.n_pairs))),
                       shape=(n, mdp.n_pairs))
    graph = vstack([owner @ edges, csr_matrix((np.ones(start.size), (np.zeros(start.size, int), start)),
                                              shape=(1, n))])  # a root node n pointing at the start set
    graph = hstack([graph, csr_matrix((n + 1, 1))]).tocsr()
    reached = breadth_first_order(graph, n, directed=True, return_predecessors=False)
    assert reached.size - 1 == n  # every built state reached, and no more (validate: rows stay inside)
    assert len(S.configs) > 2 ** 3  # stacks and jobs beyond the start set's configurations


@pytest.mark.parametrize("preemptive", [True, False])
def test_closed_form_no_delay(preemptive):
    """One process, U = D = 0, T = 1, pd = 1: gain -> r / (1 - (1 - p) a^2)."""
    a, r, p = 1.02, 2.0, 0.5
    sc = one_server([{"A": [[a]], "R": [[r]]}], U=0, D=0, T=(1,), pu=p, pd=1.0, preemptive=preemptive, cap=80)
    assert gain(build(sc)) == pytest.approx(r / (1 - (1 - p) * a * a), rel=1e-9)


@pytest.mark.parametrize("preemptive", [True, False])
def test_closed_form_pipeline(preemptive):
    """One process, U = D = 1, T = 3, p = 1: one delivery every 3 slots, tau cycles 5, 6, 7."""
    sc = one_server([{"A": [[1.1]]}], U=1, D=1, T=(3,), p=1.0, preemptive=preemptive, cap=12)
    q = mse_table(np.array([[1.1]]), np.eye(1), 12)
    g = gain(build(sc))
    assert g == pytest.approx((q[4] + q[5] + q[6]) / 3, rel=1e-10)
    assert g == pytest.approx(10.3645542423, rel=1e-10)


def test_perfect_and_dead_channels_build():
    for p in (0.0, 1.0):
        mdp = build(paper(p=p))
        mdp.validate()
    # with no arrivals after the first slot, at most one job ever runs, and never a stacked one
    auto = preemption_automaton(paper(p=0.0))
    later = [c for i, c in enumerate(auto.configs) if i not in auto.initial]
    assert later and all(c.b == (0, 0) and c.stack == () for c in later)
    auto = preemption_automaton(paper(p=1.0))
    later = [c for i, c in enumerate(auto.configs) if i not in auto.initial]
    assert later and all(c.b == (1, 1) for c in later)
