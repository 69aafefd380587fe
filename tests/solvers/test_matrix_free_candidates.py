"""Candidate actions of the matrix-free improvement sweeps (``candidates_rel``), per configuration
(``candidates="config"``; the per-row sets are tested in test_matrix_free_row_candidates.py).

Once the bracket is narrow, the in-place improvement sweeps try, per configuration, only the
actions the last certificate's greedy policy takes in its box; the certificate passes always try
every action. So the certified gain may not move: solves with candidates on close on the gain
of the stored-matrix value iteration (an independent route, no matrix-free code), on both model
kinds and from a random start. The restricted sweep itself is checked against the fixed-policy
kernel: an improvement sweep with one candidate per configuration is that policy's sweep.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.errors import SolverError  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout, matrix_free_value_iteration  # noqa: E402
from wncs_lp.solvers.matrix_free.operator import Operator, Reduce, Write  # noqa: E402
from wncs_lp.solvers.matrix_free.sweeper import Sweeper  # noqa: E402


def paper(name, cap):
    return wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])


def inside(sol, ref, rel=1e-9):
    """The stored-matrix gain inside the matrix-free certificate and the other way round."""
    s = rel * abs(ref.gain)
    return (sol.gain_lower - s <= ref.gain <= sol.gain_upper + s
            and ref.gain_lower - s <= sol.gain <= ref.gain_upper + s)


@pytest.fixture(scope="module", params=[("paper_p1234", 7), ("paper_preemption_p12", 8)], ids=["wncs", "preemption"])
def case(request):
    sc = paper(*request.param)
    return System.from_scenario(sc), wncs_lp.solve(wncs_lp.build(sc), "vi")


@pytest.fixture(scope="module")
def sweeper():
    system = System.from_scenario(paper("paper_p1234", 7))
    layout = BoxLayout.from_system(system)
    op = Operator.build(system, layout)
    return system, layout, Sweeper(op, 1, None)


@pytest.mark.parametrize("rel", [1e-2, 1e6])
def test_candidates_keep_the_certified_gain(case, rel):
    system, ref = case
    sol = matrix_free_value_iteration(system, candidates_rel=rel, candidates="config")
    assert sol.status == "optimal" and inside(sol, ref)


def test_candidates_from_a_random_start_still_certify(case):
    system, ref = case
    n = BoxLayout.from_system(system).n_states
    h0 = np.random.default_rng(3).normal(scale=10 * ref.gain, size=n)
    # on from the first certificate, whose greedy policy is that of a random h
    sol = matrix_free_value_iteration(system, h0=h0, candidates_rel=1e6, candidates="config")
    assert sol.status == "optimal" and inside(sol, ref)


def test_one_candidate_per_configuration_is_that_policys_sweep(sweeper):
    system, layout, sw = sweeper
    rng = np.random.default_rng(11)
    j = rng.integers(0, system.n_actions)  # one action per configuration
    pol = np.repeat(j, np.diff(layout.off)).astype(np.uint8)
    h = rng.normal(scale=100.0, size=layout.n_states)
    h_imp, pol_imp = h.copy(), np.zeros_like(pol)
    cand = (np.uint64(1) << j.astype(np.uint64)).astype(np.uint64)
    sw.all_actions(h_imp, None, pol_imp, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 3.0, cand)
    h_fix = h.copy()
    sw.fixed(h_fix, None, pol, Write.IN_PLACE, 0.8, 3.0)
    assert np.array_equal(pol_imp, pol)
    assert np.allclose(h_imp, h_fix, rtol=1e-14, atol=0)


def test_every_candidate_is_the_full_sweep_and_used_actions_are_the_policys(sweeper):
    system, layout, sw = sweeper
    rng = np.random.default_rng(5)
    h = rng.normal(scale=100.0, size=layout.n_states)
    h_all, pol_all = h.copy(), np.zeros(layout.n_states, np.uint8)
    sw.all_actions(h_all, None, pol_all, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0)
    h_c, pol_c = h.copy(), np.zeros(layout.n_states, np.uint8)
    every = np.full(layout.n_configs, np.iinfo(np.uint64).max, np.uint64)
    sw.all_actions(h_c, None, pol_c, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0, every)
    assert np.array_equal(h_all, h_c) and np.array_equal(pol_all, pol_c)
    cand = sw.used_actions(pol_all, np.zeros(layout.n_configs, np.uint64))
    for c in range(layout.n_configs):
        seen = np.unique(pol_all[layout.off[c]:layout.off[c + 1]])
        assert int(cand[c]) == sum(1 << int(a) for a in seen)


def test_a_certificate_pass_refuses_candidates(sweeper):
    _, layout, sw = sweeper
    h, pol = np.zeros(layout.n_states), np.zeros(layout.n_states, np.uint8)
    with pytest.raises(SolverError, match="certificate"):
        sw.all_actions(h, None, pol, None, Reduce.MIN, Write.NONE, True, 1.0, 0.0, np.ones(layout.n_configs, np.uint64))


def test_candidates_rel_is_checked():
    with pytest.raises(SolverError, match="candidates_rel"):
        matrix_free_value_iteration(paper("paper_p12", 4), candidates_rel=-1.0)
