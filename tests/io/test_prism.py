"""PRISM's explicit files (``wncs-lp export --format prism``, :func:`wncs_lp.io.save_prism`),
read back by a parser written from PRISM's manual (``tests/reference/model_files.py``) and checked
in Storm, loaded through stormpy's sparse-model builder: the minimal long-run average cost is the
toolkit's certified gain, and a constrained scenario's multi-objective optimum its certified
constrained optimum."""
from __future__ import annotations

import json

import numpy as np
import pytest
from reference.model_files import parse_prism, storm_mdp

import wncs_lp
from wncs_lp.cli import main
from wncs_lp import solve
from wncs_lp.io import initial_state, multi_objective_property, save_prism
from wncs_lp.mdp import MDP

P12 = str(wncs_lp.scenario_path("paper_p12"))
PRE = str(wncs_lp.scenario_path("paper_preemption_p12"))
BUDGET = str(wncs_lp.scenario_path("paper_p12_cloud_budget"))
STORM_RTOL, STORM_MULTI_ATOL = 1e-6, 1e-4  # Storm's stated precisions (LRA relative, multi-objective absolute)


def _storm_value(model, formula: str, state: int) -> float:
    import stormpy

    return stormpy.model_checking(model, stormpy.parse_properties(formula)[0]).get_value(state)


