"""Relaxation 4 (pairs of processes' ages kept jointly in relaxation 2's tables): its certificate
against the approximate LP's constraints written out state by state over the AoI box (a reference
written here from docs/bounds.md, with the automaton's per-configuration outcome lists), its bound
against the exact g* of the solver and against relaxation 2's bound."""
from __future__ import annotations

from itertools import product

import numpy as np
import pytest
from bounds_reference import shape
from joint_reference import three_processes

from wncs_lp.bounds import GroupBoundPolicy, bound_policy, parse_relaxation
from wncs_lp.bounds.joint_chains import JointData, certify_tables
from wncs_lp.bounds.lower import lower_bound
from wncs_lp.bounds.pairs import GroupChains, candidate_partitions, certify_group_tables
from wncs_lp.errors import SolverError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp import solve

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


def box_gain_groups(system, groups, tables) -> float:
    """min over every (tau, C, a) of the box of c(tau) + sum_o P(o) h(tau', C'_o) - h(tau, C), with
    h(tau, C) = sum_G h_G(tau_G, C) (tables indexed [C, tau_{G[0]} - 1, tau_{G[1]} - 1]) and
    tau'_k = min(tau_k + 1, delta_k if delta_k > 0, tau_hat_k)."""
    caps = np.asarray(system.caps)
    tau = np.array(list(product(*[range(1, int(c) + 1) for c in caps])), dtype=np.int64)
    cost = sum(np.asarray(system.q[k])[tau[:, k] - 1] for k in range(caps.size))

    def h(t, c):
        return sum(np.asarray(tab)[(np.full(t.shape[0], c),) + tuple(t[:, k] - 1 for k in g)]
                   for g, tab in zip(groups, tables))

    best = np.inf
    for c, per_action in enumerate(system.automaton.outcomes):
        here = h(tau, c)
        for outcomes in per_action:
            ahead = 0.0
            for nxt, delta, p in outcomes:
                d = np.asarray(delta)[None, :]
                t2 = np.minimum(tau + 1, caps[None, :])
                ahead = ahead + p * h(np.where(d > 0, np.minimum(t2, d), t2), nxt)
            best = min(best, float((cost + ahead - here).min()))
    return best


@pytest.fixture(scope="module")
def three():
    """Three processes at cap 5 (30 configurations): relaxation 2 is 2.9% below g* there."""
    sc = three_processes(5)
    system = System.from_scenario(sc)
    r2 = lower_bound(system, 2)
    return system, solve(build(sc)).gain_upper, r2, lower_bound(system, 4, start=r2)


def _grids(system, groups, rng, scale=50.0):
    return [scale * rng.standard_normal((system.n_configs,) + tuple(int(system.caps[k]) for k in g)) for g in groups]


@pytest.mark.parametrize("groups", [((0, 2), (1,)), ((0, 1), (2,)), ((0,), (1,), (2,))])
def test_certificate_is_the_box_test_state_by_state(three, groups):
    """-max_p sum_G max_tau_G [...] equals the min over every (tau, C, a) of the box (the check is
    exact, not only valid), and every random table certifies at most g*."""
    system, g_star, _, _ = three
    data = JointData.from_system(system)
    chains = GroupChains.build(data, groups)
    rng = np.random.default_rng(5)
    for _ in range(2):
        grids = _grids(system, groups, rng)
        cert = certify_group_tables(chains, [t.reshape(system.n_configs, -1) for t in grids])
        assert cert.raw == pytest.approx(box_gain_groups(system, groups, grids), rel=1e-12, abs=1e-9)
        assert cert.lower_bound <= cert.raw
        assert cert.lower_bound <= g_star


def test_separable_tables_certify_as_relaxation_2s(three):
    """Group tables h_G = sum_{k in G} h_k are relaxation 2's constraints: the same bound."""
    system, _, r2, _ = three
    data = JointData.from_system(system)
    chains = GroupChains.build(data, ((0, 2), (1,)))
    sep = [np.asarray(h) for h in r2.tables.h]
    assert certify_group_tables(chains, chains.from_separable(sep)).raw == pytest.approx(
        certify_tables(data, sep).raw, rel=1e-12)


