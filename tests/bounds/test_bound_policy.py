"""The policy of a bound: its act() against a brute-force argmin, its gain by two exact evaluators
and by simulation, its place against the optimum."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from bounds_reference import brute_lookahead, shape

from wncs_lp import scenario_path
from wncs_lp.bounds import BoundPolicy, ValueTables, bound_policy, private_bound
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies.suboptimal import SeparableGreedyPolicy, SuboptimalPolicy
from wncs_lp.scenario import load_scenario
from wncs_lp.simulate import simulate
from wncs_lp import solve
from wncs_lp.solvers.matrix_free import matrix_free_evaluate

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


def _setup(sc):
    system = System.from_scenario(sc)
    res = private_bound(system)
    return system, res, bound_policy(res, system)


@pytest.mark.parametrize("name", ["paper", "u3", "three-servers"])
def test_act_is_the_argmin_of_the_separable_lookahead(name):
    system, res, pol = _setup(shape(name))
    mdp = build(system.scenario)
    st = mdp.states
    rng = np.random.default_rng(1)
    rows = rng.choice(mdp.n_states, size=min(600, mdp.n_states), replace=False)
    acts = pol.act(np.asarray(st.tau)[rows], np.asarray(st.config)[rows])
    for r, j in zip(rows, acts):
        v = brute_lookahead(system, [(k,) for k in range(system.n_processes)], res.tables.h, res.tables.column,
                            np.asarray(st.tau)[r], int(st.config[r]))
        assert v[j] <= v.min() + 1e-9 * max(1.0, abs(v.min())), f"state {mdp.state_label(int(r))}"


def test_gain_by_two_exact_evaluators_and_against_the_optimum():
    sc = load_scenario(scenario_path("paper_p1234"), ["tau_cap=7"])
    system, res, pol = _setup(sc)
    mdp = build(sc)
    exact = evaluate(mdp, pol)
    mf = matrix_free_evaluate(system, pol)
    assert mf.gain_lower - 1e-9 * mf.gain <= exact.gain <= mf.gain_upper + 1e-9 * mf.gain
    opt = solve(mdp)
    assert res.lower_bound <= opt.gain_upper * (1 + 1e-12)
    assert exact.gain >= opt.gain_lower * (1 - 1e-9)


def test_simulation_agrees_with_the_exact_gain():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=9"])
    system, res, pol = _setup(sc)
    exact = evaluate(build(sc), pol).gain
    mc = simulate(pol, slots=20_000, reps=16, seed=3, burn_in=500, progress=False)
    assert abs(mc.mean - exact) <= 5 * mc.stderr + 1e-3 * exact


def test_column_maps_are_read_through():
    """The same value function stored in permuted rows, read through the inverse permutation,
    gives the same policy; and identity columns on the paper's Poisson tables give the paper's
    suboptimal policy."""
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=8"])
    system, res, pol = _setup(sc)
    rng = np.random.default_rng(0)
    h, cols = [], []
    for hk, ck in zip(res.tables.h, res.tables.column):
        perm = rng.permutation(hk.shape[0])  # row r of the new table = row perm[r] of the old
        inv = np.argsort(perm)
        h.append(hk[perm])
        cols.append(inv[ck])
    permuted = BoundPolicy(replace(res, tables=ValueTables(tuple(h), tuple(cols))), system)
    mdp = build(sc)
    np.testing.assert_array_equal(permuted.on_mdp(mdp), pol.on_mdp(mdp))
    sub = SuboptimalPolicy(system)
    same = SeparableGreedyPolicy(system, [p.h for p in sub.poisson])
    np.testing.assert_array_equal(same.on_mdp(mdp), sub.on_mdp(mdp))


def test_tables_of_another_system_are_refused():
    _, res, _ = _setup(load_scenario(scenario_path("paper_p12"), ["tau_cap=8"]))
    other = System.from_scenario(load_scenario(scenario_path("paper_p14"), ["tau_cap=8"]))
    with pytest.raises(PolicyError, match="another system|value table"):
        BoundPolicy(res, other)


def test_describe_names_the_relaxation():
    _, res, pol = _setup(load_scenario(scenario_path("paper_p12"), ["tau_cap=8"]))
    d = pol.describe()
    assert d["relaxation"] == "private-servers" and d["lower_bound"] == res.lower_bound
    assert pol.name == "bound[private-servers]"


def test_policy_maps_like_any_policy():
    from wncs_lp.policy_grids import policy_grid

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=8"])
    system, res, pol = _setup(sc)
    mdp = build(sc)
    A, S, _ = policy_grid(mdp, pol, "idle")
    st = mdp.states
    cells = S[S >= 0]
    assert cells.size > 10
    j = pol.act(np.asarray(st.tau)[cells], np.asarray(st.config)[cells])
    np.testing.assert_array_equal(A[S >= 0], mdp.a_indices[mdp.pair_ptr[cells] + j])


def test_make_policy_by_name_is_the_policy_of_the_auto_bound():
    # the factory's "relaxation" is lower_bound(system, "auto") then bound_policy: the same actions
    # on every state, and an exact gain between the optimum and its own certified bound's reach
    from wncs_lp.bounds import lower_bound
    from wncs_lp.workflow import make_policy

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=8"])
    system = System.from_scenario(sc)
    pol = make_policy("relaxation", system)
    ref = bound_policy(lower_bound(system, "auto"), system)
    mdp = build(sc)
    st = mdp.states
    tau, cfg = np.asarray(st.tau), np.asarray(st.config)
    assert np.array_equal(pol.act(tau, cfg), ref.act(tau, cfg))
    opt = solve(mdp)
    assert evaluate(mdp, pol).gain >= opt.gain_lower * (1 - 1e-9)
