"""Tests of the average-cost solvers against independent references.

Every expected number comes from a computation done here (brute force over all deterministic
policies with numpy.linalg, or a hand-derived closed form), never from the solvers' output.
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from wncs_lp import solve
from wncs_lp.errors import ModelError, PolicyError, SolverError
from wncs_lp.mdp import MDP
from wncs_lp.solvers import (
    METHODS,
    bellman_step,
    bracket,
    evaluate_policy,
    policy_iteration,
    q_values,
    relative_value_iteration,
    solve_lp,
    value_iteration,
)

# ------------------------------------------------------------------------- references


def dense_gain(P_d: np.ndarray, c_d: np.ndarray) -> tuple[float, np.ndarray]:
    """Gain and stationary distribution of an irreducible chain, by numpy.linalg directly.

    Solves pi (P - I) = 0 with the last equation replaced by sum(pi) = 1.
    """
    n = P_d.shape[0]
    A = (P_d - np.eye(n)).T.copy()
    A[-1, :] = 1.0
    rhs = np.zeros(n)
    rhs[-1] = 1.0
    pi = np.linalg.solve(A, rhs)
    return float(pi @ c_d), pi


def brute_force(mdp: MDP) -> tuple[float, list[tuple[int, ...]]]:
    """Optimal gain over all deterministic stationary policies, and the optimal ones."""
    P = mdp.P.toarray()
    choices = [list(mdp.pairs_of(s)) for s in range(mdp.n_states)]
    gains = {}
    for pol in itertools.product(*choices):
        idx = np.array(pol)
        gains[pol] = dense_gain(P[idx], mdp.cost[idx])[0]
    best = min(gains.values())
    return best, [p for p, g in gains.items() if g <= best + 1e-9]


def random_mdp(seed: int) -> MDP:
    """3-6 states, 1-3 actions per state (some states with one action), dense positive P."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 7))
    m = 3
    P = rng.random((n, m, n)) + 0.05
    P /= P.sum(axis=2, keepdims=True)
    cost = rng.uniform(0.0, 10.0, size=(n, m))
    feasible = rng.random((n, m)) < 0.6
    feasible[:, 0] = True
    feasible[0, 1:] = False  # state 0 has a single action
    return MDP.from_dense(P, cost, feasible)


SEEDS = list(range(12))

# ------------------------------------------------------------------------- brute force


@pytest.mark.parametrize("seed", SEEDS)
def test_all_methods_match_brute_force(seed):
    mdp = random_mdp(seed)
    g_star, optimal = brute_force(mdp)
    P = mdp.P.toarray()
    for method in METHODS:
        sol = solve(mdp, method)
        assert sol.method == method
        assert sol.status == "optimal", (method, sol.status, sol.stats)
        assert sol.gain == pytest.approx(g_star, abs=1e-8, rel=1e-8), method
        assert sol.gain_lower - 1e-9 <= g_star <= sol.gain_upper + 1e-9, method
        assert sol.gap < 1e-6
        # the returned policy achieves g* (evaluated independently)
        g_pol, pi_pol = dense_gain(P[sol.policy], mdp.cost[sol.policy])
        assert g_pol == pytest.approx(g_star, abs=1e-9, rel=1e-9), method
        if method == "pi":  # its occupation: the stationary law of the returned policy, on its pairs
            np.testing.assert_allclose(sol.occupation[sol.policy], pi_pol, atol=1e-10)
            assert sol.occupation.sum() == pytest.approx(1.0, abs=1e-12)
        assert sol.bias[0] == 0.0
    lp = solve(mdp, "lp")
    # raw LP objective (no polishing) is accurate to roughly the solver tolerance
    assert lp.stats["lp_objective"] == pytest.approx(g_star, rel=1e-7)
    assert lp.occupation.sum() == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("method", ["auto", "iterative"])
