"""Relaxation 4 on interchangeable processes: each group's chain lumped by the permutations that
keep every group (GroupLumps) has the whole chain's gain at symmetric prices (the whole chain
solved without the reduction), its tables certify on the whole system, and the bound found on
the lumped chains is valid against the exact g* (the solver) and as tight as the whole search's."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import EDGE, REMOTE

from wncs_lp.bounds.joint_chains import JointData
from wncs_lp.bounds.joint_symmetry import process_symmetry
from wncs_lp.bounds.lower import lower_bound
from wncs_lp.bounds import pairs_kernels
from wncs_lp.bounds.pairs import GroupChains, GroupLumps, certify_group_tables, group_cut, solve_group_chain
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")



@pytest.fixture(scope="module")
def twice():
    """Two scalar process types twice (A = 1.2, 1.1, 1.2, 1.1), cap 6, p = 0.7: classes (1, 3) and
    (2, 4); relaxation 2 is 0.14% below g* there."""
    sc = scenario_from_dict({"model": {"kind": "wncs", "tau_cap": 6}, "channel": {"success_probability": 0.7},
                             "process": [{"A": [[1.2]]}, {"A": [[1.1]]}, {"A": [[1.2]]}, {"A": [[1.1]]}],
                             "server": [REMOTE, EDGE]}, source="<pairs symmetry>")
    system = System.from_scenario(sc)
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    assert sym.classes == ((0, 2), (1, 3))
    r2 = lower_bound(system, 2)
    return system, data, sym, solve(build(sc)).gain_upper, r2


@pytest.mark.parametrize("groups, lumped", [(((0, 2), (1, 3)), True), (((0, 1), (2, 3)), False)])
def test_lumped_chain_has_the_whole_chains_gain(twice, groups, lumped):
    """At prices constant on the price orbits, each lumped chain's gain is the whole chain's (solved
    without the reduction) and its table, spread back, satisfies the whole chain's Bellman brackets;
    a pairing that splits every class keeps no permutation (nothing lumped)."""
    _, data, sym, _, _ = twice
    chains = GroupChains.build(data, groups)
    lumps = GroupLumps.build(data, chains.groups, sym)
    assert (lumps.n_prices < data.n_pairs) == lumped
    assert all((lp.data.n_configs < data.n_configs) == lumped for lp in lumps.chains)
    rng = np.random.default_rng(3)
    prices = rng.normal(scale=5.0, size=(chains.n_groups, lumps.n_prices))
    prices -= prices.mean(axis=0)
    whole_prices = prices[:, lumps.pair_orbit]
    for i in range(chains.n_groups):
        small = solve_group_chain(lumps.chains[i], 0, prices[i][lumps.price_of[i]], None, tol=1e-12)
        whole = solve_group_chain(chains, i, whole_prices[i], None, tol=1e-12)
        assert small.lower == pytest.approx(whole.lower, rel=1e-9)
        # the spread table is a Bellman sub-solution of the whole chain with the lumped bracket
        spread = lumps.spread(i, small.h)
        again = solve_group_chain(chains, i, whole_prices[i], spread, tol=np.inf)
        assert again.lower >= small.lower - 1e-8 * abs(small.lower)
        assert again.upper <= small.upper + 1e-8 * abs(small.upper)
    # the spread tables certify at least the sum of the lumped chains' lower brackets
    sols = [solve_group_chain(lumps.chains[i], 0, prices[i][lumps.price_of[i]], None, tol=1e-12)
            for i in range(chains.n_groups)]
    cert = certify_group_tables(chains, [lumps.spread(i, s.h) for i, s in enumerate(sols)])
    assert cert.lower_bound >= sum(s.lower for s in sols) - 1e-7


def test_symmetric_search_is_valid_and_as_tight_as_the_whole_one(twice):
    """Both searches stay between relaxation 2 and g*; on the lumped chains the bound is at least
    the whole chains' after the same number of steps (the same maximum of L, a smaller problem)."""
    system, _, _, g_star, r2 = twice
    sym = lower_bound(system, 4, start=r2, groups=[(0, 2), (1, 3)], max_iter=15)
    whole = lower_bound(system, 4, start=r2, groups=[(0, 2), (1, 3)], max_iter=15, symmetric=False)
    for res in (sym, whole):
        assert r2.lower_bound <= res.lower_bound <= g_star
    assert sym.lower_bound > r2.lower_bound + 1e-4 * g_star  # the pairs do tighten it here
    assert sym.lower_bound >= whole.lower_bound - 1e-4 * g_star
    # the returned prices are constant on the price orbits (the symmetric search's)
    lumps = GroupLumps.build(JointData.from_system(system), sym.tables.groups, process_symmetry(system))
    mu = np.asarray(sym.multipliers)
    assert np.allclose(mu, lumps.prices_of(mu)[:, lumps.pair_orbit])


