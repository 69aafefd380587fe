"""Degenerate models: each gives a correct, certified answer (closed forms where they exist)
or one clear error -- never NaN, never a silently wrong gain."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wncs_lp import build, load_scenario, scenario_from_dict, solve
from wncs_lp.models.cost import mse_table

F = Path(__file__).resolve().parent.parent / "formulations"
METHODS = ("lp", "rvi", "pi")


def certified(sol, expected=None, rel=1e-7):
    assert np.isfinite(sol.gain) and np.isfinite(sol.gain_lower) and np.isfinite(sol.gain_upper), sol
    assert sol.gain_lower <= sol.gain + 1e-9 * abs(sol.gain) and sol.gain <= sol.gain_upper + 1e-9 * abs(sol.gain)
    assert sol.status == "optimal", (sol.method, sol.status, sol.stats)
    if expected is not None:
        assert sol.gain == pytest.approx(expected, rel=rel), sol.method
        assert sol.gain_lower - rel * expected <= expected <= sol.gain_upper + rel * expected


def q_at(sc, taus):
    return sum(mse_table(pr.A, pr.R, pr.tau_cap, pr.weight)[t - 1] for pr, t in zip(sc.processes, taus))


@pytest.mark.parametrize("method", METHODS)
def test_channel_always_fails(method):
    """p = 0 on every link: no update ever arrives, every AoI sits at its cap."""
    sc = load_scenario(F / "paper_p12.toml", ["p=0", "tau_cap=6"])
    certified(solve(build(sc), method=method), q_at(sc, sc.tau_caps))


@pytest.mark.parametrize("method", METHODS)
def test_cap_one(method):
    """tau_hat = 1: the AoI is always 1."""
    sc = load_scenario(F / "paper_p123.toml", ["tau_cap=1"])
    certified(solve(build(sc), method=method), q_at(sc, (1, 1, 1)))


@pytest.mark.parametrize("method", METHODS)
def test_constant_cost_process(method):
    """A = 0: q(tau) = w r for every tau, so every policy costs the same."""
    sc = scenario_from_dict({
        "model": {"kind": "wncs", "tau_cap": 5},
        "channel": {"success_probability": 0.7},
        "process": [{"A": [[0.0]], "R": [[2.0]], "weight": 1.5}],
        "server": [{"uplink_delay": 1, "downlink_delay": 1, "processing_time": [2]}],
    })
    certified(solve(build(sc), method=method), 3.0)


@pytest.mark.parametrize("method", METHODS)
def test_perfect_channel_deterministic_dynamics(method):
    """p = 1: deterministic dynamics, several cycles, multichain policies exist. All methods
    must agree with each other (the LP handles multichain policies natively)."""
    sc = load_scenario(F / "paper_p12.toml", ["p=1", "tau_cap=8"])
    mdp = build(sc)
    ref = solve(mdp, method="lp")
    certified(ref)
    certified(solve(mdp, method=method), ref.gain)


@pytest.mark.parametrize("method", METHODS)
def test_preemption_perfect_channel(method):
    sc = load_scenario(F / "paper_preemption_p12.toml", ["p=1", "tau_cap=6"])
    mdp = build(sc)
    ref = solve(mdp, method="rvi")
    certified(ref)
    certified(solve(mdp, method=method), ref.gain)


@pytest.mark.parametrize("method", METHODS)
def test_useless_server(method):
    """A server whose uplink always fails: its actions are feasible but never deliver; the
    optimum equals that of the same system where that server never gets anything useful,
    which is bounded below by the one-server optimum with idling allowed on the other."""
    sc = load_scenario(F / "paper_p12.toml", ["tau_cap=6", "server.remote.p_up=0"])
    sol = solve(build(sc), method=method)
    certified(sol)
    alone = scenario_from_dict({**sc.to_dict(), "server": [sc.to_dict()["server"][1]]})
    assert sol.gain >= solve(build(alone), method="pi").gain * (1 - 1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_single_process_many_servers_idle_forced(method):
    """One process, two servers: more accepting servers than processes, so idling is allowed."""
    raw = load_scenario(F / "paper_p14.toml", ["tau_cap=7"]).to_dict()
    raw["process"] = raw["process"][1:]  # process 4 alone
    sc = scenario_from_dict(raw)
    certified(solve(build(sc), method=method))