def test_bound_is_between_relaxation_2_and_g_star(three):
    """Valid (<= g*), never looser than relaxation 2, and here it closes relaxation 2's 2.9% gap:
    the pair of processes 1 and 3 (weight 2) competing for the edge server is what the
    separable tables missed."""
    system, g_star, r2, r4 = three
    assert r4.relaxation == "joint-pairs" and r4.stats["certified"]
    assert r2.lower_bound <= r4.lower_bound <= g_star
    assert (g_star - r2.lower_bound) / g_star > 0.02
    assert (g_star - r4.lower_bound) / g_star < 1e-5
    assert r4.tables.groups == ((0, 2), (1,))  # auto's choice among the three pairings: the largest bound
    # the bound is the group check of the returned tables
    chains = GroupChains.build(JointData.from_system(system), r4.tables.groups)
    flat = [np.asarray(h).reshape(system.n_configs, -1) for h in r4.tables.h]
    assert certify_group_tables(chains, flat).lower_bound == r4.lower_bound


def test_auto_hands_the_pairs_a_loose_interior_point(three, monkeypatch):
    """Where relaxation 4 follows a slow interior point, ``auto`` stops IPX at AUTO_PAIRS_IPM_TOL
    (forced here by lowering the threshold to 0 s): the tolerance reaches relaxation 2, the bound
    stays below the exact g* and the pairs still close relaxation 2's 2.9% gap from the looser
    duals; without the rule relaxation 2 runs at ``tol``."""
    import wncs_lp.bounds.lower as lower

    system, g_star, _, _ = three
    monkeypatch.setattr(lower, "AUTO_ALL_PAIRS_BUDGET", 0.0)  # relaxation 5 (whole, it would replace 4) off
    seen = []

    def spy(system_, **options):
        seen.append(options.get("ipm_tol"))
        return lower.joint_bound(system_, **options)

    monkeypatch.setattr(lower, "_try_joint", lambda s, o: (spy(s, **o), ""))
    lower_bound(system, "auto")
    assert seen == [None]  # the interior point takes seconds here: tol
    monkeypatch.setattr(lower, "AUTO_PAIRS_IPM_FROM", 0.0)
    res = lower_bound(system, "auto")
    assert seen[-1] == lower.AUTO_PAIRS_IPM_TOL
    assert res.relaxation == "joint-pairs" and res.stats["certified"]
    assert res.lower_bound <= g_star
    assert (g_star - res.lower_bound) / g_star < 1e-4


@pytest.mark.parametrize("name", ["paper", "asymmetric", "idle"])
def test_one_pair_is_the_whole_value_function(name):
    """Two processes in one group: the tables are the whole value function over the box, so the
    bound is g* itself (up to the chains' tolerance), on several shapes."""
    sc = shape(name)
    system = System.from_scenario(sc)
    g_star = solve(build(sc)).gain_upper
    res = lower_bound(system, "joint-pairs", groups=[(0, 1)], max_iter=1, tol=1e-7)
    assert res.lower_bound <= g_star
    assert res.lower_bound == pytest.approx(g_star, rel=1e-6)


def test_greedy_policy_on_group_tables(three):
    """The bound's policy reads the group tables (GroupBoundPolicy); evaluated exactly on the
    enumerated MDP its gain is at least g*, and here (tables within 6e-7 of g*) within 1e-4 of it."""
    system, g_star, _, r4 = three
    pol = bound_policy(r4, system)
    assert isinstance(pol, GroupBoundPolicy)
    gain = evaluate(build(three_processes(5)), pol).gain
    assert g_star * (1 - 1e-9) <= gain <= g_star * (1 + 1e-4)


