"""``wncs-lp evaluate`` by size, like ``solve``: the enumerated MDP's stationary law where the stored
matrix fits, the certified matrix-free evaluation (round robin: its per-process chains) where the
guard refuses it; both state the time at the cap."""
from __future__ import annotations

import json

import pytest

import wncs_lp
from wncs_lp.cli import main

PATH = str(wncs_lp.scenario_path("paper_p12"))


def _run(capsys, *args):
    assert main(["evaluate", PATH, "--set", "tau_cap=8", "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("policy", ["greedy", "round_robin", "optimal"])
def test_evaluate_takes_the_matrix_free_route_when_the_matrix_would_not_fit(capsys, monkeypatch, policy):
    exact = _run(capsys, "--policy", policy)
    assert exact["cap_mass"]["total"] > 0.01
    import wncs_lp.models.guard as guard

    monkeypatch.setattr(guard, "build_checked",
                        lambda scenario, **kw: (_ for _ in ()).throw(guard.SizeLimitError("too large", None)))
    free = _run(capsys, "--policy", policy)
    assert "would not fit" in free["route"]
    tol = 1e-9 * exact["gain"]
    assert free["gain_lower"] - tol <= exact["gain"] <= free["gain_upper"] + tol
    if policy == "round_robin":
        assert free["how"] == "separable" and free["mse"] == pytest.approx(exact["mse"], rel=1e-9)
    else:
        assert free["how"] == "matrix-free" and free["status"] == "optimal"
        cap = free["cap_mass"]
        assert cap["total_lower"] - 1e-9 <= exact["cap_mass"]["total"] <= cap["total_upper"] + 1e-9


def test_the_iterative_law_and_the_certified_bracket_agree_with_the_lu():
    from wncs_lp import build, load_scenario
    from wncs_lp.evaluate import evaluate
    from wncs_lp.models.system import System
    from wncs_lp.workflow import make_policy

    sc = load_scenario(PATH, ["tau_cap=9"])
    system, mdp = System.from_scenario(sc), build(sc)
    for name in ("random", "round_robin"):
        pol = make_policy(name, system, mdp)
        lu, it = evaluate(mdp, pol, method="lu"), evaluate(mdp, pol, method="iterative", certify=True)
        assert (lu.method, it.method) == ("lu", "iterative")
        assert it.gain == pytest.approx(lu.gain, rel=1e-10)
        assert it.mse == pytest.approx(lu.mse, rel=1e-9) and it.utilisation == pytest.approx(lu.utilisation, rel=1e-9)
        assert it.gain_lower <= lu.gain <= it.gain_upper and it.gain_upper - it.gain_lower < 1e-6 * lu.gain
