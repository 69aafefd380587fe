"""Relaxation 5 (``lower_bound(x, 5)``, wncs_lp.bounds.all_pairs): the level-2 LP packed as a bound
with a cover of pair tables for the policies.

Independent references: g* of the exact solver on the enumerated MDP, relaxation 4's certified bound
(a relaxation whose constraints are a subset), and the exact evaluation of the greedy policy on the
enumerated MDP (:func:`wncs_lp.evaluate.evaluate`), which no policy can beat."""
from __future__ import annotations

import json

import pytest
from joint_reference import three_processes

from wncs_lp import scenario_path, solve
from wncs_lp.bounds import GroupBoundPolicy, bound_policy, parse_relaxation
from wncs_lp.bounds import all_pairs as all_pairs_module
from wncs_lp.bounds.lower import lower_bound
from wncs_lp.errors import SizeLimitError, WncsError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario


@pytest.fixture(scope="module")
def three():
    """Three processes at cap 5: relaxation 2 is 2.9% below g* there, relaxation 4's best pairing
    6e-7."""
    sc = three_processes(5)
    system = System.from_scenario(sc)
    return sc, system, solve(build(sc)).gain_upper, lower_bound(system, 4), lower_bound(system, 5)


def test_between_relaxation_4_and_g_star(three):
    _, _, g_star, r4, r5 = three
    assert r5.relaxation == "joint-all-pairs" and r5.status == "optimal" and r5.certified
    assert r5.lower_bound <= g_star
    assert r5.lower_bound >= r4.lower_bound - 1e-9 * g_star
    assert r5.stats["lp_value"] >= r5.lower_bound - 1e-9 * g_star  # the certificate does not exceed the LP
    assert len(r5.tables.groups) == 3 and r5.tables.n_processes == 3  # every pair of three, no lumping


def test_greedy_policy_on_the_cover_is_optimal_here(three):
    """The bound is within 1e-8 of g* here, so its greedy policy, evaluated exactly on the enumerated
    MDP, is at g* within the evaluation's tolerance -- and never below it."""
    sc, system, g_star, _, r5 = three
    pol = bound_policy(r5, system)
    assert isinstance(pol, GroupBoundPolicy)
    gain = evaluate(build(sc), pol).gain
    assert g_star * (1 - 1e-9) <= gain <= g_star * (1 + 1e-6)


def test_memory_guard_refuses_before_building(three, monkeypatch):
    _, system, _, _, _ = three
    monkeypatch.setattr(all_pairs_module, "ALL_PAIRS_BYTES_PER_NNZ", {"ipx": 10**15})
    monkeypatch.setattr(all_pairs_module, "level2_bound", lambda *a, **k: pytest.fail("built despite the guard"))
    with pytest.raises(SizeLimitError, match=r"relaxation 5 .*level-2 LP.*relaxation 4"):
        lower_bound(system, 5)


def test_names_and_options():
    assert parse_relaxation(5) == parse_relaxation("joint-all-pairs") == "joint-all-pairs"
    with pytest.raises(WncsError, match="groups"):
        lower_bound(System.from_scenario(three_processes(4)), 5, groups=[(0, 1)])


def test_command_line(capsys):
    """``wncs-lp bound --relaxation 5``: processes 1 and 2 of the paper are one pair, the whole
    system, so the bound is g* up to the solver's tolerance (the command's ``--tol``, 1e-6)."""
    path = str(scenario_path("paper_p12"))
    rc = main_json(["bound", path, "--set", "tau_cap=8", "--relaxation", "5", "--json"])
    out = json.loads(capsys.readouterr().out)
    g_star = solve(build(load_scenario(path, ["tau_cap=8"]))).gain_upper
    assert rc == 0
    assert out["bound"]["relaxation"] == "joint-all-pairs"
    assert out["bound"]["lower_bound"] <= g_star
    assert out["bound"]["lower_bound"] == pytest.approx(g_star, rel=1e-5)


def main_json(argv):
    from wncs_lp.cli import main

    return main(argv)
