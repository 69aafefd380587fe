"""``"auto"``'s rule for relaxation 5 (every pair's ages at once, its LP solved whole): it runs where
its LP is predicted to fit the CPU budget (whole, else lumped), is skipped with the prediction said
otherwise, and its tables reach the bound's policies.

Independent references: g* of the exact solver on the enumerated MDP (no relaxation can pass it),
relaxation 2's interior point (whose LP's constraints are a subset of relaxation 5's, lumped or not:
wncs_lp.bounds.level2), and the exact evaluation of the policies on the enumerated MDP, which no
policy can beat."""
from __future__ import annotations

import time

import pytest
from joint_reference import three_processes

from wncs_lp import scenario_path, solve
from wncs_lp.bounds import GroupBoundPolicy, lower
from wncs_lp.bounds.all_pairs import all_pairs_size
from wncs_lp.bounds.gaps import policy_source
from wncs_lp.bounds.joint_chains import JointData
from wncs_lp.bounds.lower import all_pairs_plan, lower_bound
from wncs_lp.bounds.named import named_policy
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario


@pytest.fixture(scope="module")
def three():
    """Three processes at cap 5 (30 configurations): relaxation 2 is 2.9% below g* there, relaxation
    5 within 1e-8 of it (tests/bounds/test_all_pairs.py); its LP is predicted to take seconds."""
    sc = three_processes(5)
    system = System.from_scenario(sc)
    return sc, system, solve(build(sc)).gain_upper, lower_bound(system, "auto")


def test_auto_runs_relaxation_5_where_predicted_to_fit(three):
    _, system, g_star, auto = three
    plan = all_pairs_plan(system)
    assert plan["runs"] and plan["whole"] and plan["lump"] is None
    assert plan["predicted"] <= lower.AUTO_ALL_PAIRS_BUDGET
    bounds = auto.stats["auto_bounds"]
    assert auto.relaxation == "joint-all-pairs" == auto.stats["auto_choice"]
    assert auto.lower_bound == max(bounds.values()) <= g_star
    # its LP contains relaxation 2's constraints: never below relaxation 2's interior point (its tolerance)
    assert auto.lower_bound >= bounds["joint-configuration"] - 1e-6 * g_star
    assert auto.lower_bound >= g_star * (1 - 1e-6) > bounds["joint-configuration"] * (1 + 1e-2)
    reason = auto.stats["auto_reason"]
    assert "relaxation 5, its whole LP" in reason and "predicted" in reason
    # relaxation 4's start is the probe (its bundle not run: relaxation 5's LP contains its constraints)
    assert "relaxation 4's start only" in reason and bounds["joint-pairs"] <= auto.lower_bound


def test_not_run_where_relaxation_4s_start_sees_no_gap(three, monkeypatch):
    """Where the pairs' start does not raise relaxation 2's bound (forced: a gain of 100% asked),
    relaxation 5 is not run either, and auto says so with its prediction."""
    _, system, g_star, _ = three
    monkeypatch.setattr(lower, "AUTO_PAIRS_MIN_GAIN", 1.0)
    monkeypatch.setattr(lower, "all_pairs_bound", lambda *a, **k: pytest.fail("relaxation 5 run without a gap"))
    res = lower_bound(system, "auto")
    assert "joint-all-pairs" not in res.stats["auto_bounds"] and res.lower_bound <= g_star
    assert "relaxation 5 not run: relaxation 4's start saw no gap" in res.stats["auto_reason"]


def test_auto_policies_read_relaxation_5s_tables(three):
    """The policy factory's lookahead (``auto``'s bound, then its greedy policy on the tables) and
    the gap report's choice of tables: relaxation 5's cover, evaluated exactly at g* here."""
    sc, system, g_star, auto = three
    look = named_policy("lookahead", system)
    assert isinstance(look.base, GroupBoundPolicy) and look.base.result.relaxation == "joint-all-pairs"
    mdp = build(sc)
    for pol in (look.base, look):
        gain = evaluate(mdp, pol).gain
        assert g_star * (1 - 1e-9) <= gain <= g_star * (1 + 1e-6)
    source, why = policy_source(auto, system)
    assert source is auto and why == ""  # no other relaxation's tables beat the optimum's


def test_skipped_beyond_the_budget_with_the_prediction(three, monkeypatch):
    _, system, g_star, _ = three
    monkeypatch.setattr(lower, "AUTO_ALL_PAIRS_BUDGET", 1e-9)
    monkeypatch.setattr(lower, "all_pairs_bound", lambda *a, **k: pytest.fail("relaxation 5 built beyond its budget"))
    monkeypatch.setattr(lower, "AUTO_PAIRS_BUDGET", 0.0)  # relaxation 4 off too: not what is tested here
    plan = all_pairs_plan(system)
    assert not plan["runs"] and plan["predicted"] > 1e-9
    res = lower_bound(system, "auto")
    assert "joint-all-pairs" not in res.stats["auto_bounds"] and res.lower_bound <= g_star
    assert "relaxation 5 not run" in res.stats["auto_reason"] and "predicted" in res.stats["auto_reason"]


def test_lumped_where_the_whole_lp_does_not_fit(three, monkeypatch):
    """A budget between the LP lumped at 4 and the whole LP: auto lumps at 4 (the largest threshold
    that fits, and the least it takes), still at least relaxation 2's interior point and at most g*;
    relaxation 4 then runs its bundle too (the lumped LP does not contain its constraints)."""
    _, system, g_star, _ = three
    at4, whole = all_pairs_size(system, 4)["predicted_seconds"], all_pairs_size(system)["predicted_seconds"]
    assert at4 < whole
    monkeypatch.setattr(lower, "AUTO_ALL_PAIRS_BUDGET", at4 * 1.001)
    plan = all_pairs_plan(system)
    assert plan["runs"] and plan["lump"] == 4 and not plan["whole"]
    res = lower_bound(system, "auto")
    bounds = res.stats["auto_bounds"]
    assert "lumped from 4" in res.stats["auto_reason"]
    assert bounds["joint-configuration"] - 1e-6 * g_star <= bounds["joint-all-pairs"] <= g_star
    assert "relaxation 4 from relaxation 2's optimum" in res.stats["auto_reason"]


def test_a_solve_beyond_its_guard_is_stopped_and_said(three, monkeypatch):
    _, system, g_star, _ = three
    monkeypatch.setattr(lower, "AUTO_ALL_PAIRS_GUARD", {"factor": 0.0, "slack": 0.0})
    res = lower_bound(system, "auto")
    assert "joint-all-pairs" not in res.stats["auto_bounds"] and res.lower_bound <= g_star
    assert "it could not run" in res.stats["auto_reason"]


def test_eight_processes_skipped_by_a_count(monkeypatch):
    """At eight processes (cap 20: 1.0 billion nonzeros) the rule says no from the automaton's counts,
    in milliseconds, without the joint data's arrays."""
    system = System.from_scenario(load_scenario(scenario_path("bounds_p1234_twice")))
    system.automaton.flat(system.n_processes)  # the system holds it already (relaxations 1-3 read it)
    monkeypatch.setattr(JointData, "from_system", classmethod(lambda cls, s: pytest.fail("joint data built")))
    c0 = time.process_time()
    plan = all_pairs_plan(system)
    assert time.process_time() - c0 < 0.5
    assert not plan["runs"] and plan["size"]["nnz"] > 10**9
    assert "relaxation 5 not run" in plan["rule"] and "predicted" in plan["rule"]

