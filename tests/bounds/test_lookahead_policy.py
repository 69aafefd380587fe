"""The two-step lookahead policy: its act() against a brute-force argmin over the automaton's
outcome lists, its gain by two exact evaluators and against the optimum, and where the tables are
exact (one process, one server, idling allowed) the optimum itself."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import brute_lookahead, shape

from wncs_lp import scenario_path
from wncs_lp.bounds import LookaheadPolicy, bound_policy, grouped_bound, private_bound
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies import GreedyPolicy
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import load_scenario
from wncs_lp import solve
from wncs_lp.solvers.matrix_free import matrix_free_evaluate

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


def _after(system, tau, delta) -> tuple[np.ndarray, float]:
    """The AoI vector one slot after ``tau`` with deliveries ``delta`` (0: none), and its cost."""
    nt = [min(tau[k] + 1, int(system.caps[k])) for k in range(system.n_processes)]
    nt = np.array([min(t, delta[k]) if delta[k] > 0 else t for k, t in enumerate(nt)])
    return nt, sum(float(system.q[k][nt[k] - 1]) for k in range(system.n_processes))


def brute_two_step(system, groups, h, column, tau, c: int) -> np.ndarray:
    """sum_o P(o | C, a) [c(tau'_o) + min_a' brute_lookahead(tau'_o, C'_o)[a']] per feasible action
    of configuration c, by loops over the automaton's outcome lists."""
    out = []
    for outs in system.automaton.outcomes[c]:
        v = 0.0
        for nxt, delta, p in outs:
            nt, cost = _after(system, tau, delta)
            v += p * (cost + brute_lookahead(system, groups, h, column, nt, nxt).min())
        out.append(v)
    return np.array(out)


def _check_argmin(system, pol, groups, h, column, n=150, seed=1):
    rng = np.random.default_rng(seed)
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, n) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, n)
    acts = pol.act(tau, cfg)
    for r in range(n):
        v = brute_two_step(system, groups, h, column, tau[r], int(cfg[r]))
        assert v[acts[r]] <= v.min() + 1e-9 * max(1.0, abs(v.min())), (tau[r], cfg[r], v, acts[r])


@pytest.mark.parametrize("name", ["paper", "u3", "three-servers"])
def test_act_is_the_argmin_of_the_two_step_lookahead(name):
    system = System.from_scenario(shape(name))
    res = private_bound(system)
    pol = LookaheadPolicy(bound_policy(res, system))
    _check_argmin(system, pol, [(k,) for k in range(system.n_processes)], res.tables.h, res.tables.column)


def test_act_on_group_tables():
    # both processes in one group: a table over (tau_1, tau_2, C_G), read through C-order strides
    system = System.from_scenario(shape("paper"))
    res = grouped_bound(system, [(0, 1)])
    pol = LookaheadPolicy(bound_policy(res, system))
    _check_argmin(system, pol, res.tables.groups, res.tables.h, res.tables.column, n=60)


def test_gain_by_two_exact_evaluators_and_against_the_optimum():
    sc = load_scenario(scenario_path("paper_p123"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    greedy = bound_policy(private_bound(system), system)
    pol = LookaheadPolicy(greedy, threads=1)  # the serial kernel only: one compilation in the tests
    mdp = build(sc)
    exact = evaluate(mdp, pol)
    mf = matrix_free_evaluate(system, pol)
    assert mf.gain_lower - 1e-9 * mf.gain <= exact.gain <= mf.gain_upper + 1e-9 * mf.gain
    opt = solve(mdp)
    assert exact.gain >= opt.gain_lower * (1 - 1e-9)
    # the greedy policy is left intact by the lookahead built on it
    assert np.array_equal(greedy.on_mdp(mdp), bound_policy(private_bound(system), system).on_mdp(mdp))


def test_exact_tables_give_the_optimum():
    # one process on one server with idling allowed: relaxation 1 is the system itself at
    # lambda = 0, its table the optimal bias, and both the greedy and the lookahead policy optimal
    sc = shape("one-idle")
    system = System.from_scenario(sc)
    mdp = build(sc)
    opt = solve(mdp)
    pol = LookaheadPolicy(bound_policy(private_bound(system), system))
    assert evaluate(mdp, pol).gain == pytest.approx(opt.gain, rel=1e-9)


def test_factory_name_and_refusals():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    pol = make_policy("lookahead", system)
    assert isinstance(pol, LookaheadPolicy) and pol.name.startswith("lookahead[bound[")
    with pytest.raises(PolicyError, match="SeparableGreedyPolicy"):
        LookaheadPolicy(GreedyPolicy(system))
    with pytest.raises(PolicyError, match="tau"):
        pol.act(np.array([[0, 1]]), np.array([0]))


def test_policy_gaps_by_name_and_the_best_row():
    from wncs_lp.bounds import policy_gaps

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    res = private_bound(system)
    report = policy_gaps(res, system, ["bound", "lookahead", "index"])
    mdp = build(sc)
    names = [r.policy for r in report.rows]
    assert names[1] == "lookahead[bound[private-servers]]" and names[2] == "index"
    assert report.rows[1].gain == pytest.approx(evaluate(mdp, LookaheadPolicy(bound_policy(res, system))).gain,
                                                rel=1e-8)
    assert report.best.gain_upper == min(r.gain_upper for r in report.rows)
    assert report.summary()["best"] == report.best.policy


def test_candidates_restrict_the_lookahead_to_the_greedy_best():
    system = System.from_scenario(shape("three-servers"))
    res = private_bound(system)
    greedy = bound_policy(res, system)
    rng = np.random.default_rng(4)
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, 200) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, 200)
    # one candidate: the greedy policy's own action
    assert np.array_equal(LookaheadPolicy(greedy, candidates=1).act(tau, cfg), greedy.act(tau, cfg))
    # as many as any configuration has: the full lookahead
    full = LookaheadPolicy(bound_policy(res, system))
    assert np.array_equal(LookaheadPolicy(bound_policy(res, system), candidates=system.max_actions).act(tau, cfg),
                          full.act(tau, cfg))
    # two: the two-step argmin over the two actions of least greedy value
    assert system.max_actions > 2
    two = LookaheadPolicy(bound_policy(res, system), candidates=2).act(tau, cfg)
    groups = [(k,) for k in range(system.n_processes)]
    for r in range(60):
        g = greedy.values(tau[r:r + 1], cfg[r:r + 1])[0][: system.n_actions[cfg[r]]]
        best2 = np.sort(np.argsort(g, kind="stable")[:2])
        v = brute_two_step(system, groups, res.tables.h, res.tables.column, tau[r], int(cfg[r]))
        assert two[r] == best2[np.argmin(v[best2])]
    with pytest.raises(PolicyError, match="candidates"):
        LookaheadPolicy(greedy, candidates=0)
    with pytest.raises(PolicyError, match="depth"):
        LookaheadPolicy(greedy, depth=4)


def brute_three_step(system, groups, h, column, tau, c: int, middle: int) -> np.ndarray:
    """sum_o P(o | C, a) [c(tau'_o) + min over the ``middle`` actions of least greedy value at s'_o
    (ties: the first) of brute_two_step there], per feasible action of configuration c."""
    out = []
    for outs in system.automaton.outcomes[c]:
        v = 0.0
        for nxt, delta, p in outs:
            nt, cost = _after(system, tau, delta)
            g = brute_lookahead(system, groups, h, column, nt, nxt)
            best = np.sort(np.argsort(g, kind="stable")[:middle])
            v += p * (cost + brute_two_step(system, groups, h, column, nt, nxt)[best].min())
        out.append(v)
    return np.array(out)


def test_depth_three_against_a_brute_force():
    system = System.from_scenario(shape("three-servers"))
    res = private_bound(system)
    pol = LookaheadPolicy(bound_policy(res, system), depth=3, middle=2)
    assert pol.name.startswith("lookahead3-m2[")
    groups = [(k,) for k in range(system.n_processes)]
    rng = np.random.default_rng(5)
    tau = np.stack([rng.integers(1, int(system.caps[k]) + 1, 25) for k in range(system.n_processes)], axis=1)
    cfg = rng.integers(0, system.n_configs, 25)
    acts = pol.act(tau, cfg)
    for r in range(25):
        v = brute_three_step(system, groups, res.tables.h, res.tables.column, tau[r], int(cfg[r]), 2)
        assert v[acts[r]] <= v.min() + 1e-9 * max(1.0, abs(v.min())), (tau[r], cfg[r], v, acts[r])


def test_the_lookahead_by_name_restricts_its_candidates_only_on_large_systems(monkeypatch):
    """Exact (every action) where no configuration has more than AUTO_CANDIDATES_FROM actions; the
    AUTO_CANDIDATES best greedy actions beyond."""
    from wncs_lp.bounds import lookahead

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    assert lookahead.auto_candidates(system) is None and make_policy("lookahead", system).candidates is None
    monkeypatch.setattr(lookahead, "AUTO_CANDIDATES_FROM", system.max_actions - 1)
    monkeypatch.setattr(lookahead, "AUTO_CANDIDATES", 2)
    pol = make_policy("lookahead", system)
    assert pol.candidates == 2 and pol.name.startswith("lookahead-k2[bound[")
