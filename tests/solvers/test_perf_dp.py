"""Fused DP kernels (numba and scipy agree), certified value iteration / MPI, PI on a multichain
iterate, and ``method="auto"``. No wall-clock assertions: speed lives in ``benchmarks/``."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp.solvers import bracket, policy_iteration, relative_value_iteration, value_iteration
from wncs_lp import solve
from wncs_lp.solvers import kernels
from wncs_lp.solvers.kernels import ScipyKernel, get_kernel, numba_available, prepare

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba not installed (the 'fast'/'test' extra)")

#: spec section 5 reference gain, processes 1, 2 on remote + edge, cap 12
P12_GAIN = 749.834326444


def random_mdp(seed: int, n: int = 40, max_actions: int = 3, per_pair_cost: bool = True) -> MDP:
    rng = np.random.default_rng(seed)
    s_idx, a_idx, rows, cost = [], [], [], []
    for s in range(n):
        for a in range(int(rng.integers(1, max_actions + 1))):
            row = np.zeros(n)
            k = int(rng.integers(1, 5))
            row[rng.choice(n, size=k, replace=False)] = rng.random(k) + 0.1
            row[(s + 1) % n] += 0.05  # irreducible under every policy
            rows.append(row / row.sum())
            s_idx.append(s)
            a_idx.append(a)
            cost.append(rng.random() * 10 if per_pair_cost else float(s % 7))
    return MDP.from_arrays(s_idx, a_idx, cost, np.array(rows), n)


@pytest.fixture(scope="module")
def p12():
    return build(load_scenario(scenario_path("paper_p12.toml")))


# ------------------------------------------------------------------------ kernels
def test_prepare_is_exact_and_compact(p12):
    d = prepare(p12)
    np.testing.assert_array_equal(d.table[d.codes], p12.P.data)  # codes reproduce the doubles exactly
    assert d.codes.dtype == np.uint8
    assert d.cost_per_state and d.cost.shape == (p12.n_states,)
    assert d.bytes_per_sweep < d.bytes_per_sweep_plain
    assert prepare(p12) is d  # cached per MDP
    m = random_mdp(0)
    assert not prepare(m).cost_per_state


@needs_numba
@pytest.mark.parametrize("seed, per_pair", [(1, True), (2, False), (3, True)])
def test_numba_and_scipy_jacobi_sweeps_agree(seed, per_pair):
    mdp = random_mdp(seed, per_pair_cost=per_pair)
    rng = np.random.default_rng(seed)
    h = rng.normal(size=mdp.n_states) * 5
    out_n, out_s = np.empty_like(h), np.empty_like(h)
    lo_s, hi_s = get_kernel(mdp, "scipy").jacobi(h, out_s, 0.7, 0.3)
    for threads in (1, 2):  # the serial and the parallel (prange) sweep
        lo_n, hi_n = get_kernel(mdp, "numba", threads=threads).jacobi(h, out_n, 0.7, 0.3)
        np.testing.assert_allclose(out_n, out_s, rtol=1e-13, atol=1e-12)
        assert lo_n == pytest.approx(lo_s, abs=1e-12) and hi_n == pytest.approx(hi_s, abs=1e-12)
    assert (lo_s, hi_s) == pytest.approx(bracket(mdp, h), abs=1e-12)


@pytest.mark.parametrize("max_actions", [1, 3, kernels.LATER_PAIRS_MAX + 4])  # one pair; the later-pair minimum; reduceat
def test_scipy_jacobi_sweep_matches_a_python_reference(max_actions):
    mdp = random_mdp(5, n=60, max_actions=max_actions)
    assert (np.diff(mdp.pair_ptr).max() > kernels.LATER_PAIRS_MAX) == (max_actions > kernels.LATER_PAIRS_MAX)
    h = np.random.default_rng(5).normal(size=mdp.n_states) * 5
    K = ScipyKernel(mdp)
    d = np.array([min(mdp.cost[l] + float((mdp.P[l] @ h)[0]) for l in mdp.pairs_of(s)) - h[s]
                  for s in range(mdp.n_states)])
    for _ in range(2):  # the buffers reused by the next sweep
        out = np.full_like(h, np.nan)
        lo, hi = K.jacobi(h, out, 0.7, 0.3)
        np.testing.assert_allclose(out, h + 0.7 * (d - 0.3), rtol=1e-13, atol=1e-12)
        assert lo == pytest.approx(d.min(), abs=1e-12) and hi == pytest.approx(d.max(), abs=1e-12)


@needs_numba
def test_numba_in_place_sweeps_match_a_python_reference():
    mdp = random_mdp(4)
    rng = np.random.default_rng(4)
    h = rng.normal(size=mdp.n_states)
    K = get_kernel(mdp, "numba")
    # Gauss-Seidel: states in order, in place, first minimiser recorded
    ref, ref_pol = h.copy(), np.zeros(mdp.n_states, np.int64)
    for s in range(mdp.n_states):
        pairs = list(mdp.pairs_of(s))
        q = [mdp.cost[l] + float((mdp.P[l] @ ref)[0]) for l in pairs]
        j = int(np.argmin(q))
        ref_pol[s] = pairs[j]
        ref[s] += 0.8 * (q[j] - ref[s] - 0.1)
    got, pol = h.copy(), np.zeros(mdp.n_states, np.int64)
    K.gauss_seidel(got, 0.8, 0.1, pol)
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-13)
    np.testing.assert_array_equal(pol, ref_pol)
    # fixed-policy sweep
    ref2 = got.copy()
    for s in range(mdp.n_states):
        l = pol[s]
        ref2[s] += 0.5 * (mdp.cost[l] + float((mdp.P[l] @ ref2)[0]) - ref2[s])
    K.evaluate(got, 0.5, 0.0, pol)
    np.testing.assert_allclose(got, ref2, rtol=1e-13, atol=1e-13)


def test_scipy_fallback_when_numba_is_missing(monkeypatch, p12):
    monkeypatch.setattr(kernels, "_NUMBA", False)
    assert not numba_available()
    assert isinstance(get_kernel(p12, "auto"), ScipyKernel)
    with pytest.raises(ValueError, match="numba"):
        get_kernel(p12, "numba")
    sol = value_iteration(p12)  # "auto" scheme -> Jacobi on scipy
    assert sol.ok and sol.stats["kernel"] == "scipy" and sol.stats["scheme"] == "jacobi"
    assert sol.gain_lower <= P12_GAIN + 1e-6 and P12_GAIN - 1e-6 <= sol.gain_upper
    with pytest.raises(ValueError, match="unknown kernel"):
        get_kernel(p12, "cuda")


# ------------------------------------------------------------------------ solvers
@pytest.mark.parametrize("kernel", ["scipy", pytest.param("numba", marks=needs_numba)])
def test_rvi_same_iterations_with_either_kernel(p12, kernel):
    sol = relative_value_iteration(p12, kernel=kernel)
    ref = relative_value_iteration(p12, kernel="scipy")
    assert sol.ok and sol.iterations == ref.iterations
    assert sol.gain == pytest.approx(ref.gain, rel=1e-12)
    assert sol.stats["kernel"] == kernel


@pytest.mark.parametrize(
    "kw",
    [
        dict(kernel="scipy"),
        pytest.param(dict(kernel="numba", scheme="mpi"), marks=needs_numba),
        pytest.param(dict(kernel="numba", scheme="gs"), marks=needs_numba),
        pytest.param(dict(kernel="numba", scheme="jacobi"), marks=needs_numba),
        pytest.param(dict(kernel="numba", scheme="jacobi", threads=2), marks=needs_numba),
    ],
)
def test_value_iteration_is_certified_on_the_reference_row(p12, kw):
    sol = value_iteration(p12, **kw)
    assert sol.ok and sol.method == "vi"
    assert sol.gap <= 1e-9  # default tolerance of the issue
    assert sol.gain_lower - 1e-6 <= P12_GAIN <= sol.gain_upper + 1e-6
    assert sol.gain == pytest.approx(P12_GAIN, rel=1e-9)
    # the reported certificate is the bracket of the reported bias
    lo, hi = bracket(p12, sol.bias)
    assert (lo, hi) == pytest.approx((sol.gain_lower, sol.gain_upper), rel=1e-12)


@needs_numba
def test_numba_and_scipy_value_iteration_agree(p12):
    a = value_iteration(p12, kernel="numba")
    b = value_iteration(p12, kernel="scipy")
    assert abs(a.gain - b.gain) <= max(a.gain_upper - a.gain_lower, b.gain_upper - b.gain_lower)
    # same optimal actions where the optimal action is clear-cut
    np.testing.assert_array_equal(p12.a_indices[a.policy], p12.a_indices[b.policy])


def test_value_iteration_warm_start_and_budget(p12):
    cold = value_iteration(p12)
    warm = value_iteration(p12, h0=cold.bias)
    assert warm.ok and warm.iterations < cold.iterations / 3
    short = value_iteration(p12, max_iter=3)
    assert short.status == "max_iter" and short.gain_lower <= P12_GAIN + 1e-6 <= short.gain_upper + 2e-6


def test_value_iteration_on_a_periodic_chain():
    two_cycle = MDP.from_arrays([0, 1], [0, 0], [1.0, 0.0], [[0.0, 1.0], [1.0, 0.0]])
    for scheme in (["jacobi"] + (["mpi", "gs"] if numba_available() else [])):
        sol = value_iteration(two_cycle, scheme=scheme, stall_checks=3)
        assert sol.ok and sol.gain == pytest.approx(0.5, abs=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_value_iteration_matches_policy_iteration_on_random_mdps(seed):
    mdp = random_mdp(10 + seed)
    pi = policy_iteration(mdp)
    vi = value_iteration(mdp, tol=1e-11, stall_checks=2)
    assert vi.ok and vi.gain_lower - 1e-9 <= pi.gain <= vi.gain_upper + 1e-9


def test_bad_value_iteration_arguments(p12):
    from wncs_lp.errors import SolverError

    with pytest.raises(SolverError, match="scheme"):
        value_iteration(p12, scheme="sor")
    with pytest.raises(SolverError, match="relax"):
        value_iteration(p12, relax=1.5)
    with pytest.raises(SolverError, match="in-place"):
        value_iteration(p12, kernel="scipy", scheme="gs")


def test_policy_iteration_survives_a_multichain_iterate():
    """The preemption paper instance at p = 1: greedy-cost PI meets a multichain iterate."""
    mdp = build(load_scenario(scenario_path("paper_preemption_p12.toml"), ["p=1"]))
    from wncs_lp.errors import PolicyError

    with pytest.raises(PolicyError, match="multichain"):
        policy_iteration(mdp, multichain="raise")
    sol = policy_iteration(mdp)
    assert sol.ok and sol.method == "pi"
    assert "multichain" in sol.stats["fallback"]
    assert sol.gap < 1e-9
    vi = value_iteration(mdp)
    assert vi.gain_lower - 1e-9 <= sol.gain <= vi.gain_upper + 1e-9
    assert solve(mdp, "pi").ok


# ------------------------------------------------------------------------ auto
def test_auto_picks_and_cross_checks(p12):
    sol = solve(p12, "auto")
    st = sol.stats
    assert sol.ok and st["method_requested"] == "auto" and st["auto_choice"] in ("lp", "vi")
    assert sol.method == "auto"
    assert st["cross_check_method"] in ("lp", "vi") and st["cross_check_method"] != st["auto_choice"]
    assert st["cross_check_agree"] is True and st["cross_check_rel_diff"] < 1e-8
    assert sol.gain == pytest.approx(P12_GAIN, rel=1e-9)
    assert "auto_choice" in sol.summary()


def test_auto_thresholds_and_need(p12):
    small = solve(p12, "auto", lp_small_pairs=10**9, cross_check_max_pairs=0)
    assert small.stats["auto_choice"] == "lp" and small.stats["cross_check_method"] is None
    big = solve(p12, "auto", lp_small_pairs=0, cross_check_max_pairs=0)
    assert big.stats["auto_choice"] == "vi"
    occ = solve(p12, "auto", need="occupation", lp_small_pairs=0, cross_check_max_pairs=0)
    assert occ.stats["auto_choice"] == "lp" and occ.occupation is not None
    from wncs_lp.errors import SolverError

    with pytest.raises(SolverError, match="need"):
        solve(p12, "auto", need="everything")


@pytest.mark.parametrize("name, sets", [("paper_p12.toml", []), ("paper_preemption_p12.toml", ["tau_cap=6"])])
def test_iterative_evaluation_matches_lu_on_the_models(name, sets):
    """BiCGSTAB (the large-chain path) against the sparse LU on the paper's chains, with the
    value-iteration optimal policy; the gain also lies in value iteration's certificate."""
    from wncs_lp.solvers import evaluate_policy

    mdp = build(load_scenario(scenario_path(name), sets))
    vi = value_iteration(mdp, tol=1e-11)
    it = evaluate_policy(mdp, vi.policy, method="iterative")
    lu = evaluate_policy(mdp, vi.policy, method="direct")
    assert it.solver == "bicgstab" and lu.solver == "splu"
    assert it.gain == pytest.approx(lu.gain, rel=1e-11)
    assert vi.gain_lower - 1e-9 <= it.gain <= vi.gain_upper + 1e-9
    np.testing.assert_allclose(it.bias, lu.bias, atol=1e-8 * np.max(np.abs(lu.bias)))
    np.testing.assert_allclose(it.stationary, lu.stationary, atol=1e-11)
