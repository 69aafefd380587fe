"""LP formulations: the forced-state reduction is exact, and every formulation reaches the same
certified optimum with honest accuracy numbers. No wall-clock assertions (see benchmarks/)."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.errors import SolverError
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp.solvers import value_iteration
from wncs_lp.solvers.lp import build_lp, build_reduced_lp, solve_lp
from wncs_lp.solvers.reduce import reduce_forced


@pytest.fixture(scope="module")
def p12():
    return build(load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"]))


@pytest.fixture(scope="module")
def pre():
    return build(load_scenario(scenario_path("paper_preemption_p12.toml"), ["tau_cap=6"]))


@pytest.fixture(scope="module")
def refs(p12, pre):
    return {id(m): value_iteration(m, tol=1e-12) for m in (p12, pre)}


def forced_cycle_mdp() -> MDP:
    """States 0, 1 have two actions; 2 -> 3 -> 4 -> 2 is a forced cycle (kept), 5 is forced
    with a self-loop (eliminated), 6 -> 5 forced (eliminated)."""
    n = 7
    rows, s_idx, cost = [], [], []

    def add(s, dist, c):
        r = np.zeros(n)
        for j, p in dist.items():
            r[j] += p
        rows.append(r)
        s_idx.append(s)
        cost.append(c)

    add(0, {1: 0.5, 6: 0.5}, 1.0)
    add(0, {2: 1.0}, 3.0)
    add(1, {0: 1.0}, 2.0)
    add(1, {5: 0.7, 1: 0.3}, 0.5)
    add(2, {3: 0.9, 0: 0.1}, 4.0)
    add(3, {4: 1.0}, 1.0)
    add(4, {2: 0.5, 1: 0.5}, 2.0)
    add(5, {5: 0.6, 0: 0.4}, 5.0)
    add(6, {5: 1.0}, 0.2)
    a_idx = [0, 1, 0, 1, 0, 0, 0, 0, 0]
    return MDP.from_arrays(s_idx, a_idx, cost, np.array(rows), n)


def test_reduction_is_exact(p12, refs):
    red = reduce_forced(p12)
    assert red.n_eliminated > 0.4 * p12.n_states
    np.testing.assert_allclose(np.asarray(red.Q.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert red.tau.min() >= 1.0
    # the Bellman equation of the forced states is what lift_h solves
    ref = refs[id(p12)]
    h = red.lift_h(ref.bias[red.D], ref.gain)
    np.testing.assert_allclose(h, ref.bias, atol=1e-7 * np.abs(ref.bias).max())
    # lift_x of the reference policy's stationary decision frequencies gives back its stationary distribution
    from wncs_lp.solvers import evaluate_policy

    ev = evaluate_policy(p12, ref.policy)
    x = np.zeros(p12.n_pairs)
    x[ref.policy] = ev.stationary
    np.testing.assert_allclose(red.lift_x(x[red.dpairs]), x, atol=1e-12)
    assert red.tau @ x[red.dpairs] == pytest.approx(1.0, abs=1e-12)
    assert red.C @ x[red.dpairs] == pytest.approx(ev.gain, rel=1e-12)


def test_forced_cycles_and_self_loops():
    mdp = forced_cycle_mdp()
    red = reduce_forced(mdp)
    assert set(red.F.tolist()) == {5, 6}  # the forced cycle 2-3-4 stays
    assert set(red.D.tolist()) == {0, 1, 2, 3, 4}
    sols = {f: solve_lp(mdp, formulation=f) for f in ("primal", "reduced", "dual")}
    g = sols["primal"].gain
    for f, s in sols.items():
        assert s.ok and s.gain == pytest.approx(g, rel=1e-9), f
        assert s.stats["lp_objective"] == pytest.approx(g, rel=1e-6), f


@pytest.mark.parametrize("formulation", ["primal", "reduced", "dual", "auto"])
@pytest.mark.parametrize("polish", ["pi", "vi"])
def test_formulations_agree(p12, pre, refs, formulation, polish):
    for mdp in (p12, pre):
        ref = refs[id(mdp)]
        s = solve_lp(mdp, formulation=formulation, polish=polish)
        st = s.stats
        assert s.ok, (formulation, s.status)
        assert s.gain == pytest.approx(ref.gain, rel=1e-10)
        assert ref.gain_lower - 1e-9 * ref.gain <= s.gain <= ref.gain_upper + 1e-9 * ref.gain
        assert s.gap < 1e-9
        assert st["lp_objective"] == pytest.approx(ref.gain, rel=1e-6)
        for k in ("full_balance_residual", "full_norm_residual", "full_dual_violation", "full_gap_rel"):
            assert np.isfinite(st[k]) and st[k] < 1e-5, (k, st[k])
        assert s.occupation.sum() == pytest.approx(1.0, abs=1e-9)
        assert st["formulation"] in ("primal", "reduced", "dual")


def test_auto_formulation_choice(p12, pre):
    assert solve_lp(p12, formulation="auto").stats["formulation"] == "reduced"
    # preemption: few forced states, and eliminating them densifies the LP
    assert solve_lp(pre, formulation="auto").stats["formulation"] == "primal"
    lp_r, red = build_reduced_lp(p12)
    assert lp_r.A_eq.shape[0] == red.n_decision and lp_r.A_eq.nnz < build_lp(p12).A_eq.nnz


def test_bad_arguments(p12):
    with pytest.raises(SolverError, match="formulation"):
        solve_lp(p12, formulation="simplex")
    with pytest.raises(SolverError, match="dual"):
        solve_lp(p12, formulation="dual", backend="cvxpy")
    with pytest.raises(SolverError, match="polish"):
        solve_lp(p12, polish="newton")
    for form in ("primal", "dual"):
        with pytest.raises(SolverError, match="unknown Clarabel setting 'tol_magic'"):
            solve_lp(p12, formulation=form, settings={"tol_magic": 1.0})


def test_reduced_with_cvxpy_backend(p12, refs):
    s = solve_lp(p12, backend="cvxpy", formulation="reduced")
    assert s.ok and s.gain == pytest.approx(refs[id(p12)].gain, rel=1e-10)


@pytest.mark.parametrize("refine", [None, True])
def test_default_settings_and_their_override(p12, refs, refine, monkeypatch):
    """Iterative refinement is off by default; turning it back on is honoured (checked on the
    settings object handed to Clarabel); both answers agree with certified value iteration."""
    import wncs_lp.solvers.lp as lpmod

    seen = []
    orig = lpmod.clarabel_settings

    def spy(*args):
        st = orig(*args)
        seen.append(st.iterative_refinement_enable)
        return st

    monkeypatch.setattr(lpmod, "clarabel_settings", spy)
    extra = None if refine is None else {"iterative_refinement_enable": True}
    s = solve_lp(p12, backend="clarabel", settings=extra, polish=False)
    assert seen == [bool(refine)]
    assert s.stats["clarabel_settings"]["iterative_refinement_enable"] is bool(refine)
    assert s.stats["lp_objective"] == pytest.approx(refs[id(p12)].gain, rel=1e-7)
    assert s.stats["full_balance_residual"] < 1e-5


def test_polish_true_picks_vi_on_large_models(p12, refs, monkeypatch):
    import wncs_lp.solvers.lp as lpmod

    assert solve_lp(p12).stats["polish"] == "pi"  # 2,703 states: below the threshold
    monkeypatch.setattr(lpmod, "POLISH_VI_MIN_STATES", p12.n_states)
    s = solve_lp(p12)
    assert s.stats["polish"] == "vi" and s.stats["polish_vi_sweeps"] >= 1
    assert s.ok and s.gain == pytest.approx(refs[id(p12)].gain, rel=1e-10)
