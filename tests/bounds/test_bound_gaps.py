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
from wncs_lp.solvers import solve

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