@pytest.mark.parametrize("seed", SEEDS[:4])
def test_evaluate_policy_matches_dense(seed, method):
    """Sparse LU ("auto" on these small chains) and BiCGSTAB against numpy.linalg on the dense chain."""
    tol = 1e-12 if method == "auto" else 1e-11
    mdp = random_mdp(seed)
    P = mdp.P.toarray()
    rng = np.random.default_rng(100 + seed)
    det = np.array([rng.choice(list(mdp.pairs_of(s))) for s in range(mdp.n_states)], dtype=np.int64)
    g_ref, pi_ref = dense_gain(P[det], mdp.cost[det])
    ev = evaluate_policy(mdp, det, method=method)
    assert ev.solver == ("splu" if method == "auto" else "bicgstab")
    assert ev.gain == pytest.approx(g_ref, abs=tol, rel=tol)
    np.testing.assert_allclose(ev.stationary, pi_ref, atol=tol)
    assert ev.bias[0] == 0.0
    # Poisson equation g + h = c + P h
    np.testing.assert_allclose(ev.gain + ev.bias, mdp.cost[det] + P[det] @ ev.bias, atol=100 * tol)
    bare = evaluate_policy(mdp, det, method=method, stationary=False)  # the Poisson solve alone
    assert bare.stationary is None and bare.gain == pytest.approx(g_ref, abs=tol, rel=tol)
    np.testing.assert_allclose(bare.gain + bare.bias, mdp.cost[det] + P[det] @ bare.bias, atol=100 * tol)
    if method == "iterative":  # a warm start from another policy's bias gives the same answer
        other = evaluate_policy(mdp, mdp.pair_ptr[:-1].astype(np.int64), method="direct")
        assert evaluate_policy(mdp, det, method=method, h0=other.bias).gain == pytest.approx(g_ref, rel=tol)

    # randomised: mixture weights per pair
    w = rng.random(mdp.n_pairs)
    w /= np.add.reduceat(w, mdp.pair_ptr[:-1])[mdp.s_indices]
    P_mix = np.zeros((mdp.n_states, mdp.n_states))
    c_mix = np.zeros(mdp.n_states)
    for l in range(mdp.n_pairs):
        P_mix[mdp.s_indices[l]] += w[l] * P[l]
        c_mix[mdp.s_indices[l]] += w[l] * mdp.cost[l]
    g_mix, pi_mix = dense_gain(P_mix, c_mix)
    ev = evaluate_policy(mdp, w, method=method)
    assert ev.gain == pytest.approx(g_mix, abs=tol, rel=tol)
    np.testing.assert_allclose(ev.stationary, pi_mix, atol=tol)


def test_iterative_evaluation_falls_back_to_lu():
    """An iteration cap too small to converge: the sparse LU answers, and says so."""
    mdp = random_mdp(SEEDS[0])
    det = mdp.pair_ptr[:-1].astype(np.int64)
    ev = evaluate_policy(mdp, det, method="iterative", maxiter=1)
    assert ev.solver == "bicgstab->splu"
    ref = evaluate_policy(mdp, det, method="direct")
    assert ref.solver == "splu" and ev.gain == ref.gain
    with pytest.raises(SolverError, match="unknown evaluation method 'lu'"):
        evaluate_policy(mdp, det, method="lu")


# ------------------------------------------------------------------------- closed form


def machine_replacement(p=0.2, q=0.5, R=1.0, K=3.0, b=1.0) -> MDP:
    """State 0 = working (cost 0, breaks w.p. p); state 1 = broken (cost b per slot plus
    repair R: fixed w.p. q; or replace K: fixed w.p. 1)."""
    s = [0, 1, 1]
    a = [0, 0, 1]
    c = [0.0, b + R, b + K]
    P = [[1 - p, p], [q, 1 - q], [1.0, 0.0]]
    return MDP.from_arrays(s, a, c, P)


def test_two_state_closed_form():
    p, q, R, K, b = 0.2, 0.5, 1.0, 3.0, 1.0
    # hand computation: pi_1 = p/(p+q) under "repair", p/(p+1) under "replace"
    g_repair = p / (p + q) * (b + R)  # = 4/7
    g_replace = p / (p + 1) * (b + K)  # = 2/3
    assert g_repair < g_replace
    # bias with h(0) = 0: g + h(0) = (1-p) h(0) + p h(1)  =>  h(1) = g / p = 20/7
    h1 = g_repair / p
    mdp = machine_replacement(p, q, R, K, b)
    for method in METHODS:
        sol = solve(mdp, method)
        assert sol.status == "optimal"
        assert sol.gain == pytest.approx(4.0 / 7.0, abs=1e-9)
        assert sol.policy.tolist() == [0, 1]  # repair
        np.testing.assert_allclose(sol.bias, [0.0, 20.0 / 7.0], atol=1e-7)
    assert h1 == pytest.approx(20.0 / 7.0)
    lo, hi = bracket(mdp, np.array([0.0, 20.0 / 7.0]))
    assert lo == pytest.approx(4.0 / 7.0, abs=1e-14) and hi == pytest.approx(4.0 / 7.0, abs=1e-14)


