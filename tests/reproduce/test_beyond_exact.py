"""The report's "beyond the paper" section B3 (certified lower bounds and the bound's policy).

Every number is checked against an independent route: g* against policy iteration on the
enumerated MDP, the bound's policy against the exact sparse evaluation of the same policy on that
MDP, each certified gap against the true gap it must bound from above; the Monte Carlo rows
against the bound they are measured from.
"""
from __future__ import annotations

import dataclasses
import shutil

import pytest

from wncs_lp.bounds import LookaheadPolicy, bound_policy, lower_bound
from wncs_lp.evaluate import evaluate
from wncs_lp.models.system import System
from wncs_lp.reproduce import beyond, beyondexact as b3
from wncs_lp.reproduce.context import PROFILES, Context

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

TINY = b3.BeyondExactSettings((b3.Instance(b3.FOUR, 6, True), b3.Instance("bounds_mix6.toml", 3, False)),
                              slots=3_000, reps=4, burn_in=200, steps=3)
#: the bound the section computes, rebuilt through the library
SEARCH = {"max_iter": TINY.steps, "time_limit": None}


@pytest.fixture(scope="module")
def tiny(quick_reproduction, tmp_path_factory):
    """The section run in this process on a copy of the quick reproduction's cache: the suite's
    quick reproduction (tests/conftest.py) computes B3 on these very settings, so its steps are
    read, not computed twice (a cache entry's key is its step, parameters and code, not the
    profile's name); whatever it did not leave is computed here."""
    prof = dataclasses.replace(PROFILES["quick"], name="tiny-b3")
    b3.SETTINGS["tiny-b3"] = TINY
    out = tmp_path_factory.mktemp("b3")
    if (quick_reproduction.out / "cache").is_dir():
        shutil.copytree(quick_reproduction.out / "cache", out / "cache")
    ctx = Context(out, prof)
    (sec,) = beyond.run_beyond(ctx, ["B3"])
    yield out, sec, ctx
    del b3.SETTINGS["tiny-b3"]


def test_section_has_a_table_and_no_verdict(tiny):
    out, sec, _ = tiny
    assert sec["id"] == "B3" and "verdict" not in sec
    assert "could not be computed" not in sec["summary"], sec["numbers"].get("error")
    (tab,) = sec["tables"]
    assert (out / tab).read_text().startswith("scenario,processes,servers,cap,states,g_star,row")
    assert "| scenario | N | cap |" in sec["details"]
    assert [i["processes"] for i in sec["numbers"]["instances"]] == [4, 6]


def test_four_processes_against_the_enumerated_mdp(tiny):
    _, sec, ctx = tiny
    inst = sec["numbers"]["instances"][0]
    sc = ctx.scenario(b3.FOUR, ["tau_cap=6", "p=0.9"])
    ref = ctx.solve(sc)  # policy iteration on the stored matrix
    opt = inst["optimum"]  # certified to B2's relative width 1e-7
    assert opt["gain_lower"] - 1e-9 * ref.gain <= ref.gain <= opt["gain_upper"] + 1e-9 * ref.gain
    lb = inst["bounds"][0]["lower_bound"]
    assert lb <= ref.gain * (1 + 1e-12)
    # the bound's policy, rebuilt from the library and evaluated on the stored matrix
    system = System.from_scenario(sc)
    pol = bound_policy(lower_bound(system, "auto", **SEARCH), system)
    exact = evaluate(ctx.mdp(sc), pol).gain
    row = next(r for r in inst["policies"] if r["policy"].startswith("bound"))
    assert row["how"] == "exact"
    assert row["gain"] == pytest.approx(exact, rel=1e-7)
    # and the two-step lookahead on the same tables, on the stored matrix
    ahead = evaluate(ctx.mdp(sc), LookaheadPolicy(pol)).gain
    (row2,) = [r for r in inst["policies"] if r["policy"].startswith("lookahead")]
    assert row2["how"] == "exact" and row2["gain"] == pytest.approx(ahead, rel=1e-7)
    for r in inst["policies"]:  # a certified gap bounds the true one from above
        assert r["gap"] >= r["gain"] / ref.gain - 1 - 1e-9
        assert r["gain"] >= ref.gain * (1 - 1e-9)
    if inst["bounds"][0]["relaxation"] != "private-servers":  # relaxation 1's policy is shown beside
        first = evaluate(ctx.mdp(sc), bound_policy(lower_bound(system, 1), system)).gain
        (row1,) = [r for r in inst["policies"] if r["policy"] == "bound[private-servers]"]
        assert row1["gain"] == pytest.approx(first, rel=1e-7)
        best = min((r for r in inst["policies"] if r["policy"].startswith(("bound", "lookahead"))),
                   key=lambda r: r["gap"])
        assert f"best bound's policy ({best['policy']}) is within" in sec["summary"]


def test_monte_carlo_rows_against_the_exact_evaluation(tiny):
    # six processes at cap 3 are small enough for the certified matrix-free evaluation, which the
    # section's Monte Carlo row of the bound's policy must agree with (4 standard errors)
    from wncs_lp.solvers.matrix_free import matrix_free_evaluate

    _, sec, ctx = tiny
    inst = sec["numbers"]["instances"][1]
    lb = inst["bounds"][0]["lower_bound"]
    assert inst["how"] == "monte-carlo" and "optimum" not in inst
    system = System.from_scenario(ctx.scenario("bounds_mix6.toml", ["tau_cap=3"]))
    ev = matrix_free_evaluate(system, bound_policy(lower_bound(system, "auto", **SEARCH), system), tol=1e-10)
    assert lb <= ev.gain_upper
    exact = ev.gain
    row = next(r for r in inst["policies"] if r["policy"].startswith("bound"))
    # (+ the exact bracket's width: with the bound's tables as control variate the residual can be
    # constant along the path, a standard error of round-off size)
    assert abs(row["gain"] - exact) <= 4 * row["stderr"] + (ev.gain_upper - ev.gain_lower)
    for r in inst["policies"]:
        assert r["gain_upper"] >= r["gain"]
        assert r["gap"] == pytest.approx((r["gain_upper"] - lb) / lb, rel=1e-12)


def test_a_second_run_is_read_from_the_cache(tiny):
    out, sec, _ = tiny
    ctx = Context(out, dataclasses.replace(PROFILES["quick"], name="tiny-b3"))
    (again,) = beyond.run_beyond(ctx, ["B3"])
    assert ctx.cache.misses == 0 and ctx.cache.hits >= len(TINY.instances)  # every instance read back
    assert again["numbers"]["instances"] == sec["numbers"]["instances"]
