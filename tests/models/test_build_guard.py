"""The size guard where it was missing (issue 16): ``wncs_lp.build`` refuses by default with the
estimate and has a ``force=`` escape; ``solve --method lp`` counts the LP's memory."""
from __future__ import annotations

import json

import pytest

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.models import guard
from wncs_lp.models.guard import SizeLimitError, estimate_size

P12 = str(wncs_lp.scenario_path("paper_p12"))


@pytest.fixture
def scenario():
    return wncs_lp.load_scenario(P12, ["tau_cap=8"])


def test_library_build_is_guarded_with_a_force_escape(scenario, monkeypatch):
    est = estimate_size(scenario)
    monkeypatch.setattr(guard, "available_memory", lambda: est.build_bytes)  # limit: half of it
    with pytest.raises(SizeLimitError) as info:
        wncs_lp.build(scenario)
    msg = str(info.value)
    assert f"up to {est.states:,} states" in msg and "GiB" in msg and "force=True" in msg
    assert info.value.estimate.states == est.states
    mdp = wncs_lp.build(scenario, force=True)
    assert mdp.n_states <= est.states


def test_solve_with_the_lp_counts_the_lp_memory(scenario, monkeypatch, capsys):
    est = estimate_size(scenario)
    # room for the build, not for the build and the LP
    monkeypatch.setattr(guard, "available_memory", lambda: 2 * (est.build_bytes + est.lp_bytes // 2))
    for method in ("lp", "lp-cvxpy"):
        assert main(["solve", P12, "--set", "tau_cap=8", "--method", method, "--json"]) == 2
        err = json.loads(capsys.readouterr().out)
        assert err["type"] == "SizeLimitError" and "(LP included)" in err["error"]
        assert "value iteration" in err["error"]  # the cheaper route that fits
    assert main(["solve", P12, "--set", "tau_cap=8", "--method", "vi", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["status"] == "optimal"
    assert main(["evaluate", P12, "--set", "tau_cap=8", "--policy", "optimal", "--method", "lp", "--json"]) == 2
    assert "(LP included)" in json.loads(capsys.readouterr().out)["error"]
