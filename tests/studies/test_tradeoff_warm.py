"""Warm-started trade-off curves (issue 18): HiGHS dual simplex re-solves from the previous basis.

Expectations come from elsewhere than the warm path: the cold curve (Clarabel interior point +
crossover, a different solver and algorithm) point by point; the two-state closed form
g*(b) = 1 - 2b, lambda = 2 (tests/constrained/test_lp.py); the least reachable send rate 0 from
the model (with ``allow_idle`` the remote server can stay unused).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import wncs_lp
from wncs_lp.constrained import LinearConstraint, constraints_for
from wncs_lp.constrained import warm as warm_mod
from wncs_lp.studies.tradeoff import read_points, tradeoff
from wncs_lp.constrained.warm import WarmConstrainedLP
from wncs_lp.errors import InfeasibleConstraintsError, SolverError
from wncs_lp.scenario import ConstraintSpec


def two_state_mdp() -> wncs_lp.MDP:
    """The two-state MDP of test_lp.py: state 0 "stay" (cost 1) or "go" (cost 0, to state 1),
    state 1 back to 0 (cost 0). With the "go" frequency bounded by b < 1/2: g* = 1 - 2b, lambda = 2,
    and the optimal policy goes with probability b / (1 - b)."""
    P = np.zeros((2, 2, 2))
    P[0, 0, 0] = 1.0
    P[0, 1, 1] = 1.0
    P[1, 0, 0] = 1.0
    cost = np.array([[1.0, 0.0], [0.0, 0.0]])
    feasible = np.array([[True, True], [True, False]])
    return wncs_lp.MDP.from_dense(P, cost, feasible)


GO = np.array([0.0, 1.0, 0.0])  # pairs: (0, stay), (0, go), (1, back)
ROOT = Path(__file__).resolve().parents[2]
REMOTE = ConstraintSpec("send_rate", server=0, max=0.2, label="send_rate[remote] <= 0.2")
EDGE = ConstraintSpec("send_rate", server=1, max=0.3, label="send_rate[edge] <= 0.3")
# b = -0.05 is infeasible (least rate 0); kinks of the curve at cap 7 avoided by the grid
GRID = [-0.05, 0.02, 0.06, 0.1, 0.15, 0.2, 0.25, 0.3, 0.33, 0.45]


@pytest.fixture(scope="module")
def p7():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=true", "tau_cap=7"])
    return wncs_lp.build(sc)


@pytest.fixture(scope="module")
def curves(p7):
    return (tradeoff(p7, [REMOTE], 0, GRID, method="lp", plot=False),
            tradeoff(p7, [REMOTE], 0, GRID, method="lp", plot=False, warm=False))


def test_warm_curve_equals_the_cold_curve_point_by_point(curves):
    warm, cold = curves
    assert [p.bound for p in warm.points] == [p.bound for p in cold.points] == GRID
    assert [p.feasible for p in warm.points] == [p.feasible for p in cold.points]
    methods = [p.method for p in warm.points if p.feasible]
    assert methods[0] == "lp-highs" and set(methods[1:]) == {"lp-warm"}  # only the first feasible point is cold
    assert {p.method for p in cold.points if p.feasible} == {"lp"}
    for w, c in zip(warm.feasible_points, cold.feasible_points):
        assert w.ok and c.ok, (w, c)
        assert w.gain == pytest.approx(c.gain, rel=1e-9)
        assert w.gain_lower <= w.gain * (1 + 1e-12) and w.gain_upper - w.gain_lower <= 1e-6 * w.gain
        assert w.multiplier == pytest.approx(c.multiplier, rel=1e-6, abs=1e-6 * w.gain)
        assert w.value == pytest.approx(c.value, abs=1e-9)
        assert w.randomized_states <= 1  # a basic solution: one bound row, at most one mixed state
    assert sum(p.multiplier > 0 for p in warm.feasible_points) >= 4  # the bound binds on much of the grid


def test_infeasible_bound_inside_a_warm_sweep_is_a_row_and_the_sweep_goes_on(p7, curves):
    warm, _ = curves
    p = warm.point(-0.05)
    assert p.status == "infeasible" and p.reachable == pytest.approx(0.0, abs=1e-9)
    # in the middle of a sweep: the points after it are re-solved warm and still certified
    res = tradeoff(p7, [REMOTE], 0, [-0.2, -0.1, 0.1, 0.2], method="lp", plot=False)
    assert [q.status for q in res.points] == ["infeasible", "infeasible", "optimal", "optimal"]
    assert res.point(0.2).gain == pytest.approx(warm.point(0.2).gain, rel=1e-9)
    # the same through the solver object: infeasible between two feasible bounds
    (c,) = constraints_for(p7, [REMOTE])
    solver = WarmConstrainedLP(p7, [c])
    a = solver.solve([c.with_bounds(max=0.1)])
    with pytest.raises(InfeasibleConstraintsError) as info:
        solver.solve([c.with_bounds(max=-0.01)])
    assert info.value.sides == ("max",) and info.value.reachable[0] == pytest.approx(0.0, abs=1e-9)
    b = solver.solve([c.with_bounds(max=0.15)])
    assert a.method == "lp-highs" and b.method == "lp-warm" and b.ok
    assert b.gain == pytest.approx(warm.point(0.15).gain, rel=1e-9)


def test_two_state_closed_form_through_the_warm_path():
    mdp = two_state_mdp()
    bs = [0.1, 0.2, 0.35, 0.4, 0.45]
    res = tradeoff(mdp, [LinearConstraint(GO, max=0.1, label="go <= b")], 0, bs, method="lp", plot=False)
    for b, p in zip(bs, res.points):
        assert p.ok and p.gain == pytest.approx(1 - 2 * b, abs=1e-10)
        assert p.gain_lower <= 1 - 2 * b + 1e-10 <= p.gain_upper + 2e-10
        assert p.multiplier == pytest.approx(2.0, rel=1e-9)
        assert p.randomized_states == 1 and p.value == pytest.approx(b, abs=1e-12)
    assert [p.method for p in res.points] == ["lp-highs"] + ["lp-warm"] * 4
    # the policy itself: go with probability b / (1 - b) in state 0
    solver = WarmConstrainedLP(mdp, [LinearConstraint(GO, max=0.1)])
    for b in (0.3, 0.1):
        sol = solver.solve([LinearConstraint(GO, max=b)])
        assert sol.policy[1] == pytest.approx(b / (1 - b), abs=1e-12)
        assert list(sol.randomized_states) == [0]


def test_other_constraints_stay_fixed_and_rows_must_match(p7):
    res = tradeoff(p7, [EDGE, REMOTE], 1, [0.1, 0.2], method="lp", plot=False)
    cold = tradeoff(p7, [EDGE, REMOTE], 1, [0.1, 0.2], method="lp", plot=False, warm=False)
    np.testing.assert_allclose(res.gains, cold.gains, rtol=1e-9)
    assert res.points[1].method == "lp-warm"
    (c,) = constraints_for(p7, [REMOTE])
    solver = WarmConstrainedLP(p7, [c])
    with pytest.raises(SolverError, match="only their bounds may change"):
        solver.solve([c.with_bounds(min=0.0)])  # a new row
    (e,) = constraints_for(p7, [EDGE])
    with pytest.raises(SolverError, match="only their bounds may change"):
        solver.solve([e])  # other values


class _Interrupt:
    """Wraps WarmConstrainedLP.solve: counts calls and raises KeyboardInterrupt at call ``stop``."""

    def __init__(self, real, stop=None):
        self.real, self.stop, self.calls, self.bounds = real, stop, 0, []

    def __call__(self, obj, constraints, **kw):
        self.calls += 1
        if self.stop is not None and self.calls == self.stop:
            raise KeyboardInterrupt
        self.bounds.append(constraints[0].max)
        return self.real(obj, constraints, **kw)

    def method(self):
        """A plain function (bound as a method when set on the class)."""
        return lambda obj, constraints, **kw: self(obj, constraints, **kw)


def test_interrupted_warm_sweep_resumes(p7, curves, tmp_path, monkeypatch):
    real = WarmConstrainedLP.solve
    grid = [0.05, 0.1, 0.15, 0.2, 0.25]
    first = _Interrupt(real, stop=3)
    monkeypatch.setattr(warm_mod.WarmConstrainedLP, "solve", first.method())
    with pytest.raises(KeyboardInterrupt):
        tradeoff(p7, [REMOTE], 0, grid, method="lp", out=tmp_path / "t", plot=False)
    assert [p.bound for p in read_points(tmp_path / "t" / "tradeoff.csv")] == [0.05, 0.1]
    second = _Interrupt(real)
    monkeypatch.setattr(warm_mod.WarmConstrainedLP, "solve", second.method())
    res = tradeoff(p7, [REMOTE], 0, grid, method="lp", out=tmp_path / "t", plot=False)
    assert second.calls == 3 and second.bounds == [0.15, 0.2, 0.25]
    assert res.computed == 3 and res.reused == 2 and [p.bound for p in res.points] == grid
    assert [p.method for p in res.points] == ["lp-highs", "lp-warm", "lp-highs", "lp-warm", "lp-warm"]
    # the same numbers as the cold curve (another solver), and a cold rerun into the same folder
    # is accepted (warm and cold solve the same LP: not a setting that must match)
    cold = tradeoff(p7, [REMOTE], 0, grid, method="lp", plot=False, warm=False)
    np.testing.assert_allclose(res.gains, cold.gains, rtol=1e-9)
    third = tradeoff(p7, [REMOTE], 0, grid + [0.3], method="lp", out=tmp_path / "t", plot=False, warm=False)
    assert third.reused == 5 and third.computed == 1 and third.point(0.3).method == "lp"


def test_warm_restart_over_budget_is_solved_cold(p7):
    (c,) = constraints_for(p7, [REMOTE])
    solver = WarmConstrainedLP(p7, [c], budget=0.0)  # every restart is out of budget at once
    a = solver.solve([c.with_bounds(max=0.05)])
    b = solver.solve([c.with_bounds(max=0.3)])
    assert a.method == b.method == "lp-highs" and b.ok
    assert "warm_abandoned" in b.stats and solver.solves["abandoned"] == 1
    cold = WarmConstrainedLP(p7, [c.with_bounds(max=0.3)]).solve([c.with_bounds(max=0.3)])
    assert b.gain == pytest.approx(cold.gain, rel=1e-12)


def test_cli_cold_flag(tmp_path):
    text = Path(wncs_lp.scenario_path("paper_p12.toml")).read_text().replace("allow_idle = false", "allow_idle = true")
    sc = tmp_path / "p12_remote.toml"
    sc.write_text(text + '\n[[constraint]]\nquantity = "send_rate"\nserver = "remote"\nmax = 0.2\n')

    def run(out, *extra):
        proc = subprocess.run([sys.executable, "-m", "wncs_lp", "tradeoff", str(sc), "--constraint", "1", "--values",
                               "0.1:0.3:0.1", "--set", "tau_cap=6", "--method", "lp", "--out", str(tmp_path / out),
                               "--no-plot", *extra], capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert proc.returncode == 0, proc.stderr
        return read_points(tmp_path / out / "tradeoff.csv")

    warm, cold = run("w"), run("c", "--cold")
    assert [p.method for p in warm] == ["lp-highs", "lp-warm", "lp-warm"]
    assert [p.method for p in cold] == ["lp"] * 3
    np.testing.assert_allclose([p.gain for p in warm], [p.gain for p in cold], rtol=1e-9)
