"""Matrix-free time at the cap and evaluation under another separable cost.

The expected number of processes at their cap, sum_k m_k, computed matrix-free for a policy,
against the stationary law of the same policy on the enumerated MDP (:func:`policy_cap_mass`).
"""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp as w
from wncs_lp.errors import SolverError
from wncs_lp.formulations import scenario_path
from wncs_lp.models.system import System
from wncs_lp.policies import MatrixFreePolicy
from wncs_lp.workflow import make_policy
from wncs_lp.solvers.matrix_free import (cap_cost, matrix_free_cap_mass, matrix_free_evaluate,
                                         matrix_free_value_iteration)
from wncs_lp.truncation import CAP_COUNT_ATOL, policy_cap_mass


@pytest.mark.parametrize("name,overrides", [
    ("paper_p12.toml", ["tau_cap=8"]),
    ("paper_p123.toml", ["tau_cap=8"]),
    ("paper_p1234.toml", ["tau_cap=7", "p=1.0"]),  # p = 1: the exact reachable domain
    ("paper_preemption_p12.toml", ["tau_cap=8"]),
])
def test_optimal_policy_time_at_cap_matches_the_stationary_law(name, overrides):
    sc = w.load_scenario(scenario_path(name), overrides)
    mdp = w.build(sc)
    mf = matrix_free_value_iteration(sc, tol=1e-10)
    on = mf.on_mdp(mdp)  # the same policy as pair indices
    ref = policy_cap_mass(mdp, on.policy)
    pol = MatrixFreePolicy.from_solution(mf)
    ev = matrix_free_cap_mass(sc, pol)  # in-place sweeps from h = 0 (no Jacobi warm start)
    assert ev.status == "optimal"
    m = float(sum(ref.per_process))
    assert ev.gain_lower - 1e-12 <= m <= ev.gain_upper + 1e-12
    assert ev.gain_upper - ev.gain_lower <= 1.01e-7
    # the commands' coarser width, and the Jacobi warm start the evaluation used to take: each
    # bracket still holds the stationary law's value
    coarse = matrix_free_cap_mass(sc, pol, atol=CAP_COUNT_ATOL)
    warm = matrix_free_cap_mass(sc, pol, warm_start=True)
    for e in (coarse, warm):
        assert e.status == "optimal" and e.gain_lower - 1e-12 <= m <= e.gain_upper + 1e-12
    assert coarse.gain_upper - coarse.gain_lower <= CAP_COUNT_ATOL
    # sum_k m_k brackets the share of time with some process at its cap
    assert ref.total <= m + 1e-12 and m / len(ref.per_process) <= ref.total + 1e-12


def test_a_baseline_under_a_custom_cost_is_a_weighted_cap_mass():
    sc = w.load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"])
    mdp = w.build(sc)
    system = System.from_scenario(sc)
    pol = make_policy("greedy", system)
    ref = policy_cap_mass(mdp, pol.on_mdp(mdp))
    cost = cap_cost(sc) * np.array([[3.0], [0.5]])  # 3 m_1 + 0.5 m_2
    ev = matrix_free_evaluate(sc, pol, cost=cost, tol=1e-10, atol=1e-10)
    assert ev.gain == pytest.approx(3.0 * ref.per_process[0] + 0.5 * ref.per_process[1], abs=1e-8)


def test_bad_cost_tables_are_refused():
    sc = w.load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"])
    pol = make_policy("greedy", System.from_scenario(sc))
    with pytest.raises(SolverError, match="cost must be an"):
        matrix_free_evaluate(sc, pol, cost=np.zeros((3, 8)))
    with pytest.raises(SolverError, match="non-finite"):
        matrix_free_evaluate(sc, pol, cost=np.full((2, 8), np.nan))
