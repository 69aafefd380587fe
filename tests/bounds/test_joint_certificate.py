"""The certificate of relaxation 2 (``certify_tables``), the only thing its bound rests on, against
references that do not use it: the Bellman sub-solution test state by state over the AoI box and
over the enumerated MDP (tests/bounds/joint_reference.py), and the exact g* of the solver."""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import shape
from joint_reference import box_gain, box_value_iteration, mdp_gain, three_processes

from wncs_lp import scenario_path
from wncs_lp.errors import SolverError
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp import solve
from wncs_lp.bounds.joint_chains import JointData, certify_tables

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

SHAPES = ("paper", "u2", "idle", "three processes")


@pytest.fixture(scope="module", params=SHAPES)
def case(request):
    sc = three_processes() if request.param == "three processes" else shape(request.param)
    system = System.from_scenario(sc)
    mdp = build(sc)
    return system, JointData.from_system(system), mdp, solve(mdp).gain_upper


def _random_tables(system, rng, scale=50.0, offset=0.0):
    return [offset + scale * rng.standard_normal((system.n_configs, int(c))) for c in system.caps]


def test_certificate_is_the_box_test_state_by_state(case):
    """-max_p sum_k max_tau [...] equals min over every (tau, C, a) of c + E h' - h, and never
    exceeds the same test on the reachable pairs of the enumerated MDP."""
    system, data, mdp, _ = case
    rng = np.random.default_rng(7)
    for _ in range(3):
        tables = _random_tables(system, rng)
        cert = certify_tables(data, tables)
        assert cert.raw == pytest.approx(box_gain(system, tables), rel=1e-12, abs=1e-9)
        assert cert.lower_bound <= cert.raw <= mdp_gain(mdp, tables) + 1e-9


def test_any_tables_give_a_lower_bound(case):
    system, data, _, g_star = case
    rng = np.random.default_rng(11)
    for scale, offset in ((1.0, 0.0), (300.0, 0.0), (5.0, 1e9)):
        assert certify_tables(data, _random_tables(system, rng, scale, offset)).lower_bound <= g_star


def test_round_off_is_bounded_under_huge_offsets(case):
    """Per-process constants change no constraint: tables shifted by 2^33 (exactly: the entries
    are multiples of 2^-10) certify the same bound within the round-off bounds."""
    system, data, _, _ = case
    tables = [np.round(t * 1024) / 1024 for t in _random_tables(system, np.random.default_rng(3))]
    a = certify_tables(data, tables)
    b = certify_tables(data, [t + 2.0 ** 33 * (k + 1) for k, t in enumerate(tables)])
    assert abs(a.raw - b.raw) <= a.roundoff + b.roundoff
    assert 0 < a.roundoff < 1e-6


def _one_process():
    return scenario_from_dict({
        "model": {"kind": "wncs", "tau_cap": 9}, "channel": {"success_probability": 0.9},
        "process": [{"A": [[1.02, 1], [0, 1]]}],
        "server": [{"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1},
                   {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2}]},
        source="<one process>")


def test_exact_bias_certifies_g_star_and_broken_tables_are_rejected():
    """One process: the separable form is the whole value function, so the exact bias over the
    box certifies g* (the certificate is not loose); raising one value breaks the Bellman
    inequality there, and the check then certifies less, exactly as the box test says."""
    sc = _one_process()
    system = System.from_scenario(sc)
    data = JointData.from_system(system)
    g_star = solve(build(sc)).gain_upper
    lo, hi, bias = box_value_iteration(system)
    assert lo == pytest.approx(g_star, rel=1e-9) and hi == pytest.approx(g_star, rel=1e-9)
    good = certify_tables(data, [bias])
    assert good.lower_bound == pytest.approx(g_star, rel=1e-9) and good.lower_bound <= g_star * (1 + 1e-12)
    for c, t in ((0, 3), (system.n_configs - 1, 0), (1, 8)):
        broken = bias.copy()
        broken[c, t] += 25.0
        cert = certify_tables(data, [broken])
        assert cert.lower_bound < good.lower_bound - 1.0
        assert cert.raw == pytest.approx(box_gain(system, [broken]), rel=1e-12)


def test_bad_tables_certify_nothing_or_are_refused():
    system = System.from_scenario(load_scenario(scenario_path("paper_p12"), ["tau_cap=7"]))
    data = JointData.from_system(system)
    tables = [np.zeros((system.n_configs, int(c))) for c in system.caps]
    tables[1][3, 2] = np.nan
    assert certify_tables(data, tables).lower_bound == -np.inf
    tables[1][3, 2] = np.inf
    assert certify_tables(data, tables).lower_bound == -np.inf
    with pytest.raises(SolverError, match="process 2 has shape"):
        certify_tables(data, [tables[0], tables[1][:, :-1]])
    with pytest.raises(SolverError, match="2 value tables"):
        certify_tables(data, tables[:1])


def test_numba_and_numpy_kernels_agree(case):
    """The priced chain's Bellman operator and the stationary push: numba against numpy / scipy."""
    from wncs_lp.bounds.joint_chains import Kernels, kernels_available

    if not kernels_available():
        pytest.fail("numba is a test dependency of relaxation 2")
    system, data, _, _ = case
    rng = np.random.default_rng(5)
    fast, slow = Kernels("numba"), Kernels("numpy")
    for k in range(data.n_processes):
        shape_k = (data.n_configs, int(data.caps[k]))
        h, price = rng.standard_normal(shape_k), rng.standard_normal(data.n_pairs)
        out = [np.empty(shape_k), np.empty(shape_k)]
        pols = [np.empty(shape_k, np.int64), np.empty(shape_k, np.int64)]
        fast.bellman(data, k, h, price, out[0], pols[0])
        slow.bellman(data, k, h, price, out[1], pols[1])
        np.testing.assert_allclose(out[0], out[1], rtol=1e-12, atol=1e-12)
        w = rng.random((data.n_pairs, shape_k[1]))
        y = rng.random(shape_k)
        pushed = [np.empty(shape_k), np.empty(shape_k)]
        fast.push(data, k, y, w, pushed[0])
        slow.push(data, k, y, w, pushed[1])
        np.testing.assert_allclose(pushed[0], pushed[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("lazy", [0.5, 0.25, 0.1])
def test_lazy_power_finds_the_stationary_law_of_a_periodic_chain(lazy):
    """The cuts' power iteration on a chain of period 2 (a walk on 0..4 reflecting at both ends:
    plain power iteration oscillates) reaches its stationary law, the closed form of a
    birth-death chain, pi_i proportional to prod_{j<i} up_j / down_{j+1}, for every lazy weight."""
    from wncs_lp.bounds.joint_chains import lazy_power

    up = np.array([1.0, 0.6, 0.3, 0.2, 0.0])
    P = np.zeros((5, 5))
    for i in range(5):
        if i < 4:
            P[i, i + 1] = up[i]
        if i > 0:
            P[i, i - 1] = 1.0 - up[i]
    pi = np.cumprod(np.r_[1.0, up[:-1] / (1.0 - up[1:])])
    pi /= pi.sum()

    def push(y, out):
        out[:] = y @ P

    y, res, sweeps = lazy_power(push, np.ones(5), tol=1e-13, max_sweeps=100_000, lazy=lazy)
    assert res <= 1e-13 and sweeps < 100_000
    np.testing.assert_allclose(y, pi, rtol=1e-10, atol=1e-13)
    with pytest.raises(SolverError, match="lazy"):
        lazy_power(push, np.ones(5), tol=1e-9, max_sweeps=10, lazy=1.0)
