"""Policies against a bound: the certified gap, exact and by Monte Carlo."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.bounds import policy_gaps, private_bound
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies import GreedyPolicy
from wncs_lp.scenario import load_scenario
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=9"])
    system = System.from_scenario(sc)
    return sc, system, private_bound(system)


def test_exact_gaps_bracket_the_true_gaps(p12):
    sc, system, res = p12
    report = policy_gaps(res, system, ["bound", "suboptimal", GreedyPolicy(system)])
    assert report.how == "exact" and [r.how for r in report.rows] == ["exact"] * 3
    mdp = build(sc)
    g_star = solve(mdp).gain
    for row, pol in zip(report.rows, ["bound", "suboptimal", "greedy"]):
        assert row.gain_upper >= row.gain
        assert row.gap == pytest.approx((row.gain_upper - res.lower_bound) / res.lower_bound, rel=1e-12)
        assert row.gap >= (row.gain - g_star) / g_star - 1e-9  # the certified gap bounds the true one
    greedy = evaluate(mdp, GreedyPolicy(system)).gain
    assert report.row("greedy").gain == pytest.approx(greedy, rel=1e-8)
    assert report.row("bound").policy == "bound[private-servers]"


def test_monte_carlo_gaps_use_the_upper_confidence_limit(p12):
    _, system, res = p12
    report = policy_gaps(res, system, ["bound", "static"], exact=False, slots=4000, reps=8, seed=5, burn_in=200)
    assert report.how == "monte-carlo"
    for row in report.rows:
        assert row.how == "monte-carlo" and row.detail["reps"] == 8
        assert row.gain_upper > row.gain  # mean + t * stderr
        assert row.gap == pytest.approx((row.gain_upper - res.lower_bound) / res.lower_bound, rel=1e-12)
    again = policy_gaps(res, system, ["bound"], exact=False, slots=4000, reps=8, seed=5, burn_in=200)
    assert again.rows[0].gain == report.rows[0].gain  # seeded


def test_size_decides_the_route(p12):
    _, system, res = p12
    assert policy_gaps(res, system, ["greedy"], exact_max_states=10, slots=500, reps=3).how == "monte-carlo"
    summary = policy_gaps(res, system, ["greedy"]).summary()
    assert summary["how"] == "exact" and summary["policies"][0]["policy"] == "greedy"
    assert np.isfinite(summary["policies"][0]["gap"])


def test_projected_value_on_a_lazy_system_is_the_enumerated_tables_value():
    """The control variate's h(tau, C) on a lazily explored system (columns of configurations met
    after the bound found by projection) equals the bound's own tables on the enumerated system."""
    import numpy as np

    import wncs_lp
    from wncs_lp.bounds import lower_bound
    from wncs_lp.bounds.projected import ProjectedValue
    from wncs_lp.models.system import System

    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p1234"), ["tau_cap=5"])
    full = System.from_scenario(sc)
    lazy = System.from_scenario(sc, explore="lazy")
    res_full, res_lazy = lower_bound(full, 1), lower_bound(lazy, 1)
    known = len(lazy.automaton.configs)
    lazy.expand(np.arange(known))  # configurations the bound's columns never saw
    rng = np.random.default_rng(0)
    for _ in range(3):
        lazy.expand(np.arange(len(lazy.automaton.configs)))
    c_lazy = np.arange(len(lazy.automaton.configs))
    assert c_lazy.size > known  # the check reaches past the bound's columns
    c_full = np.array([full.automaton.index[lazy.automaton.configs[c]] for c in c_lazy])
    tau = rng.integers(1, 6, size=(c_lazy.size, sc.n_processes))
    got = ProjectedValue(res_lazy, lazy)(tau, c_lazy)
    want = res_full.tables.value(tau, c_full)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_the_bound_policy_builds_on_a_lazy_system_that_grew_after_the_bound():
    """A greedy policy of a bound built after a simulation has met configurations the bound's column
    maps never saw (it had refused them as "tables numbered otherwise") values every action as on
    the enumerated system; the two-step lookahead, whose arrays are the pairs known when it is
    built, refuses a lazily explored system by name."""
    from wncs_lp.bounds import LookaheadPolicy, bound_policy, lower_bound
    from wncs_lp.errors import PolicyError

    sc = load_scenario(scenario_path("paper_p1234"), ["tau_cap=5"])
    full, lazy = System.from_scenario(sc), System.from_scenario(sc, explore="lazy")
    res_full, res_lazy = lower_bound(full, 1), lower_bound(lazy, 1)
    for _ in range(3):
        lazy.expand(np.arange(len(lazy.automaton.configs)))
    n = len(lazy.automaton.configs)
    assert n > res_lazy.tables.column[0].shape[0]  # the system grew past the tables' maps
    c_lazy = np.arange(n)
    c_full = np.array([full.automaton.index[lazy.automaton.configs[c]] for c in c_lazy])
    tau = np.random.default_rng(1).integers(1, 6, size=(n, sc.n_processes))
    pol = bound_policy(res_lazy, lazy)
    got, want = pol.values(tau, c_lazy), bound_policy(res_full, full).values(tau, c_full)
    fin = np.isfinite(want)
    np.testing.assert_array_equal(np.isfinite(got), fin)
    np.testing.assert_allclose(got[fin], want[fin], rtol=1e-12, atol=0)
    with pytest.raises(PolicyError, match="explored lazily"):
        LookaheadPolicy(pol)
