"""The spec's reference table, and LP (Clarabel direct) = LP (cvxpy) = value iteration = policy
iteration on varied scenarios: independent methods must agree, each with a certificate."""
from __future__ import annotations

from pathlib import Path

import pytest

from wncs_lp import build, load_scenario, scenario_from_dict, solve

FORMULATIONS = Path(__file__).resolve().parent.parent / "formulations"

# reference gains of an independent implementation, certified to 1e-11 relative
REFERENCE = [
    ("paper_p12.toml", 10_419, 14_934, 749.834326444),
    ("paper_p14.toml", 7_340, 12_181, 432.180362984),
]


@pytest.fixture(scope="module", params=REFERENCE, ids=[r[0] for r in REFERENCE])
def reference(request):
    name, states, pairs, gain = request.param
    return build(load_scenario(FORMULATIONS / name)), states, pairs, gain


def _contains(sol, g, slack=1e-10):
    return sol.gain_lower - slack * abs(g) <= g <= sol.gain_upper + slack * abs(g)


def test_reference_by_lp(reference):
    mdp, states, pairs, gain = reference
    assert (mdp.n_states, mdp.n_pairs) == (states, pairs)
    sol = solve(mdp, method="lp")
    assert sol.status == "optimal"
    # the raw LP objective itself, not only the polished gain, is within 1e-7
    assert sol.stats["lp_objective"] == pytest.approx(gain, rel=1e-7)
    assert sol.gain == pytest.approx(gain, rel=1e-7)
    assert _contains(sol, gain)


def test_reference_by_value_iteration(reference):
    mdp, _, _, gain = reference
    sol = solve(mdp, method="rvi")
    assert sol.status == "optimal"
    assert sol.gain == pytest.approx(gain, rel=1e-9)
    assert _contains(sol, gain)
    assert sol.gap < 1e-9


def _scenario(processes, servers, **model):
    return scenario_from_dict(
        {
            "model": {"kind": "wncs", **model},
            "channel": {"success_probability": 0.85},
            "process": processes,
            "server": servers,
        }
    )


A2 = [[1.1, 0.3], [0.0, 1.02]]
OWN = {
    # three processes, three servers, uplink delay 2 and 3, non-identity R, weights
    "3proc-3srv": _scenario(
        [
            {"A": [[1.2]], "tau_cap": 4, "weight": 2.0},
            {"A": A2, "R": [[1.0, 0.2], [0.2, 0.5]], "tau_cap": 4},
            {"A": [[1.05]], "R": [[3.0]], "tau_cap": 4, "weight": 0.5},
        ],
        [
            {"name": "far", "uplink_delay": 2, "downlink_delay": 0, "processing_time": [3, 3, 3]},
            {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [2, 1, 1], "p_up": 0.95},
            {"name": "slow", "uplink_delay": 0, "downlink_delay": 1, "processing_time": [2, 2, 2], "p_down": 0.7},
        ],
    ),
    # idling allowed, per-server p_up / p_down
    "idle-perlink": _scenario(
        [{"A": [[1.3]], "tau_cap": 10}, {"A": A2, "tau_cap": 8, "weight": 1.5}],
        [
            {"uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1, "p_up": 0.6, "p_down": 0.9},
            {"uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2, "p_up": 0.95, "p_down": 0.8},
        ],
        allow_idle=True,
    ),
    # not distinct: a process may go to both servers at once
    "nondistinct-U2": _scenario(
        [{"A": [[1.15]], "tau_cap": 6}, {"A": [[1.02]], "R": [[4.0]], "tau_cap": 6}],
        [
            {"uplink_delay": 2, "downlink_delay": 2, "processing_time": [1, 2]},
            {"uplink_delay": 0, "downlink_delay": 1, "processing_time": [3, 2]},
        ],
        distinct=False,
    ),
    # the paper's three processes at a small cap
    "paper-p123-cap5": load_scenario(FORMULATIONS / "paper_p123.toml", ["tau_cap=5"]),
}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n == "3proc-3srv" else n for n in OWN])
def test_all_methods_agree(name):
    mdp = build(OWN[name])
    mdp.validate()
    sols = {m: solve(mdp, method=m) for m in ("lp", "lp-cvxpy", "rvi", "pi")}
    ref = sols["pi"].gain
    for m, sol in sols.items():
        assert sol.status == "optimal", (m, sol.status, sol.stats)
        assert sol.gain == pytest.approx(ref, rel=1e-6), m
        assert _contains(sol, ref, slack=1e-9), m
    # the raw LP objectives of the two LP paths agree with each other and with DP
    assert sols["lp"].stats["lp_objective"] == pytest.approx(ref, rel=1e-6)
    assert sols["lp-cvxpy"].stats["lp_objective"] == pytest.approx(ref, rel=1e-6)
