"""QuantEcon's ``DiscreteDP`` and pymdptoolbox's ``(P, R)`` (:mod:`wncs_lp.io.toolkits`), each solved by
that package's own solver and checked against independent references: a direct linear solve of
the discounted equations and one Bellman step (numpy), the average-cost optimum the toolkit
certifies (through the exact inequality linking the discounted value to the gain and bias), and
the other package."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import wncs_lp
from wncs_lp.io import InteropError, from_mdptoolbox_policy, to_mdptoolbox, to_quantecon
from wncs_lp.mdp import MDP
from wncs_lp.solvers.dp import evaluate_policy

# pymdptoolbox 4.0b3 compares sparse matrices with 0 in its input check (scipy warns; harmless)
pytestmark = pytest.mark.filterwarnings("ignore::scipy.sparse.SparseEfficiencyWarning")

P12 = str(wncs_lp.scenario_path("paper_p12"))
PRE = str(wncs_lp.scenario_path("paper_preemption_p12"))


@pytest.fixture(scope="module", params=[P12, PRE], ids=["wncs", "preemption"])
def solved(request):
    """A small MDP of each model kind (cap 7) and its certified average-cost optimum."""
    mdp = wncs_lp.build(wncs_lp.load_scenario(request.param, ["tau_cap=7"]))
    sol = wncs_lp.solve(mdp, "pi")
    assert sol.status == "optimal"
    return mdp, sol


def _pairs_of_sigma(mdp: MDP, sigma: np.ndarray) -> np.ndarray:
    """The pair of (s, sigma[s]) in every state, by a plain search of the pair arrays."""
    pairs = np.empty(mdp.n_states, dtype=np.int64)
    for s in range(mdp.n_states):
        lo, hi = mdp.pair_ptr[s], mdp.pair_ptr[s + 1]
        (k,) = np.flatnonzero(mdp.a_indices[lo:hi] == sigma[s])
        pairs[s] = lo + k
    return pairs


def _discounted_value(mdp: MDP, pairs: np.ndarray, beta: float) -> np.ndarray:
    """The discounted cost of a deterministic policy: (I - beta P_pi) V = c_pi, solved directly."""
    P_pi = mdp.P.tocsr()[pairs]
    A = sp.identity(mdp.n_states, format="csc") - beta * P_pi.tocsc()
    return spla.spsolve(A, np.asarray(mdp.cost)[pairs])


def _bellman(mdp: MDP, V: np.ndarray, beta: float) -> np.ndarray:
    """One discounted Bellman step on costs: min over the pairs of each state of c + beta P V."""
    return np.minimum.reduceat(np.asarray(mdp.cost) + beta * (mdp.P @ V), mdp.pair_ptr[:-1])


@pytest.mark.parametrize("beta", [0.9, 0.99])
def test_quantecon_solves_the_discounted_problem(solved, beta):
    mdp, sol = solved
    ddp = to_quantecon(mdp, beta)
    assert ddp.num_states == mdp.n_states and ddp.num_sa_pairs == mdp.n_pairs
    res = ddp.solve(method="policy_iteration")
    V = -np.asarray(res.v)  # QuantEcon maximises r = -c
    # (1) its value is the value of its own policy, by a direct linear solve
    V_pi = _discounted_value(mdp, _pairs_of_sigma(mdp, np.asarray(res.sigma)), beta)
    np.testing.assert_allclose(V, V_pi, rtol=1e-10)
    # (2) and it is optimal: one Bellman step leaves it in place
    np.testing.assert_allclose(_bellman(mdp, V_pi, beta), V_pi, rtol=1e-10)
    # (3) the toolkit's certified average-cost optimum (g*, h) bounds it, from the optimality equation:
    #     V(s) - g*/(1 - beta) - h(s) lies in [-max h, -min h] for every beta
    h, g_lo, g_hi = np.asarray(sol.bias), sol.gain_lower, sol.gain_upper
    slack = (g_hi - g_lo) / (1 - beta) + 1e-7 * np.abs(V).max()
    assert np.all(V - g_hi / (1 - beta) - h <= -h.min() + slack)
    assert np.all(V - g_lo / (1 - beta) - h >= -h.max() - slack)


def test_pymdptoolbox_relative_value_iteration_finds_our_gain(solved):
    import mdptoolbox.mdp as mt

    mdp, sol = solved
    P, R = to_mdptoolbox(mdp)
    assert len(P) == len(mdp.action_table) and R.shape == (mdp.n_states, len(mdp.action_table))
    eps = 1e-9 * abs(sol.gain)
    rvi = mt.RelativeValueIteration(P, R, epsilon=eps, max_iter=50_000)
    rvi.run()
    assert rvi.iter < 50_000
    g = -rvi.average_reward  # the bracket's upper end (rewards are minus costs)
    assert sol.gain_lower - 1e-9 * abs(sol.gain) <= g <= sol.gain_upper + eps
    # its policy, mapped back to our pairs and evaluated exactly, is optimal
    pairs = from_mdptoolbox_policy(mdp, np.asarray(rvi.policy))
    assert np.array_equal(mdp.s_indices[pairs], np.arange(mdp.n_states))
    assert evaluate_policy(mdp, pairs).gain == pytest.approx(sol.gain, rel=1e-8)


def test_the_padding_changes_nothing(solved):
    """The padded MDP (every action in every state, a padded one repeating the state's first
    pair), solved by the toolkit, has the original's certified gain and discounted values."""
    mdp, sol = solved
    P, R = to_mdptoolbox(mdp)
    n, A = R.shape
    padded = MDP.from_arrays(np.repeat(np.arange(n), A), np.tile(np.arange(A), n), -R.ravel(),
                             sp.vstack([P[a][s] for s in range(n) for a in range(A)]).tocsr(), n)
    assert padded.n_pairs == n * A > mdp.n_pairs
    sol_padded = wncs_lp.solve(padded, "pi")
    assert sol_padded.gain == pytest.approx(sol.gain, rel=1e-12)
    v = to_quantecon(mdp, 0.95).solve(method="policy_iteration").v
    np.testing.assert_allclose(to_quantecon(padded, 0.95).solve(method="policy_iteration").v, v, rtol=1e-12)


