"""The convex front end over the occupation measure (docs/constraints.md section 7).

Expected values come from elsewhere: certified value iteration (``wncs_lp.solve(..., "vi")``)
on the MDP or on the same MDP with another cost vector, the constrained LP route, and closed
forms derived by hand on a three-pair MDP.
"""
from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest

import wncs_lp
from wncs_lp.constrained import LinearConstraint, evaluate_rows, with_cost
from wncs_lp import solve
from wncs_lp.constrained.convex import OccupationProgram
from wncs_lp.errors import InfeasibleConstraintsError, SolverError
from wncs_lp.models.quantities import pair_values
from wncs_lp.scenario import ConstraintSpec


def paper(cap: int):
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=true", f"tau_cap={cap}"])
    return wncs_lp.build(sc)


@pytest.fixture(scope="module")
def p6():
    mdp = paper(6)
    return mdp, OccupationProgram(mdp), wncs_lp.solve(mdp, "vi")


def averages(mdp, policy, vectors):
    """Exact long-run averages of a deterministic (n,) or randomised (L,) policy, by evaluate_rows."""
    pol = np.asarray(policy)
    if pol.shape != (mdp.n_pairs,):
        probs = np.zeros(mdp.n_pairs)
        probs[pol] = 1.0
        pol = probs
    cons = [LinearConstraint(v, max=1e300) for v in vectors]
    return evaluate_rows(mdp, pol, cons)["values"]


