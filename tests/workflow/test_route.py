"""The one route from a scenario to a solution (issue 23 section 1, issue 27 item 17).

Expectations come from elsewhere than the route: the gain of the same scenario built and solved
by hand with another method; the matrix-free answer against value iteration on the built MDP;
the registry's rows against the signatures of the functions they name.
"""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp
from wncs_lp import methods
from wncs_lp.errors import SolverError
from wncs_lp.models import guard
from wncs_lp.constrained.registry import CONSTRAINED_ENTRIES
from wncs_lp.solvers.registry import AVERAGE
from wncs_lp.workflow import ScenarioSolve, WarmStart, run_scenario

P12 = wncs_lp.scenario_path("paper_p12")


@pytest.fixture(scope="module")
def small():
    sc = wncs_lp.load_scenario(P12, ["tau_cap=8"])
    return sc, wncs_lp.build(sc)


def _within(sol, gain: float, rel: float = 1e-8) -> bool:
    slack = rel * abs(sol.gain)
    return sol.gain_lower - slack <= gain <= sol.gain_upper + slack


def test_solve_takes_a_scenario_a_file_or_a_shipped_name(small, tmp_path):
    sc, mdp = small
    ref = wncs_lp.solve(mdp, "pi")
    assert _within(ref, wncs_lp.solve(sc).gain)
    path = tmp_path / "p12.toml"
    path.write_text(P12.read_text().replace("tau_cap = 12", "tau_cap = 8"))
    assert _within(ref, wncs_lp.solve(str(path), "vi").gain)
    assert _within(ref, wncs_lp.solve(path, "vi").gain)
    shipped = wncs_lp.solve("paper_p12", "vi")  # its own cap, 12
    whole = wncs_lp.solve(wncs_lp.build(wncs_lp.load_scenario(P12)), "pi")
    assert _within(whole, shipped.gain)


@pytest.mark.parametrize("bad", [None, 42, [1, 2], {"p": 0.9}])
def test_anything_else_is_one_solver_error_naming_its_type(bad):
    with pytest.raises(SolverError, match=type(bad).__name__):
        wncs_lp.solve(bad)


def test_the_constrained_step_names_a_scenario_instead_of_an_attribute_error():
    from wncs_lp.constrained.registry import run_constrained

    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=7"])
    with pytest.raises(SolverError, match="takes an MDP.*got Scenario"):
        run_constrained(sc, sc.constraints)
    # wncs_lp.solve solves a scenario's bounds, as the command line does
    got = wncs_lp.solve(sc)
    direct = wncs_lp.solve(wncs_lp.build(sc), "lp-cvxpy", constraints=sc.constraints)
    assert got.gain == pytest.approx(direct.gain, rel=1e-7) and got.stats["method_requested"] == "auto"
    plain = wncs_lp.solve(sc, "vi", constrained=False)
    assert plain.gain < got.gain  # the bound costs something


def test_one_solve_takes_the_criterion_and_its_argument(small):
    """criterion= and its argument: the discounted answer on a scenario is the one on its built MDP
    (the exact value of the same policy: the route adds nothing), a constrained solve of an MDP
    takes its bounds, and each mismatch is one clear error naming what was expected."""
    sc, mdp = small
    direct = wncs_lp.solve(mdp, "lp", discount=0.9)  # the discounted LP on HiGHS
    routed = wncs_lp.solve(sc, discount=0.9)  # auto -> policy iteration, through the route
    assert routed.method == "pi" and routed.ok and direct.ok
    np.testing.assert_allclose(routed.value, direct.value, rtol=1e-9)
    assert wncs_lp.solve(sc, "pi", criterion="discounted", discount=0.9).method == "pi"
    budget = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=7"])
    with pytest.raises(SolverError, match=r"discounted criterion solves the unconstrained problem.*constrained=False"):
        wncs_lp.solve(budget, discount=0.9)
    cons = wncs_lp.solve(wncs_lp.build(budget), "lp", constraints=budget.constraints)
    assert cons.gain > wncs_lp.solve(budget, "lp", criterion="average").gain  # the bound costs something
    for kw, message in [({"criterion": "lp"}, "unknown criterion 'lp'; expected one of 'average', 'discounted'"),
                        ({"criterion": "discounted"}, "needs its discount factor: discount=beta"),
                        ({"criterion": "constrained"}, "needs its bounds: constraints="),
                        ({"discount": 0.9, "criterion": "average"}, "criterion 'average' takes none"),
                        ({"constraints": [], "criterion": "discounted", "discount": 0.5},
                         "criterion 'discounted' takes none"),
                        ({"discount": 1.0}, r"beta must be in \[0, 1\); got 1.0")]:
        with pytest.raises(SolverError, match=message):
            wncs_lp.solve(mdp, **kw)


