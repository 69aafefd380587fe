"""Policies and exact evaluation: ordering of the policies, Lemma 2, interface consistency."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.policies import (
    GreedyPolicy,
    OptimalPolicy,
    RandomPolicy,
    StaticPolicy,
    SuboptimalPolicy,
    System,
    TauIndependentPolicy,
    best_static,
    default_assignment,
    static_assignments,
)
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp.workflow import make_policy
from wncs_lp import solve
from wncs_lp.solvers.dp import evaluate_policy

A1 = [[1.02, 1, 0, 1], [0, 1, 0.2, 0], [0, 0, 1, 0], [0, 0, 0, 1.01]]
A2 = [[1, 1, 0], [0, 1.02, 0], [0, 0, 1]]


def own_scenarios():
    """Three scenarios of our own: unequal links and weights, idling allowed, three servers."""
    a = scenario_from_dict(
        {
            "model": {"kind": "wncs", "tau_cap": 7},
            "channel": {"success_probability": 0.8},
            "process": [{"A": A1, "weight": 2.0}, {"A": [[1.1]]}],
            "server": [
                {"name": "far", "uplink_delay": 2, "downlink_delay": 1, "slots_per_dimension": 1, "p_up": 0.7},
                {"name": "near", "uplink_delay": 0, "downlink_delay": 1, "processing_time": [5, 2], "p_down": 0.95},
            ],
        },
        source="<own-a>",
    )
    b = scenario_from_dict(
        {
            "model": {"kind": "wncs", "tau_cap": 6, "allow_idle": True},
            "channel": {"success_probability": 0.85},
            "process": [{"A": A2}, {"A": [[1.02, 1], [0, 1]]}, {"A": [[1.05]], "tau_cap": 5}],
            "server": [
                {"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1},
                {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2},
            ],
        },
        source="<own-b>",
    )
    c = scenario_from_dict(
        {
            "model": {"kind": "wncs", "tau_cap": 8},
            "channel": {"success_probability": 0.75},
            "process": [{"A": [[1.1, 0.5], [0, 1.0]]}, {"A": [[1.2]]}],
            "server": [
                {"name": "s1", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [2, 1]},
                {"name": "s2", "uplink_delay": 1, "downlink_delay": 0, "processing_time": [1, 2]},
                {"name": "s3", "uplink_delay": 0, "downlink_delay": 1, "processing_time": [1, 1]},
            ],
        },
        source="<own-c>",
    )
    return [a, b, c]


SCENARIOS = [
    ("paper_p12", lambda: load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"])),
    ("paper_p123", lambda: load_scenario(scenario_path("paper_p123.toml"), ["tau_cap=6"])),
    ("own-a", lambda: own_scenarios()[0]),
    ("own-b", lambda: own_scenarios()[1]),
    ("own-c", lambda: own_scenarios()[2]),
]


@pytest.fixture(scope="module", params=SCENARIOS, ids=[s[0] for s in SCENARIOS])
def case(request):
    sc = request.param[1]()
    system = System.from_scenario(sc)
    mdp = build(sc)
    sol = solve(mdp, "pi")
    assert sol.ok
    pols = {
        "optimal": OptimalPolicy(mdp, sol, system),
        "suboptimal": SuboptimalPolicy(system),
        "static": StaticPolicy(system, default_assignment(sc)),
        "greedy": GreedyPolicy(system),
        "random": RandomPolicy(system),
    }
    evals = {k: evaluate(mdp, p) for k, p in pols.items()}
    return {"scenario": sc, "system": system, "mdp": mdp, "solution": sol, "policies": pols, "evals": evals}


def test_policy_ordering(case):
    """optimal <= suboptimal <= random base (policy improvement), optimal <= static, greedy."""
    g = {k: e.gain for k, e in case["evals"].items()}
    tol = 1e-9 * g["optimal"]
    assert abs(g["optimal"] - case["solution"].gain) <= tol
    assert g["optimal"] <= g["suboptimal"] + tol
    assert g["suboptimal"] <= g["random"] + tol
    assert g["optimal"] <= g["static"] + tol
    assert g["optimal"] <= g["greedy"] + tol
    # the improvement is real on these instances (not just equality)
    assert g["suboptimal"] < g["random"] - 1e-6 * g["random"]


def test_evaluate_agrees_with_solver_evaluation(case):
    """evaluate (LU on the recurrent class) = evaluate_policy (LU on the whole chain)."""
    mdp = case["mdp"]
    for name, pol in case["policies"].items():
        ref = evaluate_policy(mdp, pol.on_mdp(mdp))
        assert case["evals"][name].gain == pytest.approx(ref.gain, rel=1e-10), name


def test_iterative_and_power_iteration_paths_agree(case, monkeypatch):
    """The iterative paths for large classes (BiCGSTAB, then the power iteration) give the LU
    path's gain."""
    import wncs_lp.chain as chain_mod
    import wncs_lp.evaluate as ev_mod

    monkeypatch.setattr(chain_mod, "ITERATIVE_MIN_STATES", 2)
    mdp = case["mdp"]
    for name in ("random", "suboptimal", "greedy"):
        lu = ev_mod.PolicyChain(mdp, case["policies"][name].on_mdp(mdp), method="lu").stationary
        g = ev_mod.evaluate(mdp, case["policies"][name]).gain
        assert g == pytest.approx(case["evals"][name].gain, rel=1e-10), name
        assert g == pytest.approx(lu @ ev_mod.PolicyChain(mdp, case["policies"][name].on_mdp(mdp)).cost,
                                  rel=1e-10), name
    monkeypatch.setattr(chain_mod, "_iterative_stationary", lambda Pc: None)  # BiCGSTAB misses: power iteration
    for name in ("random", "greedy"):
        g = ev_mod.evaluate(mdp, case["policies"][name]).gain
        assert g == pytest.approx(case["evals"][name].gain, rel=1e-10), name


