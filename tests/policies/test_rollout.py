"""The rollout policy: one decision against a rollout written out here with loops over the
automaton's outcome lists, its gain by exact evaluation against Monte Carlo, the optimum where the
tables are the optimal bias, and the greedy policy at horizon 1."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path, solve
from wncs_lp.bounds import bound_policy, policy_gaps, private_bound
from wncs_lp.bounds.gaps import policy_by_name
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies import GreedyPolicy
from wncs_lp.policies.rollout import RolloutPolicy
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp.simulate import simulate

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    return sc, system, private_bound(system), build(sc)


def _after(system, tau, delta):
    nt = [min(tau[k] + 1, int(system.caps[k])) for k in range(system.n_processes)]
    return [min(t, delta[k]) if delta[k] > 0 else t for k, t in enumerate(nt)]


def _h(system, tables, tau, c):
    return sum(float(hk[col[c], tau[k] - 1]) for k, (hk, col) in enumerate(zip(tables.h, tables.column)))


def _greedy_values(system, tables, tau, c):
    """E[h(s') | s, a] per feasible action of configuration c, by loops over its outcome lists."""
    return np.array([sum(p * _h(system, tables, _after(system, tau, d), nxt) for nxt, d, p in outs)
                     for outs in system.automaton.outcomes[c]])


def _brute_rollout(system, tables, tau, c, candidates, uniforms):
    """Q of each of the ``candidates`` actions of least greedy value (ties: the first): its greedy
    value plus the mean over the rows of ``uniforms`` of the greedy policy's Bellman residuals of h
    along the path the row draws (outcome o = #{i : u >= cumulative probability i})."""
    g = _greedy_values(system, tables, tau, c)
    cand = np.argsort(g, kind="stable")[:candidates]
    q = []
    for a in cand:
        total = 0.0
        for row in uniforms:
            t, cc, act = list(tau), c, a
            for u in row:
                outs = system.automaton.outcomes[cc][act]
                cum = np.cumsum([p for _, _, p in outs])
                o = min(int(np.sum(u >= cum)), len(outs) - 1)
                nxt, d, _ = outs[o]
                t, cc = _after(system, t, d), nxt
                v = _greedy_values(system, tables, t, cc)
                act = int(np.argmin(v))
                cost = sum(float(system.q[k][t[k] - 1]) for k in range(system.n_processes))
                total += cost + v[act] - _h(system, tables, t, cc)
        q.append(g[a] + total / len(uniforms))
    return cand, np.array(q)


def test_a_decision_against_a_rollout_written_out(p12):
    _, system, res, _ = p12
    pol = RolloutPolicy(bound_policy(res, system), res.tables.value, candidates=3, horizon=4, samples=3, seed=7)
    assert pol.uniforms.shape == (3, 3) and pol.name.startswith("rollout-k3-h4-s3[bound[")
    rng = np.random.default_rng(2)
    n = 25
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, n) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, n)
    acts = pol.act(tau, cfg)
    for r in range(n):
        cand, q = _brute_rollout(system, res.tables, tau[r], int(cfg[r]), 3, pol.uniforms)
        assert acts[r] in cand
        assert q[list(cand).index(acts[r])] <= q.min() + 1e-9 * max(1.0, abs(q.min())), (tau[r], cfg[r], cand, q)


def test_gain_exact_against_monte_carlo_and_horizon_one_is_the_greedy_policy(p12):
    _, system, res, mdp = p12
    greedy = bound_policy(res, system)
    pol = RolloutPolicy(greedy, res.tables.value, candidates=3, horizon=4, samples=8)
    exact = evaluate(mdp, pol).gain
    mc = simulate(pol, slots=2_000, reps=8, seed=3, burn_in=100, control=res.tables.value)
    assert abs(mc.mean - exact) <= 4.5 * mc.stderr + 1e-9 * exact, (mc.mean, mc.stderr, exact)
    assert exact >= solve(mdp).gain_lower * (1 - 1e-9)
    one = RolloutPolicy(greedy, res.tables.value, horizon=1)
    assert np.array_equal(one.on_mdp(mdp), greedy.on_mdp(mdp))


