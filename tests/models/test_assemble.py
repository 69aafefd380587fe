"""The vectorised builder engine returns exactly the MDP of the original loop builder.

``build_aoi_mdp`` (BFS reachability over (config, tau) + CSR written by index arithmetic) and
``build_aoi_mdp_loop`` (the original per-(config, action, outcome) loop, kept as the
benchmark baseline) must agree array for array: state numbering, pair order, action
labels, costs, and P's data / indices / indptr. No wall-clock assertions here; the speed
is measured in ``benchmarks/``.
"""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.models.cost import cost_tables
from wncs_lp.models.preemption import preemption_automaton
from reference.loop_builder import build_aoi_mdp_loop
from wncs_lp.models.assemble import build_aoi_mdp
from wncs_lp.models.automaton import ConfigAutomaton, FlatAutomaton
from wncs_lp.models.wncs import wncs_automaton
from wncs_lp.scenario import load_scenario


def assert_same_mdp(a, b):
    assert (a.n_states, a.n_pairs) == (b.n_states, b.n_pairs)
    for f in ("s_indices", "a_indices", "cost", "pair_ptr", "action_table"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    for f in ("data", "indices", "indptr"):
        np.testing.assert_array_equal(getattr(a.P, f), getattr(b.P, f), err_msg=f"P.{f}")
    assert a.P.has_canonical_format and b.P.has_canonical_format
    np.testing.assert_array_equal(a.states.tau, b.states.tau)
    np.testing.assert_array_equal(a.states.config, b.states.config)
    np.testing.assert_array_equal(a.states._lookup, b.states._lookup)
    assert a.states._lookup.dtype == b.states._lookup.dtype
    assert a.states.caps == b.states.caps


def _both(auto, sc):
    new = build_aoi_mdp(auto, sc.tau_caps, cost_tables(sc))
    old = build_aoi_mdp_loop(auto, sc.tau_caps, cost_tables(sc))
    return new, old


@pytest.mark.parametrize(
    "name, sets",
    [
        ("paper_p12.toml", []),
        ("paper_p14.toml", ["tau_cap=7"]),
        ("paper_p123.toml", ["tau_cap=6"]),
        ("paper_p12.toml", ["tau_cap=9", "p=1.0"]),
        ("paper_p12.toml", ["tau_cap=8", "p=0.0"]),
        ("paper_preemption_p12.toml", []),
        ("paper_preemption_p12.toml", ["tau_cap=7", "p=1.0"]),
        ("preemption_p123_u0d0.toml", ["tau_cap=5"]),
    ],
)
def test_vectorised_builder_equals_loop_builder(name, sets):
    sc = load_scenario(scenario_path(name), sets)
    auto = (preemption_automaton if sc.model.kind == "preemption" else wncs_automaton)(sc)
    new, old = _both(auto, sc)
    assert_same_mdp(new, old)
    new.validate()


def test_hand_built_automaton_without_flat_arrays():
    """An automaton built by hand (no ``flat_arrays``) is flattened from ``outcomes``."""
    # two configurations; config 1 is only reached through a delivery of age 2 to process 1
    auto = ConfigAutomaton(
        configs=["a", "b"],
        initial=[0],
        actions=[[(0,), (1,)], [(0,)]],
        outcomes=[
            [[(0, (0, 0), 1.0)], [(1, (2, 0), 0.7), (0, (0, 0), 0.3)]],
            [[(0, (0, 3), 0.5), (0, (0, 0), 0.25), (1, (0, 0), 0.25)]],
        ],
    )
    qs = [np.arange(1.0, 5.0), np.arange(1.0, 4.0) * 2]
    from types import SimpleNamespace

    sc = SimpleNamespace(tau_caps=(4, 3))
    new = build_aoi_mdp(auto, sc.tau_caps, qs)
    old = build_aoi_mdp_loop(auto, sc.tau_caps, qs)
    assert_same_mdp(new, old)
    assert isinstance(auto.flat_arrays, FlatAutomaton)
    new.validate()
    # config "b" is entered with tau_1 = 2 and then only grows: tau_1 = 1 never occurs there
    grid = new.states.lookup_grid(1)
    assert (grid[0] == -1).all() and (grid[1:] >= 0).any()


def test_flat_arrays_match_outcomes():
    sc = load_scenario(scenario_path("paper_preemption_p12.toml"), ["tau_cap=6"])
    auto = preemption_automaton(sc)
    ref = FlatAutomaton.from_outcomes(auto.outcomes, sc.n_processes)
    got = auto.flat()
    for f in ("act_ptr", "out_ptr", "out_nxt", "out_prob"):
        np.testing.assert_array_equal(getattr(got, f), getattr(ref, f), err_msg=f)
    np.testing.assert_array_equal(got.deltas[got.out_delta], ref.deltas[ref.out_delta])
