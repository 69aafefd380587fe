"""Every relaxation's bound below the exact optimum at five and six processes (issue 33): small
caps, several shapes -- three servers with asymmetric links (per-server p_up / p_down), idling
allowed with interchangeable processes (relaxation 2's LP reduced by their symmetry), the paper's
remote + edge servers -- each with g* from the enumerated MDP's LP (an independent solver of the
whole system), and the relaxations' order: relaxations 2 and 3 never looser than relaxation 1."""
from __future__ import annotations

import pytest

from wncs_lp.bounds import lower_bound
from wncs_lp.bounds.lower import AUTO_PAIRS_MIN_GAIN
from wncs_lp.bounds.joint import ipm_plan
from wncs_lp.bounds.joint_chains import JointData
from wncs_lp.bounds.joint_symmetry import process_symmetry
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


def _server(name, U, D, T, **links):
    return {"name": name, "uplink_delay": U, "downlink_delay": D, "processing_time": T, **links}


def _scalar(a, cap, weight=1.0):
    return {"A": [[a]], "weight": weight, "tau_cap": cap}


SHAPES = {
    # five processes on three servers, every link asymmetric, no idling (equality capacities)
    "five, three servers, asymmetric links": (
        [_scalar(1.1, 4), _scalar(1.05, 4), _scalar(1.2, 3), _scalar(1.02, 3, 2.0), _scalar(1.3, 3)],
        [_server("a", 0, 0, [1, 1, 2, 1, 1], p_up=0.7, p_down=0.95),
         _server("b", 0, 0, [2, 2, 1, 2, 2], p_up=0.95, p_down=0.8),
         _server("c", 0, 1, [1, 1, 1, 1, 1], p_up=0.9, p_down=0.6)], False),
    # six processes, idling allowed (inequality capacities), two interchangeable pairs
    "six, idling, interchangeable pairs": (
        [_scalar(1.1, 5), _scalar(1.3, 4), _scalar(1.1, 5), _scalar(1.3, 4), _scalar(1.05, 4), _scalar(1.2, 4)],
        [_server("a", 0, 0, [2, 1, 2, 1, 1, 2], p_up=0.8, p_down=0.9), _server("b", 1, 0, [1, 1, 1, 1, 2, 1])], True),
    # six processes on the paper's remote (U = D = 1) and edge servers
    "six, remote and edge": (
        [_scalar(1.1, 4), _scalar(1.3, 3), _scalar(1.05, 4), _scalar(1.3, 3), _scalar(1.02, 3), _scalar(1.2, 3)],
        [_server("remote", 1, 1, [1] * 6), _server("edge", 0, 0, [2, 2, 1, 1, 2, 1])], False),
}


@pytest.fixture(scope="module", params=list(SHAPES), ids=list(SHAPES))
def case(request):
    procs, servers, idle = SHAPES[request.param]
    sc = scenario_from_dict({"model": {"kind": "wncs", "allow_idle": idle}, "channel": {"success_probability": 0.9},
                             "process": procs, "server": servers}, source=f"<{request.param}>")
    system = System.from_scenario(sc)
    auto = lower_bound(system, "auto")  # relaxations 1 and 2 (by the interior point: small LPs)
    grouped = lower_bound(system, 3)
    return request.param, system, solve(build(sc)).gain_upper, auto, grouped


def test_every_bound_is_below_g_star(case):
    _, _, g_star, auto, grouped = case
    bounds = {**auto.stats["auto_bounds"], grouped.relaxation: grouped.lower_bound}
    assert {"private-servers", "joint-configuration", "grouped-private-servers"} <= set(bounds)
    assert set(bounds) <= {"private-servers", "joint-configuration", "grouped-private-servers", "joint-pairs",
                           "joint-all-pairs"}
    for name, value in bounds.items():
        assert value <= g_star, (name, value, g_star)
    assert auto.lower_bound == max(auto.stats["auto_bounds"].values())


def test_relaxations_2_and_3_never_looser_than_relaxation_1(case):
    _, _, _, auto, grouped = case
    bounds = auto.stats["auto_bounds"]
    r1 = bounds["private-servers"]
    assert auto.stats.get("ipm_tables") is True or auto.relaxation != "joint-configuration"
    assert bounds["joint-configuration"] >= r1 - 1e-4 * abs(r1)  # the interior point's tolerance
    assert grouped.lower_bound >= r1 - 1e-9 * abs(r1)


def test_auto_keeps_relaxation_4_only_where_its_start_pays(case):
    """Relaxation 4 runs after relaxation 2's interior point; kept (and then valid above) only
    where its start raised relaxation 2's bound by more than AUTO_PAIRS_MIN_GAIN, said otherwise."""
    _, _, _, auto, _ = case
    bounds = auto.stats["auto_bounds"]
    if "joint-pairs" in bounds:
        assert bounds["joint-pairs"] > bounds["joint-configuration"] * (1 + AUTO_PAIRS_MIN_GAIN)
        assert auto.relaxation in ("joint-pairs", "joint-all-pairs")
    else:
        assert "relaxation 4" in auto.stats["auto_reason"]


def test_the_shapes_are_not_degenerate(case):
    """Relaxation 1 is strictly below g* on every shape, so the bounds are tested where they can err."""
    _, _, g_star, auto, _ = case
    assert auto.stats["auto_bounds"]["private-servers"] < g_star * (1 - 1e-3)


def test_interchangeable_processes_reduce_the_lp(case):
    name, system, _, _, _ = case
    data = JointData.from_system(system)
    classes = ipm_plan(data, process_symmetry(system, data))["classes"]
    assert classes == ([[0, 2], [1, 3]] if "interchangeable" in name else [])
