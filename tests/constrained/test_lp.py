"""The constrained occupation-measure LP against independent answers.

* a two-state MDP whose constrained optimum is known in closed form;
* strong duality on the paper's model: LP value = Lagrangian bound = exact cost of the policy;
* Clarabel direct and through cvxpy agree; a bound that does not bind leaves the unconstrained
  optimum (certified value iteration) unchanged; infeasible bounds name what is reachable.
"""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp
from wncs_lp.chain import PolicyChain
from wncs_lp.constrained import LinearConstraint, with_cost
from wncs_lp import solve
from wncs_lp.errors import InfeasibleConstraintsError, SolverError
from wncs_lp.evaluate import evaluate
from wncs_lp.models.quantities import pair_values
from wncs_lp.models.system import System
from wncs_lp.scenario import ConstraintSpec


def two_state_mdp() -> wncs_lp.MDP:
    """State 0: "stay" (cost 1, stay in 0) or "go" (cost 0, to state 1); state 1: back to 0, cost 0.

    Going with probability p in state 0 gives pi(0) = 1/(1+p), average cost (1-p)/(1+p) and
    a "go" frequency p/(1+p). Bounding that frequency by b < 1/2: p* = b/(1-b), g* = 1 - 2b
    (linear in b, so the multiplier is 2).
    """
    P = np.zeros((2, 2, 2))
    P[0, 0, 0] = 1.0  # stay
    P[0, 1, 1] = 1.0  # go
    P[1, 0, 0] = 1.0
    cost = np.array([[1.0, 0.0], [0.0, 0.0]])
    feasible = np.array([[True, True], [True, False]])
    return wncs_lp.MDP.from_dense(P, cost, feasible)


GO = np.array([0.0, 1.0, 0.0])  # pairs: (0, stay), (0, go), (1, back)


@pytest.mark.parametrize("method", ["lp", "lp-highs", "lp-cvxpy"])
@pytest.mark.parametrize("b", [0.1, 0.2, 0.4])
def test_closed_form_two_state_mix(method, b):
    mdp = two_state_mdp()
    sol = solve(mdp, method, constraints=[LinearConstraint(GO, max=b, label="go <= b")])
    assert sol.ok, sol
    assert sol.gain == pytest.approx(1 - 2 * b, abs=1e-8)
    assert sol.gain_lower <= 1 - 2 * b + 1e-8 and sol.gain_upper >= 1 - 2 * b - 1e-8
    assert list(sol.randomized_states) == [0]
    assert sol.policy[1] == pytest.approx(b / (1 - b), abs=1e-8)  # not b: the mix is not the frequency
    (rep,) = sol.constraints
    assert rep.active and rep.side == "max" and rep.value == pytest.approx(b, abs=1e-9)
    assert rep.multiplier == pytest.approx(2.0, rel=1e-6)


def test_min_bound_enters_as_a_max_bound_with_positive_multiplier():
    # "stay" frequency >= 0.7 is the same set as "go" frequency <= 0.15 (x_stay + 2 x_go = 1)
    mdp = two_state_mdp()
    stay = np.array([1.0, 0.0, 0.0])
    sol = solve(mdp, "lp", constraints=[LinearConstraint(stay, min=0.7, label="stay >= 0.7")])
    assert sol.gain == pytest.approx(0.7, abs=1e-8)
    rep = sol.constraints[0]
    assert rep.side == "min" and rep.active
    # g*(m) = m for a min bound m on the stay frequency: dg/dm = +1 = lambda
    assert rep.multiplier == pytest.approx(1.0, rel=1e-6)


@pytest.fixture(scope="module")
def p12():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=true", "tau_cap=6"])
    mdp = wncs_lp.build(sc)
    return sc, mdp, wncs_lp.solve(mdp, "vi")


def test_strong_duality_and_backends_agree(p12):
    _, mdp, opt = p12
    spec = ConstraintSpec("send_rate", server=0, max=0.15, label="send_rate[remote] <= 0.15")
    a = solve(mdp, "lp", constraints=[spec])
    b = solve(mdp, "lp-cvxpy", constraints=[spec])
    c = solve(mdp, "lp-highs", constraints=[spec])
    for s in (a, b, c):
        assert s.ok, s
        # LP value = Lagrangian lower bound = exact cost of the returned policy
        assert s.solver_gain == pytest.approx(s.gain, rel=1e-7)
        assert s.gain_lower == pytest.approx(s.gain, rel=1e-7) and s.gain_lower <= s.gain_upper
        assert s.constraints[0].value <= 0.15 + 1e-9 and s.constraints[0].active
        assert s.n_randomized <= 1
        assert s.gain > opt.gain_upper  # the bound binds
    assert a.gain == pytest.approx(b.gain, rel=1e-7) and a.gain == pytest.approx(c.gain, rel=1e-9)
    assert a.multipliers[0] == pytest.approx(b.multipliers[0], rel=1e-5)
    assert a.multipliers[0] == pytest.approx(c.multipliers[0], rel=1e-5)