def test_lemma2_base_gain(case):
    """Lemma 2: sum_k g_k of the per-process chains = exact gain of the random policy."""
    sub = case["policies"]["suboptimal"]
    exact = case["evals"]["random"].gain
    assert sub.base_gain == pytest.approx(exact, rel=1e-9, abs=0)


def test_lemma2_relative_value(case):
    """Lemma 2, second half: sum_k h_k(tau_k, C) solves the random policy's Poisson equation."""
    mdp, system = case["mdp"], case["system"]
    sub = case["policies"]["suboptimal"]
    st = mdp.states
    h = np.zeros(mdp.n_states)
    for k, pp in enumerate(sub.poisson):
        h += pp.h[st.config, st.tau[:, k] - 1]
    from wncs_lp.chain import policy_matrices

    P, c = policy_matrices(mdp, RandomPolicy(system).on_mdp(mdp))
    resid = sub.base_gain + h - c - P @ h
    assert np.max(np.abs(resid)) <= 1e-8 * max(np.max(np.abs(h)), 1.0)


def test_suboptimal_is_one_improvement_step(case):
    """On the MDP, the suboptimal policy is the first-minimiser greedy policy of sum_k h_k."""
    mdp = case["mdp"]
    sub = case["policies"]["suboptimal"]
    st = mdp.states
    h = np.zeros(mdp.n_states)
    for k, pp in enumerate(sub.poisson):
        h += pp.h[st.config, st.tau[:, k] - 1]
    q = mdp.P @ h  # the state cost does not depend on the action
    chosen = sub.on_mdp(mdp)
    qmin = np.minimum.reduceat(q, mdp.pair_ptr[:-1])
    scale = np.max(np.abs(q))
    assert np.all(q[chosen] <= qmin + 1e-10 * scale)


def test_mse_and_utilisation(case):
    for ev in case["evals"].values():
        assert sum(ev.mse) == pytest.approx(ev.gain, rel=1e-10)
        assert all(0.0 <= u <= 1.0 + 1e-12 for u in ev.utilisation)
        assert len(ev.utilisation) == case["scenario"].n_servers


def test_act_matches_on_mdp(case):
    """act on the decoded states gives the pairs of on_mdp (the one interface)."""
    mdp = case["mdp"]
    st = mdp.states
    for name in ("optimal", "suboptimal", "static", "greedy"):
        pol = case["policies"][name]
        pairs = pol.on_mdp(mdp)
        rows = np.random.default_rng(0).choice(mdp.n_states, size=min(500, mdp.n_states), replace=False)
        j = pol.act(st.tau[rows], st.config[rows], np.random.default_rng(1))
        np.testing.assert_array_equal(mdp.pair_ptr[rows] + j, pairs[rows])


def test_best_static_is_best():
    sc = load_scenario(scenario_path("paper_p123.toml"), ["tau_cap=5"])
    system, mdp = System.from_scenario(sc), build(sc)
    best = best_static(system, mdp)
    assert len(best.gain_search) == len(static_assignments(sc)) == 6
    g = evaluate(mdp, best).gain
    assert g == pytest.approx(min(best.gain_search.values()), rel=1e-12)
    assert g <= evaluate(mdp, StaticPolicy(system, default_assignment(sc))).gain + 1e-9 * g
    assert solve(mdp, "pi").gain <= g * (1 + 1e-9)


def test_default_assignment_paper():
    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=4"])
    assert default_assignment(sc) == (0, 1)  # process 1 -> remote (loop 6 < 8), process 2 -> edge
    sc3 = load_scenario(scenario_path("paper_p123.toml"), ["tau_cap=4"])
    # the specification's rule: every process but the first goes to the other server
    assert default_assignment(sc3) == (0, 1, 1)
    sc4 = load_scenario(scenario_path("paper_p1234.toml"), ["tau_cap=4"])
    assert default_assignment(sc4) == (0, 1, 1, 1)


