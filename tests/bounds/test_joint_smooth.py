"""Relaxation 2 by L-BFGS on the entropy-smoothed lumped Lagrangian (bounds/joint_smooth.py): the
soft Bellman operator lies within its smoothing error below the hard one (numba and numpy alike),
and the smoothed ascent reaches the LP's optimum (HiGHS's interior point on the whole LP), which
the supergradient steps do not, below the exact g* (the solver)."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import EDGE, REMOTE

from wncs_lp import solve
from wncs_lp.bounds.joint import joint_bound
from wncs_lp.bounds.joint_chains import JointData, Kernels
from wncs_lp.bounds.joint_ipm import ipm_tables
from wncs_lp.bounds.joint_symmetry import lumped_chains, process_symmetry
from wncs_lp.bounds.private import private_bound
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

SLOW, FAST = [[1.05]], [[1.3]]


@pytest.fixture(scope="module")
def twice():
    """Two scalar processes (A = 1.05, 1.3) twice (two classes of interchangeable processes) at cap 5:
    the system, its LP's optimum (IPX, whole LP, no symmetry), relaxation 1's bound and g*. Here
    relaxation 2's optimum is 0.3% above relaxation 1's bound."""
    sc = scenario_from_dict({"model": {"kind": "wncs", "tau_cap": 5}, "channel": {"success_probability": 0.9},
                             "process": [{"A": SLOW}, {"A": FAST}, {"A": SLOW}, {"A": FAST}],
                             "server": [REMOTE, EDGE]}, source="<smooth>")
    system = System.from_scenario(sc)
    lp = ipm_tables(JointData.from_system(system), tol=1e-9).objective
    return system, lp, private_bound(system).lower_bound, solve(build(sc)).gain_upper


@pytest.mark.parametrize("eta", [0.05, 2.0])
def test_soft_bellman_is_within_its_smoothing_error_below_the_hard_one(twice, eta):
    """min_p v_p - eta log A <= softmin_eta v <= min_p v_p at every state, the weights a
    distribution over each configuration's pairs; numba and numpy give the same."""
    system = twice[0]
    data = JointData.from_system(system)
    chain = lumped_chains(process_symmetry(system, data), data).chains[1]
    rng = np.random.default_rng(3)
    h = rng.normal(scale=5.0, size=(chain.n_configs, int(chain.caps[0])))
    price = rng.normal(scale=2.0, size=chain.n_pairs)
    hard, pol = np.empty_like(h), np.empty(h.shape, dtype=np.int64)
    Kernels("numpy").bellman(chain, 0, h, price, hard, pol)
    out = {}
    for name in ("numba", "numpy"):
        th, w = np.empty_like(h), np.empty((chain.n_pairs, h.shape[1]))
        Kernels(name).soft_bellman(chain, 0, h, price, eta, th, w)
        out[name] = th, w
    np.testing.assert_allclose(out["numba"][0], out["numpy"][0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out["numba"][1], out["numpy"][1], rtol=1e-10, atol=1e-14)
    th, w = out["numba"]
    n_act = np.diff(chain.act_ptr)[:, None]
    assert np.all(th <= hard + 1e-12) and np.all(th >= hard - eta * np.log(n_act) - 1e-12)
    np.testing.assert_allclose(np.add.reduceat(w, chain.act_ptr[:-1], axis=0), 1.0, rtol=1e-12)


def test_smooth_reaches_the_lp_optimum_below_g_star(twice):
    """From relaxation 1's prices the smoothed ascent certifies the LP's optimum (to 1e-5: its last
    temperature's error bound is 1e-4), above relaxation 1 and the supergradient steps' bound, and
    below g*."""
    system, lp, r1, g_star = twice
    res = joint_bound(system, method="smooth", max_iter=1000, time_limit=None)
    steps = joint_bound(system, method="ascent", max_iter=40, time_limit=None)
    assert res.stats["classes"] == [[0, 2], [1, 3]] and res.stats["found_in"] == "the smoothed ascent"
    assert r1 < steps.lower_bound < res.lower_bound <= g_star
    assert res.lower_bound == pytest.approx(lp, rel=1e-5) and lp <= g_star * (1 + 1e-9)


def test_smooth_stopped_after_one_evaluation_still_certifies(twice):
    """A search cut short keeps the best unsmoothed point met (here the start): relaxation 1's
    prices on the lumped chains, a valid bound at least relaxation 1's (to the chains' tolerance)."""
    system, lp, r1, g_star = twice
    res = joint_bound(system, method="smooth", max_iter=1, time_limit=None)
    assert res.stats["ascent_steps"] == 2 and r1 * (1 - 1e-5) <= res.lower_bound <= lp * (1 + 1e-9) and res.lower_bound <= g_star
