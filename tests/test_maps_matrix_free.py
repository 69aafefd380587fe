"""Policy maps of matrix-free policies (no MDP): the grid against the stored-matrix map of the
same policy, the drawing, and ``wncs-lp map --method matrix-free`` (and auto switching to it)."""
from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import wncs_lp as w  # noqa: E402
from wncs_lp.cli import main  # noqa: E402
from wncs_lp.errors import ModelError  # noqa: E402
from wncs_lp.policy_grids import matrix_free_grid, matrix_free_region_stats, policy_grid, region_stats  # noqa: E402
from wncs_lp.policies import MatrixFreePolicy  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402
from wncs_lp.viz import plot_matrix_free_map  # noqa: E402


@pytest.fixture(scope="module", params=[("paper_p123", "tau_cap=9", (1, 3), {2: 4}),
                                        ("paper_p1234", "tau_cap=8", (2, 4), {1: 3, 3: 5}),
                                        ("paper_preemption_p12", "tau_cap=8", (1, 2), {})])
def case(request):
    name, cap, axes, fixed = request.param
    sc = w.load_scenario(w.scenario_path(name), [cap])
    mdp = w.build(sc)
    sol = matrix_free_value_iteration(sc)
    return sc, mdp, sol, axes, fixed


def test_grid_equals_the_stored_matrix_map_of_the_same_policy(case):
    sc, mdp, sol, axes, fixed = case
    pol = MatrixFreePolicy.from_solution(sol)
    on = sol.on_mdp(mdp)  # the same policy as pair indices on the enumerated MDP
    configs = range(len(mdp.states.configs))
    checked = 0
    for c in list(configs)[:: max(1, len(mdp.states.configs) // 12)]:
        A_mdp, S, _ = policy_grid(mdp, on, c, axes, fixed)
        if fixed and not (S >= 0).any():
            continue
        try:
            A_mf, labels, used, cid = matrix_free_grid(pol, c, axes, fixed)
        except ModelError:  # a fixed value outside this configuration's box: unreachable in the MDP too
            assert not (S >= 0).any()
            continue
        assert cid == c and all(used[k] == v for k, v in fixed.items())
        reach = S >= 0
        assert np.all(A_mf[reach] >= 0), "a reachable state lies outside the layout box"
        want = [tuple(int(x) for x in np.atleast_1d(mdp.action_table[a])) for a in A_mdp[reach]]
        got = [tuple(int(x) for x in np.atleast_1d(labels[a])) for a in A_mf[reach]]
        assert want == got
        checked += int(reach.sum())
    assert checked > 0


def test_region_stats_name_actions_like_the_stored_matrix_map(case):
    sc, mdp, sol, axes, fixed = case
    c = 0  # the idle configuration: its box holds every fixed value of these cases
    mf = matrix_free_region_stats(MatrixFreePolicy.from_solution(sol), c, axes, fixed)
    ref = region_stats(mdp, sol.on_mdp(mdp), c, axes=axes, fixed_tau=fixed, scenario=sc)
    # the layout box may hold a few cells the MDP does not reach; every action of the stored
    # matrix's map is there under the same name, with at least its cells
    for name, r in ref["per_action"].items():
        assert name in mf["per_action"] and mf["per_action"][name]["cells"] >= r["cells"]


def test_plot_returns_axes_with_one_entry_per_action(case):
    sc, mdp, sol, axes, fixed = case
    ax = plot_matrix_free_map(sol, 0, axes, fixed)
    A, labels, _, _ = matrix_free_grid(MatrixFreePolicy.from_solution(sol), 0, axes, fixed)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sum("cells]" in t for t in texts) == len(np.unique(A[A >= 0]))
    assert "matrix-free" in ax.get_title()


def test_bad_fixed_values_are_named():
    sc = w.load_scenario(w.scenario_path("paper_p123"), ["tau_cap=9"])
    pol = MatrixFreePolicy.from_solution(matrix_free_value_iteration(sc))
    with pytest.raises(ModelError, match="tau_3 = 12 outside 1..9"):
        matrix_free_grid(pol, 0, (1, 2), {3: 12})
    with pytest.raises(ModelError, match="axes must be 2 distinct"):
        matrix_free_grid(pol, 0, (1, 1))
    with pytest.raises(ModelError, match="no reachable configuration matches"):
        matrix_free_grid(pol, "nonsense configuration", (1, 2))


def test_cli_map_matrix_free_and_auto_fallback(tmp_path, capsys, monkeypatch):
    path = str(w.scenario_path("paper_p123"))
    out = tmp_path / "m.png"
    assert main(["map", path, "--set", "tau_cap=9", "--method", "matrix-free", "--servers", "idle", "--fix", "3=4",
                 "--out", str(out), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert out.stat().st_size > 1000 and got["method"] == "matrix-free" and got["regions"]["per_action"]
    assert main(["map", path, "--set", "tau_cap=9", "--method", "vi", "--servers", "idle", "--fix", "3=4",
                 "--out", str(tmp_path / "r.png"), "--json"]) == 0
    ref = json.loads(capsys.readouterr().out)
    assert ref["gain"] == pytest.approx(got["gain"], rel=1e-8)
    # three axes without --slice: refused before any solve, for both routes
    for method in ("matrix-free", "vi"):
        assert main(["map", path, "--set", "tau_cap=9", "--method", method, "--servers", "idle", "--axes", "1,2,3",
                     "--out", str(tmp_path / "x.png")]) == 2
        assert "a map takes two processes" in capsys.readouterr().err
    # the slice needs the MDP: refused with one line
    assert main(["map", path, "--set", "tau_cap=9", "--method", "matrix-free", "--servers", "idle", "--slice", "12",
                 "--out", str(tmp_path / "s.png")]) == 2
    assert "--slice is not available" in capsys.readouterr().err

    import wncs_lp.models.guard as guard

    def refuse(scenario, **kw):
        raise guard.SizeLimitError("the MDP would need more memory than the limit", None)

    monkeypatch.setattr(guard, "build_checked", refuse)
    assert main(["map", path, "--set", "tau_cap=9", "--servers", "idle", "--fix", "3=4", "--out", str(out),
                 "--json"]) == 0
    auto = json.loads(capsys.readouterr().out)
    assert "would not fit" in auto["matrix_free_reason"] and auto["regions"] == got["regions"]