# ---------------------------------------------------------------- a hand-made MDP
# state 0: action a (d1 = 0, d2 = 2) goes to state 1; action b (d1 = 3, d2 = 0) stays w.p. 1/2.
# state 1: one action (d1 = d2 = 1) back to state 0.
# Balance: x1 = x_a + x_b / 2, normalisation 2 x_a + 3/2 x_b = 1, so with x_b free:
#   D1 = x_a + 7/2 x_b = 1/2 + 11/4 x_b,   D2 = 3 x_a + 1/2 x_b = 3/2 - 7/4 x_b.
# min max(D1, D2): D1 = D2 at x_b = 2/9, value 10/9, x = (1/3, 2/9, 4/9), pi(b | 0) = 2/5.
# min D2 s.t. D1 <= 0.7: x_b = 4/55, value 151/110, multiplier (7/4) / (11/4) = 7/11.
D1 = np.array([0.0, 3.0, 1.0])
D2 = np.array([2.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def tiny():
    P = np.zeros((2, 2, 2))
    P[0, 0, 1] = 1.0
    P[0, 1, 0] = P[0, 1, 1] = 0.5
    P[1, 0, 0] = 1.0
    cost = np.array([[2.0, 3.0], [2.0, 0.0]])
    feasible = np.array([[True, True], [True, False]])
    return wncs_lp.MDP.from_dense(P, cost, feasible)


def test_tiny_minmax_hand_computed(tiny):
    prog = OccupationProgram(tiny)
    sol = prog.solve(cp.Minimize(cp.maximum(prog.average(D1), prog.average(D2))))
    assert sol.method == "convex" and sol.ok, sol
    assert sol.gain == pytest.approx(10 / 9, rel=1e-9)
    assert sol.stats["objective_exact"] == sol.gain and sol.stats["certificate"] == "solver_dual"
    assert sol.gain_lower == pytest.approx(10 / 9, rel=1e-7) and sol.gain_upper == sol.gain
    np.testing.assert_allclose(sol.occupation, [1 / 3, 2 / 9, 4 / 9], atol=1e-9)
    np.testing.assert_allclose(sol.policy, [3 / 5, 2 / 5, 1.0], atol=1e-8)
    assert sol.randomized_states.tolist() == [0]
    assert sol.stats["cost_exact"] == pytest.approx(2 / 3 + 3 * 2 / 9 + 2 * 4 / 9, rel=1e-9)
    # the same optimum in epigraph form: an auxiliary variable, re-optimised with x fixed
    t = cp.Variable()
    epi = prog.solve(cp.Minimize(t), {"d1": prog.average(D1) <= t, "d2": prog.average(D2) <= t})
    assert epi.ok and epi.gain == pytest.approx(10 / 9, rel=1e-8)
    assert epi.stats["objective_exact_method"].startswith("resolved")
    assert [c.label for c in epi.constraints] == ["d1", "d2"] and all(c.active for c in epi.constraints)
    # the process names need a scenario
    with pytest.raises(SolverError, match="needs an MDP built by wncs_lp.build"):
        prog.process_cost(0)


def test_tiny_linear_program_hand_computed(tiny):
    prog = OccupationProgram(tiny)
    sol = prog.solve(cp.Minimize(prog.average(D2)), {"d1 <= 0.7": prog.average(D1) <= 0.7})
    assert sol.ok and sol.stats["certificate"] == "lagrangian", sol
    assert sol.gain == pytest.approx(151 / 110, rel=1e-9)
    # the Lagrangian bound is first-order in the multiplier's error (L is piecewise linear in lambda)
    assert sol.gain_lower <= sol.gain + 1e-12 and sol.gain_lower == pytest.approx(151 / 110, rel=1e-7)
    (rep,) = sol.constraints
    assert rep.active and rep.value == pytest.approx(0.7, rel=1e-9) and rep.multiplier == pytest.approx(7 / 11, rel=1e-6)
    # the same bound written as 0.7 >= D1, and a Maximize of the negated objective plus a constant
    alt = prog.solve(cp.Maximize(5 - prog.average(D2)), [0.7 >= prog.average(D1)])
    assert alt.ok and alt.gain == pytest.approx(5 - 151 / 110, rel=1e-9)
    assert alt.gain_lower <= alt.gain_upper + 1e-12 and alt.gain_upper == pytest.approx(5 - 151 / 110, rel=1e-8)


def test_cost_objective_is_the_unconstrained_optimum(p6):
    mdp, prog, vi = p6
    sol = prog.solve(cp.Minimize(prog.cost()))
    assert sol.ok and sol.method == "convex" and sol.stats["certificate"] == "lagrangian", sol
    # the certified value-iteration bracket contains the program's value; the brackets overlap
    tol = 1e-9 * vi.gain
    assert vi.gain_lower - tol <= sol.gain <= vi.gain_upper + tol
    assert sol.gain_lower <= vi.gain_upper + tol and vi.gain_lower <= sol.gain_upper + tol
    assert sol.gap <= 1e-6
    assert sol.stats["cost_exact"] == pytest.approx(sol.gain, rel=1e-12)
    # the solver's own numbers are reported
    for key in ("solver_status", "solver_objective", "solver_dual_objective", "duality_gap_abs", "duality_gap_rel"):
        assert key in sol.stats
    assert sol.stats["solver_objective"] == pytest.approx(vi.gain, rel=1e-7)


def test_linear_constraint_matches_the_constrained_lp(p6):
    mdp, prog, vi = p6
    rate = pair_values(mdp, ConstraintSpec("send_rate", server=0))
    B = 0.7 * float(averages(mdp, vi.policy, [rate])[0])
    ref = solve(mdp, "lp", constraints=[ConstraintSpec("send_rate", server=0, max=B, label="x")])
    sol = prog.solve(cp.Minimize(prog.cost()), {"x": prog.send_rate(0) <= B})
    assert ref.ok and sol.ok, (ref, sol)
    assert sol.gain == pytest.approx(ref.gain, rel=1e-7)
    assert sol.gain_lower == pytest.approx(ref.gain_lower, rel=1e-6)
    assert sol.gain > vi.gain_upper  # the bound binds
    (a,), (b,) = sol.constraints, ref.constraints
    assert a.active and a.value == pytest.approx(B, rel=1e-7) and a.multiplier == pytest.approx(b.multiplier, rel=1e-4)
    assert sol.n_randomized <= 1  # crossover: a basic solution randomises in at most one state
    # by name, and the exact averages of the returned policy agree with the report
    by_name = prog.solve(cp.Minimize(prog.cost()), [prog.send_rate("remote") <= B])
    assert by_name.gain == pytest.approx(sol.gain, rel=1e-9)
    assert prog.value(prog.send_rate(0), sol) == pytest.approx(float(averages(mdp, sol.policy, [rate])[0]), rel=1e-12)


def test_minmax_fairness_between_independent_bounds():
    mdp = paper(7)  # process 1 dominates: the unconstrained optimum is not min-max fair at this cap
    prog = OccupationProgram(mdp)
    mse = [prog.process_cost(k) for k in range(2)]
    fair = prog.solve(cp.Minimize(cp.maximum(*mse)))
    assert fair.ok, fair
    vecs = [pair_values(mdp, ConstraintSpec("process_cost", process=k)) for k in range(2)]
    exact = averages(mdp, fair.policy, vecs)
    assert fair.gain == pytest.approx(max(exact), rel=1e-12)  # the reported value is the exact max-MSE
    assert fair.stats["cost_exact"] == pytest.approx(sum(exact), rel=1e-9)
    # upper: the unconstrained optimal policy's max-MSE; lower: max over k of the per-process optimum
    vi = wncs_lp.solve(mdp, "vi")
    unconstrained_max = max(averages(mdp, vi.policy, vecs))
    per_process = [wncs_lp.solve(with_cost(mdp, v), "vi") for v in vecs]
    lower = max(s.gain_lower for s in per_process)
    assert lower * (1 - 1e-8) <= fair.gain <= unconstrained_max * (1 + 1e-9)
    assert fair.gain < unconstrained_max - 1.0
    # here the lower bound is attained (the policy minimising process 1's MSE keeps process 2 below it)
    assert fair.gain == pytest.approx(lower, rel=1e-7)
    assert fair.gain_lower <= fair.gain_upper * (1 + 1e-8) and fair.gap <= 1e-6
    # the program's quantities match the scenario's per-pair vectors
    assert prog.value(mse[1], fair) == pytest.approx(exact[1], rel=1e-12)


def test_bad_names_and_failed_solves_raise_one_clear_error(p6):
    mdp, prog, _ = p6
    cases = [
        (lambda: prog.process_cost("process-3"), "process_cost: unknown process 'process-3'; the processes are "
                                                 "0 = 'process-1', 1 = 'process-2'"),
        (lambda: prog.aoi(2), "aoi: process index 2 out of range (0-based)"),
        (lambda: prog.send_rate("cloud"), "send_rate: unknown server 'cloud'; the servers are 0 = 'remote', 1 = 'edge'"),
        (lambda: prog.send_rate(0, process="nope"), "send_rate: unknown process 'nope'"),
        (lambda: prog.send_rate(True), "send_rate: a server is a 0-based index or a name, got True"),
        (lambda: prog.average(np.ones(3)), "one value per state-action pair"),
    ]
    for call, text in cases:
        with pytest.raises(SolverError) as err:
            call()
        msg = str(err.value)
        assert text in msg and "\n" not in msg, msg
    assert prog.process_cost("process-2") is not None and prog.server_names == ("remote", "edge")
    with pytest.raises(InfeasibleConstraintsError, match="solver status infeasible"):
        prog.solve(cp.Minimize(prog.cost()), {"impossible": prog.send_rate(0) >= 1.5})
    with pytest.raises(SolverError, match="not convex"):
        prog.solve(cp.Maximize(cp.maximum(prog.process_cost(0), prog.process_cost(1))))
    with pytest.raises(SolverError, match="must be cvxpy.Minimize"):
        prog.solve(prog.cost())
    with pytest.raises(SolverError, match="unrecognized solver setting 'nonsense'"):
        prog.solve(cp.Minimize(prog.cost()), settings={"nonsense": 1})
    # an iteration limit is not hidden: the policy is still evaluated exactly, the status says why
    short = prog.solve(cp.Minimize(cp.maximum(prog.process_cost(0), prog.process_cost(1))), max_iter=2)
    # (cvxpy's own word, by cvxpy's table: an iteration limit is MAX_ITER)
    assert short.status == "max_iter:user_limit" and short.stats["clarabel_status"] == "MaxIterations"
    assert short.status_code == "max_iter" and not short.ok