def test_the_route_reports_what_it_built(small):
    sc, mdp = small
    run = run_scenario(sc, "vi")
    assert isinstance(run, ScenarioSolve) and run.built and run.mdp.n_states == mdp.n_states
    assert run.method == run.requested == "vi" and run.route == "asked for" and not run.constrained
    assert run.build_seconds > 0 and run.seconds >= run.build_seconds
    np.testing.assert_array_equal(run.solution.sigma, run.mdp.a_indices[run.solution.policy])
    assert "vi (asked for)" in repr(run) and "2,703 states" in repr(run)
    mf = run_scenario(sc, "matrix-free")
    assert not mf.built and mf.method == "matrix-free" and _within(run.solution, mf.gain)


def test_auto_falls_back_to_matrix_free_when_the_stored_matrix_would_not_fit(small, monkeypatch):
    sc, mdp = small
    ref = wncs_lp.solve(mdp, "vi")

    def refuse(scenario, **kw):
        raise guard.SizeLimitError("the MDP would need more memory than the limit", None)

    monkeypatch.setattr(guard, "build_checked", refuse)
    run = run_scenario(sc)
    assert run.method == "matrix-free" and run.requested == "auto" and run.mdp is None
    assert run.route == "auto: the stored matrix would not fit in memory" and _within(ref, run.gain)
    assert wncs_lp.solve(sc).method == "matrix-free"  # the library's auto is the command line's
    for kw in ({"need_mdp": True}, {"method": "vi"}):  # the caller needs the MDP, or asked for a stored one
        with pytest.raises(guard.SizeLimitError):
            run_scenario(sc, **kw)


def test_a_warm_start_is_used_on_the_same_state_space_only(small):
    sc, mdp = small
    first = run_scenario(sc, "vi")
    warm = first.warm()
    assert isinstance(warm, WarmStart)
    again = run_scenario(sc.with_overrides({"p": 0.85}), "vi", warm=warm)
    assert again.warm_start and again.solution.iterations < first.solution.iterations
    pi = run_scenario(sc.with_overrides({"p": 0.85}), "pi", warm=warm)
    assert pi.warm_start and _within(again.solution, pi.gain)
    lp = run_scenario(sc.with_overrides({"p": 0.85}), "lp", warm=warm)
    assert not lp.warm_start  # the LP takes none
    other = run_scenario(sc.with_overrides({"tau_cap": 7}), "vi", warm=warm)
    assert not other.warm_start  # another state space


def test_a_method_for_the_other_kind_of_problem_is_refused_with_the_list(small):
    sc, _ = small
    with pytest.raises(SolverError, match="'lagrangian' does not solve an unconstrained scenario.*matrix-free"):
        run_scenario(sc, "lagrangian")
    budget = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=7"])
    with pytest.raises(SolverError, match=r"'rvi' does not solve a scenario with \[\[constraint\]\] tables"):
        run_scenario(budget, "rvi")
    with pytest.raises(SolverError, match="takes no keyword 'tolerance'"):
        run_scenario(sc, "vi", tolerance=1e-8)


# ----------------------------------------------------------------------------- the registry
def test_every_row_of_the_vocabulary_has_one_entry_and_no_other():
    assert [e.row for e in AVERAGE.values()] == list(methods.TABLE.values())
    assert [e.row for e in CONSTRAINED_ENTRIES.values()] == list(methods.CONSTRAINED.values())
    assert all(e.row.criterion == methods.AVERAGE for e in AVERAGE.values())
    assert all(e.row.criterion == methods.CONSTRAINED_CRITERION for e in CONSTRAINED_ENTRIES.values())


@pytest.mark.parametrize("entry", [*AVERAGE.values(), *CONSTRAINED_ENTRIES.values()], ids=lambda e: e.row.name)
def test_every_row_names_a_function_that_takes_what_the_row_says(entry):
    import inspect

    row = entry.row
    if entry.choose is not None:
        assert entry.run is None and callable(entry.choose)
        return
    fn = entry.function()
    params = inspect.signature(fn).parameters
    for key, _ in row.preset:
        assert key in params
    warm = {methods.BIAS: "h0", methods.POLICY: "policy0"}.get(row.warm_start)
    if warm is not None:
        assert warm in params
    assert row.memory in (methods.STORED, methods.STORED_LP, methods.BOX)
    if row.takes == methods.SCENARIO_INPUT:
        assert callable(entry.function(on_mdp=True)) and row.memory == methods.BOX
    if row.fallback is not None:
        assert methods.TABLE[row.fallback].takes == methods.SCENARIO_INPUT