def test_overlapping_groups_act_as_the_sum_they_hold(three):
    """Group tables may overlap (the level-2 relaxation's every pair): with h_kl = (h_k + h_l) / (N - 1)
    over all pairs, sum_kl h_kl = sum_k h_k, so the greedy policy on the cover takes relaxation 2's
    separable policy's action in every state of the box (BoundPolicy computes it independently)."""
    from dataclasses import replace
    from itertools import combinations

    from wncs_lp.bounds import GroupTables

    system, _, r2, _ = three
    N = system.n_processes
    sep = [np.asarray(h) for h in r2.tables.h]  # (|C|, tau_hat_k) each
    pairs = tuple(combinations(range(N), 2))
    h = tuple((sep[k][:, :, None] + sep[l][:, None, :]) / (N - 1) for k, l in pairs)
    cover = GroupTables(pairs, h, tuple(np.arange(system.n_configs) for _ in pairs))
    assert cover.n_processes == N
    pol = bound_policy(replace(r2, tables=cover), system)
    assert isinstance(pol, GroupBoundPolicy)
    tau = np.array(list(product(*[range(1, int(c) + 1) for c in system.caps])), dtype=np.int64)
    for c in range(system.n_configs):
        cfg = np.full(tau.shape[0], c)
        np.testing.assert_allclose(cover.value(tau, cfg), r2.tables.value(tau, cfg), rtol=1e-12, atol=1e-9)
        v_cover, v_sep = pol.values(tau, cfg), bound_policy(r2, system).values(tau, cfg)
        np.testing.assert_allclose(v_cover, v_sep, rtol=1e-12, atol=1e-9)


def test_names_groups_and_candidates():
    assert parse_relaxation(4) == parse_relaxation("joint-pairs") == "joint-pairs"
    # interchangeable processes pair with each other; four others every way
    assert candidate_partitions(8, ((0, 4), (1, 5), (2, 6), (3, 7))) == [((0, 4), (1, 5), (2, 6), (3, 7))]
    assert sorted(candidate_partitions(4)) == [((0, 1), (2, 3)), ((0, 2), (1, 3)), ((0, 3), (1, 2))]
    assert len(candidate_partitions(3)) == 3
    data = JointData.from_system(System.from_scenario(three_processes(4)))
    chains = GroupChains.build(data, ((0, 1), (2,)))
    with pytest.raises(SolverError, match="2 group tables"):
        certify_group_tables(chains, [np.zeros(chains.shape(0))])
    with pytest.raises(SolverError, match=r"group table 1 \(processes \[3\]\) has shape"):
        certify_group_tables(chains, [np.zeros(chains.shape(0)), np.zeros((data.n_configs, 3))])
    bad_tables = [np.zeros(chains.shape(0)), np.full(chains.shape(1), np.nan)]
    assert certify_group_tables(chains, bad_tables).lower_bound == -np.inf  # certifies nothing
    for bad in ([(0, 1)], [(0, 1, 2)], [(0, 1), (1, 2)], [("a",), (1, 2)]):
        with pytest.raises(SolverError, match="partition"):
            GroupChains.build(data, bad)


def test_command_line_runs_it_with_its_groups(capsys):
    """``wncs-lp bound --relaxation 4 --groups 1,2``: processes 1 and 2 of the paper in one pair,
    so the bound is g* (the exact solver's)."""
    import json

    from wncs_lp import scenario_path
    from wncs_lp.cli import main
    from wncs_lp.scenario import load_scenario

    path = str(scenario_path("paper_p12"))
    rc = main(["bound", path, "--set", "tau_cap=5", "--relaxation", "4", "--groups", "1,2", "--json"])
    out = json.loads(capsys.readouterr().out)
    g_star = solve(build(load_scenario(path, ["tau_cap=5"]))).gain_upper
    assert out["bound"]["relaxation"] == "joint-pairs"
    assert out["bound"]["lower_bound"] == pytest.approx(g_star, rel=1e-6) and out["bound"]["lower_bound"] <= g_star
    assert rc in (0, 1)  # 1: the bundle's own stopping rule not met (the bound holds either way)


def test_threads_split_the_configurations_and_change_no_number(three):
    """Two threads sweep each chain's configurations in parallel, each writing its own rows: the same
    Bellman operator, so the same search and the same certified bound to the last bit (what
    ``wncs-lp bound --threads`` relies on)."""
    system, _, r2, r4 = three
    two = lower_bound(system, 4, start=r2, threads=2)
    assert two.lower_bound == r4.lower_bound and two.stats["bundle_steps"] == r4.stats["bundle_steps"]
    assert all(np.array_equal(a, b) for a, b in zip(two.tables.h, r4.tables.h))