@pytest.mark.parametrize("path", [P12, PRE])
def test_prism_files_hold_the_mdp(tmp_path, path):
    sc = wncs_lp.load_scenario(path, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    files = save_prism(mdp, tmp_path / "m", scenario=sc)
    assert sorted(f.name for f in files.values()) == ["m.lab", "m.srew", "m.sta", "m.tra"]  # state-only cost
    d = parse_prism(tmp_path / "m")
    assert d["n"] == mdp.n_states
    np.testing.assert_array_equal(d["s_indices"], mdp.s_indices)
    assert d["actions"] == [f"a{a}" for a in mdp.a_indices]
    assert (d["P"] != mdp.P).nnz == 0  # exact doubles
    assert list(d["rewards"]) == ["cost"]
    np.testing.assert_array_equal(d["rewards"]["cost"], mdp.cost)
    # states: (config, tau_1..tau_N), numbered in lexicographic order as PRISM's own exports are
    assert d["variables"] == ["config"] + [f"tau{k + 1}" for k in range(len(sc.processes))]
    np.testing.assert_array_equal(d["values"][:, 0], mdp.states.config)
    np.testing.assert_array_equal(d["values"][:, 1:], mdp.states.tau)
    keys = [tuple(v) for v in d["values"].tolist()]
    assert keys == sorted(keys)
    assert d["labels"]["init"] == {initial_state(mdp)} and d["labels"]["deadlock"] == set()
    tau = np.asarray(mdp.states.tau)
    assert d["labels"]["at_cap"] == set(np.flatnonzero(np.any(tau >= np.asarray(mdp.states.caps), axis=1)).tolist())


@pytest.mark.parametrize("path", [P12, PRE])
def test_storm_finds_our_gain_in_the_prism_files(tmp_path, path):
    pytest.importorskip("stormpy")  # skipped only when stormpy is not installed
    sc = wncs_lp.load_scenario(path, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    save_prism(mdp, tmp_path / "m.tra", scenario=sc)  # a .tra suffix names the prefix too
    d = parse_prism(tmp_path / "m")
    (init,) = d["labels"]["init"]
    model = storm_mdp(d["P"], d["s_indices"], d["rewards"], init)
    assert (model.nr_states, model.nr_choices) == (mdp.n_states, mdp.n_pairs)
    g_storm = _storm_value(model, 'R{"cost"}min=? [LRA]', init)
    sol = wncs_lp.solve(mdp, "vi")
    assert sol.status == "optimal"
    slack = STORM_RTOL * abs(sol.gain)
    assert sol.gain_lower - slack <= g_storm <= sol.gain_upper + slack


def test_constrained_scenario_in_prism_files(tmp_path):
    pytest.importorskip("stormpy")
    sc = wncs_lp.load_scenario(BUDGET, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    files = save_prism(mdp, tmp_path / "b", scenario=sc)
    # two reward structures, numbered as PRISM's -importmodel b.all finds them; send_rate depends on the action,
    # so both come with a .trew and a .srew (PRISM pairs them by number, and their names must match)
    assert sorted(f.name for f in files.values()) == ["b.lab", "b.sta", "b.tra", "b1.srew", "b1.trew", "b2.srew",
                                                      "b2.trew"]
    assert (tmp_path / "b1.trew").read_text().splitlines()[2] == f"{mdp.n_states} {mdp.n_pairs} 0"
    assert (tmp_path / "b2.srew").read_text().splitlines()[2] == f"{mdp.n_states} 0"
    d = parse_prism(tmp_path / "b")
    assert list(d["rewards"]) == ["cost", "send_rate_remote"]
    np.testing.assert_array_equal(d["rewards"]["cost"], mdp.cost)
    sends = np.asarray(mdp.action_table)[mdp.a_indices, 0] != 0
    np.testing.assert_array_equal(d["rewards"]["send_rate_remote"], sends.astype(float))
    (init,) = d["labels"]["init"]
    g_storm = _storm_value(storm_mdp(d["P"], d["s_indices"], d["rewards"], init), multi_objective_property(sc), init)
    cs = solve(mdp, constraints=sc.constraints)
    assert cs.status == "optimal"
    slack = STORM_MULTI_ATOL + STORM_RTOL * abs(cs.gain)
    assert cs.gain_lower - slack <= g_storm <= cs.gain_upper + slack


def test_action_dependent_cost_goes_to_the_transition_rewards(tmp_path):
    """An MDP of one's own, without decoded states, whose cost depends on the action: the cost is
    a choice reward (.trew), the states one variable, and the parsed model has the same optimum."""
    P = np.zeros((3, 2, 3))
    P[0, 0] = [0.5, 0.5, 0]
    P[0, 1] = [0, 0, 1]
    P[1, 0] = [0, 0.5, 0.5]
    P[1, 1] = [1, 0, 0]
    P[2, 0] = [1, 0, 0]
    cost = np.array([[1.0, 3.0], [2.0, 0.5], [4.0, 0.0]])
    feasible = np.array([[True, True], [True, True], [True, False]])
    mdp = MDP.from_dense(P, cost, feasible)
    files = save_prism(mdp, tmp_path / "x")
    assert sorted(f.name for f in files.values()) == ["x.lab", "x.srew", "x.sta", "x.tra", "x.trew"]
    d = parse_prism(tmp_path / "x")
    assert d["variables"] == ["s"] and d["values"][:, 0].tolist() == [0, 1, 2]
    np.testing.assert_array_equal(d["rewards"]["cost"], mdp.cost)
    back = MDP.from_arrays(d["s_indices"], mdp.a_indices, d["rewards"]["cost"], d["P"], d["n"])
    assert wncs_lp.solve(back, "pi").gain == pytest.approx(wncs_lp.solve(mdp, "pi").gain, rel=1e-12)


def test_cli_export_prism(tmp_path, capsys):
    out = tmp_path / "run" / "b"
    out.parent.mkdir()
    assert main(["export", BUDGET, "--set", "tau_cap=8", "--format", "prism", "--out", str(out), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["format"] == "prism" and payload["out"] == str(out)
    assert sorted(payload["files"]) == sorted(str(out.parent / f) for f in ["b.tra", "b.sta", "b.lab", "b1.srew",
                                                                            "b1.trew", "b2.srew", "b2.trew"])
    assert payload["reward_models"] == ["cost", "send_rate_remote"]
    assert payload["multi_objective"] == 'multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2 [LRA])'
    assert payload["bytes"] == sum((out.parent / f).stat().st_size for f in payload["files"])
    # the format from the extension: .tra (or .all) means prism
    assert main(["export", P12, "--set", "tau_cap=8", "--out", str(tmp_path / "p.all"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "prism"
    assert (tmp_path / "p.tra").exists() and (tmp_path / "p.srew").exists()
    assert main(["export", P12, "--set", "tau_cap=8", "--format", "prism", "--compress", "--out",
                 str(tmp_path / "q")]) == 2
    err = capsys.readouterr().err
    assert "--compress applies to --format npz only" in err and not (tmp_path / "q.tra").exists()
