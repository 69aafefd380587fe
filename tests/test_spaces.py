"""The one state-space interface (:mod:`wncs_lp.spaces`): an MDP's state table and a matrix-free
solve's AoI box answer the same questions alike on one scenario. The oracles are independent: the
LP on the stored matrix against certified value iteration on the box (two solvers), and the state
table's own decoding against the layout's arithmetic."""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp as w
from wncs_lp.errors import PolicyError
from wncs_lp.policy_grids import policy_grid, region_stats
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration
from wncs_lp.spaces import BoxSpace, EnumeratedSpace, space_of


@pytest.fixture(scope="module")
def p12():
    sc = w.load_scenario(w.scenario_path("paper_p12"), ["tau_cap=8"])
    mdp = w.build(sc)
    return sc, mdp, w.solve(mdp, "lp"), matrix_free_value_iteration(sc)


def test_space_of_picks_the_implementation(p12):
    _, mdp, lp, mf = p12
    assert isinstance(space_of(mdp), EnumeratedSpace) and isinstance(space_of(mf), BoxSpace)
    space = space_of(mf)
    assert space_of(space) is space
    with pytest.raises(PolicyError, match="no state space in ndarray"):
        space_of(np.zeros(3))


def test_both_spaces_number_the_same_configurations_and_find_every_reachable_state(p12):
    _, mdp, _, mf = p12
    E, B = space_of(mdp), space_of(mf)
    assert E.caps == B.caps and E.configs == B.configs
    assert [E.describe(c) for c in range(len(E.configs))] == [B.describe(c) for c in range(len(B.configs))]
    assert E.config_id("idle") == B.config_id("idle")
    tau, cfg = np.asarray(mdp.states.tau), np.asarray(mdp.states.config)
    for c in range(len(E.configs)):
        rows = np.flatnonzero(cfg == c)
        assert np.array_equal(E.lookup(tau[rows], c), rows)  # the state table's own numbering
        idx = B.lookup(tau[rows], c)
        assert np.all(idx >= 0), "a reachable state lies outside the AoI box"
        assert np.array_equal(B.tau_of(idx), tau[rows]) and np.all(B.config_of(idx) == c)
        low, high = B.box(c)
        assert np.all(tau[rows] >= low) and np.all(tau[rows] <= high)


def test_the_lp_and_the_matrix_free_solve_give_the_same_grid_through_the_interface(p12):
    _, mdp, lp, mf = p12
    assert lp.gain == pytest.approx(0.5 * (mf.gain_lower + mf.gain_upper), rel=1e-8)
    E, B = space_of(mdp), space_of(mf)
    checked = 0
    for c in range(len(E.configs)):
        A_e, S_e, fixed = policy_grid(E, lp, c, (1, 2))
        A_b, S_b, _ = policy_grid(B, mf, c, (1, 2), fixed)
        reach = S_e >= 0
        assert np.all(S_b[reach] >= 0)
        got = [B.action_label(c, a) for a in A_b[reach]]
        assert [E.action_label(c, a) for a in A_e[reach]] == got
        names = E.names()
        assert [E.action_name(c, a, names) for a in A_e[reach]] == [B.action_name(c, a) for a in A_b[reach]]
        checked += int(reach.sum())
    assert checked == mdp.n_states  # two processes: every state is on its configuration's grid


def test_region_stats_take_either_space(p12):
    sc, mdp, lp, mf = p12
    ref = region_stats(mdp, lp, "idle", scenario=sc)
    box = region_stats(space_of(mf), mf, "idle")
    for name, r in ref["per_action"].items():  # the box may hold a few cells the MDP does not reach
        assert box["per_action"][name]["cells"] >= r["cells"]


def test_value_counts_count_the_states_of_each_aoi_value(p12):
    _, mdp, _, mf = p12
    E, B = space_of(mdp), space_of(mf)
    tau, cfg = np.asarray(mdp.states.tau), np.asarray(mdp.states.config)
    for c in (0, len(E.configs) // 2, len(E.configs) - 1):
        box_tau = B.tau_of(np.arange(mf.layout.off[c], mf.layout.off[c + 1]))
        counts_e, mass_e = E.value_counts(c, weights=np.ones(mdp.n_states))
        counts_b, _ = B.value_counts(c)
        for k, cap in enumerate(E.caps):
            values = np.arange(1, cap + 1)
            want = [(tau[cfg == c, k] == v).sum() for v in values]
            assert list(counts_e[k]) == want and list(mass_e[k]) == want
            assert list(counts_b[k]) == [(box_tau[:, k] == v).sum() for v in values]
