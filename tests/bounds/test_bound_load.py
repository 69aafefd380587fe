"""Bounds in the many-sensors-per-server regime (issue 33; docs/bounds.md, "Many sensors on one
server"): the lab's scalar sensors (A = 1.05, 1.1, 1.15, ...; p = 0.8) queued on ONE server, the
edge one (U = D = 0, T = 2) or the cloud one (U = D = 1, T = 1). g* comes from the enumerated MDP's
LP (the whole system, an independent solver). Every relaxation lies below it; a group holding
every sensor of the server (relaxation 3's and 4's pair at two sensors, relaxation 3's triple at
three) is the whole system and meets it. How loose the others are is a measurement
(benchmarks/calibration_load.py), not asserted here: nothing independent fixes it."""
from __future__ import annotations

import pytest

from wncs_lp import solve
from wncs_lp.bounds import grouped_bound, lower_bound
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

A = (1.05, 1.1, 1.15)
SERVERS = {"edge": {"uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2},
           "cloud": {"uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1}}
#: (server, sensors, cap)
CASES = [("edge", 2, 12), ("edge", 3, 12), ("cloud", 2, 12)]


@pytest.fixture(scope="module", params=CASES, ids=[f"{s}-{n}-cap{c}" for s, n, c in CASES])
def case(request):
    server, n, cap = request.param
    sc = scenario_from_dict({"model": {"kind": "wncs", "allow_idle": False, "tau_cap": cap},
                             "channel": {"success_probability": 0.8},
                             "process": [{"A": [[a]], "R": [[1.0]]} for a in A[:n]],
                             "server": [{"name": server, **SERVERS[server]}]}, source=f"<{request.param}>")
    system = System.from_scenario(sc)
    bounds = {number: lower_bound(system, number, **({"method": "ipm"} if number == 2 else {})).lower_bound
              for number in (1, 2, 3, 4)}
    whole = grouped_bound(system, [tuple(range(n))]).lower_bound if n == 3 else None
    return server, n, solve(build(sc)).gain_upper, bounds, whole


def test_every_relaxation_is_below_g_star(case):
    _, _, g_star, bounds, _ = case
    for number, value in bounds.items():
        assert value <= g_star * (1 + 1e-9), (number, value, g_star)


def test_groups_never_looser_and_whole_groups_exact(case):
    _, n, g_star, bounds, whole = case
    assert bounds[4] >= bounds[2] - 1e-6 * g_star  # pairs carry relaxation 2's tables
    assert bounds[3] >= bounds[1] - 1e-9 * g_star
    if n == 2:  # the pair is every sensor of the one server: the whole system
        assert bounds[3] == pytest.approx(g_star, rel=1e-6)
        assert bounds[4] == pytest.approx(g_star, rel=1e-5)
    else:
        assert whole == pytest.approx(g_star, rel=1e-8)  # the group of all three is the whole system

