"""The level-2 relaxation (wncs_lp.bounds.level2; docs/bounds.md, "Many sensors on one server"):
every pair's ages on the joint configuration at once, its LP solved whole, its duals certified by
the LP-sized check U(C, a).

Independent references: g* of the enumerated MDP's LP (the whole system), and a brute-force check
of the approximate-LP inequality written out state by state over the whole AoI box (written here
with numpy, the value function V = sum of pair tables at the lumped ages + process tables, the
successor's class taken of the full successor age -- so it also checks that the lumped ages move
as one state). The certificate must be at most the box check for any tables and prices (the
maximum of a sum is at most the sum of the maxima), equal to it at the LP's duals, at most g*,
and equal to g* when one pair is the whole system."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from wncs_lp import solve
from wncs_lp.bounds import lower_bound
from wncs_lp.bounds.joint_chains import JointData
from wncs_lp.bounds.level2 import (LEVEL2_SOLVERS, Level2Tables, certify_level2, independent_rows, level2_bound, level2_layout,
                                   level2_lp, level2_tables)
from wncs_lp.errors import ArgumentError
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

A = (1.05, 1.1, 1.15, 1.2)
SERVERS = {"edge": {"uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2},
           "cloud": {"uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1}}
#: (servers, sensors, cap)
CASES = [(("edge",), 2, 8), (("edge",), 3, 8), (("cloud",), 3, 6), (("edge", "cloud"), 3, 5)]


def system_of(servers, n, cap) -> System:
    sc = scenario_from_dict({"model": {"kind": "wncs", "allow_idle": False, "tau_cap": cap},
                             "channel": {"success_probability": 0.8},
                             "process": [{"A": [[a]], "R": [[1.0]]} for a in A[:n]],
                             "server": [{"name": s, **SERVERS[s]} for s in servers]}, source="<level2 test>")
    return System.from_scenario(sc)


@pytest.fixture(scope="module", params=CASES, ids=[f"{'+'.join(s)}-{n}-cap{c}" for s, n, c in CASES])
def case(request):
    servers, n, cap = request.param
    system = system_of(servers, n, cap)
    return n, cap, JointData.from_system(system), solve(build(system.scenario)).gain_upper, system


def box_check(data: JointData, lay, tables: Level2Tables) -> float:
    """min over every (tau, C, a) of the box of sum_k q_k + E V(tau', C') - V(tau, C)."""
    N, P = data.n_processes, int(data.act_ptr[-1])
    tau = [g.ravel() for g in np.meshgrid(*[np.arange(c) for c in lay.caps], indexing="ij")]

    def value(ages, config):
        v = 0.0
        for i, (k, l) in enumerate(lay.pairs):
            ck, cl = lay.lumps[k], lay.lumps[l]
            v = v + tables.pair[i][config, np.minimum(ages[k], ck - 1) * cl + np.minimum(ages[l], cl - 1)]
        for k in range(N):
            if tables.single[k] is not None:
                v = v + tables.single[k][config, ages[k]]
        return v

    cost = sum(np.asarray(data.q[k])[tau[k]] for k in range(N))
    best = np.inf
    for p in range(P):
        here = value(tau, data.pair_c[p])
        nxt = np.zeros_like(cost)
        for e in range(data.out_ptr[p], data.out_ptr[p + 1]):
            new = [np.minimum(tau[k] + 1, data.sat[e, k]) for k in range(N)]
            nxt = nxt + data.out_prob[e] * value(new, data.out_nxt[e])
        best = min(best, float((cost + nxt - here).min()))
    return best


def random_tables(lay, rng, scale=5.0) -> Level2Tables:
    nC, P = lay.n_configs, lay.n_pairs_ca
    pair = tuple(rng.normal(scale=scale, size=(nC, lay.lumps[k] * lay.lumps[l])) for k, l in lay.pairs)
    price = tuple((rng.normal(scale=scale, size=(P, lay.lumps[k])), rng.normal(scale=scale, size=(P, lay.lumps[l])))
                  for k, l in lay.pairs)
    single = tuple(rng.normal(scale=scale, size=(nC, c)) if lay.lumped(k) else None for k, c in enumerate(lay.caps))
    return Level2Tables(pair=pair, price=price, single=single)


@pytest.mark.parametrize("lump", [None, 3])
def test_certificate_below_g_star_and_equal_to_the_box_check(case, lump):
    n, cap, data, g_star, _ = case
    r = level2_bound(data, lump=lump)
    assert r.status == "kOptimal"
    assert r.lower_bound <= g_star * (1 + 1e-12)
    assert r.lower_bound == pytest.approx(r.lp_value, rel=1e-6)  # the duals carry the LP's value
    box = box_check(data, r.layout, r.tables)
    assert r.certificate.raw <= box + 1e-9 * abs(box)  # max of a sum <= sum of the maxima
    assert r.certificate.raw == pytest.approx(box, rel=1e-9)  # and equal at the LP's duals
    if n == 2 and lump is None:  # the pair is the whole system
        assert r.lower_bound == pytest.approx(g_star, rel=1e-7)
    rng = np.random.default_rng(cap)
    for _ in range(3):  # any tables and prices: a valid bound, never above the box check
        t = random_tables(r.layout, rng)
        cert = certify_level2(data, r.layout, t)
        assert cert.lower_bound <= box_check(data, r.layout, t) <= g_star


def test_lumping_is_between_relaxation_2_and_the_whole_pairs(case):
    n, cap, data, g_star, system = case
    full = level2_bound(data).lower_bound
    rel2 = lower_bound(system, 2, method="ipm").lower_bound
    values = [level2_bound(data, lump=c).lower_bound for c in (1, cap - 2, cap)]
    assert values[-1] == pytest.approx(full, rel=1e-7)  # lumping at the cap lumps nothing
    for v in values:
        assert rel2 <= v * (1 + 1e-6)  # relaxation 2's LP is a subset of the lumped constraints
        assert v <= full * (1 + 1e-7) <= g_star * (1 + 1e-7)  # and the lumped ones of the whole pairs'


@pytest.fixture(scope="module")
def edge3():
    system = system_of(("edge",), 3, 8)
    data = JointData.from_system(system)
    return data, solve(build(system.scenario)).gain_upper, level2_bound(data).lower_bound


@pytest.mark.parametrize("solver", LEVEL2_SOLVERS)
def test_every_solver_gives_a_certified_bound(edge3, solver):
    data, g_star, ipx = edge3
    r = level2_bound(data, solver=solver, tol=1e-7)
    assert r.lower_bound <= g_star
    assert r.lower_bound == pytest.approx(ipx, rel=1e-5)


def test_the_layout_counts_what_the_builder_builds():
    data = JointData.from_system(system_of(("edge", "cloud"), 3, 5))
    for lump in (None, 2, (5, 1, 3)):
        lay = level2_layout(data, lump)
        A, b, c = level2_lp(data, lay)
        assert A.shape == (lay.rows, lay.cols) and b.shape == (lay.rows,) and c.shape == (lay.cols,)
        assert A.nnz <= lay.nnz
        # every pair column leaves one balance row and enters with probability one: its balance entries sum to 0
        for i in range(len(lay.pairs)):
            lo, hi = lay.balance[i], lay.consistency[i][0]
            cols = A[lo:hi, lay.y[i]:lay.y[i] + (hi - lo) // lay.n_configs * lay.n_pairs_ca]
            assert np.abs(np.asarray(cols.sum(axis=0))).max() < 1e-12


@pytest.mark.parametrize("servers,n,cap,lump", [(("edge",), 3, 6, None), (("edge",), 4, 4, None), (("edge",), 3, 6, 4),
                                                (("edge",), 4, 5, (5, 3, 5, 2)), (("cloud",), 3, 2, None),
                                                (("cloud",), 3, 3, 2)])
def test_the_dropped_rows_are_implied_and_the_kept_ones_independent(servers, n, cap, lump):
    data = JointData.from_system(system_of(servers, n, cap))
    lay = level2_layout(data, lump)
    A, b, c = level2_lp(data, lay)
    keep = independent_rows(lay)
    dense = A.toarray()
    rank = np.linalg.matrix_rank(dense)
    assert np.linalg.matrix_rank(dense[keep]) == rank == keep.sum()  # full rank, and nothing lost
    whole = linprog(c, A_eq=A, b_eq=b, bounds=(0, None), method="highs").fun
    kept = linprog(c, A_eq=A[keep], b_eq=b[keep], bounds=(0, None), method="highs").fun
    assert kept == pytest.approx(whole, rel=1e-9)


def test_bad_input_names_the_argument():
    data = JointData.from_system(system_of(("edge",), 2, 4))
    with pytest.raises(ArgumentError, match="lump"):
        level2_layout(data, 0)
    with pytest.raises(ArgumentError, match="lump"):
        level2_layout(data, (2, 2, 2))
    with pytest.raises(ArgumentError, match="solver"):
        level2_bound(data, solver="simplex")
    lay = level2_layout(data)
    with pytest.raises(ValueError):
        level2_tables(lay, np.zeros(lay.rows + 1))
