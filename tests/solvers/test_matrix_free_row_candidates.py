"""Candidate actions per row (``candidates="row"``, ``candidates_near``).

The improvement sweeps between two certificates may try, on each row (the last AoI axis of a
configuration's box), only the actions the last certificate found within ``candidates_near`` x
the previous width of the minimum somewhere on the row (``candidates_near=0``: the greedy policy's
actions on the row). The certificate passes still take the minimum over every action, so the
certified gain may not move: solves close on the stored-matrix value iteration's gain (an
independent route) on both model kinds and from a random start. The bit sets themselves are
checked against brute force: the policy's actions per row, and the actions whose value (each
action's own fixed-policy pass, another kernel) is within the margin of the row's minimum.
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

# the same two small cases and gain check as the per-configuration candidates' tests
from test_matrix_free_candidates import case, inside, paper  # noqa: E402,F401




@pytest.mark.parametrize("near", [0.0, 1.0])
def test_row_candidates_keep_the_certified_gain(case, near):
    system, ref = case
    sol = matrix_free_value_iteration(system, candidates="row", candidates_near=near)
    assert sol.status == "optimal" and inside(sol, ref)


def test_row_candidates_from_a_random_start_still_certify(case):
    system, ref = case
    n = BoxLayout.from_system(system).n_states
    h0 = np.random.default_rng(4).normal(scale=10 * ref.gain, size=n)
    # on from the first certificate, whose greedy policy is that of a random h
    sol = matrix_free_value_iteration(system, h0=h0, candidates="row", candidates_near=1.0, candidates_rel=1e6)
    assert sol.status == "optimal" and inside(sol, ref)


@pytest.fixture(scope="module")
def rows():
    system = System.from_scenario(paper("paper_p1234", 6))
    layout = BoxLayout.from_system(system)
    sw = Sweeper(Operator.build(system, layout), 1, None)
    rng = np.random.default_rng(9)
    h = rng.normal(scale=30.0, size=layout.n_states)
    nact = np.repeat(np.asarray(system.n_actions), np.diff(layout.off))
    values = []  # each action's value at every state, by the fixed-policy kernel
    for j in range(int(nact.max())):
        out = np.empty_like(h)
        sw.fixed(h, out, np.where(j < nact, j, 0).astype(np.uint8), Write.OUT, 1.0, 0.0)
        values.append(np.where(j < nact, out, np.inf))
    row_of = np.repeat(np.arange(sw.n_rows), np.repeat(layout.dims[:, -1], np.diff(sw.row_off)))
    return sw, layout, h, np.array(values), row_of


def row_sets(row_of, n_rows, mask):
    """Per row, the bit set of the actions j with mask[j, s] at some state s of the row."""
    bits = np.zeros(n_rows, np.uint64)
    for j in range(mask.shape[0]):
        hit = np.zeros(n_rows, bool)
        np.logical_or.at(hit, row_of, mask[j])
        bits[hit] |= np.uint64(1 << j)
    return bits


def test_row_actions_are_the_policys_actions_on_each_row(rows):
    sw, layout, h, values, row_of = rows
    pol = values.argmin(axis=0).astype(np.uint8)
    got = sw.row_actions(pol, np.zeros(sw.n_rows, np.uint64))
    want = row_sets(row_of, sw.n_rows, pol[None, :] == np.arange(values.shape[0])[:, None])
    assert row_of.size == layout.n_states and np.array_equal(got, want)


@pytest.mark.parametrize("near", [0.0, 5.0, 1e300])
def test_near_minimal_actions_cover_every_action_within_the_margin(rows, near):
    sw, layout, h, values, row_of = rows
    pol = np.zeros(layout.n_states, np.uint8)
    nbits = np.zeros(sw.n_rows, np.uint64)
    lo, hi = sw.all_actions(h, None, pol, None, Reduce.MIN, Write.NONE, True, 1.0, 0.0, near=near, nbits=nbits)
    # the certificate is the plain one: min / max of T h - h
    d = values.min(axis=0) - h
    assert np.isclose(lo, d.min(), rtol=0, atol=1e-9) and np.isclose(hi, d.max(), rtol=0, atol=1e-9)
    # every action within the margin of a state's minimum (a little slack for the two kernels'
    # round-off) is marked on its row, the minimiser first of all
    best = values.min(axis=0)
    must = values <= best[None, :] + near - 1e-9 * (1 + np.abs(best[None, :]))
    must[pol, np.arange(layout.n_states)] = True
    want = row_sets(row_of, sw.n_rows, must)
    assert np.all(nbits & want == want)
    if near == 1e300:  # every action of the configuration
        full = row_sets(row_of, sw.n_rows, np.isfinite(values))
        assert np.array_equal(nbits, full)
    if near == 0.0:  # some row has an action left out (the check above is not vacuous)
        assert np.any(nbits != row_sets(row_of, sw.n_rows, np.isfinite(values)))


def test_near_is_for_certificates_and_options_are_checked(rows):
    sw, layout, h, _, _ = rows
    pol = np.zeros(layout.n_states, np.uint8)
    with pytest.raises(SolverError, match="near-minimal"):
        sw.all_actions(h.copy(), None, pol, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0, near=1.0,
                       nbits=np.zeros(sw.n_rows, np.uint64))
    with pytest.raises(SolverError, match="candidates_near"):
        matrix_free_value_iteration(paper("paper_p12", 4), candidates_near=-1.0)
    with pytest.raises(SolverError, match="candidates"):
        matrix_free_value_iteration(paper("paper_p12", 4), candidates="plane")
