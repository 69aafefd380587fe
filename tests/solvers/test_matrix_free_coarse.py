"""The shift while the bracket is wide (``gain_hint``, ``wide_shift``) and the coarse start
(``coarse_ratio``: a solve at smaller caps whose bias, each AoI clamped into its boxes, starts the
solve and whose gain is its ``gain_hint``).

Neither touches the certificate (min / max of T h - h on one h, for any h), so the certified gain
may not move: solves with them close on the stored-matrix value iteration's gain (an independent
route, no matrix-free code) on both model kinds, from a random start and with a hint far off
either way. The clamped start is checked against the layouts' own indexing (``BoxLayout.index``
of the clamped AoI vectors), the coarse caps against their rule.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

from wncs_lp.errors import SolverError  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout, matrix_free_value_iteration  # noqa: E402
from wncs_lp.cli.common import solution_json  # noqa: E402
from wncs_lp.solvers.matrix_free.iterate import coarse_caps  # noqa: E402
from wncs_lp.solvers.matrix_free.start import clamped_values  # noqa: E402

# the same two small cases (processes 1-4 at cap 7, the preemption model at cap 8) and gain check
from test_matrix_free_candidates import case, inside, paper  # noqa: E402,F401


def test_coarse_start_keeps_the_certified_gain(case):
    system, ref = case
    sol = matrix_free_value_iteration(system, coarse_ratio=0.7, coarse_states=0, coarse_far=0.0)
    co = sol.stats["coarse"]
    if system.scenario.model.kind == "preemption":
        # its configurations hold AoI values (the pipeline's), so they change with the caps: no
        # layout of smaller caps to read a start from, and the solve goes on from zero
        assert co is None and sol.stats["gain_hint"] is None
    else:
        assert co is not None and co["used"] and co["caps"] == [int(c) for c in coarse_caps(system.caps, 0.7)]
        assert all(c < int(k) for c, k in zip(co["caps"], system.caps))
        # the optimal gain grows with the caps: the coarse one is below the certified bracket
        assert sol.stats["gain_hint"] == co["gain"] and co["gain_upper"] < sol.gain_lower
        # --json keeps scalars only: the coarse solve's passes and time must reach it as such
        shown = solution_json(sol)["stats"]
        assert shown["coarse_used"] is True and shown["coarse_sweeps"] == co["sweeps"] > 0
        assert shown["coarse_eval_sweeps"] == co["eval_sweeps"] and shown["coarse_seconds"] == co["seconds"]
    assert sol.status == "optimal" and inside(sol, ref)


def test_a_coarse_start_near_the_midpoint_is_dropped(case):
    # processes 1-4 at cap 7: the first midpoint (min c + max c) / 2 = 250.1 is below 10x the
    # cap-5 gain, so the solve is the plain one (one thread: the same passes and bits)
    system, ref = case
    if system.scenario.model.kind == "preemption":
        return
    q = [np.asarray(t)[:int(c)] for t, c in zip(system.q, system.caps)]
    assert 0.5 * (sum(x.min() for x in q) + sum(x.max() for x in q)) < 10 * ref.gain
    plain = matrix_free_value_iteration(system, coarse_ratio=0.0)
    sol = matrix_free_value_iteration(system, coarse_ratio=0.7, coarse_states=0)
    co = sol.stats["coarse"]
    assert co is not None and not co["used"] and sol.stats["gain_hint"] is None
    assert co["first_midpoint_over_gain"] < 10
    assert (sol.gain, sol.gain_lower, sol.gain_upper, sol.iterations) == \
        (plain.gain, plain.gain_lower, plain.gain_upper, plain.iterations)


@pytest.mark.parametrize("hint", [0.0, 0.5, 30.0])
def test_a_hint_far_off_still_certifies(case, hint):
    system, ref = case
    n = BoxLayout.from_system(system).n_states
    h0 = np.random.default_rng(5).normal(scale=10 * ref.gain, size=n)
    sol = matrix_free_value_iteration(system, h0=h0, gain_hint=hint * ref.gain, wide_rel=1e-3)
    assert sol.status == "optimal" and inside(sol, ref)


@pytest.mark.parametrize("rule", ["lo", "best", "geo"])
def test_wide_shift_rules_keep_the_certified_gain(case, rule):
    system, ref = case
    sol = matrix_free_value_iteration(system, wide_shift=rule, wide_rel=1e-2)
    assert sol.status == "optimal" and inside(sol, ref)


def test_the_coarse_start_is_off_below_its_size_and_with_a_start_given(case):
    system, _ = case
    assert matrix_free_value_iteration(system, coarse_ratio=0.7, tol=1e-3).stats["coarse"] is None
    n = BoxLayout.from_system(system).n_states
    sol = matrix_free_value_iteration(system, coarse_ratio=0.7, coarse_states=0, coarse_far=0.0, h0=np.zeros(n),
                                      tol=1e-3)
    assert sol.stats["coarse"] is None and sol.stats["gain_hint"] is None


def test_clamped_values_read_the_small_layout_at_the_clamped_aoi():
    big_sys = System.from_scenario(paper("paper_p123", 7))
    small_sys = System.from_scenario(paper("paper_p123", 4))
    big, small = BoxLayout.from_system(big_sys), BoxLayout.from_system(small_sys)
    h_small = np.random.default_rng(1).normal(size=small.n_states)
    got = clamped_values(small, h_small, big, np.empty(big.n_states))
    s = np.arange(big.n_states)
    c, tau = big.config_of(s), big.tau_of(s)
    lo, hi = small.lo[c] + 1, small.lo[c] + small.dims[c]  # 1-based AoI bounds of the small boxes
    idx = small.index(np.clip(tau, lo, hi), c)
    assert np.all(idx >= 0) and np.array_equal(got, h_small[idx])


def test_coarse_caps_and_bad_options():
    assert coarse_caps([30, 25, 12, 3], 0.6667).tolist() == [20, 17, 8, 2]
    assert coarse_caps([2, 1], 0.5).tolist() == [2, 1]
    for bad in ({"coarse_ratio": 1.0}, {"coarse_ratio": -0.1}, {"coarse_states": -1}, {"coarse_tol": 0.0},
                {"gain_hint": float("nan")}, {"wide_rel": 0.0}, {"wide_shift": "median"}, {"coarse_far": -1.0}):
        with pytest.raises(SolverError, match=next(iter(bad))):
            matrix_free_value_iteration(paper("paper_p12", 4), **bad)
