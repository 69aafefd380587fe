"""The scenarios shipped for the bounds: what they are, and a bound below a simulated policy."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.bounds import bound_policy, private_bound
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario
from wncs_lp.simulate import simulate


def test_eight_processes_are_the_paper_types_twice():
    sc = load_scenario(scenario_path("bounds_p1234_twice"))
    paper = load_scenario(scenario_path("paper_p1234"))
    assert sc.n_processes == 8 and sc.tau_caps == (20,) * 8
    for k in range(8):
        np.testing.assert_array_equal(sc.processes[k].A, paper.processes[k % 4].A)
    assert [s.processing_time for s in sc.servers] == [t * 2 for t in (s.processing_time for s in paper.servers)]


def test_mix_and_three_servers():
    mix = load_scenario(scenario_path("bounds_mix6"))
    assert mix.n_processes == 6 and mix.n_servers == 2
    fog = load_scenario(scenario_path("bounds_p1234_fog"))
    assert fog.n_processes == 4 and [s.name for s in fog.servers] == ["remote", "edge", "fog"]
    assert (fog.servers[2].uplink_delay, fog.servers[2].downlink_delay) == (1, 0)


@pytest.mark.parametrize("name", ["bounds_p1234_twice", "bounds_mix6", "bounds_p1234_fog"])
def test_bound_below_its_simulated_policy(name):
    sc = load_scenario(scenario_path(name), ["tau_cap=8"])
    system = System.from_scenario(sc)
    res = private_bound(system)
    assert res.status == "optimal" and res.lower_bound > 0
    mc = simulate(bound_policy(res, system), slots=3000, reps=6, seed=1, burn_in=300, progress=False)
    assert res.lower_bound <= mc.mean + 5 * mc.stderr
