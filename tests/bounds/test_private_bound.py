"""Relaxation 1: validity against the exact optimum, the brute-force LP, tightness where the
relaxation is the system itself, and the multiplier search."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import SHAPES, relaxation1_lp, shape

from wncs_lp import scenario_path
from wncs_lp.bounds import lower_bound, private_bound
from wncs_lp.bounds.private import private_chains, private_lower_bound_at
from wncs_lp.errors import WncsError
from wncs_lp.models import build, model_for
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


def _optimum(sc, method="pi"):
    """The toolkit's certified optimum: (gain_lower, gain_upper)."""
    sol = solve(build(sc), method=method)
    assert sol.status == "optimal"
    return sol.gain_lower, sol.gain_upper


@pytest.mark.parametrize("name,cap", [("paper_p12", 8), ("paper_p123", 7), ("paper_p1234", 7)])
def test_bound_below_the_optimum_on_the_paper_processes(name, cap):
    sc = load_scenario(scenario_path(name), [f"tau_cap={cap}"])
    res = private_bound(sc)
    lo, hi = _optimum(sc, "auto")
    assert res.status == "optimal"
    assert res.lower_bound <= hi * (1 + 1e-12)
    assert res.lower_bound > 0.9 * lo  # a bound, not a trivial one
    assert res.lower_bound <= res.relaxation_upper * (1 + 1e-12)
    assert res.stats["capacity"] == "equality"


@pytest.mark.parametrize("name", SHAPES)
def test_bound_below_the_optimum_on_every_shape(name):
    sc = shape(name)
    res = private_bound(sc)
    lo, hi = _optimum(sc)
    assert res.lower_bound <= hi * (1 + 1e-12), f"{name}: LB {res.lower_bound} above g* <= {hi}"
    assert res.lower_bound > 0.8 * lo
    equality = not sc.model.allow_idle and sc.n_processes >= sc.n_servers
    assert res.stats["capacity"] == ("equality" if equality else "inequality")
    if not equality:
        assert np.all(res.multipliers >= 0)


@pytest.mark.parametrize("name", ["paper", "u3", "idle", "three-servers"])
def test_bound_equals_the_brute_force_lp_of_the_relaxation(name):
    """The LP of relaxation 1 written out whole (reference builder, claims by walking the
    timeline, scipy linprog) has the value of the certified dual the package maximises."""
    sc = shape(name)
    lp = relaxation1_lp(sc)
    res = private_bound(sc, tol=1e-9)
    assert res.lower_bound == pytest.approx(lp, rel=1e-7)
    assert res.lower_bound <= lp * (1 + 1e-9)  # a dual value never exceeds the primal's


def _one_process_one_server(p: float, T: int, U: int, D: int, cap: int):
    return scenario_from_dict({
        "model": {"kind": "wncs", "tau_cap": cap}, "channel": {"success_probability": p},
        "process": [{"A": [[1.1]]}],
        "server": [{"name": "s", "uplink_delay": U, "downlink_delay": D, "processing_time": [T]}],
    })


@pytest.mark.parametrize("p,T,U,D", [(0.8, 1, 0, 0), (0.9, 3, 1, 1), (0.7, 2, 2, 1)])
def test_one_process_on_one_server_is_its_own_relaxation(p, T, U, D):
    """N = M = 1 without idling: the averaged capacity E[claim] = 1 with claim <= 1 forces the
    claim in every visited pair, so the private system is the system and LB = g*."""
    sc = _one_process_one_server(p, T, U, D, cap=12)
    lo, hi = _optimum(sc)
    res = private_bound(sc, tol=1e-10)
    assert lo * (1 - 1e-9) <= res.lower_bound <= hi * (1 + 1e-12)


def test_the_multipliers_maximise_the_certified_bound():
    """LB(lambda) at the returned multipliers is not beaten at any point around them."""
    sc = load_scenario(scenario_path("paper_p1234"), ["tau_cap=9"])
    res = private_bound(sc, tol=1e-9)
    chains, which = private_chains(model_for(sc))
    mult = np.bincount(which).astype(float)
    lam = res.multipliers
    for d in [(1, 0), (-1, 0), (0, 1), (0, -1), (10, -10), (-10, 10), (30, 30), (-30, -30)]:
        lb, _ = private_lower_bound_at(chains, mult, lam + np.array(d, float))
        assert lb <= res.lower_bound * (1 + 1e-9)
    again, _ = private_lower_bound_at(chains, mult, lam)
    assert again == pytest.approx(res.lower_bound, rel=1e-12)


def test_identical_processes_share_one_private_chain():
    sc = load_scenario(scenario_path("bounds_p1234_twice"), ["tau_cap=8"])
    chains, which = private_chains(model_for(sc))
    assert len(chains) == 4 and sorted(np.bincount(which).tolist()) == [2, 2, 2, 2]
    res = private_bound(System.from_scenario(sc), tol=1e-9)
    np.testing.assert_array_equal(res.process_gains[:4], res.process_gains[4:])
    # against the LP written out with one private chain per process (no sharing)
    assert res.lower_bound == pytest.approx(relaxation1_lp(sc), rel=1e-7)


def test_result_parts_add_up():
    res = private_bound(load_scenario(scenario_path("paper_p12"), ["tau_cap=9"]))
    assert res.lower_bound == pytest.approx(res.process_gains.sum() - res.multipliers.sum(), rel=1e-12)
    assert res.tables.n_processes == 2 and res.relaxation == "private-servers"
    assert "gain_lower" in res.certified_by
    summary = res.summary()
    assert summary["lower_bound"] == res.lower_bound and len(summary["multipliers"]) == 2
    assert "private-servers" in repr(res)


def test_preemption_model_is_refused_with_the_reason():
    sc = load_scenario(scenario_path("paper_preemption_p12"), ["tau_cap=7"])
    with pytest.raises(WncsError, match="preemption"):
        private_bound(sc)
    with pytest.raises(WncsError, match="preemption"):
        lower_bound(sc, "private-servers")
