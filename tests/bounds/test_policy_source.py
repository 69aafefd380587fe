"""The policy side's tables (``policy_source``): a bound whose tables make a poor greedy policy hands
the policies another relaxation's tables, and the gaps stay against the bound's own certificate."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wncs_lp import scenario_path, solve
from wncs_lp.bounds import lower_bound, policy_gaps, private_bound
from wncs_lp.bounds.gaps import policy_source
from wncs_lp.bounds.policy import bound_policy
from wncs_lp.bounds.result import ValueTables
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def p12():
    """Processes 1-2 at cap 9: relaxation 1, and the same bound with its tables negated (a greedy
    policy that prefers old ages), each policy's gain evaluated exactly on the enumerated MDP."""
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=9"])
    system = System.from_scenario(sc)
    good = private_bound(system)
    bad = replace(good, tables=ValueTables(h=tuple(-np.asarray(h) for h in good.tables.h), column=good.tables.column))
    mdp = build(sc)
    gains = {name: evaluate(mdp, bound_policy(r, system)).gain for name, r in (("good", good), ("bad", bad))}
    return sc, system, good, bad, gains, mdp


def test_the_premise_the_negated_tables_make_a_poor_policy(p12):
    *_, gains, _ = p12
    assert gains["bad"] > 1.1 * gains["good"]  # beyond the pilot's margin and its noise


def test_tables_clearly_better_replace_the_bounds_own(p12):
    _, system, good, bad, _, _ = p12
    pick, why = policy_source(replace(bad, alternatives=(good,)), system)
    assert pick is good and "pilot" in why
    pick, why = policy_source(replace(good, alternatives=(bad,)), system)
    assert pick.tables is good.tables and why == ""
    assert policy_source(good, system) == (good, "")  # no alternatives: nothing simulated


def test_gaps_of_other_tables_are_against_the_bounds_certificate(p12):
    _, system, good, bad, gains, mdp = p12
    lb = 0.99 * good.lower_bound  # another certified bound: the gaps must be against it
    bound = replace(bad, lower_bound=lb)
    report = policy_gaps(bound, system, ["bound"], tables=good)
    row = report.rows[0]
    assert row.gain == pytest.approx(gains["good"], rel=1e-6)
    assert row.gap == pytest.approx((row.gain_upper - lb) / lb, rel=1e-12)
    assert report.summary()["tables_from"] == good.relaxation and report.lower_bound == lb
    assert row.gain >= solve(mdp).gain - 1e-6


def test_auto_keeps_the_other_relaxations_beside_its_choice(p12):
    _, system, _, _, _, _ = p12
    res = lower_bound(system, "auto")
    others = {r.relaxation for r in res.alternatives}
    assert res.relaxation not in others and others and all(r.lower_bound <= res.lower_bound for r in res.alternatives)