def test_own_swap_computes_half_the_chain_and_changes_no_gain(twice):
    """A same-type pair's chain lumped also by its own swap (PairSwap): each sweep computes one state
    of each orbit and mirrors the rest, so the gain and the table are the chain's solved whole (on
    the chain lumped only by the swaps disjoint from the pair); the cut's push from one state of
    each orbit equals the whole push of the policy mixing p and sigma p at the fixed states, and
    the cut prices the policy at the chain's gain (a + <x, mu> = g, the defining property of a cut
    of an optimal policy)."""
    _, data, sym, _, _ = twice
    chains = GroupChains.build(data, ((0, 2), (1, 3)))
    swapped = GroupLumps.build(data, chains.groups, sym)
    plain = GroupLumps.build(data, chains.groups, sym, own_swap=False)
    rng = np.random.default_rng(5)
    prices = rng.normal(scale=5.0, size=(chains.n_groups, swapped.n_prices))
    prices -= prices.mean(axis=0)
    for i in range(chains.n_groups):
        ch, sw = swapped.chains[i], swapped.chains[i].swap(0)
        assert sw is not None and plain.chains[i].swap(0) is None and 0.4 < sw.share < 0.8
        mu = prices[i][swapped.price_of[i]]
        fast = solve_group_chain(ch, 0, mu, None, tol=1e-12)
        slow = solve_group_chain(plain.chains[i], 0, mu, None, tol=1e-12)
        assert fast.lower == pytest.approx(slow.lower, rel=1e-10) and fast.upper == pytest.approx(slow.upper, rel=1e-10)
        assert np.allclose(fast.h, slow.h, atol=1e-8 * np.abs(slow.h).max())
        # the push: from a sigma-invariant law, the whole chain's under p and under sigma p, averaged
        ages = np.arange(ch.shape(0)[1])
        image = (ages % ch.c2[0]) * ch.c2[0] + ages // ch.c2[0]
        y = rng.random(ch.shape(0))
        y += y[sw.config][:, image]
        c1, c2, _, out_ptr, out_nxt, out_prob, s1, s2 = ch.args(0)
        mixed = sw.pair[fast.policy[sw.config][:, image]]
        fixed = (sw.kind[:, None] == 1) & (image == ages)[None, :]
        assert np.all((mixed == fast.policy) | fixed)  # equivariant off the fixed states
        whole = [np.empty_like(y) for _ in range(3)]
        for pol, out in ((fast.policy, whole[0]), (mixed, whole[1])):
            pairs_kernels.push(y, pol, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, out)
        pairs_kernels.push_sym(y, fast.policy, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, sw.kind, sw.config, whole[2])
        assert np.allclose(whole[2], 0.5 * (whole[0] + whole[1]), rtol=0, atol=1e-12 * y.sum())
        a, x, _ = group_cut(ch, 0, fast.policy)
        assert a + x @ mu == pytest.approx(fast.lower, rel=1e-8)


def test_own_swap_search_is_the_same_bound_and_valid(twice):
    """The search on the chains lumped by their own swaps finds the bound of the search without
    (the same chains, their gains to the chains' accuracy), below the exact g*; on two threads
    (the configurations computed and mirrored split between them, the cuts side by side) the same
    numbers to the last bit."""
    system, _, _, g_star, r2 = twice
    swapped = lower_bound(system, 4, start=r2, groups=[(0, 2), (1, 3)], max_iter=15)
    plain = lower_bound(system, 4, start=r2, groups=[(0, 2), (1, 3)], max_iter=15, own_swap=False)
    assert r2.lower_bound < swapped.lower_bound <= g_star
    assert swapped.lower_bound == pytest.approx(plain.lower_bound, rel=1e-8)
    two = lower_bound(system, 4, start=r2, groups=[(0, 2), (1, 3)], max_iter=15, threads=2)
    assert two.lower_bound == swapped.lower_bound and two.stats["bundle_steps"] == swapped.stats["bundle_steps"]
    assert all(np.array_equal(a, b) for a, b in zip(two.tables.h, swapped.tables.h))
