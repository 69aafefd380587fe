"""Transient cost over the first T slots against a brute-force recursion on the reference model.

The brute force expands the tree of the reference model's transitions (tests/reference/wncs.py, its
own states and dictionaries of next states) from the start, slot by slot, memoised by (state, slots
left): the fixed policy's expectation, round robin's with its pointer, and the finite-horizon
optimum (a minimum over the actions at every node).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

import reference.wncs as ref
from policies.test_baselines import RAW, max_age_order, serve
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import scenario_from_dict
from wncs_lp.transient import transient_cost

T = 5


@pytest.fixture(scope="module")
def case():
    sc = scenario_from_dict(RAW, source="transient")
    _, model = ref.build_reference(sc)
    caps = tuple(p.tau_cap for p in sc.processes)
    (start,) = [s for s in ref.initial_states(sc) if s[0] == caps]
    return sc, model, start, System.from_scenario(sc), build(sc)


def brute(sc, model, start, choose):
    """E[cost of slots 0..T-1] from ``start``; ``choose(state, memory)`` -> (action or None for the
    minimum over all actions, next memory)."""

    @lru_cache(maxsize=None)
    def value(s, memory, left):
        if left == 0:
            return 0.0
        c, pairs = model[s]
        want, nxt = choose(s, memory)
        best = float("inf")
        for a, row in pairs:
            if want is not None and a != want:
                continue
            best = min(best, sum(p * value(s2, nxt, left - 1) for s2, p in row.items()))
        return c + best

    return value(start, 0, T)


def test_fixed_policy_against_brute_force(case):
    sc, model, start, system, mdp = case
    expected = brute(sc, model, start, lambda s, m: (serve(sc, s[1], max_age_order(sc, s[0])), 0))
    got = transient_cost(mdp, make_policy("max_age", system, mdp), T)
    assert got.total == pytest.approx(expected, rel=1e-12)
    assert got.per_slot.sum() == pytest.approx(got.total, rel=1e-12)
    assert got.per_slot[0] == pytest.approx(model[start][0], rel=1e-12)  # slot 0 costs c(start)


def test_round_robin_against_brute_force(case):
    sc, model, start, system, mdp = case
    N = sc.n_processes

    def choose(s, r):
        want = serve(sc, s[1], [(r + d) % N for d in range(N)])
        sent = [(k - 1 - r) % N for k in want if k]
        return want, (r + max(sent) + 1) % N if sent else r

    got = transient_cost(mdp, make_policy("round_robin", system, mdp), T)
    assert got.total == pytest.approx(brute(sc, model, start, choose), rel=1e-12)


def test_finite_horizon_optimum_against_brute_force(case):
    sc, model, start, system, mdp = case
    expected = brute(sc, model, start, lambda s, m: (None, 0))
    opt = transient_cost(mdp, "optimal", T)
    assert opt.total == pytest.approx(expected, rel=1e-12)
    # no fixed policy does better over the horizon, from any state
    fixed = transient_cost(mdp, make_policy("greedy", system, mdp), T)
    assert np.all(opt.values <= fixed.values + 1e-9)


def test_a_start_by_aoi_and_the_long_run(case):
    sc, model, start, system, mdp = case
    pol = make_policy("max_age", system, mdp)
    fresh = transient_cost(mdp, pol, 400, start=(1, 1, 1))
    stale = transient_cost(mdp, pol, 400)
    assert fresh.total < stale.total  # a fresh start costs less ...
    g = evaluate(mdp, pol).gain
    assert fresh.per_slot[-1] == pytest.approx(g, rel=1e-6)  # ... and both settle at the gain
    assert stale.per_slot[-1] == pytest.approx(g, rel=1e-6)