# ------------------------------------------------------------------------- operator details


def test_bellman_step_ties_go_to_first_pair():
    # state 0 has three pairs with equal Q, state 1 two with equal Q
    s = [0, 0, 0, 1, 1]
    a = [0, 1, 2, 0, 1]
    c = [1.0, 1.0, 1.0, 2.0, 2.0]
    P = [[0.5, 0.5]] * 5
    mdp = MDP.from_arrays(s, a, c, P)
    Th, greedy = bellman_step(mdp, np.zeros(2))
    assert Th.tolist() == [1.0, 2.0]
    assert greedy.tolist() == [0, 3]
    # strictly better later pair wins
    mdp2 = MDP.from_arrays(s, a, [1.0, 1.0, 0.5, 2.0, 2.0], P)
    assert bellman_step(mdp2, np.zeros(2))[1].tolist() == [2, 3]
    assert q_values(mdp, np.array([0.0, 2.0])).tolist() == [2.0, 2.0, 2.0, 3.0, 3.0]


# ------------------------------------------------------------------------- periodic chain


def two_cycle() -> MDP:
    """Deterministic 2-cycle 0 -> 1 -> 0 with costs 1 and 0: g* = 1/2 (by hand)."""
    return MDP.from_arrays([0, 1], [0, 0], [1.0, 0.0], [[0.0, 1.0], [1.0, 0.0]])


def test_periodic_chain_needs_aperiodicity_transform():
    mdp = two_cycle()
    plain = relative_value_iteration(mdp, aperiodicity=1.0, max_iter=200)
    assert plain.status == "max_iter"  # span of T h - h stays 1: plain VI oscillates
    assert plain.gain_upper - plain.gain_lower == pytest.approx(1.0)
    sol = relative_value_iteration(mdp, aperiodicity=0.5)
    assert sol.status == "optimal"
    assert sol.gain == pytest.approx(0.5, abs=1e-10)
    # h(1) - h(0) from g + h(0) = 1 + h(1)  =>  h(1) = -1/2
    np.testing.assert_allclose(sol.bias, [0.0, -0.5], atol=1e-9)
    for method in ("lp", "lp-cvxpy", "pi"):
        assert solve(mdp, method).gain == pytest.approx(0.5, abs=1e-9)


def test_rvi_warm_start_and_max_iter_status():
    mdp = random_mdp(3)
    g_star, _ = brute_force(mdp)
    cold = relative_value_iteration(mdp)
    warm = relative_value_iteration(mdp, h0=cold.bias)
    assert warm.status == "optimal" and warm.iterations <= 2
    assert warm.gain == pytest.approx(g_star, abs=1e-8)
    short = relative_value_iteration(mdp, max_iter=2)
    assert short.status == "max_iter" and not short.ok
    assert short.gain_lower <= g_star + 1e-12 <= short.gain_upper + 2e-12


# ------------------------------------------------------------------------- multichain


def two_closed_classes():
    """States 0 and 1 absorbing with costs 1 and 5, state 2 (cost 3) splits between them: the
    optimal gain is 1 from state 0 and 5 from state 1 (by hand), so no single gain exists."""
    return MDP.from_arrays([0, 1, 2], [0, 0, 0], [1.0, 5.0, 3.0], [[1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]])


