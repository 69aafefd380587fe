"""Results in a notebook (issue 26): a short printout, an HTML form, ``to_frame()`` state by state,
and one clear error when pandas is missing; the one certificate value every result shares
(issue 23 §3)."""
from __future__ import annotations

import math
import sys
import warnings
from dataclasses import replace

import numpy as np
import pytest

import wncs_lp
from wncs_lp.display import PANDAS_HINT
from wncs_lp.errors import WncsError
from wncs_lp.solvers.dp import evaluate_policy
from wncs_lp.solvers.result import NO_CERTIFICATE, Certificate, Solution


@pytest.fixture(scope="module")
def small():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    return sc, mdp, wncs_lp.solve(mdp, "pi")


# --------------------------------------------------------------------------- the certificate
def test_certificate_value():
    c = Certificate(1.0, 3.0)
    assert (c.width, c.midpoint, c.gap) == (2.0, 2.0, 1.0)
    assert c.contains(1.0) and c.contains(3.0) and not c.contains(3.1) and c.contains(3.1, rtol=0.05)
    assert Certificate(1.0, 1.0 + 1e-10).closed(1e-9) and not c.closed(0.5) and c.closed(0.0, atol=2.0)
    assert str(c) == "1 <= g <= 3" and str(Certificate(2.5)) == "2.5 <= g"  # one-sided: a lower bound
    assert Certificate(2.5).upper == math.inf
    assert math.isnan(NO_CERTIFICATE.width)
    with pytest.raises(TypeError, match="real number"):
        Certificate("1", 2.0)
    with pytest.raises(AttributeError):
        c.lower = 0.0


def test_solution_holds_one_certificate_and_is_still_made_with_its_ends(small):
    _, mdp, sol = small
    assert isinstance(sol.certificate, Certificate)
    assert (sol.gain_lower, sol.gain_upper) == (sol.certificate.lower, sol.certificate.upper)
    assert sol.gap == pytest.approx(sol.certificate.width / abs(sol.gain))
    moved = replace(sol, gain_lower=sol.gain_lower - 1.0)  # one end moves, the other stays
    assert moved.gain_lower == sol.gain_lower - 1.0 and moved.gain_upper == sol.gain_upper
    made = Solution(method="x", status="optimal", gain=1.0, gain_lower=0.5, gain_upper=1.5, bias=np.zeros(2),
                    policy=np.zeros(2, np.int64))
    assert made.certificate == Certificate(0.5, 1.5)
    with pytest.raises(TypeError, match="both gain_lower and gain_upper"):
        Solution(method="x", status="optimal", gain=1.0, gain_lower=0.5, bias=np.zeros(2), policy=np.zeros(2))


def test_policy_evaluation_certificate_holds_the_exact_gain(small):
    _, mdp, sol = small
    # an independent gain: the stationary law of the policy's chain (balance rows with one replaced by
    # the normalisation), not the Poisson equation the evaluation solves
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    n = mdp.n_states
    A = (mdp.P[sol.policy].T - sp.identity(n)).tolil()
    A[n - 1, :] = np.ones(n)
    rhs = np.zeros(n)
    rhs[-1] = 1.0
    pi = spsolve(A.tocsc(), rhs)
    g = float(pi @ mdp.cost[sol.policy])
    ev = evaluate_policy(mdp, sol.policy)
    assert ev.certificate.contains(g, rtol=1e-12) and ev.ok and ev.status == "optimal"
    assert ev.summary()["gain_lower"] <= g + 1e-9 * g
    text = repr(ev)
    assert text.startswith(f"PolicyEvaluation of {n:,} states") and "residual:" in text and "array(" not in text


