"""Relaxation 2's LP reduced by interchangeable processes: the classes are found only where the
automaton is symmetric, the reduced LP has the whole LP's optimum and full row rank, its tables
are spread by the swaps and certify the same bound, below the exact g* (the solver)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from bounds_reference import EDGE, REMOTE

from wncs_lp.bounds.joint import joint_bound
from wncs_lp.bounds.joint_chains import JointData, certify_tables
from wncs_lp.bounds.joint_ipm import ipm_tables
from wncs_lp.bounds.joint_symmetry import ProcessSymmetry, process_symmetry, symmetric_lp, symmetric_lp_shape
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

SCALAR, DOUBLE = [[1.02]], [[1.02, 1], [0, 1]]


def _scenario(procs, servers=(REMOTE, EDGE), cap=3):
    return scenario_from_dict({"model": {"kind": "wncs", "tau_cap": cap}, "channel": {"success_probability": 0.9},
                               "process": procs, "server": list(servers)}, source="<symmetry>")


@pytest.fixture(scope="module")
def twice():
    """Two process types twice (scalar, double integrator, scalar, double integrator) at cap 3."""
    sc = _scenario([{"A": SCALAR}, {"A": DOUBLE}, {"A": SCALAR}, {"A": DOUBLE}])
    system = System.from_scenario(sc)
    data = JointData.from_system(system)
    return system, data, process_symmetry(system, data), solve(build(sc)).gain_upper


def test_classes_are_the_interchangeable_processes(twice):
    _, _, sym, _ = twice
    assert sym.classes == ((0, 2), (1, 3)) and not sym.trivial
    assert sym.generators() == [(0, 2), (1, 3)] and sym.generators(fixed=0) == [(1, 3)]


@pytest.mark.parametrize("procs, servers, classes", [
    # the same dynamics, another weight: other costs
    ([{"A": SCALAR}, {"A": DOUBLE}, {"A": SCALAR, "weight": 2.0}, {"A": DOUBLE}], (REMOTE, EDGE),
     ((0,), (1, 3), (2,))),
    # the same costs, another processing time on the edge server: the automaton is not symmetric
    ([{"A": SCALAR}, {"A": DOUBLE}, {"A": SCALAR}],
     (REMOTE, {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [2, 4, 3]}),
     ((0,), (1,), (2,))),
], ids=["weight", "processing-time"])
def test_no_class_without_symmetry(procs, servers, classes):
    assert process_symmetry(System.from_scenario(_scenario(procs, servers))).classes == classes


def _rank(matrix) -> int:
    """Numerical rank by QR with column pivoting (faster than an SVD)."""
    r = scipy.linalg.qr(matrix.toarray().T, mode="r", pivoting=True)[0]
    d = np.abs(np.diag(r))
    return int((d > d[0] * 1e-10).sum())


def test_reduced_lp_has_full_row_rank():
    """The rows dropped are exactly the dependent ones: two interchangeable scalar processes and a
    third, cap 3 (498 rows)."""
    system = System.from_scenario(_scenario([{"A": SCALAR}, {"A": SCALAR}, {"A": [[1.05]]}]))
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    assert sym.classes == ((0, 1), (2,))
    lp = symmetric_lp(sym, data)
    assert _rank(lp.A) == lp.A.shape[0]


def test_reduced_lp_has_the_shape_it_announces(twice):
    _, data, sym, _ = twice
    lp = symmetric_lp(sym, data)
    shape = symmetric_lp_shape(sym, data)
    assert (shape["rows"], shape["cols"]) == (lp.keep.size, lp.A.shape[1]) and shape["nnz"] >= lp.A.nnz
    full = symmetric_lp(ProcessSymmetry.none(data.n_processes), data)
    assert lp.A.nnz < 0.5 * full.A.nnz


def test_reduced_lp_certifies_the_whole_lp_optimum(twice):
    system, data, sym, g_star = twice
    whole = ipm_tables(data, tol=1e-9)
    reduced = ipm_tables(data, symmetry=sym, tol=1e-9)
    assert reduced.objective == pytest.approx(whole.objective, rel=1e-7)
    lb_whole = certify_tables(data, whole.tables).lower_bound
    lb_reduced = certify_tables(data, reduced.tables).lower_bound
    assert lb_reduced == pytest.approx(lb_whole, rel=1e-7)
    assert lb_reduced <= g_star
    # the twins' tables are the representative's moved by the swap
    cmap, _ = sym.transposition(0, 2)
    assert np.array_equal(reduced.tables[2], reduced.tables[0][cmap])


def test_joint_bound_uses_the_symmetry_and_stays_below_g_star(twice):
    system, _, _, g_star = twice
    res = joint_bound(system, method="ipm", max_iter=0, ipm_tol=1e-8)
    assert res.stats["ipm_plan"]["classes"] == [[0, 2], [1, 3]] and res.stats["ipm_tables"]
    assert res.lower_bound <= g_star
    plain = joint_bound(system, method="ipm", max_iter=0, ipm_tol=1e-8, symmetry=False)
    assert plain.stats["ipm_plan"]["classes"] == []
    assert res.lower_bound == pytest.approx(plain.lower_bound, rel=1e-6)


def test_orbit_tables_round_trip(twice):
    """The compact form of symmetric tables (the representatives' on their orbits) gives them back."""
    from wncs_lp.bounds.joint_symmetry import orbit_tables, spread_orbit_tables

    _, data, sym, _ = twice
    tables = ipm_tables(data, symmetry=sym, tol=1e-8).tables
    back = spread_orbit_tables(sym, data, orbit_tables(sym, data, tables))
    for h, b in zip(tables, back):
        np.testing.assert_allclose(b, h, rtol=0, atol=1e-9 * np.abs(h).max())


@pytest.fixture(scope="module")
def lumped(twice):
    """The reduced LP solved tightly, and the lumped chains of its representatives."""
    from wncs_lp.bounds.joint_symmetry import lumped_chains

    _, data, sym, _ = twice
    return ipm_tables(data, symmetry=sym, tol=1e-9), lumped_chains(sym, data)


def test_lumped_lagrangian_at_the_coupling_duals_is_the_whole_lp_optimum(twice, lumped):
    """L(nu) at the reduced LP's coupling duals is the whole LP's optimum (HiGHS on the LP without
    symmetry), and the lumped chains' biases, spread to every process, certify it, below g*."""
    from wncs_lp.bounds.joint_chains import Kernels
    from wncs_lp.bounds.joint_symmetry import spread_orbit_tables

    _, data, sym, g_star = twice
    run, chains = lumped
    assert [c.n_configs for c in chains.chains] == [o.n_configs for o in symmetric_lp(sym, data).orbits]
    value, sols = chains.lagrangian(run.prices, Kernels("auto"), tol=1e-12)
    whole = ipm_tables(data, tol=1e-9).objective
    assert value == pytest.approx(whole, rel=1e-6)
    bound = certify_tables(data, spread_orbit_tables(sym, data, [s.h for s in sols])).lower_bound
    assert bound == pytest.approx(whole, rel=1e-6) and bound <= g_star


@pytest.mark.parametrize("seed", [0, 1])
def test_lumped_lagrangian_is_below_the_lp_and_its_tables_certify_it(twice, lumped, seed):
    """At any prices (the optimal ones perturbed) L(nu) is at most the LP's optimum, and the spread
    biases certify at least L(nu) (less the chains' brackets)."""
    from wncs_lp.bounds.joint_chains import Kernels
    from wncs_lp.bounds.joint_symmetry import spread_orbit_tables

    _, data, sym, _ = twice
    run, chains = lumped
    rng = np.random.default_rng(seed)
    prices = [p + rng.normal(scale=0.3 * np.abs(p).max(), size=p.size) for p in run.prices]
    value, sols = chains.lagrangian(prices, Kernels("auto"), tol=1e-12)
    assert value < run.objective - 1e-6 * abs(run.objective)
    bound = certify_tables(data, spread_orbit_tables(sym, data, [s.h for s in sols])).lower_bound
    widths = sum(w * (s.upper - s.lower) for w, s in zip(chains.weights, sols))
    assert bound >= value - widths - 1e-9 * abs(value)


def test_ipm_route_reads_the_lumped_chains(twice):
    system, _, _, g_star = twice
    res = joint_bound(system, method="ipm", max_iter=0, ipm_tol=1e-8)
    phases = [h[1] for h in res.stats["history"]]
    assert "lumped chains" in phases[-1]
    assert "start" not in phases  # the bundle's start is not solved when the interior point returns tables
    assert res.stats["lumped_lagrangian"] == pytest.approx(res.lower_bound, rel=1e-6) and res.lower_bound <= g_star


def test_lumped_ascent_climbs_from_relaxation_1_and_stays_below_the_lp():
    """The projected supergradient steps on the lumped chains (no interchangeable processes here:
    one chain per process): certified, above relaxation 1's bound (its start), at most the whole
    LP's optimum (HiGHS) and the exact g* (the solver)."""
    from wncs_lp.bounds.private import private_bound
    from wncs_lp import load_scenario, scenario_path

    sc = load_scenario(scenario_path("paper_p1234"), ["tau_cap=6"])
    system = System.from_scenario(sc)
    res = joint_bound(system, method="ascent", max_iter=40, time_limit=None)
    lp_optimum = ipm_tables(JointData.from_system(system), tol=1e-9).objective
    r1 = private_bound(system).lower_bound
    assert res.stats["ascent_steps"] == 40 and res.stats["ascent_value"] > res.stats["ascent_start"]
    assert r1 < res.lower_bound <= lp_optimum * (1 + 1e-9) and lp_optimum <= solve(build(sc)).gain_upper
    assert res.lower_bound == pytest.approx(res.stats["ascent_value"], rel=1e-6)


def test_the_reduced_route_is_sized_as_reduced_and_loose_ipx_is_repaired(twice, lumped, monkeypatch):
    """``lower_bound(x, 2, method="ipm")`` is guarded by the reduced LP's and the lumped chains' size,
    not the whole LP's (sixteen processes: 4.25M nonzeros against 595M): with memory for the first
    only, the whole route is refused and the reduced one runs; IPX stopped at 1e-2 and repaired by
    the lumped chains certifies within 1e-2 of the LP's optimum (HiGHS at 1e-9), below g*."""
    from wncs_lp.bounds import lower_bound
    from wncs_lp.bounds.joint import joint_size
    from wncs_lp.models import guard

    system, _, _, g_star = twice
    whole = joint_size(system)["memory_bytes"]
    monkeypatch.setattr(guard, "available_memory", lambda: int(0.5 * whole / guard.MEMORY_FRACTION))
    with pytest.raises(guard.SizeLimitError):
        lower_bound(system, 2)
    res = lower_bound(system, 2, method="ipm", ipm_tol=1e-2)
    optimum = lumped[0].objective
    assert res.stats["ipm_tables"] and (1 - 1e-2) * optimum <= res.lower_bound <= min(optimum * (1 + 1e-9), g_star)
