"""``wncs-lp solve --method matrix-free``, and auto switching to it when the stored matrix would not fit."""
from __future__ import annotations

import json

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
    # the solve's own time, the time-at-cap evaluation's and the whole command's, each reported apart
    # (the command's "seconds" once stood where readers took the solve's)
    assert 0 < mf["solve_seconds"] and 0 < mf["cap_mass_seconds"]
    assert mf["solve_seconds"] + mf["cap_mass_seconds"] <= mf["seconds"]
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


def test_out_writes_the_compact_policy_that_loads_back(tmp_path, capsys):
    import os

    import numpy as np

    from wncs_lp.policies import MatrixFreePolicy
    from wncs_lp.solvers.matrix_free import load_solution, matrix_free_evaluate

    path = str(wncs_lp.scenario_path("paper_p12"))
    out = tmp_path / "p12.npz"
    old = os.umask(0o022)
    try:
        assert main(["solve", path, "--set", "tau_cap=9", "--method", "matrix-free", "--out", str(out), "--json"]) == 0
    finally:
        os.umask(old)
    got = _json(capsys)
    assert (out.stat().st_mode & 0o777) == 0o644  # readable by others, as the umask says
    sc = wncs_lp.load_scenario(path, ["tau_cap=9"])
    back = load_solution(out, sc)
    assert back.local_actions.dtype == np.uint8 and back.gain == got["gain"]
    # the stored policy, evaluated exactly again, has the optimal gain (within both certificates)
    ev = matrix_free_evaluate(sc, MatrixFreePolicy.from_solution(back), tol=1e-10)
    assert got["gain_lower"] - 1e-9 * got["gain"] <= ev.gain <= got["gain_upper"] + 1e-9 * got["gain"]