@pytest.mark.parametrize("method", ["vi", "rvi", "pi"])
def test_a_start_dependent_gain_is_said_so(method):
    sol = solve(two_closed_classes(), method)
    assert sol.status == "inaccurate:start_dependent" and sol.status_code == "inaccurate" and not sol.ok
    assert sol.gain_lower <= 1.0 and 5.0 <= sol.gain_upper  # every start's gain is inside
    assert "depends on the start state" in sol.message and "several closed classes" in sol.message
    assert "max_iter" not in sol.message
    assert "depends on the start state" in sol.stats["stop"]
    if method != "pi":
        assert sol.iterations < 1_000  # stopped when the bracket settled, not by the budget (100,000)


def test_a_slowly_converging_unichain_mdp_is_not_called_start_dependent():
    # two near-absorbing states that leak into each other with probability 1e-3: one class, g* = 3
    # (by symmetry the stationary law is uniform over states 0 and 1)
    eps = 1e-3
    mdp = MDP.from_arrays([0, 1], [0, 0], [1.0, 5.0], [[1 - eps, eps], [eps, 1 - eps]])
    for method in ("vi", "rvi"):
        sol = solve(mdp, method, max_iter=200_000)
        assert sol.status == "optimal" and sol.gain == pytest.approx(3.0, rel=1e-8), sol.stats


def test_values_that_overflow_are_an_error_not_an_optimal_inf():
    P = np.array([[[0.5, 0.5], [0.2, 0.8]], [[0.9, 0.1], [0.3, 0.7]]])
    cost = 1.7e308 * np.array([[1.0, 0.5], [0.6, 1.0]])
    with pytest.raises(ModelError, match=r"cost of pair 0 \(state 0\) is 1.7e\+308"):
        MDP.from_dense(P, cost)  # the validated constructor refuses such costs at the source
    mdp = MDP.from_dense(P, cost, check=False)  # an unchecked MDP still never iterates on inf
    for fn in (value_iteration, relative_value_iteration):
        with pytest.raises(SolverError, match=r"values overflow .* the costs \(max \|c\| = 1.7e\+308\)"):
            fn(mdp)


@pytest.mark.parametrize("bad", [dict(tol=-1.0), dict(tol=float("nan")), dict(tol=0.0), dict(tol=float("inf")),
                                 dict(atol=float("nan")), dict(max_iter=0), dict(check_every=0),
                                 dict(stall_checks=0), dict(eval_sweeps=-1)])
def test_value_iteration_options_out_of_range(bad):
    (field, _), = bad.items()
    mdp = random_mdp(0)
    with pytest.raises(SolverError, match=field):
        value_iteration(mdp, **bad)
    if field in ("tol", "atol", "max_iter"):
        with pytest.raises(SolverError, match=field):
            relative_value_iteration(mdp, **bad)



def test_evaluate_policy_rejects_multichain():
    # states 0 and 1 absorbing, state 2 splits between them
    mdp = MDP.from_arrays([0, 1, 2], [0, 0, 0], [1.0, 2.0, 0.0], [[1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]])
    with pytest.raises(PolicyError, match="2 recurrent classes") as exc:
        evaluate_policy(mdp, np.array([0, 1, 2]))
    assert "state 0" in str(exc.value) and "state 1" in str(exc.value)


def test_evaluate_policy_rejects_bad_policies():
    mdp = machine_replacement()
    with pytest.raises(PolicyError, match="belongs to state"):
        evaluate_policy(mdp, np.array([1, 2]))
    with pytest.raises(PolicyError, match="sum to"):
        evaluate_policy(mdp, np.array([1.0, 0.5, 0.6]))
    with pytest.raises(PolicyError):
        evaluate_policy(mdp, np.array([0, 1, 2]))