def test_policy_values_agree_with_independent_evaluation(p12):
    sc, mdp, _ = p12
    specs = [ConstraintSpec("send_rate", server=0, max=0.15, label="r"),
             ConstraintSpec("process_cost", process=1, max=300.0, label="q2")]
    sol = solve(mdp, "lp", constraints=specs)
    ev = evaluate(mdp, sol.policy, System.from_scenario(sc), "mixed")
    assert ev.randomised and ev.gain == pytest.approx(sol.gain, rel=1e-10)
    assert ev.mse[1] == pytest.approx(sol.constraints[1].value, rel=1e-10)
    # send rate by decoding each pair's action label (not through pair_values)
    sent = np.array([mdp.action_label(l)[0] != 0 for l in range(mdp.n_pairs)], float)
    assert float(sent @ sol.occupation) == pytest.approx(sol.constraints[0].value, abs=1e-12)
    # at most as many randomised states as active bounds (a basic solution)
    assert sol.n_randomized <= sum(c.active for c in sol.constraints)


def test_bound_that_does_not_bind_leaves_the_unconstrained_optimum(p12):
    _, mdp, opt = p12
    d = pair_values(mdp, ConstraintSpec("send_rate", server=0))
    rate = float(d[opt.policy] @ PolicyChain(mdp, opt.policy).stationary)
    sol = solve(mdp, "lp", constraints=[LinearConstraint(d, max=rate + 0.05, label="loose")])
    assert opt.gain_lower - 1e-7 * opt.gain <= sol.gain <= opt.gain_upper + 1e-7 * opt.gain
    assert sol.multipliers[0] == pytest.approx(0.0, abs=1e-6 * opt.gain)
    assert not sol.constraints[0].active and sol.n_randomized == 0


def test_infeasible_bound_names_the_least_reachable_value():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["tau_cap=6"])  # allow_idle = false
    mdp = wncs_lp.build(sc)
    d = pair_values(mdp, ConstraintSpec("send_rate", server=0))
    least = wncs_lp.solve(with_cost(mdp, d), "lp")  # independent: the LP minimising the rate alone
    assert least.gain > 0.01  # without idling the remote server cannot stay unused
    spec = ConstraintSpec("send_rate", server=0, max=0.01, label="send_rate[remote] <= 0.01")
    with pytest.raises(InfeasibleConstraintsError) as info:
        solve(mdp, "lp", constraints=[spec])
    err = info.value
    assert isinstance(err, ValueError) and "\n" not in str(err)
    assert err.constraints == ("send_rate[remote] <= 0.01",) and err.sides == ("max",)
    assert err.reachable[0] == pytest.approx(least.gain, rel=1e-7)
    assert "send_rate[remote] <= 0.01" in str(err) and f"{least.gain:.6g}"[:5] in str(err)


def test_jointly_infeasible_bounds_are_all_named(p12):
    _, mdp, _ = p12
    d = pair_values(mdp, ConstraintSpec("send_rate", server=0))
    cons = [LinearConstraint(d, max=0.1, label="rate <= 0.1"), LinearConstraint(d, min=0.2, label="rate >= 0.2")]
    with pytest.raises(InfeasibleConstraintsError) as info:
        solve(mdp, "lp", constraints=cons)
    assert info.value.jointly and info.value.constraints == ("rate <= 0.1", "rate >= 0.2")


def test_bad_constraint_objects_are_clear(p12):
    _, mdp, _ = p12
    with pytest.raises(SolverError, match="pairs"):
        solve(mdp, "lp", constraints=[LinearConstraint(np.ones(3), max=1.0, label="short")])
    with pytest.raises(SolverError, match="min = 2 > max = 1"):
        LinearConstraint(np.ones(3), max=1.0, min=2.0, label="x")
    with pytest.raises(SolverError, match="finite"):
        LinearConstraint(np.ones(3), max=float("nan"), label="x")
    with pytest.raises(SolverError, match="unknown constrained method"):
        solve(mdp, "simplex", constraints=[ConstraintSpec("cost", max=1e9, label="c")])
    with pytest.raises(SolverError, match="at least one constraint"):
        solve(mdp, "lp", constraints=[])
