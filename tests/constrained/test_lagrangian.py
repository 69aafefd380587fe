"""The Lagrangian route for one constraint (spec section 5) against independent expectations.

Hand-made MDPs whose constrained optimum is derived in closed form here; the paper model
against the constrained LP (another algorithm) and the unconstrained LP; unreachable bounds
against the least send rate computed by the unconstrained LP with cost d.
"""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp
from wncs_lp.constrained import LinearConstraint, with_cost
from wncs_lp import solve
from wncs_lp.constrained.lagrangian import LP_MAX_PAIRS, solve_lagrangian
from wncs_lp.errors import InfeasibleConstraintsError, SolverError
from wncs_lp.mdp import MDP
from wncs_lp.scenario import ConstraintSpec

# --------------------------------------------------------------------------- hand-made MDPs
Q = 0.8  # success probability of a send


def sender_mdp() -> MDP:
    """State 0 "stale" (cost 2), state 1 "fresh" (cost 0.5).

    In state 0: action 0 = wait (stay), action 1 = send (to state 1 w.p. Q, else stay).
    State 1 decays back to 0 w.p. 1/2 (both actions identical there).

    With send probability p in state 0: mu_1 = 2 p Q mu_0, so mu_0 = 1 / (1 + 2pQ),
    send rate = p / (1 + 2pQ), gain = (2 + pQ) / (1 + 2pQ). Always sending is optimal
    unconstrained (rate 1 / (1 + 2Q) = 5/13). Under rate <= b < 5/13 the bound binds:
    p* = b / (1 - 2Qb) (not linear in b: one randomised state, a ratio), and the gain along
    the bound is g(b) = 2 - 3Qb, so the multiplier is lambda* = -g'(b) = 3Q = 2.4.
    """
    P = np.zeros((2, 2, 2))
    P[0, 0] = [1.0, 0.0]
    P[0, 1] = [1 - Q, Q]
    P[1, 0] = P[1, 1] = [0.5, 0.5]
    cost = np.array([[2.0, 2.0], [0.5, 0.5]])
    return MDP.from_dense(P, cost)


def send_values(mdp: MDP) -> np.ndarray:
    """1 on the pair (state 0, send)."""
    return ((mdp.s_indices == 0) & (mdp.a_indices == 1)).astype(float)


def pair(mdp: MDP, s: int, a: int) -> int:
    return int(np.flatnonzero((mdp.s_indices == s) & (mdp.a_indices == a))[0])


@pytest.mark.parametrize("b", [0.05, 0.2, 0.3])
def test_sender_max_bound_matches_closed_form(b):
    mdp = sender_mdp()
    con = LinearConstraint(send_values(mdp), max=b, label="send <= b")
    sol = solve_lagrangian(mdp, [con])
    p_star = b / (1 - 2 * Q * b)
    assert sol.status == "optimal"
    assert sol.gain == pytest.approx(2 - 3 * Q * b, rel=1e-9)
    assert sol.gain_lower <= 2 - 3 * Q * b + 1e-9 <= sol.gain_upper + 2e-9
    assert sol.multipliers[0] == pytest.approx(3 * Q, rel=1e-6)
    assert list(sol.randomized_states) == [0]
    assert sol.policy[pair(mdp, 0, 1)] == pytest.approx(p_star, rel=1e-9)
    assert sol.policy[pair(mdp, 0, 0)] == pytest.approx(1 - p_star, rel=1e-9)
    assert sol.constraints[0].value == pytest.approx(b, rel=1e-9)
    assert sol.constraints[0].active and sol.constraints[0].side == "max"
    assert sol.stats["mix_state"] == 0