def test_lp_polish_handles_transient_states():
    """Weakly communicating MDP: optimal g* = 0.5 (stay in state 1); stay-stay is multichain.

    0: stay (cost 1) | go to 1 (cost 5);  1: stay (0.5) | go to 0 (5);  2: to 0 (0) | to 1 (3).
    By hand: h(1) = h(0) - 4.5 from g + h(0) = 5 + h(1) in state 0, and h(2) = 3 + h(1) - g = -2.
    """
    P = np.zeros((6, 3))
    P[[0, 1, 2, 3, 4, 5], [0, 1, 1, 0, 0, 1]] = 1.0
    mdp = MDP.from_arrays([0, 0, 1, 1, 2, 2], [0, 1, 0, 1, 0, 1], [1, 5, 0.5, 5, 0, 3], P)
    for method in ("lp", "lp-cvxpy", "rvi"):
        sol = solve(mdp, method)
        assert sol.status == "optimal", (method, sol.status)
        assert sol.gain == pytest.approx(0.5, abs=1e-9)
        np.testing.assert_allclose(sol.bias, [0.0, -4.5, -2.0], atol=1e-7)
    # unpolished: the dual keeps slack in the transient state 0, so the bracket stays open
    raw = solve_lp(mdp, polish=False)
    assert raw.gain_lower <= 0.5 + 1e-8 <= raw.gain_upper + 2e-8
    assert (raw.status == "optimal") == (raw.gap < 1e-6)


# ------------------------------------------------------------------------- LP duals


@pytest.mark.parametrize("backend", ["clarabel", "cvxpy"])
@pytest.mark.parametrize("seed", SEEDS[:6])
def test_lp_dual_bias_complementary_slackness(seed, backend):
    mdp = random_mdp(seed)
    g_star, _ = brute_force(mdp)
    sol = solve_lp(mdp, backend=backend, polish=False)
    h = sol.bias
    g = sol.stats["lp_dual_gain"]
    assert g == pytest.approx(g_star, rel=1e-7)
    assert sol.gain == pytest.approx(g_star, rel=1e-7)  # unpolished gain = LP objective
    slack = mdp.cost + mdp.P.toarray() @ h - g - h[mdp.s_indices]  # c + P h - g - h(s) >= 0
    scale = 1.0 + np.abs(mdp.cost).max()
    assert slack.min() >= -1e-7 * scale
    support = sol.occupation > 1e-4
    assert support.any()
    assert np.abs(slack[support]).max() <= 1e-6 * scale
    assert sol.gain_lower - 1e-9 <= g_star <= sol.gain_upper + 1e-9
    assert sol.status == "optimal"


# ------------------------------------------------------------------------- failures


def test_unknown_method():
    with pytest.raises(SolverError, match="'lp'.*'rvi'"):
        solve(machine_replacement(), "simplex")
    with pytest.raises(ValueError):
        solve(machine_replacement(), "simplex")
    with pytest.raises(SolverError):
        solve_lp(machine_replacement(), backend="gurobi")


@pytest.mark.parametrize("backend, native", [("clarabel", "MaxIterations"), ("cvxpy", "user_limit")])
def test_unsolved_status_is_reported(backend, native):
    # one interior-point iteration: the backend's own iteration-limit status, by its own table, is
    # MAX_ITER with the native word as the reason (no longer "inaccurate" in Clarabel's words)
    mdp = random_mdp(5)
    sol = solve_lp(mdp, backend=backend, max_iter=1)
    assert sol.status != "optimal"
    assert sol.stats["solver_status"] == native
    assert sol.status == f"max_iter:{native}"
    assert sol.status_code == "max_iter" and sol.status_reason == native
    assert not sol.ok and native in sol.message


def test_policy_iteration_from_bad_start_and_stats():
    mdp = random_mdp(7)
    g_star, optimal = brute_force(mdp)
    worst = np.array([mdp.pair_ptr[s + 1] - 1 for s in range(mdp.n_states)])
    sol = policy_iteration(mdp, policy0=worst)
    assert sol.status == "optimal"
    assert sol.gain == pytest.approx(g_star, abs=1e-10)
    assert tuple(sol.policy.tolist()) in optimal
    assert sol.occupation.sum() == pytest.approx(1.0)
    summary = sol.summary()
    assert summary["method"] == "pi" and "changes" not in summary


def test_evaluate_policy_checks_h0_on_every_path():
    """A bad warm start is an error whichever solver runs, not silently ignored."""
    mdp = random_mdp(SEEDS[0])
    det = mdp.pair_ptr[:-1].astype(np.int64)
    for method in ("auto", "direct", "iterative"):
        for bad in (np.zeros(mdp.n_states + 1), np.full(mdp.n_states, np.nan), "abc"):
            with pytest.raises(SolverError, match="h0 must be a finite array"):
                evaluate_policy(mdp, det, method=method, h0=bad)
