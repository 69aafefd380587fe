"""``wncs-lp solve --method matrix-free``, and auto switching to it when the stored matrix would not fit."""
from __future__ import annotations

import json

import pytest

import wncs_lp
from wncs_lp.cli import main


def _json(capsys):
    return json.loads(capsys.readouterr().out)


def test_matrix_free_from_the_command_line_agrees_with_value_iteration(capsys):
    path = str(wncs_lp.scenario_path("paper_p12"))
    assert main(["solve", path, "--set", "tau_cap=9", "--method", "matrix-free", "--json"]) == 0
    mf = _json(capsys)
    assert main(["solve", path, "--set", "tau_cap=9", "--method", "vi", "--json"]) == 0
    vi = _json(capsys)
    assert mf["method"] == "matrix-free" and mf["status"] == "optimal"
    # each gain inside the other's certificate
    assert vi["gain_lower"] - 1e-9 * vi["gain"] <= mf["gain"] <= vi["gain_upper"] + 1e-9 * vi["gain"]
    assert mf["gain_lower"] - 1e-9 * mf["gain"] <= vi["gain"] <= mf["gain_upper"] + 1e-9 * mf["gain"]


def test_auto_switches_to_matrix_free_when_the_guard_refuses(capsys, monkeypatch):
    import wncs_lp.models.guard as guard

    def refuse(scenario, **kw):  # the guard's refusal of a stored matrix (as for processes 1-4 at cap 30)
        raise guard.SizeLimitError("the MDP would need more memory than the limit", None)

    monkeypatch.setattr(guard, "build_checked", refuse)
    path = str(wncs_lp.scenario_path("paper_p12"))
    assert main(["solve", path, "--set", "tau_cap=9", "--json"]) == 0
    out = _json(capsys)
    assert out["method"] == "matrix-free" and "would not fit" in out["matrix_free_reason"]
    assert out["status"] == "optimal"
    # an explicit stored-matrix method is still refused
    assert main(["solve", path, "--set", "tau_cap=9", "--method", "vi"]) == 2


def test_matrix_free_solves_the_preemption_model_too(capsys):
    path = str(wncs_lp.scenario_path("paper_preemption_p12"))
    assert main(["solve", path, "--set", "tau_cap=8", "--method", "matrix-free", "--json"]) == 0
    mf = _json(capsys)
    assert main(["solve", path, "--set", "tau_cap=8", "--method", "vi", "--json"]) == 0
    vi = _json(capsys)
    assert vi["gain_lower"] - 1e-9 * vi["gain"] <= mf["gain"] <= vi["gain_upper"] + 1e-9 * vi["gain"]
