"""A researcher's own systems: per-link probabilities, cost families, random arrivals
(``docs/model.md``, "Beyond the paper"), each against an independent construction.

* a plain reference builder written from the docs (``tests/reference/own_systems.py``, its own
  state representation and a coarser lumping of ages), fed to ``MDP.from_arrays``: the same gain
  as the package's LP, value iteration and matrix-free solver;
* closed forms: one process on one server with U = D = 0, T = 1 -- with arrivals
  E[q(min(1 + A + X, tau_hat))], A, X independent geometric laws (exact at every cap), and the
  MSE's limits r / (1 - (1 - p) a^2) and its Bernoulli-arrival analogue; the cost families'
  averages of a geometric AoI; the preemption model's lambda pu pd.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

import reference.own_systems as ref
import wncs_lp
from wncs_lp.errors import ScenarioError
from wncs_lp.mdp import MDP
from wncs_lp.models import build, model_for
from wncs_lp.models.cost import cost_tables
from wncs_lp.scenario import scenario_from_dict

MIXED = {
    "model": {"kind": "wncs"},
    "channel": {"success_probability": 0.9},
    "process": [{"name": "a", "A": [[1.1]], "tau_cap": 5, "arrival_probability": 0.6, "cost": {"power": 1.5}},
                {"name": "b", "A": [[1.0, 0.2], [0.0, 1.0]], "tau_cap": 4, "weight": 2.0}],
    "server": [{"name": "cloud", "uplink_delay": 1, "downlink_delay": 1, "processing_time": [1, 2],
                "p_up": [0.95, 0.7], "p_down": [0.9, 0.8]},
               {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [2, 1], "p_up": 0.85}],
}


def one_server(lam=1.0, p=0.9, pd=1.0, cap=20, cost="aoi", A=((1.0,),), R=None, kind="wncs"):
    proc = {"A": [list(r) for r in A], "tau_cap": cap, "cost": cost}
    if R is not None:
        proc["R"] = [list(r) for r in R]
    if lam < 1:
        proc["arrival_probability"] = lam
    return scenario_from_dict({"model": {"kind": kind}, "process": [proc],
                               "server": [{"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1],
                                           "p_up": p, "p_down": pd}]})


def geometric(q, n):
    """P(G = j) = q (1 - q)^j, j = 0..n-1."""
    return q * (1.0 - q) ** np.arange(n)


def capped_mean(f, lam, p, cap):
    """E[f(min(1 + A + X, cap))], A ~ geometric(lam), X ~ geometric(p) independent (docs/model.md)."""
    law = np.convolve(geometric(lam, cap), geometric(p, cap))[:cap - 1]  # P(A + X = y), y < cap - 1
    tau = np.arange(1, cap)
    return float(law @ f(tau) + (1.0 - law.sum()) * f(cap))


@pytest.fixture(scope="module")
def mixed():
    sc = scenario_from_dict(MIXED)
    states, model = ref.build(sc)
    s, a, c, P, n = ref.to_arrays(states, model)
    g_ref = wncs_lp.solve(MDP.from_arrays(s, a, c, P, n), "pi")
    return sc, g_ref


# ----------------------------------------------------------------------------- all three fields
@pytest.mark.parametrize("method", ["lp", "vi", "matrix-free"])
def test_reference_gain_from_every_solver(mixed, method):
    sc, g_ref = mixed
    assert g_ref.status == "optimal"
    sol = wncs_lp.solve(sc, method)
    assert sol.status == "optimal"
    tol = 1e-9 * g_ref.gain
    assert sol.gain_lower - tol <= g_ref.gain <= sol.gain_upper + tol
    assert sol.gain == pytest.approx(g_ref.gain, rel=1e-9)


def test_reference_gain_with_pipelines_of_ages():
    """Uplink and downlink pipelines of several places (U = 2, D = 2; D = 1) carry the ages at send."""
    raw = {"model": {"kind": "wncs", "allow_idle": True}, "channel": {"success_probability": 0.85},
           "process": [{"name": "a", "A": [[1.1]], "tau_cap": 7, "arrival_probability": 0.5}],
           "server": [{"name": "far", "uplink_delay": 2, "downlink_delay": 2, "processing_time": [2], "p_up": [0.9]},
                      {"name": "near", "uplink_delay": 0, "downlink_delay": 1, "processing_time": [3], "p_down": 0.7}]}
    sc = scenario_from_dict(raw)
    s, a, c, P, n = ref.to_arrays(*ref.build(sc))
    g_ref = wncs_lp.solve(MDP.from_arrays(s, a, c, P, n), "pi").gain
    assert wncs_lp.solve(sc, "lp").gain == pytest.approx(g_ref, rel=1e-11)


def test_reference_costs_are_the_families():
    sc = scenario_from_dict(MIXED)
    for pr, mine in zip(sc.processes, cost_tables(sc)):
        np.testing.assert_allclose(mine, ref.cost_table(pr), rtol=1e-13)
    np.testing.assert_allclose(cost_tables(sc)[0], np.arange(1, 6) ** 1.5)


# ----------------------------------------------------------------------------- arrivals: closed forms
@pytest.mark.parametrize("lam, p", [(1.0, 0.9), (0.5, 0.6), (0.3, 0.9), (0.8, 0.45)])
def test_arrivals_aoi_closed_form_at_every_cap(lam, p):
    sol = wncs_lp.solve(one_server(lam, p, cap=15), "lp")
    assert sol.gain == pytest.approx(capped_mean(lambda t: np.asarray(t, dtype=float), lam, p, 15), rel=1e-10)


def test_arrivals_hand_built_mdp():
    """One process (AoI cost, lambda, uplink p, pd = 1) on one server with U = D = 0, T = 1, cap 3,
    written state by state from docs/model.md: states (tau, alpha), alpha lumped at
    a = tau_hat - (U + T + D) = 2; the one action sends the buffer, which succeeds w.p. p and
    sets tau' = min(tau + 1, alpha + 1, 3); alpha' = 0 w.p. lambda, else min(alpha + 1, 2)."""
    lam, p, cap = 0.35, 0.7, 3
    states = [(tau, alpha) for tau in range(1, cap + 1) for alpha in range(3)]
    index = {s: i for i, s in enumerate(states)}
    P = np.zeros((9, 9))
    for (tau, alpha), i in index.items():
        for ok, p_ok in ((True, p), (False, 1 - p)):
            t2 = min(tau + 1, alpha + 1, cap) if ok else min(tau + 1, cap)
            for new_alpha, p_gen in ((0, lam), (min(alpha + 1, 2), 1 - lam)):
                P[i, index[(t2, new_alpha)]] += p_ok * p_gen
    cost = np.array([float(tau) for tau, _ in states])
    hand = wncs_lp.solve(MDP.from_dense(P[:, None, :], cost[:, None]), "pi")
    mine = wncs_lp.solve(one_server(lam, p, cap=cap), "lp")
    assert mine.gain == pytest.approx(hand.gain, rel=1e-12)
    assert mine.gain == pytest.approx(capped_mean(lambda t: np.asarray(t, dtype=float), lam, p, cap), rel=1e-12)


def test_arrivals_aoi_limit():
    lam, p = 0.4, 0.7
    sol = wncs_lp.solve(one_server(lam, p, cap=80), "vi")
    assert sol.gain == pytest.approx(1 / lam + 1 / p - 1, rel=1e-9)


@pytest.mark.parametrize("lam", [1.0, 0.6])
def test_arrivals_mse_limit(lam):
    a, r, p = 1.1, 0.5, 0.8
    z = a * a
    limit = r * (z * lam * p / ((1 - (1 - lam) * z) * (1 - (1 - p) * z)) - 1) / (z - 1)
    if lam == 1.0:
        assert limit == pytest.approx(r / (1 - (1 - p) * a * a), rel=1e-14)  # the paper's closed form
    sol = wncs_lp.solve(one_server(lam, p, cap=70, cost="mse", A=((a,),), R=((r,),)), "vi")
    assert sol.gain == pytest.approx(limit, rel=1e-9)


def test_arrival_probability_one_is_sampling_at_will():
    first = {k: v for k, v in MIXED["process"][0].items() if k != "arrival_probability"}
    at_will = scenario_from_dict({**MIXED, "process": [first, MIXED["process"][1]]})
    one = scenario_from_dict({**MIXED, "process": [dict(first, arrival_probability=1.0), MIXED["process"][1]]})
    assert not one.has_arrivals and one.fingerprint() == at_will.fingerprint()
    a, b = build(one), build(at_will)
    assert a.n_states == b.n_states and (a.P != b.P).nnz == 0


def test_arrival_configurations_and_lumping():
    sc = one_server(0.5, 0.9, cap=6)
    model = model_for(sc)
    alphas = sorted({c.alpha for c in model.automaton.configs})
    assert alphas == [(x,) for x in range(6)]  # a = tau_hat - loop = 5: ages 0..5
    init = model.automaton.configs[model.automaton.initial[0]]
    assert model.is_idle(init) and init.alpha == (0,)
    assert "sensor ages: 0" in model.describe(init)


# ----------------------------------------------------------------------------- per-link probabilities
def test_per_link_uplink_and_downlink():
    # one process on two edge servers (U = D = 0, T = 1): sending to server m resets tau w.p.
    # pu_m pd_m, so the optimum sends to the better link every slot (no idling, one process)
    raw = {"model": {"kind": "wncs"}, "process": [{"A": [[1.0]], "tau_cap": 30, "cost": "aoi"}],
           "server": [{"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1], "p_up": [0.9], "p_down": 0.5},
                      {"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1], "p_up": 0.6, "p_down": [0.95]}]}
    sol = wncs_lp.solve(scenario_from_dict(raw), "lp")
    # one server a slot (distinct processes, more accepting servers than processes: the other
    # idles): the better link has success 0.6 * 0.95 > 0.9 * 0.5; tau = min(1 + G, 30), G geometric
    best = max(0.9 * 0.5, 0.6 * 0.95)
    assert sol.gain == pytest.approx(float(np.sum((1 - best) ** np.arange(30))), rel=1e-10)


def test_per_link_list_checked():
    raw = {**MIXED, "server": [dict(MIXED["server"][0], p_up=[0.9]), MIXED["server"][1]]}
    with pytest.raises(ScenarioError, match=r"server\[1\]\.p_up.*list of 2"):
        scenario_from_dict(raw)
    raw = {**MIXED, "server": [dict(MIXED["server"][0], p_down=[0.9, 1.5]), MIXED["server"][1]]}
    with pytest.raises(ScenarioError, match=r"server\[1\]\.p_down\[2\]"):
        scenario_from_dict(raw)


# ----------------------------------------------------------------------------- cost families
@pytest.mark.parametrize("cost, f", [("aoi", lambda t: t), ({"power": 2.0}, lambda t: t ** 2.0),
                                     ([0.5, 1, 1, 3, 3, 7, 8, 8, 9, 10, 11, 12], lambda t: np.array(
                                         [0.5, 1, 1, 3, 3, 7, 8, 8, 9, 10, 11, 12])[t - 1])])
def test_cost_family_average_of_a_geometric_aoi(cost, f):
    # one process, U = D = 0, T = 1, success s = pu pd: tau = min(1 + G, cap), G geometric(s)
    cap, pu, pd = 12, 0.8, 0.75
    sol = wncs_lp.solve(one_server(1.0, pu, pd, cap=cap, cost=cost), "lp")
    law = geometric(pu * pd, cap - 1)
    t = np.arange(1, cap)
    expected = float(law @ f(t) + (1 - law.sum()) * f(np.array([cap]))[0])
    assert sol.gain == pytest.approx(expected, rel=1e-10)


def test_cost_family_changes_only_the_cost():
    sc = scenario_from_dict(MIXED)
    other = sc.replace(**{"process.1.cost": "aoi", "process.2.cost": [1, 2, 3, 4, 5]})
    a, b = build(sc), build(other)
    assert a.n_states == b.n_states and (a.P != b.P).nnz == 0
    assert not np.array_equal(a.cost, b.cost)


@pytest.mark.parametrize("cost, field, why", [
    ("mse2", "process[1].cost", "expected \"mse\", \"aoi\""),
    ({"power": 0}, "process[1].cost.power", "number > 0"),
    ({"exponent": 2}, "process[1].cost.exponent", "unknown field"),
    ([1, 2, 3], "process[1].cost", "at least tau_cap = 5"),
    ([1, 2, 1, 4, 5], "process[1].cost[3]", "nondecreasing"),
    ([-1, 2, 3, 4, 5], "process[1].cost[1]", ">= 0"),
    ([1, 2, 3, 4, float("inf")], "process[1].cost[5]", "finite"),
])
def test_cost_checked_on_load(cost, field, why):
    raw = {**MIXED, "process": [dict(MIXED["process"][0], cost=cost), MIXED["process"][1]]}
    with pytest.raises(ScenarioError, match=rf"{re.escape(field)}.*{re.escape(why)}"):
        scenario_from_dict(raw)


@pytest.mark.parametrize("lam", [0, -0.1, 1.5, "half"])
def test_arrival_probability_checked_on_load(lam):
    raw = {**MIXED, "process": [dict(MIXED["process"][0], arrival_probability=lam), MIXED["process"][1]]}
    with pytest.raises(ScenarioError, match=r"process\[1\]\.arrival_probability"):
        scenario_from_dict(raw)


# ----------------------------------------------------------------------------- the preemption model
@pytest.mark.parametrize("lam, pu, pd", [(1.0, 0.7, 0.9), (0.5, 0.9, 0.8)])
def test_preemption_links_and_arrivals_closed_form(lam, pu, pd):
    # one process: it starts whenever its update arrives (w.p. lam pu) and is delivered w.p. pd
    # with age U + T + D = 1; the AoI is min(1 + G, cap), G geometric(lam pu pd)
    cap = 25
    sol = wncs_lp.solve(one_server(lam, pu, pd, cap=cap, kind="preemption"), "lp")
    expected = float(np.sum((1 - lam * pu * pd) ** np.arange(cap)))
    assert sol.gain == pytest.approx(expected, rel=1e-10)


def test_preemption_arrivals_are_thinned_arrivals():
    base = {"model": {"kind": "preemption"}, "channel": {"success_probability": 0.9},
            "process": [{"A": [[1.1]], "tau_cap": 5}, {"A": [[1.0]], "tau_cap": 4, "cost": "aoi"}],
            "server": [{"uplink_delay": 1, "downlink_delay": 1, "processing_time": [2, 1], "p_down": [0.8, 0.95]}]}
    with_lam = scenario_from_dict({**base, "process": [dict(base["process"][0], arrival_probability=0.5),
                                                       base["process"][1]]})
    thinned = scenario_from_dict({**base, "server": [dict(base["server"][0], p_up=[0.45, 0.9])]})
    a, b = build(with_lam), build(thinned)
    assert a.n_states == b.n_states and abs(a.P - b.P).max() < 1e-15
    assert math.isclose(wncs_lp.solve(with_lam, "lp").gain, wncs_lp.solve(thinned, "lp").gain, rel_tol=1e-12)



# ----------------------------------------------------------------------------- defaults and overrides
def test_defaults_written_out_change_nothing():
    """Writing every new field at its default gives the same scenario, fingerprint and MDP: the
    caches of scenarios without the fields stay valid."""
    plain = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=7"])
    spelled = plain.replace(**{"process.1.cost": "mse", "process.2.arrival_probability": 1.0,
                               "server.remote.p_up": [0.9, 0.9], "server.edge.p_down": [0.9, 0.9]})
    assert spelled == plain and spelled.fingerprint() == plain.fingerprint()
    a, b = build(plain), build(spelled)
    assert a.n_states == b.n_states and (a.P != b.P).nnz == 0 and np.array_equal(a.cost, b.cost)


def test_new_fields_as_overrides():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), [
        "tau_cap=7", "process.1.cost={power=2}", "process.2.cost=[1,2,3,4,5,6,7]", "process.2.arrival_probability=0.5",
        "server.edge.p_up=[0.9,0.7]"])
    assert str(sc.processes[0].cost) == "aoi^2" and sc.processes[1].cost.table == (1, 2, 3, 4, 5, 6, 7)
    assert sc.processes[1].arrival_probability == 0.5 and sc.servers[1].p_up == (0.9, 0.7)
    assert "cost=aoi^2" in sc.describe() and "pu=[0.9, 0.7]" in sc.describe() and "lambda=0.5" in sc.describe()
    with pytest.raises(ScenarioError, match=r"process\[2\]\.cost.*at least tau_cap = 8"):
        sc.replace(tau_cap=8)  # the table is shorter than the new cap


def test_size_bound_counts_the_ages():
    for raw in (MIXED, {**MIXED, "process": [dict(MIXED["process"][0]), dict(MIXED["process"][1], arrival_probability=0.3)]}):
        model = model_for(scenario_from_dict(raw))
        assert model.automaton_bounds().configs >= len(model.automaton.configs)


def test_a_process_without_a_working_link_is_warned_about():
    raw = {**MIXED, "server": [dict(MIXED["server"][0], p_up=[0.95, 0.0]), dict(MIXED["server"][1], p_down=[0.9, 0.0])]}
    warnings = scenario_from_dict(raw).degenerate_warnings()
    assert any("process 'b' is never delivered" in w for w in warnings)
    assert not any("server" in w and "never delivers" in w for w in warnings)  # both servers still serve 'a'


# ----------------------------------------------------------------------------- reach
def test_exploration_keeps_no_raw_outcome_list():
    """A step's plain outcome lists are dropped once merged (with random arrivals an action has
    hundreds of raw outcomes: keeping them all ran 5 sensors out of memory before the budget
    stopped the exploration); a SharedOutcomes list is merged once for every configuration."""
    import gc
    import weakref

    from wncs_lp.models.automaton import SharedOutcomes, explore_configs

    class Plain(list):
        pass

    refs, merged = [], []

    class Shared(SharedOutcomes):
        def __iter__(self):
            merged.append(1)
            return super().__iter__()

    shared = Shared([(0, (0,), 0.5), (1, (2,), 0.5)])

    def step(c):
        outs = Plain([((c + 1) % 3, (1,), 0.25), ((c + 2) % 3, (0,), 0.75)])
        refs.append(weakref.ref(outs))
        return [((1,), outs), ((2,), shared)]

    auto = explore_configs([0], step)
    gc.collect()
    assert len(auto.configs) == 3 and all(r() is None for r in refs) and len(merged) == 1


def test_many_sensors_with_arrivals_are_refused_by_the_budget():
    from wncs_lp.models.automaton import ExplorationLimitError, exploration_limit

    raw = {"model": {"kind": "wncs"}, "channel": {"success_probability": 0.9},
           "process": [{"A": [[1.1]], "tau_cap": 10, "arrival_probability": 0.5} for _ in range(6)],
           "server": [{"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1] * 6}]}
    model = model_for(scenario_from_dict(raw))
    assert model.automaton_bounds().configs >= 10 ** 6
    with exploration_limit(500), pytest.raises(ExplorationLimitError, match="exploration budget"):
        model.automaton


def test_preemption_fields_in_the_other_rooms():
    """The preemption model with per-link probabilities, a cost family and random arrivals: the
    matrix-free solver's gain is the LP's, the simulator agrees with the exact evaluation, and the
    bounds refuse the kind by name (as without the fields)."""
    from wncs_lp.bounds import lower_bound
    from wncs_lp.errors import WncsError
    from wncs_lp.evaluate import evaluate
    from wncs_lp.models.system import System
    from wncs_lp.policies import GreedyPolicy
    from wncs_lp.simulate import simulate

    raw = {"model": {"kind": "preemption"}, "channel": {"success_probability": 0.9},
           "process": [{"A": [[1.1]], "tau_cap": 6, "arrival_probability": 0.6},
                       {"A": [[1.0]], "tau_cap": 5, "cost": {"power": 2.0}}],
           "server": [{"uplink_delay": 1, "downlink_delay": 1, "processing_time": [2, 1], "p_up": [0.95, 0.7],
                       "p_down": [0.8, 0.99]}]}
    sc = scenario_from_dict(raw)
    lp = wncs_lp.solve(sc, "lp")
    assert wncs_lp.solve(sc, "matrix-free").gain == pytest.approx(lp.gain, rel=1e-9)
    system, mdp = System.from_scenario(sc), build(sc)
    greedy = GreedyPolicy(system)
    exact = evaluate(mdp, greedy.on_mdp(mdp)).gain
    sim = simulate(greedy, slots=8_000, reps=6, seed=2, burn_in=200)
    assert abs(sim.mean - exact) <= 4.5 * sim.stderr and exact >= lp.gain_lower
    with pytest.raises(WncsError, match="preemption"):
        lower_bound(sc, 1)


@pytest.mark.parametrize("cost, tau", [({"power": 1e308}, 2), ([1e200] * 5, 1)])
def test_overflowing_family_refused_naming_the_aoi(cost, tau):
    from wncs_lp.errors import ModelError

    raw = {**MIXED, "process": [dict(MIXED["process"][0], cost=cost), MIXED["process"][1]]}
    with pytest.raises(ModelError, match=rf"process 'a': the cost .* at AoI tau = {tau} ") as info:
        cost_tables(scenario_from_dict(raw))
    assert ("lower tau_cap below" in str(info.value)) == (tau > 1)
