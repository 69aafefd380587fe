"""The coarse correction of the matrix-free iteration (:mod:`wncs_lp.solvers.matrix_free.aggregate`).

A closed form: when the error of h against a policy's bias is constant on every configuration
(h = h_mu - W y0), the aggregated evaluation is exact, so one correction lands on h_mu (up to a
constant) and its gain is g_mu; h_mu comes from the certified matrix-free evaluation to 1e-12
(Gauss-Seidel sweeps, not the aggregation). End to end, on both model kinds, solves and
evaluations with the correction close on the stored-matrix solver's and ``evaluate``'s gains
(independent routes), from zero and from a random start, and the bracket reported is the one of
the bias returned (a correction no certificate judged is undone).
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.errors import SolverError  # noqa: E402
from wncs_lp.evaluate import evaluate  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import (  # noqa: E402
    BoxLayout,
    MatrixFreeOptions,
    matrix_free_evaluate,
    matrix_free_value_iteration,
)
from wncs_lp.solvers.matrix_free.aggregate import Aggregator  # noqa: E402
from wncs_lp.solvers.matrix_free.operator import Operator, Write  # noqa: E402
from wncs_lp.solvers.matrix_free.sweeper import Sweeper  # noqa: E402

CASES = {"wncs": ("paper_p123", "tau_cap=7"), "preemption": ("paper_preemption_p12", "tau_cap=8")}


@pytest.fixture(scope="module")
def cases():
    out = {}
    for kind, (name, cap) in CASES.items():
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path(name), [cap])
        system = System.from_scenario(sc)
        mdp = wncs_lp.build(sc)
        ref = wncs_lp.solve(mdp, "vi", tol=1e-11)
        opt = matrix_free_value_iteration(system, threads=1, tol=1e-12)
        out[kind] = (system, mdp, ref, opt, kind)
    return out


@pytest.fixture(params=sorted(CASES))
def case(cases, request):
    return cases[request.param]


def test_one_correction_removes_an_error_constant_on_each_configuration(case):
    system, _, _, opt, _ = case
    exact = matrix_free_evaluate(system, opt, threads=1, tol=1e-12, atol=1e-11)
    layout = opt.layout
    op = Operator.build(system, layout)
    y0 = np.random.default_rng(3).normal(scale=0.1 * exact.gain, size=layout.n_configs)
    h = exact.bias - np.repeat(y0, np.diff(layout.off))
    agg = Aggregator(system, op, 1)
    assert agg.correct(h, opt.local_actions)
    shift = h - exact.bias
    scale = max(1.0, float(np.abs(exact.bias).max()))
    assert np.ptp(shift) <= 1e-8 * scale
    assert agg.last_gain == pytest.approx(exact.gain, rel=1e-9)
    agg.undo(h)  # and back
    assert np.allclose(h, exact.bias - np.repeat(y0, np.diff(layout.off)), rtol=0, atol=1e-8 * scale)


def test_corrected_solves_close_on_the_stored_gain(case):
    system, _, ref, _, kind = case
    h0 = None
    if kind == "wncs":  # from a random start (the preemption model's from zero)
        n = BoxLayout.from_system(system).n_states
        h0 = np.random.default_rng(11).normal(scale=10 * ref.gain, size=n)
    sol = matrix_free_value_iteration(system, h0=h0, threads=1, tol=1e-10, aggregate=True, aggregate_rel=1.0)
    assert sol.status == "optimal" and sol.stats["aggregations"] >= 1
    s = 1e-9 * ref.gain
    assert sol.gain_lower - s <= ref.gain <= sol.gain_upper + s
    assert ref.gain_lower - s <= sol.gain <= ref.gain_upper + s
    # the bracket is that of the bias returned (recomputed here on it)
    sw = Sweeper(Operator.build(system, sol.layout), 1, sol.mask)
    pol = np.zeros(sol.layout.n_states, np.uint8)
    lo, hi = sw.all_actions(sol.bias, None, pol, None, 0, Write.NONE, True, 1.0, 0.0)
    assert (lo, hi) == pytest.approx((sol.gain_lower, sol.gain_upper), rel=1e-12)


def test_a_correction_the_budget_leaves_unjudged_is_undone(cases):
    system = cases["wncs"][0]
    sol = matrix_free_value_iteration(system, threads=1, max_iter=16, aggregate=True, aggregate_rel=1e6)
    assert sol.stats["aggregations"] >= 1
    sw = Sweeper(Operator.build(system, sol.layout), 1, sol.mask)
    pol = np.zeros(sol.layout.n_states, np.uint8)
    lo, hi = sw.all_actions(sol.bias, None, pol, None, 0, Write.NONE, True, 1.0, 0.0)
    assert (lo, hi) == pytest.approx((sol.gain_lower, sol.gain_upper), rel=1e-12)


def test_corrected_evaluation_equals_the_stored_evaluation(cases):
    system, mdp, _, opt, _ = cases["preemption"]
    ref = evaluate(mdp, opt.on_mdp(mdp).policy)
    ev = matrix_free_evaluate(system, opt, threads=1, tol=1e-10, aggregate=True, aggregate_rel=1.0)
    assert ev.status == "optimal" and ev.stats["aggregations"] >= 1
    assert ev.gain_lower - 1e-9 * ref.gain <= ref.gain <= ev.gain_upper + 1e-9 * ref.gain


@pytest.mark.parametrize("field, value", [("aggregate", 1), ("aggregate_rel", 0.0), ("aggregate_rel", float("nan"))])
def test_the_options_are_checked(field, value):
    with pytest.raises(SolverError, match=field):
        MatrixFreeOptions(**{field: value})
