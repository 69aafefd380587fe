"""The level-2 prototype of benchmarks/level2_lp.py (every pair's ages on the joint configuration at
once; docs/bounds.md, "Many sensors on one server"): its certificate -- the approximate-LP
inequality checked over the whole AoI box -- is a lower bound on g* from the enumerated MDP's LP
(an independent solver) for the LP's own duals and for arbitrary tables, and the LP is exact with
one pair of sensors on one server (the pair is the whole system)."""
from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from wncs_lp import solve
from wncs_lp.bounds.joint_chains import JointData
from wncs_lp.models import build

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")



@pytest.fixture(scope="module")
def prototype():
    """benchmarks/level2_lp.py, imported and then taken off sys.path and sys.modules again: the
    benchmarks put their folder first on sys.path, where its modules (policies, bounds, ...) would
    shadow the test folders of the same names for every later test in this process."""
    folder = Path(__file__).resolve().parents[2] / "benchmarks"
    path = list(sys.path)
    sys.path.insert(0, str(folder))
    try:
        level2 = importlib.import_module("level2_lp")
        system_for = importlib.import_module("calibration_load").system_for
    finally:
        sys.path[:] = path
        for name, module in list(sys.modules.items()):
            if Path(getattr(module, "__file__", None) or "/").parent == folder:
                del sys.modules[name]
    return level2, system_for


@pytest.mark.parametrize("sensors", [2, 3])
def test_the_certificate_is_below_g_star_and_exact_for_one_pair(prototype, sensors):
    level2, system_for = prototype
    level2_lp, certify_level2 = level2.level2_lp, level2.certify_level2
    system = system_for("edge", sensors, 8)
    g_star = solve(build(system.scenario)).gain_upper
    data = JointData.from_system(system)
    A, b, c = level2_lp(data)
    res = linprog(c, A_eq=A, b_eq=b, bounds=(0, None), method="highs-ipm")
    assert res.status == 0
    cert = certify_level2(data, res.eqlin.marginals)
    assert cert <= g_star * (1 + 1e-12)
    assert cert == pytest.approx(res.fun, rel=1e-5)  # the duals' tables carry the LP's value
    if sensors == 2:
        assert cert == pytest.approx(g_star, rel=1e-6)
    rng = np.random.default_rng(0)  # any tables give a valid (weak) bound
    assert certify_level2(data, rng.normal(scale=10.0, size=res.eqlin.marginals.size)) <= g_star
