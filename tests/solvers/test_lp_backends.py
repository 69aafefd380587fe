"""The LP's backends (Clarabel, HiGHS) and the ``auto`` rule of ``solve_lp`` (issue 18).

Every expected gain comes from certified value iteration (an independent method) or from the
other backend; the ``auto`` tests check the documented rule (:func:`choose_lp`) on MDPs built so
that the rule's inputs are known by construction. No wall-clock assertions (benchmarks/)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from wncs_lp.errors import SolverError
from wncs_lp.status import STATUS_CODES
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp.solvers import value_iteration
from wncs_lp import solve
from wncs_lp.solvers import lp as lpmod
from wncs_lp.solvers.highs import HIGHS_STATUS, HIGHS_VARIANTS
from wncs_lp.solvers.lp import FAILED_STATUSES, choose_lp, highs_max_rows, solve_lp

F = Path(__file__).resolve().parent.parent.parent / "formulations"

SHAPES = {
    "p12": ("paper_p12.toml", ["tau_cap=8"]),
    "p12_idle": ("paper_p12.toml", ["tau_cap=8", "model.allow_idle=true"]),
    "p123": ("paper_p123.toml", ["tau_cap=7"]),
    "p14": ("paper_p14.toml", ["tau_cap=8"]),
    "preemption": ("paper_preemption_p12.toml", ["tau_cap=7"]),
}


@pytest.fixture(scope="module")
def models():
    out = {}
    for k, (f, ov) in SHAPES.items():
        mdp = build(load_scenario(str(F / f), ov))
        out[k] = (mdp, value_iteration(mdp, tol=1e-12))
    return out


def random_mdp(n: int, actions: int, seed: int = 0, succ: int = 3) -> MDP:
    """``n`` states, each with ``actions`` actions whose rows have ``succ`` random successors
    (no forced state, so the reduction eliminates nothing)."""
    rng = np.random.default_rng(seed)
    L = n * actions
    s_idx = np.repeat(np.arange(n), actions)
    a_idx = np.tile(np.arange(actions), n)
    cols = rng.integers(0, n, size=(L, succ))
    cols[:, 0] = (s_idx + 1) % n  # a ring keeps every policy unichain and irreducible
    vals = rng.random((L, succ)) + 0.1
    vals /= vals.sum(axis=1, keepdims=True)
    P = sp.csr_matrix((vals.ravel(), (np.repeat(np.arange(L), succ), cols.ravel())), shape=(L, n))
    P.sum_duplicates()
    return MDP.from_arrays(s_idx, a_idx, rng.random(L) * 10.0, P, n)


def chain_mdp(n_dec: int, chain: int) -> MDP:
    """``n_dec`` decision states (2 actions) each followed by a forced chain of ``chain`` states
    back to the next decision state: the reduction eliminates every chain state and shrinks
    the LP."""
    n = n_dec * (1 + chain)
    s_idx, a_idx, cost, rows, cols, vals = [], [], [], [], [], []
    row = 0

    def add(s, a, c, dist):
        nonlocal row
        s_idx.append(s), a_idx.append(a), cost.append(c)
        for j, p in dist.items():
            rows.append(row), cols.append(j), vals.append(p)
        row += 1

    for d in range(n_dec):
        base = d * (1 + chain)
        nxt = ((d + 1) % n_dec) * (1 + chain)
        add(base, 0, 1.0 + d, {base + 1: 1.0})
        add(base, 1, 3.0, {nxt: 1.0})
        for i in range(1, chain + 1):
            add(base + i, 0, 0.5 * i, {(base + i + 1) if i < chain else nxt: 1.0})
    P = sp.csr_matrix((vals, (rows, cols)), shape=(row, n))
    return MDP.from_arrays(s_idx, a_idx, cost, P, n)


def hub_mdp(spokes: int) -> MDP:
    """``spokes`` decision states (2 actions) all feeding one forced hub state that spreads to
    every decision state: eliminating the hub turns 2 * spokes + spokes entries into
    spokes * spokes, so the reduced LP is denser than the plain one."""
    n = spokes + 1
    hub = spokes
    s_idx, a_idx, cost, rows, cols, vals = [], [], [], [], [], []
    row = 0
    for d in range(spokes):
        for a in range(2):
            s_idx.append(d), a_idx.append(a), cost.append(float(d % 5 + a))
            rows += [row, row]
            cols += [hub, (d + 1) % spokes]
            vals += [0.5, 0.5] if a == 0 else [0.9, 0.1]
            row += 1
    s_idx.append(hub), a_idx.append(0), cost.append(2.0)
    rows += [row] * spokes
    cols += list(range(spokes))
    vals += [1.0 / spokes] * spokes
    row += 1
    P = sp.csr_matrix((vals, (rows, cols)), shape=(row, n))
    return MDP.from_arrays(s_idx, a_idx, cost, P, n)


# ---------------------------------------------------------------------------------------------
# HiGHS, Clarabel and value iteration agree
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("shape", list(SHAPES))
def test_highs_clarabel_and_value_iteration_agree(models, shape):
    mdp, ref = models[shape]
    hi = solve_lp(mdp, backend="highs")
    cl = solve_lp(mdp, backend="clarabel")
    for s in (hi, cl):
        assert s.ok, (shape, s.status)
        assert ref.gain_lower - 1e-9 * ref.gain <= s.gain <= ref.gain_upper + 1e-9 * ref.gain
        assert s.gain == pytest.approx(ref.gain, rel=1e-10)
        assert s.stats["lp_objective"] == pytest.approx(ref.gain, rel=1e-6)
        assert s.occupation.sum() == pytest.approx(1.0, abs=1e-9)
        for k in ("full_balance_residual", "full_norm_residual", "full_dual_violation", "full_gap_rel"):
            assert np.isfinite(s.stats[k]) and s.stats[k] < 1e-5, (shape, k, s.stats[k])
    assert hi.method == "lp-highs" and hi.stats["backend"] == "highs" and hi.stats["solver"] == "highs"
    assert cl.method == "lp" and cl.stats["backend"] == "clarabel"
    # HiGHS ends at a vertex (crossover): its raw LP value and its dual gain are exact to round-off
    assert hi.stats["lp_objective"] == pytest.approx(ref.gain, rel=1e-9)
    assert hi.stats["lp_dual_gain"] == pytest.approx(ref.gain, rel=1e-9)
    # HiGHS's own word, never translated into Clarabel's
    assert hi.stats["solver_status"] == "kOptimal" and hi.stats["highs_status"].startswith("kOptimal")
    assert hi.stats["solver_iterations"] > 0 and hi.stats["solver_iterations"] >= hi.stats["ipm_iterations"]
    # the variant follows the width rule: the simplex up to HIGHS_SIMPLEX_MAX_WIDTH columns per row
    width = hi.stats["lp_cols"] / hi.stats["lp_rows"]
    assert hi.stats["highs_variant"] == ("simplex" if width <= lpmod.HIGHS_SIMPLEX_MAX_WIDTH else "ipx")
    assert (hi.stats["ipm_iterations"] > 0) == (hi.stats["highs_variant"] == "ipx")


@pytest.mark.parametrize("variant", HIGHS_VARIANTS)
@pytest.mark.parametrize("formulation", ["primal", "reduced"])
def test_every_highs_variant_and_formulation(models, variant, formulation):
    for shape in ("p12", "preemption"):
        mdp, ref = models[shape]
        s = solve_lp(mdp, backend="highs", formulation=formulation, settings={"variant": variant}, polish=False)
        assert s.stats["highs_variant"] == variant and s.stats["formulation"] == formulation
        assert s.stats["solver_status"] == "kOptimal"
        # unpolished: the gain is HiGHS's own LP value; the bracket of its (vertex) dual bias holds
        # g* but may be wide, as the vertex dual keeps slack on states no optimal policy visits
        assert s.gain == pytest.approx(ref.gain, rel=1e-9)
        assert s.gain_lower <= ref.gain_upper + 1e-9 * ref.gain and ref.gain_lower - 1e-9 * ref.gain <= s.gain_upper
        assert s.status in ("optimal", "inaccurate:certificate")
        s = solve_lp(mdp, backend="highs", formulation=formulation, settings={"variant": variant})
        assert s.ok and s.gain == pytest.approx(ref.gain, rel=1e-10), (shape, variant, formulation, s.status)


def test_method_lp_highs_and_default(models):
    mdp, ref = models["p12"]
    s = solve(mdp, "lp-highs")
    assert s.method == "lp-highs" and s.stats["backend"] == "highs"
    assert s.gain == pytest.approx(ref.gain, rel=1e-10)
    # method "lp" stays Clarabel; solve_lp's default is backend "auto", its choice recorded in words
    s = solve(mdp, "lp")
    assert s.method == "lp" and s.stats["backend"] == "clarabel" and s.stats["lp_choice_rule"] == "asked"
    s = solve_lp(mdp)
    assert s.ok and s.gain == pytest.approx(ref.gain, rel=1e-10)
    assert s.stats["lp_choice_rule"] in ("highs-width", "clarabel-size")
    assert {"highs": "HiGHS", "clarabel": "Clarabel"}[s.stats["backend"]] in s.stats["lp_choice"]


# ---------------------------------------------------------------------------------------------
# the auto rule
# ---------------------------------------------------------------------------------------------

def test_auto_backend_follows_the_documented_size_width_rule(monkeypatch):
    mdp = random_mdp(60, 2, seed=1)
    ref = value_iteration(mdp, tol=1e-12)
    # the rule's threshold, written out independently: R2 * (w / 2) ** p rows at width w
    assert highs_max_rows(2.0) == lpmod.HIGHS_ROWS_AT_WIDTH_2
    assert highs_max_rows(4.0) == pytest.approx(lpmod.HIGHS_ROWS_AT_WIDTH_2 * 2.0 ** lpmod.HIGHS_WIDTH_EXPONENT)
    s = solve_lp(mdp)  # 60 rows at width 2: far below the threshold
    assert s.stats["backend"] == "highs" and s.stats["lp_choice_rule"] == "highs-width"
    assert s.stats["formulation"] == "primal" and "no forced state" in s.stats["lp_choice"]
    assert s.gain == pytest.approx(ref.gain, rel=1e-10)
    # move the threshold below 60 rows at width 2: Clarabel
    monkeypatch.setattr(lpmod, "HIGHS_ROWS_AT_WIDTH_2", 59)
    s = solve_lp(mdp)
    assert s.stats["backend"] == "clarabel" and s.stats["lp_choice_rule"] == "clarabel-size"
    assert "60 rows > 59" in s.stats["lp_choice"]
    assert s.gain == pytest.approx(ref.gain, rel=1e-10)
    # the same threshold with 5 actions per state: HiGHS again (59 * 2.5 ** p >= 60)
    wide = random_mdp(60, 5, seed=2)
    s = solve_lp(wide)
    assert s.stats["backend"] == "highs" and s.stats["lp_choice_rule"] == "highs-width"
    assert s.gain == pytest.approx(value_iteration(wide, tol=1e-12).gain, rel=1e-10)


def test_auto_width_rule_without_solving():
    """Large shapes, choice only: width 2 beyond the threshold -> Clarabel; the same rows at
    width 6 -> HiGHS while within 3 ** p times the threshold."""
    n = int(lpmod.HIGHS_ROWS_AT_WIDTH_2 * 1.5)
    ch = choose_lp(random_mdp(n, 2, seed=3))
    assert (ch.backend, ch.formulation, ch.rule) == ("clarabel", "primal", "clarabel-size")
    assert n <= lpmod.HIGHS_ROWS_AT_WIDTH_2 * 3.0 ** lpmod.HIGHS_WIDTH_EXPONENT
    ch = choose_lp(random_mdp(n, 6, seed=4))
    assert (ch.backend, ch.rule) == ("highs", "highs-width")


def test_auto_formulation_rule():
    # forced chains: the reduction removes 3 of every 4 states and shrinks the matrix
    mdp = chain_mdp(40, 3)
    ch = choose_lp(mdp)
    plain_nnz = mdp.P.nnz + 2 * mdp.n_pairs
    assert ch.formulation == "reduced" and ch.reduced_lp.A_eq.nnz <= lpmod.REDUCE_MAX_NNZ_RATIO * plain_nnz
    assert ch.reduction.n_eliminated == 120 and "reduced LP" in ch.reason
    # a forced hub that everyone feeds and that feeds everyone: elimination densifies -> primal
    hub = hub_mdp(30)
    ch = choose_lp(hub)
    assert ch.formulation == "primal" and ch.reduction is None and "x the plain LP's nonzeros" in ch.reason
    for m in (mdp, hub):
        ref = value_iteration(m, tol=1e-12)
        for be in ("highs", "clarabel"):
            s = solve_lp(m, backend=be)
            assert s.ok and s.gain == pytest.approx(ref.gain, rel=1e-9), be


def test_auto_keeps_clarabel_for_its_settings_and_the_dual(models):
    mdp, ref = models["p12"]
    s = solve_lp(mdp, settings={"iterative_refinement_enable": True})
    assert s.stats["backend"] == "clarabel" and s.stats["lp_choice_rule"] == "settings"
    s = solve_lp(mdp, formulation="dual")
    assert s.stats["backend"] == "clarabel" and s.stats["lp_choice_rule"] == "dual"
    assert s.gain == pytest.approx(ref.gain, rel=1e-10)
    ch = choose_lp(mdp, backend="highs", formulation="primal")
    assert (ch.backend, ch.formulation, ch.rule) == ("highs", "primal", "asked")


# ---------------------------------------------------------------------------------------------
# bad input and failures
# ---------------------------------------------------------------------------------------------

def test_unknown_backend_variant_and_option(models):
    mdp, _ = models["p12"]
    with pytest.raises(SolverError, match="unknown LP backend 'gurobi'"):
        solve_lp(mdp, backend="gurobi")
    with pytest.raises(SolverError, match="unknown HiGHS variant 'barrier'"):
        solve_lp(mdp, backend="highs", settings={"variant": "barrier"})
    with pytest.raises(SolverError, match="HiGHS option 'no_such_option'"):
        solve_lp(mdp, backend="highs", settings={"no_such_option": 1})
    with pytest.raises(SolverError, match="dual"):
        solve_lp(mdp, backend="highs", formulation="dual")


@pytest.mark.parametrize("kw", [
    dict(max_iter=1, settings={"variant": "ipx"}),
    dict(settings={"time_limit": 1e-9}),
    dict(settings={"variant": "simplex", "simplex_iteration_limit": 3}),
])
def test_highs_limits_are_never_a_silent_answer(models, kw):
    mdp, ref = models["p123"]
    try:
        s = solve_lp(mdp, backend="highs", polish=False, **kw)
    except SolverError as exc:
        assert "kIterationLimit" in str(exc) or "kTimeLimit" in str(exc)
    else:  # a point came back: the status must say that the limit stopped it, in HiGHS's words
        assert s.status in ("max_iter:kIterationLimit", "max_iter:kTimeLimit"), s.status
        assert s.status_code == "max_iter" and not s.ok
        assert s.gain_lower <= ref.gain_upper and ref.gain_lower <= s.gain_upper


def test_highs_status_map_covers_every_highs_model_status():
    # HiGHS's statuses map into the closed codes by HiGHS's own table, not into Clarabel's words
    import highspy

    assert set(HIGHS_STATUS) == set(highspy.HighsModelStatus.__members__)
    assert set(HIGHS_STATUS.values()) <= set(STATUS_CODES)
    assert [k for k, c in HIGHS_STATUS.items() if c == "optimal"] == ["kOptimal"]
    assert {HIGHS_STATUS[k] for k in ("kInfeasible", "kUnbounded", "kUnboundedOrInfeasible")} <= {"infeasible", "failed"}
    assert not FAILED_STATUSES & set(HIGHS_STATUS)


def test_a_stop_does_not_wait_for_a_long_clarabel_iteration():
    """One interior-point iteration of a large LP lasts seconds to minutes (one KKT factorization):
    a stop asked meanwhile returns control at once, and the solve left behind is told to end at
    its next iteration."""
    import threading
    import time

    from wncs_lp import stopping
    from wncs_lp.solvers.lp import clarabel_solve

    class SlowSolver:  # Clarabel's interface: a callback after each (here 1-second) iteration
        answers: list[bool] = []

        def set_termination_callback(self, cb):
            self.cb = cb

        def solve(self):
            while True:
                time.sleep(1.0)
                self.answers.append(self.cb(None))
                if self.answers[-1]:
                    return "stopped by the callback"

    solver = SlowSolver()
    threading.Timer(0.2, stopping.request, (15,)).start()  # a stop asked mid-iteration (SIGTERM)
    t0 = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            clarabel_solve(solver)
        assert time.monotonic() - t0 < 0.8  # not the end of the iteration (1 s)
    finally:
        stopping.clear()
    deadline = time.monotonic() + 5
    while not solver.answers and time.monotonic() < deadline:
        time.sleep(0.05)
    assert solver.answers == [True]  # abandoned: stopped at its next iteration, even with the request cleared