def test_sender_min_form_and_two_sided():
    """The same bound written as -rate >= -b (a min row) and as 0.01 <= rate <= b."""
    mdp = sender_mdp()
    b = 0.2
    neg = solve_lagrangian(mdp, [LinearConstraint(-send_values(mdp), min=-b, label="-send >= -b")])
    two = solve_lagrangian(mdp, [LinearConstraint(send_values(mdp), min=0.01, max=b, label="0.01 <= send <= b")])
    for sol, side in ((neg, "min"), (two, "max")):
        assert sol.status == "optimal"
        assert sol.stats["binding_side"] == side
        assert sol.gain == pytest.approx(2 - 3 * Q * b, rel=1e-9)
        assert sol.multipliers[0] == pytest.approx(3 * Q, rel=1e-6)
        assert sol.policy[pair(mdp, 0, 1)] == pytest.approx(b / (1 - 2 * Q * b), rel=1e-9)


def test_sender_min_bound_binding_from_below():
    """A send costs e = 3 more, so never sending is optimal (gain 2). Under rate >= b the
    gain is the sender's plus e times the rate: g(b) = 2 - 3Qb + eb at the same p*, and the
    multiplier of the min bound is g'(b) = e - 3Q."""
    P = np.zeros((2, 2, 2))
    P[0, 0] = [1.0, 0.0]
    P[0, 1] = [1 - Q, Q]
    P[1, 0] = P[1, 1] = [0.5, 0.5]
    e = 3.0
    cost = np.array([[2.0, 2.0 + e], [0.5, 0.5]])
    mdp = MDP.from_dense(P, cost)
    b = 0.1
    sol = solve_lagrangian(mdp, [LinearConstraint(send_values(mdp), min=b, label="send >= b")])
    p = b / (1 - 2 * Q * b)
    g = (2 + p * Q + e * p) / (1 + 2 * p * Q)  # = 2 - 3Qb + e b along the bound
    assert g == pytest.approx(2 - 3 * Q * b + e * b)
    assert sol.status == "optimal"
    assert sol.stats["binding_side"] == "min"
    assert sol.gain == pytest.approx(g, rel=1e-9)
    assert sol.multipliers[0] == pytest.approx(e - 3 * Q, rel=1e-6)  # d g / d b = e - 3Q > 0
    assert sol.policy[pair(mdp, 0, 1)] == pytest.approx(p, rel=1e-9)


def test_sender_non_binding_and_unreachable():
    mdp = sender_mdp()
    free = solve_lagrangian(mdp, [LinearConstraint(send_values(mdp), max=0.5)])
    assert free.status == "optimal" and free.multipliers[0] == 0.0 and free.n_randomized == 0
    assert free.gain == pytest.approx((2 + Q) / (1 + 2 * Q), rel=1e-12)  # always send
    with pytest.raises(InfeasibleConstraintsError) as err:
        solve_lagrangian(mdp, [LinearConstraint(send_values(mdp), min=0.5, label="send >= 0.5")])
    assert err.value.reachable[0] == pytest.approx(1 / (1 + 2 * Q), rel=1e-8)  # the largest rate
    assert err.value.sides == ("min",)


def test_walk_skips_multichain_intermediate():
    """Two states, "stay" or "move" in each; being in state 1 costs 0 but uses the resource.

    Unconstrained: go to 1 and stay (cost 0, use 1). Under use <= 0.3 the optimum spends
    30% of the time in state 1 at cost 0.7 (lambda* = 1, where every policy ties). The walk
    from (move, stay) to (stay, move) in the natural order first makes (stay, stay):
    two recurrent classes, skipped; the reverse order passes through (move, move), use 1/2,
    and mixes in state 0: stay w.p. p with 0.7 = mu_0 = 1 / (1 + (1 - p)), so p = 4/7.
    """
    P = np.zeros((2, 2, 2))
    P[0, 0] = [1, 0]  # stay
    P[0, 1] = [0, 1]  # move
    P[1, 0] = [0, 1]  # stay
    P[1, 1] = [1, 0]  # move
    cost = np.array([[1.0, 1.0], [0.0, 0.0]])
    mdp = MDP.from_dense(P, cost)
    use = (mdp.s_indices == 1).astype(float)
    sol = solve_lagrangian(mdp, [LinearConstraint(use, max=0.3, label="use <= 0.3")])
    assert sol.status == "optimal"
    assert sol.gain == pytest.approx(0.7, rel=1e-9)
    assert sol.multipliers[0] == pytest.approx(1.0, rel=1e-9)
    assert sol.stats["walk_multichain_skipped"] >= 1
    assert sol.stats["walk_order"] == "reverse"
    assert list(sol.randomized_states) == [0]
    assert sol.policy[pair(mdp, 0, 0)] == pytest.approx(4 / 7, rel=1e-9)
    assert sol.policy[pair(mdp, 1, 1)] == 1.0