# --------------------------------------------------------------------------- printout and HTML
def test_repr_is_short_and_html_is_an_escaped_table(small):
    _, mdp, sol = small
    text = repr(sol)
    assert text == str(sol) and text.startswith(f"Solution of {mdp.n_states:,} states by pi")
    assert len(text) < 1500 and "array(" not in text
    for name in ("status", "message", "gain", "gain_lower", "gain_upper", "gap", "bias", "policy", "sigma"):
        assert any(line.strip().startswith(f"{name}:") for line in text.splitlines()), name
    html = sol._repr_html_()
    assert html.startswith('<div class="wncs-lp-result">') and html.count("<table>") == 2
    assert "&lt;= g* &lt;=" in html and "<= g*" not in html  # the message's text is escaped
    assert f"{mdp.n_states:,} rows" in html and "more rows" in html  # a preview of to_frame(), not every state
    assert len(html) < 5000
    bad = replace(sol, status="inaccurate:<script>")
    assert "<script>" not in bad._repr_html_() and "&lt;script&gt;" in bad._repr_html_()


# --------------------------------------------------------------------------- tables
def test_to_frame_with_the_mdp_decodes_states_and_names_actions(small):
    sc, mdp, sol = small
    df = sol.to_frame(mdp)
    assert list(df.columns) == ["state", "tau_1", "tau_2", "configuration", "action", "sigma", "bias"]
    assert len(df) == mdp.n_states
    np.testing.assert_array_equal(df["state"], np.arange(mdp.n_states))
    np.testing.assert_array_equal(df[["tau_1", "tau_2"]].to_numpy(), mdp.states.tau)
    np.testing.assert_array_equal(df["sigma"], mdp.a_indices[sol.policy])
    np.testing.assert_allclose(df["bias"], sol.bias)
    # the action's name, rebuilt from the action table (row m: the process sent to server m, 0 none)
    servers = [s.name for s in sc.servers]
    for s in range(0, mdp.n_states, 7):
        row = mdp.action_table[df["sigma"][s]]
        sent = [f"{int(k)} to {servers[m]}" for m, k in enumerate(row) if k > 0]
        assert df["action"][s] == "(" + (", ".join(sent) if sent else "send nothing") + ")", s


def test_to_frame_without_the_mdp_and_of_an_evaluation(small):
    _, mdp, sol = small
    df = sol.to_frame()
    assert list(df.columns) == ["state", "pair", "sigma", "bias"]
    np.testing.assert_array_equal(df["pair"], sol.policy)
    ev = evaluate_policy(mdp, sol.policy).to_frame()
    assert list(ev.columns) == ["state", "bias", "stationary"] and ev["stationary"].sum() == pytest.approx(1.0)
    with pytest.raises(WncsError, match="not this MDP's solution"):
        Solution(method="x", status="optimal", gain=1.0, gain_lower=1.0, gain_upper=1.0, bias=np.zeros(3),
                 policy=np.zeros(3, np.int64)).to_frame(mdp)


def test_to_frame_without_pandas_is_one_clear_error(small, monkeypatch):
    _, mdp, sol = small
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    with pytest.raises(WncsError, match="needs pandas") as exc:
        sol.to_frame(mdp)
    assert PANDAS_HINT in str(exc.value)
    assert sol._repr_html_().startswith("<div")  # the HTML form does not need pandas


def test_a_constrained_solution_is_certified_and_shows_its_mix():
    from wncs_lp import solve

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=6"])
    mdp = wncs_lp.build(sc)
    sol = solve(mdp, "lp", constraints=sc.constraints)
    assert isinstance(sol.certificate, Certificate) and sol.ok and sol.success
    assert sol.certificate.contains(sol.gain, rtol=1e-12)
    text = repr(sol)
    assert text.startswith("ConstrainedSolution of") and len(text) < 2000 and "array(" not in text
    assert sum(line.strip().startswith("constraint:") for line in text.splitlines()) == len(sc.constraints)
    assert "<table>" in sol._repr_html_()  # without the MDP: the rows alone
    df = sol.to_frame(mdp)
    assert list(df.columns)[-3:] == ["action", "sigma", "probability"]
    # every state appears, its probabilities sum to one, and each row is a pair the policy plays
    sums = df.groupby("state")["probability"].sum()
    assert len(sums) == mdp.n_states and np.allclose(sums, 1.0)
    assert (df.groupby("state").size() > 1).sum() == sol.n_randomized
    with pytest.raises(WncsError, match="needs its MDP"):
        sol.to_frame()