def test_static_and_greedy_rules_by_hand():
    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"])
    system = System.from_scenario(sc)
    c0 = system.initial_config  # both servers idle and accepting
    greedy = GreedyPolicy(system)
    # process 1 costlier: it takes its shortest loop (remote, 6 < 8); process 2 gets the edge
    j = greedy.act(np.array([[8, 1], [1, 8]]), np.array([c0, c0]))
    labels = [system.automaton.actions[c0][x] for x in j]
    # process 2 costlier in row 2: it takes its shortest loop: remote (1+3+1 = 5 < 6), process 1 the edge
    assert labels == [(1, 2), (2, 1)]
    static = StaticPolicy(system, (0, 1))
    j = static.act(np.array([[8, 1], [1, 8]]), np.array([c0, c0]))
    assert [system.automaton.actions[c0][x] for x in j] == [(1, 2), (1, 2)]


def test_tau_independent_base_and_errors():
    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=6"])
    system, mdp = System.from_scenario(sc), build(sc)
    # a non-uniform tau-independent base: always the first action
    first = TauIndependentPolicy(system, [np.eye(n)[0] for n in system.n_actions], name="first")
    sub = SuboptimalPolicy(system, base=first)
    g_first = evaluate(mdp, first).gain
    assert sub.base_gain == pytest.approx(g_first, rel=1e-9)
    assert evaluate(mdp, sub).gain <= g_first * (1 + 1e-12)
    with pytest.raises(PolicyError, match="unknown policy"):
        make_policy("bogus", system, mdp)
    with pytest.raises(PolicyError, match="needs the enumerated MDP"):
        make_policy("optimal", system)
    with pytest.raises(PolicyError, match="server index"):
        StaticPolicy(system, (0, 5))
    other = build(load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=5"]))
    with pytest.raises(PolicyError, match="caps"):
        GreedyPolicy(system).on_mdp(other)


def test_multichain_policy_error():
    """At p = 1 a static policy is multichain: a clear PolicyError, or averages from the start."""
    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=6", "p=1.0"])
    system, mdp = System.from_scenario(sc), build(sc)
    pol = StaticPolicy(system, (0, 1))
    with pytest.raises(PolicyError, match="multichain"):
        evaluate(mdp, pol)
    ev = evaluate(mdp, pol, multichain="initial")
    assert ev.recurrent_classes > 1
    assert sum(ev.mse) == pytest.approx(ev.gain, rel=1e-10)
    # deterministic system: the simulation from the same initial state gives the same average
    from wncs_lp.simulate import simulate

    sim = simulate(pol, slots=6000, reps=2, burn_in=600, seed=0, progress=False)
    assert sim.mean == pytest.approx(ev.gain, rel=2e-3)


def test_preemption_policies():
    """The same interface on the Section IV automaton: ordering and Lemma 2."""
    sc = load_scenario(scenario_path("paper_preemption_p12.toml"), ["tau_cap=6"])
    system, mdp = System.from_scenario(sc), build(sc)
    g_opt = solve(mdp, "pi").gain
    sub = SuboptimalPolicy(system)
    g = {name: evaluate(mdp, make_policy(name, system, mdp)).gain for name in ("optimal", "greedy", "random")}
    g["suboptimal"] = evaluate(mdp, sub).gain
    assert sub.base_gain == pytest.approx(g["random"], rel=1e-9)
    assert g_opt == pytest.approx(g["optimal"], rel=1e-9)
    assert g["optimal"] <= g["suboptimal"] * (1 + 1e-9) <= g["random"] * (1 + 1e-9)
    assert g["optimal"] <= g["greedy"] * (1 + 1e-9)
    with pytest.raises(PolicyError, match="wncs model"):
        StaticPolicy(system, (0, 0))


def test_suboptimal_without_enumeration():
    """Four processes, caps 30: tables of tau_hat_k * |C| only; the product space is never built."""
    sc = load_scenario(scenario_path("paper_p1234.toml"), ["tau_cap=30"])
    system = System.from_scenario(sc)
    sub = SuboptimalPolicy(system)
    assert sub.table_sizes == tuple(30 * system.n_configs for _ in range(4))
    rng = np.random.default_rng(0)
    tau = rng.integers(1, 31, size=(1000, 4))
    c = rng.integers(0, system.n_configs, size=1000)
    j = sub.act(tau, c)
    assert np.all((0 <= j) & (j < system.n_actions[c]))
    # the choice is the first minimiser of the separable values
    v = sub.values(tau, c)
    assert np.all(v[np.arange(1000), j] == v.min(axis=1))