def test_rejects_several_constraints():
    mdp = sender_mdp()
    con = LinearConstraint(send_values(mdp), max=0.2)
    with pytest.raises(SolverError):
        solve_lagrangian(mdp, [con, con])


# --------------------------------------------------------------------------- the paper model
@pytest.fixture(scope="module")
def p12():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=true", "tau_cap=6"])
    return wncs_lp.build(sc)


def remote(B: float | None = None, **kw) -> ConstraintSpec:
    return ConstraintSpec("send_rate", server=0, max=B, label=f"send_rate[remote] <= {B}", **kw)


@pytest.mark.parametrize("B", [0.05, 0.2, 0.33])
def test_paper_agrees_with_constrained_lp(p12, B):
    lp = solve(p12, "lp", constraints=[remote(B)])
    lag = solve(p12, "lagrangian", constraints=[remote(B)])
    assert lp.status == "optimal" and lag.status == "optimal"
    assert lag.method == "lagrangian"
    # each gain inside the other's certificate (up to the certificates' own widths)
    tol = 1e-6 * lp.gain
    assert lp.gain_lower - tol <= lag.gain <= lp.gain_upper + tol
    assert lag.gain_lower - tol <= lp.gain <= lag.gain_upper + tol
    assert lag.gain == pytest.approx(lp.gain, rel=1e-7)
    assert lag.multipliers[0] == pytest.approx(lp.multipliers[0], rel=1e-4)
    assert lag.n_randomized <= 1
    assert lag.constraints[0].value == pytest.approx(B, abs=1e-7)
    assert lag.stats["lambda_converged"]


def test_paper_non_binding_is_unconstrained_optimum(p12):
    free = wncs_lp.solve(p12, "lp")
    sol = solve_lagrangian(p12, wncs_lp.constrained.constraints_for(p12, [remote(0.9)]))
    assert sol.status == "optimal"
    assert sol.multipliers[0] == 0.0 and sol.n_randomized == 0
    assert sol.gain == pytest.approx(free.gain, rel=1e-9)
    assert sol.stats["lambda_steps"] == 1


def test_paper_unreachable_bound_names_least_rate():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=false", "tau_cap=6"])
    mdp = wncs_lp.build(sc)
    d = wncs_lp.constrained.constraints_for(mdp, [remote(1.0)])[0].values
    least = wncs_lp.solve(with_cost(mdp, d), "lp").gain  # the unconstrained LP with cost d
    assert least > 0.05
    with pytest.raises(InfeasibleConstraintsError) as err:
        solve(mdp, "lagrangian", constraints=[remote(0.5 * least)])
    assert err.value.reachable[0] == pytest.approx(least, rel=1e-7, abs=1e-9)
    assert err.value.sides == ("max",)


def test_auto_switches_at_lp_max_pairs(monkeypatch):
    import wncs_lp.constrained.lagrangian as lagrangian

    assert isinstance(LP_MAX_PAIRS, int) and LP_MAX_PAIRS > 4
    mdp = sender_mdp()  # 4 pairs
    con = LinearConstraint(send_values(mdp), max=0.2)
    small = solve(mdp, "auto", constraints=[con])
    assert small.method == "lp-highs" and small.gain == pytest.approx(2 - 3 * Q * 0.2, rel=1e-9)
    monkeypatch.setattr(lagrangian, "LP_MAX_PAIRS", 3)
    sol = solve(mdp, "auto", constraints=[con])
    assert sol.method == "lagrangian" and sol.stats["method_requested"] == "auto"
    assert sol.gain == pytest.approx(2 - 3 * Q * 0.2, rel=1e-9)
