"""Relaxation 2 by the interior point (``method="ipm"`` and ``"auto"`` on small LPs): its bound is
what the certificate gives the LP's dual tables, below the exact g* (the solver), never below
relaxation 1, and equal to the relaxation's optimum written out whole over the box (HiGHS)."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import shape
from joint_reference import box_alp, box_gain, three_processes

from wncs_lp.bounds import lower_bound, private_bound
from wncs_lp.bounds.joint import ipm_fits, joint_bound
from wncs_lp.bounds.joint_chains import JointData, certify_tables
from wncs_lp.bounds.joint_ipm import ipm_tables
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

#: processes 1, 2 of the paper at cap 8, the same with a U = 2 remote server, three processes at cap 5
CASES = (("paper", None), ("u2", None), ("three processes", 5))


@pytest.fixture(scope="module", params=CASES, ids=lambda c: c[0])
def case(request):
    name, cap = request.param
    sc = three_processes(cap) if name == "three processes" else shape(name)
    system = System.from_scenario(sc)
    res = joint_bound(system, method="ipm", max_iter=0, ipm_tol=1e-8, time_limit=60.0)
    return system, res, solve(build(sc)).gain_upper


def test_ipm_bound_is_valid(case):
    system, res, g_star = case
    assert res.stats["ipm_tables"] and res.stats["certified"], res.stats.get("ipm_status")
    assert res.lower_bound <= g_star
    assert res.lower_bound <= box_gain(system, res.tables.h)  # the independent box test of its tables
    assert res.lower_bound == certify_tables(JointData.from_system(system), res.tables.h).lower_bound


def test_ipm_bound_is_the_relaxation_optimum(case):
    """At a tight IPX tolerance the certified bound is the box ALP's optimum up to 1e-6 relative."""
    system, res, _ = case
    alp = box_alp(system)
    assert res.lower_bound <= alp * (1 + 1e-9)
    assert res.lower_bound >= alp * (1 - 1e-6)


def test_ipm_never_looser_than_relaxation_1(case):
    system, res, _ = case
    r1 = private_bound(system)
    assert res.lower_bound >= r1.lower_bound - 1e-6 * abs(r1.lower_bound)


def test_ipm_duals_alone_certify_near_the_optimum():
    """The raw duals of IPX (no chains, no bundle) certified directly: within the tolerance asked."""
    system = System.from_scenario(shape("paper"))
    data = JointData.from_system(system)
    run = ipm_tables(data, tol=1e-7)
    assert run.tables is not None and run.iterations > 0
    cert = certify_tables(data, run.tables)
    alp = box_alp(system)
    assert alp * (1 - 1e-5) <= cert.lower_bound <= alp * (1 + 1e-9)


def test_auto_takes_the_interior_point_on_small_lps():
    system = System.from_scenario(three_processes(4))
    assert ipm_fits(JointData.from_system(system))
    res = lower_bound(system, 2, max_iter=3)
    assert res.stats["auto_method"] == "ipm" and np.isfinite(res.lower_bound)
    assert res.lower_bound >= box_alp(system) * (1 - 1e-4)


def test_ipm_runs_after_another_highs_solve_with_other_threads():
    """HiGHS keeps one scheduler per process; an IPX run asking for another thread count would not
    run at all (status kNotset): the interior point must not ask."""
    import highspy

    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 2)
    h.addVar(0.0, 1.0)
    h.changeColCost(0, 1.0)
    h.run()
    data = JointData.from_system(System.from_scenario(three_processes(3)))
    assert ipm_tables(data).tables is not None


def test_ipm_policy_acts_on_the_priced_chains_tables():
    """Processes 1, 2 of the paper at cap 10: the greedy policy on IPX's raw duals is 8.3% above the
    optimum (exact evaluation; the duals are free wherever the LP's optimum puts no mass). The
    result's tables are the priced chains' at the duals' prices, whose policy is optimal there:
    its exact gain meets g* from the solver, and its bound is at least the raw duals'."""
    from wncs_lp import scenario_path
    from wncs_lp.bounds import bound_policy
    from wncs_lp.evaluate import evaluate
    from wncs_lp.scenario import load_scenario

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=10"])
    system, mdp = System.from_scenario(sc), build(sc)
    res = joint_bound(system, method="ipm")
    g_star = solve(mdp).gain_upper
    assert res.stats["found_in"] == "the priced chains at the interior point's prices"
    assert res.lower_bound >= res.stats["ipm_tables_bound"] - 1e-4 * abs(res.lower_bound)
    assert res.lower_bound <= g_star
    assert evaluate(mdp, bound_policy(res, system)).gain <= g_star * (1 + 1e-6)
