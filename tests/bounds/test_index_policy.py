"""The index policy: each index against a direct computation on one private chain (bisection on
the price with a fresh priced solve at every step), the indexability check against a scan of
prices, act() against a brute force over the action labels, the gain by two exact evaluators,
and the optimum where the relaxation is the system itself."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import shape

from wncs_lp import scenario_path
from wncs_lp.bounds import IndexPolicy, private_bound, whittle_indices
from wncs_lp.bounds.index import chain_index
from wncs_lp.bounds.private import private_chains
from wncs_lp.errors import PolicyError, SolverError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import load_scenario
from wncs_lp import solve
from wncs_lp.solvers.matrix_free import matrix_free_evaluate

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    bound = private_bound(system)
    return sc, system, bound, whittle_indices(system, bound)


def _advantage(chain, lam, m, x, states):
    """D_m(s, x) of each state s from a fresh solve (the LP, not the walk's policy iteration) of
    the chain priced at lambda with lambda_m = x: the best idling action's Q minus the best action
    sending to m."""
    price = np.array(lam, float)
    price[m] = x
    mdp = chain.priced(price)
    q = mdp.cost + mdp.P @ solve(mdp, method="lp").bias
    out = []
    for s in states:
        acts = chain.model.automaton.actions[int(mdp.states.config[s])]
        pairs = range(mdp.pair_ptr[s], mdp.pair_ptr[s + 1])
        out.append(min(q[p] for p, a in zip(pairs, acts) if not any(a))
                   - min(q[p] for p, a in zip(pairs, acts) if a[m]))
    return np.array(out)


def test_indices_against_a_direct_computation(p12):
    sc, system, bound, _ = p12
    chains, _ = private_chains(system.model)
    chain = chains[1]
    lam = bound.multipliers
    for m in range(system.n_servers):
        r = chain_index(chain, lam, m)
        idx = r["index"]
        lo0, hi0 = r["bracket"]
        states = np.flatnonzero(~np.isnan(idx))[[0, -1]]
        lo, hi = np.full(2, lo0), np.full(2, hi0)
        for _ in range(21):  # sup{x : D(x) >= 0} by bisection, each state on its own
            mid = 0.5 * (lo + hi)
            ok = np.array([_advantage(chain, lam, m, x, [s])[0] >= 0 for x, s in zip(mid, states)])
            lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
        np.testing.assert_allclose(idx[states], lo, rtol=0, atol=1e-6 * (hi0 - lo0))  # 2^-21 < 1e-6


def test_indexability_against_a_scan_of_prices(p12):
    sc, system, bound, ix = p12
    chains, _ = private_chains(system.model)
    chain, m = chains[0], 0
    r = chain_index(chain, bound.multipliers, m)
    states = np.flatnonzero(~np.isnan(r["index"]))[:12]
    xs = np.linspace(*r["bracket"], 25)
    signs = np.array([_advantage(chain, bound.multipliers, m, x, states) >= 0 for x in xs])
    switched_back = np.any(~signs[:-1] & signs[1:], axis=0)
    if r["reversals"] == 0:
        assert not switched_back.any()
    # each scanned sign agrees with the index: sending pays below it, not above
    idx = r["index"][states]
    for x, row in zip(xs, signs):
        far = np.abs(x - idx) > 1e-6 * (xs[-1] - xs[0])
        assert np.array_equal(row[far], (x < idx)[far])
    assert ix.chains[0].indexable[m] == (r["reversals"] == 0 and r["clipped"] == 0)


def test_act_is_the_brute_force_argmax_over_actions(p12):
    sc, system, bound, ix = p12
    pol = IndexPolicy(system, ix)
    mdp = build(sc)
    st = mdp.states
    tau, cfg = np.asarray(st.tau), np.asarray(st.config)
    acts = pol.act(tau, cfg)
    for s in np.random.default_rng(2).choice(mdp.n_states, 300, replace=False):
        c = int(cfg[s])
        vals = []
        for label in system.automaton.actions[c]:  # label[m] = k + 1: process k sent to server m
            v = 0.0
            for m, k1 in enumerate(label):
                if k1:
                    k = k1 - 1
                    v += ix.index(k, m)[ix.column[k][c], tau[s, k] - 1] - ix.multipliers[m]
            vals.append(v)
        assert vals[acts[s]] >= max(vals) - 1e-12 * max(1.0, abs(max(vals)))
        assert acts[s] == int(np.argmax(vals))


def test_gain_by_two_exact_evaluators(p12):
    sc, system, bound, ix = p12
    pol = IndexPolicy(system, ix)
    mdp = build(sc)
    exact = evaluate(mdp, pol)
    mf = matrix_free_evaluate(system, pol)
    assert mf.gain_lower - 1e-9 * mf.gain <= exact.gain <= mf.gain_upper + 1e-9 * mf.gain
    assert exact.gain >= solve(mdp).gain_lower * (1 - 1e-9)


def test_the_index_policy_is_optimal_when_the_relaxation_is_the_system():
    # one process on one server with idling allowed: the capacity constraint never binds
    # (lambda* = 0), the private chain is the system, and sending when the index exceeds 0 is
    # sending when it is optimal
    sc = shape("one-idle")
    system = System.from_scenario(sc)
    ix = whittle_indices(system)
    assert ix.indexable
    mdp = build(sc)
    assert evaluate(mdp, IndexPolicy(system, ix)).gain == pytest.approx(solve(mdp).gain, rel=1e-9)


def test_factory_and_refusals(p12):
    sc, system, bound, ix = p12
    assert isinstance(make_policy("index", system), IndexPolicy)
    other = System.from_scenario(load_scenario(scenario_path("paper_p14"), ["tau_cap=6"]))
    with pytest.raises(PolicyError, match="another system"):
        IndexPolicy(other, ix)
    from wncs_lp.bounds import grouped_bound

    with pytest.raises(SolverError, match="relaxation 1"):
        whittle_indices(system, grouped_bound(system))
    assert ix.summary()["indexable"] == ix.indexable