def test_the_two_toolkits_agree_on_the_discounted_value(solved):
    import mdptoolbox.mdp as mt

    mdp, _ = solved
    P, R = to_mdptoolbox(mdp)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pi = mt.PolicyIteration(P, R, 0.95)
        pi.run()
    v = to_quantecon(mdp, 0.95).solve(method="policy_iteration").v
    np.testing.assert_allclose(np.asarray(pi.V), v, rtol=1e-9)


def test_bad_inputs_are_one_clear_error(solved):
    mdp, _ = solved
    for beta in (1.0, -0.1, "0.9", float("nan")):
        with pytest.raises(InteropError, match="beta must be a number in \\[0, 1\\)"):
            to_quantecon(mdp, beta)
    with pytest.raises(InteropError, match="expected a wncs_lp MDP"):
        to_mdptoolbox(np.eye(3))
    with pytest.raises(InteropError, match="one action index in 0..\\d+ per state"):
        from_mdptoolbox_policy(mdp, np.zeros(3, dtype=int))
    with pytest.raises(InteropError, match="one action index"):
        from_mdptoolbox_policy(mdp, np.full(mdp.n_states, 99))


def test_a_missing_package_is_one_clear_import_error(solved, monkeypatch):
    """Without QuantEcon (its import blocked), to_quantecon says what it needs and how to install it."""
    import sys

    mdp, _ = solved
    monkeypatch.setitem(sys.modules, "quantecon.markov", None)  # import of it raises ImportError
    with pytest.raises(ImportError, match=r"to_quantecon needs the optional package 'quantecon'.*"
                                          r"pip install 'wncs_lp\[interop\]'"):
        to_quantecon(mdp, 0.9)
