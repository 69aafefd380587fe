"""lower_bound's dispatch: the relaxation asked for, and auto's choice (stand-in functions play
relaxation 2 here, so auto's rule is checked on bounds of known order)."""
from __future__ import annotations

from dataclasses import replace

import pytest

from wncs_lp import scenario_path
from wncs_lp.bounds import lower
from wncs_lp.bounds import RELAXATIONS, lower_bound, parse_relaxation, private_bound
from wncs_lp.errors import WncsError
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario
from wncs_lp import solve



@pytest.fixture(scope="module")
def p12():
    return System.from_scenario(load_scenario(scenario_path("paper_p12"), ["tau_cap=9"]))


def _fake_joint(monkeypatch, reach, bound):
    """Relaxation 2 played by ``reach`` (None within reach, else why not) and ``bound``; relaxation 5
    (which auto runs on two processes, where it is exact) off, so the order of 1 and 2 is what is
    checked."""
    monkeypatch.setattr(lower, "AUTO_ALL_PAIRS_BUDGET", 0.0)
    monkeypatch.setattr(lower, "joint_reach", reach)
    monkeypatch.setattr(lower, "joint_bound", bound)


def test_names_and_short_names():
    assert parse_relaxation(1) == "private-servers" and parse_relaxation("2") == "joint-configuration"
    assert parse_relaxation(3) == "grouped-private-servers"
    assert [parse_relaxation(r) for r in RELAXATIONS] == list(RELAXATIONS)
    with pytest.raises(WncsError, match="expected one of 1, 2, 3, 4, 5"):
        parse_relaxation("6")


def test_auto_is_a_valid_bound_and_says_which_fired(p12):
    res = lower_bound(p12)
    assert res.stats["auto_choice"] in RELAXATIONS and res.stats["auto_reason"]
    assert res.lower_bound <= solve(build(p12.scenario)).gain_upper * (1 + 1e-12)


def test_auto_takes_relaxation_2_within_its_reach(monkeypatch, p12):
    base = private_bound(p12)
    fake = replace(base, relaxation="joint-configuration", lower_bound=base.lower_bound + 1.0, stats={})
    _fake_joint(monkeypatch, lambda s: None, lambda s, **kw: fake)
    res = lower_bound(p12, "auto")
    assert res.relaxation == "joint-configuration" and res.stats["auto_choice"] == "joint-configuration"
    assert lower_bound(p12, "joint-configuration") is fake


def test_auto_falls_back_beyond_the_reach_of_relaxation_2(monkeypatch, p12):
    def refuse(system, **kw):
        raise WncsError("no room for the joint LP")

    _fake_joint(monkeypatch, lambda s: "2.5e9 columns", refuse)
    res = lower_bound(p12, "auto")
    assert res.relaxation == "private-servers" and "2.5e9 columns" in res.stats["auto_reason"]
    _fake_joint(monkeypatch, lambda s: None, refuse)
    res = lower_bound(p12, "auto")
    assert res.relaxation == "private-servers" and "no room for the joint LP" in res.stats["auto_reason"]


def test_scenario_or_system(p12):
    a = lower_bound(p12.scenario, "private-servers")
    b = lower_bound(p12, 1)
    assert a.lower_bound == b.lower_bound
    with pytest.raises(WncsError, match="Scenario or a System"):
        lower_bound("paper_p12.toml", "auto")


def test_auto_takes_relaxation_1_when_relaxation_2_stopped_below_it(monkeypatch, p12):
    base = private_bound(p12)
    worse = replace(base, relaxation="joint-configuration", lower_bound=base.lower_bound - 1.0, stats={})
    _fake_joint(monkeypatch, lambda s: None, lambda s, **kw: worse)
    res = lower_bound(p12, "auto")
    assert res.relaxation == "private-servers" and res.lower_bound == base.lower_bound
    assert res.stats["auto_bounds"] == {"joint-configuration": base.lower_bound - 1.0, "private-servers": base.lower_bound}
    assert "largest certified bound" in res.stats["auto_reason"]


def test_auto_beyond_the_whole_lp_takes_relaxation_2_on_the_lumped_chains(monkeypatch):
    """With relaxation 2's whole LP out of reach, auto still evaluates its Lagrangian at relaxation 1's
    prices on the lumped chains: certified, at least relaxation 1's bound, below the exact g*."""
    from wncs_lp.bounds import joint

    sc = load_scenario(scenario_path("paper_p1234"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    monkeypatch.setattr(joint, "REACH_MAX_NNZ", 1)
    res = lower_bound(system, "auto")
    assert "joint-configuration" in res.stats["auto_bounds"]
    assert "Lagrangian at relaxation 1's prices" in res.stats["auto_reason"]
    r2 = res.stats["auto_bounds"]["joint-configuration"]
    assert r2 >= res.stats["auto_bounds"]["private-servers"] * (1 - 1e-6)
    assert res.lower_bound <= solve(build(sc)).gain_upper


@pytest.mark.parametrize("option", [{"groups": [[0, 1]]}, {"cpu_limit": 10.0}, {"solve_tol": 1e-9}])
def test_auto_refuses_by_name_an_option_only_relaxations_1_or_3_take(p12, option):
    # auto hands its options to relaxation 2; relaxation 3's groups reached it as a TypeError before
    with pytest.raises(WncsError, match=next(iter(option))):
        lower_bound(p12, "auto", **option)