def test_exact_tables_give_the_optimum():
    # one process on one server with idling allowed: relaxation 1 is the system itself at lambda = 0,
    # its table the optimal bias, every Bellman residual of the greedy policy the gain: the rollout
    # ranks actions as the (optimal) greedy policy does
    sc = scenario_from_dict({"model": {"kind": "wncs", "tau_cap": 12, "allow_idle": True},
                             "channel": {"success_probability": 0.9}, "process": [{"A": [[1.1]]}],
                             "server": [{"name": "edge", "uplink_delay": 1, "downlink_delay": 0,
                                         "processing_time": [2]}]}, "one-idle")
    system = System.from_scenario(sc)
    mdp = build(sc)
    res = private_bound(system)
    pol = RolloutPolicy(bound_policy(res, system), res.tables.value, candidates=2, horizon=5, samples=4)
    assert evaluate(mdp, pol).gain == pytest.approx(solve(mdp).gain, rel=1e-9)


def test_by_name_in_the_gap_report_and_refusals(p12, monkeypatch):
    from wncs_lp.bounds import lookahead

    _, system, res, mdp = p12
    monkeypatch.setattr(lookahead, "PARALLEL_MIN_STATES", 10**12)  # the serial kernel: one compilation
    report = policy_gaps(res, system, ["bound", "rollout"])
    row = report.rows[1]
    assert row.policy.startswith("rollout-") and row.how == "exact"
    assert row.gain >= solve(mdp).gain_lower * (1 - 1e-9)
    # by name: 4 candidates on small systems, 8 where some configuration has more than AUTO_CANDIDATES_FROM actions
    assert row.policy.startswith("rollout-k4-h4-s8[")
    monkeypatch.setattr(lookahead, "AUTO_CANDIDATES_FROM", system.max_actions - 1)
    assert policy_by_name("rollout", res, system).candidates == 8
    with pytest.raises(PolicyError, match="values"):
        RolloutPolicy(GreedyPolicy(system), res.tables.value)
    with pytest.raises(PolicyError, match="horizon"):
        RolloutPolicy(bound_policy(res, system), res.tables.value, horizon=0)
    with pytest.raises(PolicyError, match="value function"):
        RolloutPolicy(bound_policy(res, system), None)


@pytest.mark.parametrize("relaxation", ["private", "grouped"])
def test_the_kernel_takes_the_numpy_rollouts_decisions(p12, relaxation):
    from wncs_lp.bounds import TableRolloutPolicy, grouped_bound

    _, system, res, _ = p12
    if relaxation == "grouped":  # one group of both processes: tables over (tau_1, tau_2, C_G)
        res = grouped_bound(system, [(0, 1)])
    greedy = bound_policy(res, system)
    fast = TableRolloutPolicy(greedy, candidates=3, horizon=4, samples=5, seed=11, threads=1)
    slow = RolloutPolicy(greedy, res.tables.value, candidates=3, horizon=4, samples=5, seed=11)
    assert np.array_equal(fast.uniforms, slow.uniforms) and fast.name == slow.name
    rng = np.random.default_rng(8)
    n = 400
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, n) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, n)
    assert np.array_equal(fast.act(tau, cfg), slow.act(tau, cfg))
    assert np.array_equal(TableRolloutPolicy(greedy, horizon=1, threads=1).act(tau, cfg), greedy.act(tau, cfg))


def test_the_direct_rule_and_the_rollout_by_name_share_their_defaults(p12):
    """Built with no options, the numpy rule and its numba twin are the same policy (they once differed:
    horizon 6 / 16 paths against 4 / 8)."""
    from wncs_lp.bounds import TableRolloutPolicy

    _, system, res, _ = p12
    greedy = bound_policy(res, system)
    fast = TableRolloutPolicy(greedy, threads=1)
    slow = RolloutPolicy(greedy, res.tables.value)
    assert (fast.candidates, fast.horizon, fast.samples) == (slow.candidates, slow.horizon, slow.samples)
    assert fast.name == slow.name and np.array_equal(fast.uniforms, slow.uniforms)
    rng = np.random.default_rng(3)
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, 200) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, 200)
    assert np.array_equal(fast.act(tau, cfg), slow.act(tau, cfg))
