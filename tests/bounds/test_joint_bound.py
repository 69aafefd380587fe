"""Relaxation 2 (joint configuration): its bound against the exact g* (the solver) and the
relaxation's own optimum (its approximate LP written out whole over the box, HiGHS), its
certificate redone by the independent box test, never looser than relaxation 1, and auto."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import shape
from joint_reference import box_alp, box_gain, three_processes

from wncs_lp.bounds import lower_bound, private_bound
from wncs_lp.bounds.joint import joint_reach
from wncs_lp.bounds.joint_chains import JointData, certify_tables
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp import solve
from wncs_lp.status import OPTIMAL

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

CASES = ("paper", "idle", "three processes")


@pytest.fixture(scope="module", params=CASES)
def case(request):
    sc = three_processes() if request.param == "three processes" else shape(request.param)
    system = System.from_scenario(sc)
    return system, lower_bound(system, 2, time_limit=60.0), solve(build(sc)).gain_upper


def test_bound_is_certified_and_below_the_optimum(case):
    system, res, g_star = case
    assert res.relaxation == "joint-configuration" and res.stats["certified"]
    assert "separable check" in res.certified_by
    # the number returned is what the independent box test certifies for the returned tables
    assert res.lower_bound <= box_gain(system, res.tables.h)
    assert res.lower_bound == certify_tables(JointData.from_system(system), res.tables.h).lower_bound
    assert res.lower_bound <= g_star


def test_bound_reaches_the_relaxation_optimum(case):
    """The approximate LP over the box, solved whole: the certified bound is a feasible point of it
    (never above) and, solved to tol = 1e-4, within 1e-3 of it."""
    system, res, g_star = case
    alp = box_alp(system)
    assert alp <= g_star * (1 + 1e-9)
    assert res.lower_bound <= alp * (1 + 1e-9)
    assert res.lower_bound >= alp * (1 - 1e-3)


def test_never_looser_than_relaxation_1(case):
    """Relaxation 1's prices mu_k = lambda . claim_k, centred, make every process's joint chain at
    least its private one, so relaxation 2 is at least relaxation 1 (docs/bounds.md)."""
    system, res, _ = case
    r1 = private_bound(system)
    assert res.lower_bound >= r1.lower_bound - 1e-6 * abs(r1.lower_bound)


def test_auto_takes_the_better_certified_bound():
    system = System.from_scenario(three_processes(tau_cap=4))
    r1, r2 = private_bound(system), lower_bound(system, 2)
    auto = lower_bound(system, "auto")
    assert auto.lower_bound >= max(r1.lower_bound, r2.lower_bound) * (1 - 1e-6)
    assert auto.lower_bound == max(auto.stats["auto_bounds"].values())
    assert auto.stats["auto_choice"] == auto.relaxation and auto.stats["auto_reason"]


def test_a_stopped_search_still_returns_a_certified_bound():
    system = System.from_scenario(three_processes())
    res = lower_bound(system, 2, time_limit=0.0)
    assert res.status != OPTIMAL and res.stats["certified"]
    assert np.isfinite(res.lower_bound)
    assert res.lower_bound <= box_gain(system, res.tables.h)
    assert joint_reach(system) is None
