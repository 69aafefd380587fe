"""Discounted solves (issue 26): each method against the closed form of a two-state MDP, the three
methods against each other, and the Laurent expansion v_beta = g/(1-beta) + h + O(1-beta) against
the exact average-cost evaluation of the same policy."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import MDP, scenario_path
from wncs_lp.errors import SolverError
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp import solve
from wncs_lp.solvers.discounted import discounted_value, laurent_terms, run_discounted
from wncs_lp.solvers.dp import evaluate_policy

METHODS = ("pi", "vi", "lp")


def two_states(stay: float, q: float) -> MDP:
    """State 0: stay (cost ``stay``, back to 0) or go (cost 3, to state 1); state 1: cost 0, back
    to state 0 with probability q."""
    P = np.array([[1.0, 0.0], [0.0, 1.0], [q, 1.0 - q]])
    return MDP.from_arrays([0, 0, 1], [0, 1, 0], [stay, 3.0, 0.0], P, 2)


def closed_form(stay: float, q: float, beta: float) -> tuple[np.ndarray, int]:
    """(v*, the optimal pair of state 0) by hand: v(1) = beta q v(0) / (1 - beta (1 - q));
    staying gives v(0) = stay / (1 - beta), going v(0) = 3 / (1 - beta^2 q / (1 - beta + beta q))."""
    v_stay = stay / (1 - beta)
    v_go = 3.0 / (1 - beta**2 * q / (1 - beta + beta * q))
    v0 = min(v_stay, v_go)
    return np.array([v0, beta * q * v0 / (1 - beta * (1 - q))]), int(v_go < v_stay)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("beta", [0.0, 0.1, 0.5, 0.9, 0.99])
def test_two_states_against_the_closed_form(method, beta):
    stay, q = 2.0, 0.5
    v, pair0 = closed_form(stay, q, beta)
    sol = solve(two_states(stay, q), method, discount=beta)
    assert sol.status == "optimal"
    np.testing.assert_allclose(sol.value, v, rtol=1e-12)
    assert np.all(sol.lower <= v + 1e-9 * v.max()) and np.all(v <= sol.value + 1e-9 * v.max())
    assert sol.policy.tolist() == [pair0, 2]
    assert sol.sigma.tolist() == [pair0, 0]


def test_the_optimal_action_switches_with_beta():
    # by hand: staying costs 2 per step, going 3 once and then nothing for a while; a patient
    # controller (beta = 0.9) goes, an impatient one (beta = 0.1) stays
    assert closed_form(2.0, 0.5, 0.9)[1] == 1 and closed_form(2.0, 0.5, 0.1)[1] == 0
    assert solve(two_states(2.0, 0.5), discount=0.9).policy[0] == 1
    assert solve(two_states(2.0, 0.5), discount=0.1).policy[0] == 0


def test_the_value_of_a_fixed_policy_by_hand():
    # always stay in state 0: v(0) = 2 / (1 - beta); a randomised half-half mix solves a 2x2 system
    mdp, beta = two_states(2.0, 0.5), 0.8
    np.testing.assert_allclose(discounted_value(mdp, np.array([0, 2]), beta)[0], 2 / (1 - beta), rtol=1e-13)
    mix = discounted_value(mdp, np.array([0.5, 0.5, 1.0]), beta)
    A = np.eye(2) - beta * np.array([[0.5, 0.5], [0.5, 0.5]])
    np.testing.assert_allclose(mix, np.linalg.solve(A, [2.5, 0.0]), rtol=1e-13)


@pytest.fixture(scope="module")
def p12():
    mdp = build(load_scenario(scenario_path("paper_p12"), ["tau_cap=7"]))
    return mdp, solve(mdp, "pi")


@pytest.mark.parametrize("beta", [0.5, 0.99])
def test_the_three_methods_agree_on_the_paper_scenario(p12, beta):
    mdp, _ = p12
    sols = [solve(mdp, m, discount=beta) for m in METHODS]
    assert all(s.status == "optimal" for s in sols)
    for s in sols[1:]:
        np.testing.assert_allclose(s.value, sols[0].value, rtol=1e-9)


def test_the_laurent_expansion_towards_the_average_cost(p12):
    mdp, sol = p12
    ev = evaluate_policy(mdp, sol.policy)
    errs = [laurent_terms(mdp, sol.policy, b, gain=ev.gain, bias=ev.bias, stationary=ev.stationary)
            for b in (0.99, 0.999, 0.9999)]
    # both errors are O(1 - beta): a tenth of 1 - beta, a tenth of the error (within 20 %)
    for a, b in zip(errs, errs[1:]):
        assert 0.08 <= b["gain_error"] / a["gain_error"] <= 0.12
        assert 0.08 <= b["bias_error"] / a["bias_error"] <= 0.12
    assert errs[-1]["gain_error"] < 1e-3 * ev.gain


def test_discounted_optimal_is_average_optimal_near_one(p12):
    mdp, sol = p12
    d = solve(mdp, discount=0.999)
    # (1 - beta) v*_beta brackets g* up to O(1 - beta); Blackwell: the policy is average-optimal
    assert np.abs((1 - 0.999) * d.value - sol.gain).max() < 0.01 * sol.gain
    g = evaluate_policy(mdp, d.policy).gain
    assert sol.gain_lower - 1e-9 * sol.gain <= g <= sol.gain_upper + 1e-9 * sol.gain


def test_bad_input_is_one_clear_error():
    mdp = two_states(2.0, 0.5)
    with pytest.raises(SolverError, match=r"beta must be in \[0, 1\); got 1"):
        solve(mdp, discount=1)
    with pytest.raises(SolverError, match="unknown discounted method 'rvi'; expected one of pi, vi, lp"):
        run_discounted(mdp, 0.5, "rvi")  # the step takes the discounted table's own names
    # wncs_lp.solve reads the average-cost vocabulary too (rvi -> vi), and refuses a name outside both
    assert solve(mdp, "rvi", discount=0.5).method == "vi"
    with pytest.raises(SolverError, match="discounted criterion solves with lp, pi, vi .*got method 'matrix-free'"):
        solve(mdp, "matrix-free", discount=0.5)

