"""``wncs-lp bound``: the bound and the gaps as one JSON object, the text, the errors."""
from __future__ import annotations

import json

import pytest

from wncs_lp import scenario_path
from wncs_lp.cli import main
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies import SuboptimalPolicy
from wncs_lp.scenario import load_scenario
from wncs_lp import solve

P12 = str(scenario_path("paper_p12"))


def _json(capsys, *argv) -> tuple[int, dict]:
    rc = main(list(argv))
    return rc, json.loads(capsys.readouterr().out)


def test_json_bound_and_exact_gaps(capsys):
    rc, out = _json(capsys, "bound", P12, "--set", "tau_cap=9", "--relaxation", "1", "--policy",
                    "--compare", "suboptimal", "--json")
    assert rc == 0 and out["scenario"] == P12 and out["overrides"] == ["tau_cap=9"]
    sc = load_scenario(P12, ["tau_cap=9"])
    mdp = build(sc)
    g_star = solve(mdp).gain_upper
    bound = out["bound"]
    assert bound["relaxation"] == "private-servers" and bound["status"] == "optimal"
    assert 0 < bound["lower_bound"] <= g_star * (1 + 1e-12)
    rows = {r["policy"]: r for r in out["policies"]["policies"]}
    assert set(rows) == {"bound[private-servers]", "suboptimal"} and out["policies"]["how"] == "exact"
    sub = evaluate(mdp, SuboptimalPolicy(System.from_scenario(sc))).gain
    assert rows["suboptimal"]["gain"] == pytest.approx(sub, rel=1e-8)
    for r in rows.values():
        assert r["gap"] == pytest.approx((r["gain_upper"] - bound["lower_bound"]) / bound["lower_bound"])
        assert r["gap"] >= -1e-12


def test_json_monte_carlo_route(capsys):
    rc, out = _json(capsys, "bound", P12, "--set", "tau_cap=9", "--policy", "--compare", "", "--exact-max-states",
                    "0", "--reps", "4", "--slots", "2000", "--seed", "7", "--json")
    assert rc == 0 and out["bound"]["stats"]["auto_choice"] in ("private-servers", "joint-configuration", "joint-all-pairs")
    (row,) = out["policies"]["policies"]
    assert row["how"] == "monte-carlo" and row["reps"] == 4 and row["seed"] == 7
    assert row["gain_upper"] > row["gain"]


def test_text_output(capsys):
    assert main(["bound", P12, "--set", "tau_cap=8", "--relaxation", "private-servers"]) == 0
    text = capsys.readouterr().out
    assert "certified lower bound: g* >=" in text and "gain_lower" in text and "multipliers" in text


def test_preemption_is_refused_with_exit_2(capsys):
    rc, out = _json(capsys, "bound", str(scenario_path("paper_preemption_p12")), "--relaxation", "1", "--json")
    assert rc == 2 and "preemption" in out["error"]


def test_unknown_relaxation_exit_2(capsys):
    rc, out = _json(capsys, "bound", P12, "--relaxation", "6", "--json")
    assert rc == 2 and "expected one of 1, 2, 3, 4, 5" in out["error"]


def test_a_search_stopped_at_its_budget_exits_0(capsys):
    """``--time-limit`` stops relaxation 4's search at its start (status max_iter): the bound is
    certified all the same (below the exact g*), so the command succeeds."""
    rc, out = _json(capsys, "bound", P12, "--set", "tau_cap=8", "--relaxation", "4", "--time-limit", "1e-6", "--json")
    g_star = solve(build(load_scenario(P12, ["tau_cap=8"]))).gain_upper
    assert out["bound"]["status"] == "max_iter" and rc == 0
    assert out["bound"]["lower_bound"] <= g_star


def test_threads_cap_every_kernel_of_the_command(capsys, monkeypatch):
    """``--threads 1`` reaches the relaxation (its count) and the policies' evaluation (the command's
    thread cap, which the lookahead, the rollout and the exact evaluations resolve their count under);
    the cap is lifted afterwards."""
    import wncs_lp.bounds as bounds
    from wncs_lp.solvers.threads import resolve_threads, threads_limit

    seen = {}
    real_lower, real_gaps = bounds.lower_bound, bounds.policy_gaps

    def lower(*a, **kw):
        seen["relaxation"] = kw.get("threads")
        return real_lower(*a, **kw)

    def gaps(*a, **kw):
        seen["cap"], seen["resolved"] = threads_limit(), resolve_threads(None)
        return real_gaps(*a, **kw)

    monkeypatch.setattr(bounds, "lower_bound", lower)
    monkeypatch.setattr(bounds, "policy_gaps", gaps)
    rc, _ = _json(capsys, "bound", P12, "--set", "tau_cap=6", "--relaxation", "2", "--policy", "--compare", "",
                  "--threads", "1", "--json")
    assert rc == 0 and seen == {"relaxation": 1, "cap": 1, "resolved": 1}
    assert threads_limit() is None
