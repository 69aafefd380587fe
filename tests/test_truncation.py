"""The mass at the cap (exact stationary law vs a Monte Carlo run of the same chain) and the
lower-bound property of the cap: g*(C) <= g*(C') for C < C' while every loop fits under C."""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp
from wncs_lp.chain import PolicyChain
from wncs_lp.errors import ModelError
from wncs_lp.truncation import CAP_MASS_WARN, cap_mass, policy_cap_mass


def test_cap_mass_agrees_with_a_monte_carlo_run_of_the_chain():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    sol = wncs_lp.solve(mdp, "vi")
    cm = policy_cap_mass(mdp, sol.policy)
    assert cm.total > CAP_MASS_WARN and cm.warn and "warning" in cm.message()
    # independent: walk the induced chain with a seeded generator and count slots at the cap
    P = PolicyChain(mdp, sol.policy).P.tocsr()
    rng = np.random.default_rng(7)
    at_cap = (np.asarray(mdp.states.tau) == np.asarray(mdp.states.caps)).any(axis=1)
    s, hits, T = 0, 0, 200_000
    u = rng.random(T)
    for t in range(T):
        row = slice(P.indptr[s], P.indptr[s + 1])
        s = int(P.indices[row][min(np.searchsorted(np.cumsum(P.data[row]), u[t], side="right"), P.indptr[s + 1] - P.indptr[s] - 1)])
        hits += at_cap[s]
    est = hits / T
    # slots are correlated: allow a generous band (the chain mixes within tens of slots)
    assert abs(est - cm.total) < 0.02, (est, cm.total)
    assert sum(cm.per_process) >= cm.total - 1e-12 and max(cm.per_process) <= cm.total + 1e-12


def test_occupation_and_state_law_give_the_same_mass():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    sol = wncs_lp.solve(mdp, "lp")
    pi = PolicyChain(mdp, sol.policy).stationary
    occ = np.zeros(mdp.n_pairs)
    occ[sol.policy] = pi
    assert cap_mass(mdp, occ).total == pytest.approx(cap_mass(mdp, pi).total, abs=1e-12)
    with pytest.raises(ModelError, match="expected a state law"):
        cap_mass(mdp, np.ones(3))


@pytest.mark.parametrize("name, caps", [("paper_p12", (8, 10)), ("paper_preemption_p12", (8, 10))])
def test_optimal_gain_is_non_decreasing_in_the_cap(name, caps):
    lo, hi = (wncs_lp.solve(wncs_lp.build(wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={c}"])), "vi")
              for c in caps)
    assert lo.gain_upper <= hi.gain_lower, (lo.gain, hi.gain)
