"""The Section II builder against the spec: reference sizes, closed forms, hand-traced rows."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.models.cost import mse_table
from wncs_lp.models import build
from wncs_lp.models.wncs import feasible_actions, idle_config
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp import solve


def one_process(a: float, r: float, p: float, cap: int, U: int, D: int, T: int, pd: float | None = None):
    server = {"uplink_delay": U, "downlink_delay": D, "processing_time": [T]}
    if pd is not None:
        server["p_down"] = pd
    return scenario_from_dict(
        {
            "model": {"kind": "wncs", "tau_cap": cap},
            "channel": {"success_probability": p},
            "process": [{"A": [[a]], "R": [[r]]}],
            "server": [server],
        }
    )


def test_cost_table_example_of_spec():
    # spec section 1: A = [[1.02]], R = [[1]] gives q(1) = 1, q(2) = 1 + 1.02^2
    np.testing.assert_allclose(mse_table(np.array([[1.02]]), np.eye(1), 2), [1.0, 1.0 + 1.02**2])
    # matrix case by the definition, summed directly
    A = np.array([[1.02, 1], [0, 1]])
    R = np.array([[2.0, 0.5], [0.5, 1.0]])
    direct = [sum(np.trace(np.linalg.matrix_power(A, i) @ R @ np.linalg.matrix_power(A, i).T) for i in range(t))
              for t in range(1, 6)]
    np.testing.assert_allclose(mse_table(A, R, 5, weight=2.0), 2.0 * np.array(direct))


@pytest.mark.parametrize(
    "name, states, pairs",
    [("paper_p12.toml", 10_419, 14_934), ("paper_p14.toml", 7_340, 12_181)],
)
def test_reference_sizes(name, states, pairs):
    """spec section 5 reference table (independent implementation)."""
    mdp = build(load_scenario(scenario_path(name)))
    assert (mdp.n_states, mdp.n_pairs) == (states, pairs)
    mdp.validate()


@pytest.mark.parametrize("p, a, r, cap", [(0.9, 1.02, 1.0, 6), (0.6, 1.2, 2.0, 9), (0.3, 1.1, 0.5, 14)])
def test_geometric_closed_form_at_every_cap(p, a, r, cap):
    """U = D = 0, T = 1, pd = 1: tau is 1 w.p. p each slot, else grows; exact at any cap.

    P(tau = j) = p (1-p)^(j-1) for j < cap and (1-p)^(cap-1) at the cap.
    """
    sc = one_process(a, r, p, cap, 0, 0, 1, pd=1.0)
    mdp = build(sc)
    assert mdp.n_states == cap and mdp.n_pairs == cap  # one forced action everywhere
    q = r * np.cumsum(a ** (2 * np.arange(cap)))
    pi = np.array([p * (1 - p) ** (j - 1) for j in range(1, cap)] + [(1 - p) ** (cap - 1)])
    exact = float(pi @ q)
    for method in ("lp", "rvi", "pi"):
        sol = solve(mdp, method=method)
        assert sol.gain == pytest.approx(exact, rel=1e-8), method
        assert sol.gain_lower - 1e-9 * exact <= exact <= sol.gain_upper + 1e-9 * exact


def test_geometric_closed_form_limit_as_cap_grows():
    """spec section 5: the gain tends to r / (1 - (1 - p) a^2) as tau_hat grows."""
    p, a, r = 0.7, 1.3, 1.5
    limit = r / (1 - (1 - p) * a * a)
    errors = []
    for cap in (5, 10, 20, 40, 80):
        errors.append(abs(solve(build(one_process(a, r, p, cap, 0, 0, 1, pd=1.0)), method="pi").gain - limit))
    assert all(e2 < e1 for e1, e2 in zip(errors, errors[1:]))
    assert errors[-1] / limit < 1e-8


@pytest.mark.parametrize("T, a, expected", [(1, 1.1, None), (3, 1.1, 10.3645542423), (2, 1.05, None)])
def test_pipeline_closed_form(T, a, expected):
    """U = D = 1, p = 1: one delivery every T slots, tau cycles through U+T+D .. U+T+D+T-1."""
    sc = one_process(a, 1.0, 1.0, 20, 1, 1, T)
    q = mse_table(np.array([[a]]), np.eye(1), 20)
    cycle = np.mean([q[t - 1] for t in range(2 + T, 2 + 2 * T)])
    if expected is not None:
        assert cycle == pytest.approx(expected, rel=1e-10)
    for method in ("lp", "rvi", "pi"):
        assert solve(build(sc), method=method).gain == pytest.approx(cycle, rel=1e-8)


def _row(mdp, s, action):
    """{(tau, config): prob} of the pair (s, action)."""
    for l in mdp.pairs_of(s):
        if tuple(mdp.action_table[mdp.a_indices[l]]) == tuple(action):
            row = mdp.P[l]
            st = mdp.states
            return {
                (tuple(int(x) for x in st.tau[j]), st.configs[st.config[j]]): float(v)
                for j, v in zip(row.indices, row.data)
            }
    raise AssertionError(f"action {action} not feasible in state {mdp.state_label(s)}")


def test_hand_traced_start_of_two_jobs():
    """Paper p12, idle servers, tau = (3, 5), action (1 to remote, 2 to edge).

    remote (U=D=1, T_1=4): a surviving update starts service next slot with d = 4.
    edge (U=D=0, T_2=6): a surviving update starts at once and gets one slot: d = 5.
    No delivery: tau -> (4, 6). p = 0.9 on each uplink.
    """
    sc = load_scenario(scenario_path("paper_p12.toml"))
    mdp = build(sc)
    idle = idle_config(sc)
    s = mdp.states.find((3, 5), idle)
    remote_busy = ((), 1, 4, (0,))
    edge_busy = ((), 2, 5, ())
    remote_idle, edge_idle = idle
    expected = {
        ((4, 6), (remote_busy, edge_busy)): 0.81,
        ((4, 6), (remote_busy, edge_idle)): 0.09,
        ((4, 6), (remote_idle, edge_busy)): 0.09,
        ((4, 6), (remote_idle, edge_idle)): 0.01,
    }
    got = _row(mdp, s, (1, 2))
    assert got.keys() == expected.keys()
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, abs=1e-15)


def test_hand_traced_remote_delivery_and_acceptance():
    """A command of process 1 in the remote downlink is delivered this slot w.p. pd = 0.9.

    tau_1 -> min(tau_1 + 1, U + T_1 + D = 6); the idle remote server accepts, and so does the
    edge; sending 2 to remote and 1 to edge: edge job 1 (T = 8) starts at once, d = 7.
    """
    sc = load_scenario(scenario_path("paper_p12.toml"))
    mdp = build(sc)
    cfg = (((), 0, 0, (1,)), ((), 0, 0, ()))
    # (10, 3) would be unreachable: a command of process 1 in the downlink means >= 5 slots
    # since the servers were idle, with no delivery of process 2 meanwhile, so tau_2 >= 6.
    assert mdp.states.find((10, 3), cfg) == -1
    s = mdp.states.find((10, 6), cfg)
    assert s >= 0
    got = _row(mdp, s, (2, 1))
    r_busy, r_idle = ((), 2, 3, (0,)), ((), 0, 0, (0,))
    e_busy, e_idle = ((), 1, 7, ()), ((), 0, 0, ())
    expected = {}
    for r_cfg, pr in ((r_busy, 0.9), (r_idle, 0.1)):
        for e_cfg, pe in ((e_busy, 0.9), (e_idle, 0.1)):
            expected[((6, 7), (r_cfg, e_cfg))] = pr * pe * 0.9
            expected[((11, 7), (r_cfg, e_cfg))] = pr * pe * 0.1
    assert got.keys() == expected.keys()
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, abs=1e-15)


def test_remote_accepts_only_when_one_slot_left():
    """U = 1: accept iff d <= 1, so with d = 2 only the edge can be used."""
    sc = load_scenario(scenario_path("paper_p12.toml"))
    busy2 = (((), 1, 2, (0,)), ((), 0, 0, ()))
    busy1 = (((), 1, 1, (0,)), ((), 0, 0, ()))
    assert feasible_actions(sc, busy2) == [(0, 1), (0, 2)]
    assert feasible_actions(sc, busy1) == [(1, 2), (2, 1)]


def test_action_sets_follow_options():
    sc = load_scenario(scenario_path("paper_p12.toml"))
    idle = idle_config(sc)
    assert feasible_actions(sc, idle) == [(1, 2), (2, 1)]
    idle_sc = sc.with_overrides({"model.allow_idle": True})
    assert sorted(feasible_actions(idle_sc, idle)) == sorted(
        [(1, 2), (1, 0), (2, 1), (2, 0), (0, 1), (0, 2), (0, 0)]
    )
    nd = sc.with_overrides({"model.distinct": False})
    assert sorted(feasible_actions(nd, idle)) == [(1, 1), (1, 2), (2, 1), (2, 2)]
    # more accepting servers than processes: idling allowed (spec section 2, Actions)
    one = sc.with_overrides({"process.2.A": [[1.0]]}).to_dict()
    one["process"] = one["process"][:1]
    sc1 = scenario_from_dict(one)
    assert sorted(feasible_actions(sc1, idle_config(sc1))) == [(0, 0), (0, 1), (1, 0)]


def test_states_decode_consistently():
    sc = load_scenario(scenario_path("paper_p14.toml"))
    mdp = build(sc)
    st = mdp.states
    assert st.tau.shape == (mdp.n_states, 2)
    assert st.tau.min() == 1 and st.tau.max() == 12
    # every state is found again from its decoded view
    rng = np.random.default_rng(0)
    for s in rng.choice(mdp.n_states, 50, replace=False):
        assert st.find(st.tau[s], int(st.config[s])) == s
    # the state cost is the sum of the q tables
    q1 = mse_table(sc.processes[0].A, sc.processes[0].R, 12)
    q4 = mse_table(sc.processes[1].A, sc.processes[1].R, 12)
    np.testing.assert_allclose(mdp.state_cost(), q1[st.tau[:, 0] - 1] + q4[st.tau[:, 1] - 1])
    # idle-server states cover the whole tau box
    grid = st.lookup_grid(idle_config(sc))
    assert (grid >= 0).all()
