"""Results other tools read (issues 16, 26): ``solve --out`` saves the policy and the bias; ``export
--format drn`` writes Storm's explicit format, checked here by an independent parser written from
Storm's format description (``tests/reference/model_files.py``) and by Storm itself; a constrained
scenario's constraint quantities travel as extra reward models, checked by Storm's multi-objective
engine against the toolkit's certified constrained optimum."""
from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
from reference.model_files import parse_drn, storm_dtmc

import wncs_lp
from wncs_lp.cli import main
from wncs_lp import solve
from wncs_lp.io import (ExportError, constraint_reward_names, initial_state, load_policy_npz,
                            multi_objective_property, reward_models, save_drn)
from wncs_lp.mdp import MDP

P12 = str(wncs_lp.scenario_path("paper_p12"))
PRE = str(wncs_lp.scenario_path("paper_preemption_p12"))
BUDGET = str(wncs_lp.scenario_path("paper_p12_cloud_budget"))


@pytest.mark.parametrize("path, sets", [(P12, ["tau_cap=8"]), (PRE, ["tau_cap=8"])])
def test_drn_round_trip_through_an_independent_parser(tmp_path, path, sets, capsys):
    out = tmp_path / "m.drn"
    assert main(["export", path, *[a for s in sets for a in ("--set", s)], "--format", "drn", "--out", str(out),
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["format"] == "drn"
    sc = wncs_lp.load_scenario(path, sets)
    mdp = wncs_lp.build(sc)
    d = parse_drn(out.read_text())
    assert d["head"] == {"type": "MDP", "reward_models": "cost", "nr_states": str(mdp.n_states),
                         "nr_choices": str(mdp.n_pairs)}
    np.testing.assert_array_equal(d["s_indices"], mdp.s_indices)
    assert d["actions"] == [f"a{a}" for a in mdp.a_indices]
    np.testing.assert_array_equal(d["rewards"]["cost"], mdp.cost)  # exact doubles
    assert (d["P"] != mdp.P).nnz == 0
    # targets ascending within each action, as Storm's matrix builder needs
    for l in range(0, mdp.n_pairs, 97):
        seg = d["P"].indices[d["P"].indptr[l]:d["P"].indptr[l + 1]]
        assert np.all(np.diff(seg) > 0)
    inits = [s for s, lab in d["labels"].items() if "init" in lab]
    assert inits == [initial_state(mdp)]
    tau = np.asarray(mdp.states.tau)
    assert np.all(tau[inits[0]] == np.asarray(mdp.states.caps))
    at_cap = {s for s, lab in d["labels"].items() if "at_cap" in lab}
    assert at_cap == set(np.flatnonzero(np.any(tau >= np.asarray(mdp.states.caps), axis=1)).tolist())
    # the parsed model has our optimal gain
    actions = np.array([int(name[1:]) for name in d["actions"]])
    back = MDP.from_arrays(d["s_indices"], actions, d["rewards"]["cost"], d["P"], mdp.n_states)
    assert wncs_lp.solve(back, "vi").gain == pytest.approx(wncs_lp.solve(mdp, "vi").gain, rel=1e-8)


def test_storm_loads_the_drn_and_finds_our_gain(tmp_path):
    stormpy = pytest.importorskip("stormpy")  # skipped only when stormpy is not installed
    sc = wncs_lp.load_scenario(P12, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    path = save_drn(mdp, tmp_path / "m.drn", scenario=sc)
    model = stormpy.build_model_from_drn(str(path))
    assert (model.nr_states, model.nr_choices) == (mdp.n_states, mdp.n_pairs)
    assert list(model.initial_states) == [initial_state(mdp)]
    assert "cost" in model.reward_models
    prop = stormpy.parse_properties('R{"cost"}min=? [LRA]')[0]
    g_storm = stormpy.model_checking(model, prop).get_value(model.initial_states[0])
    sol = wncs_lp.solve(mdp, "vi")
    assert g_storm == pytest.approx(sol.gain, rel=1e-5)  # Storm's own precision: 1e-6 relative


# Storm's stated precisions: 1e-6 relative for a long-run average, 1e-4 absolute for a multi-objective query
STORM_RTOL, STORM_MULTI_ATOL = 1e-6, 1e-4


@pytest.fixture(scope="module")
def budget():
    """The cloud-budget scenario at cap 8, its MDP and its certified constrained optimum."""
    sc = wncs_lp.load_scenario(BUDGET, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    return sc, mdp, solve(mdp, constraints=sc.constraints)


def test_constraint_quantities_travel_as_reward_models(tmp_path, budget):
    sc, mdp, _ = budget
    path = save_drn(mdp, tmp_path / "b.drn", scenario=sc)
    d = parse_drn(path.read_text())
    assert constraint_reward_names(sc) == ("send_rate_remote",)
    assert d["head"]["reward_models"] == "cost send_rate_remote"
    np.testing.assert_array_equal(d["rewards"]["cost"], mdp.cost)
    # independently of the toolkit's quantity code: 1 exactly when the action sends to server 0 (remote)
    sends = np.asarray(mdp.action_table)[mdp.a_indices, 0] != 0
    np.testing.assert_array_equal(d["rewards"]["send_rate_remote"], sends.astype(float))
    assert 'multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2 [LRA])' in path.read_text()


def test_storm_multi_objective_finds_the_constrained_optimum(tmp_path, budget):
    stormpy = pytest.importorskip("stormpy")  # skipped only when stormpy is not installed
    sc, mdp, cs = budget
    assert cs.status == "optimal"
    model = stormpy.build_model_from_drn(str(save_drn(mdp, tmp_path / "b.drn", scenario=sc)))
    assert set(model.reward_models) == {"cost", "send_rate_remote"}
    prop = stormpy.parse_properties(multi_objective_property(sc))[0]
    g_storm = stormpy.model_checking(model, prop).get_value(model.initial_states[0])
    # Storm's answer lies in the toolkit's certificate widened by Storm's own precision
    slack = STORM_MULTI_ATOL + STORM_RTOL * abs(cs.gain)
    assert cs.gain_lower - slack <= g_storm <= cs.gain_upper + slack
    # and the bound binds: without it Storm finds the lower unconstrained optimum
    g_free = stormpy.model_checking(model, stormpy.parse_properties('R{"cost"}min=? [LRA]')[0])
    assert g_free.get_value(model.initial_states[0]) < cs.gain - 1.0


def test_storm_evaluates_every_reward_model_under_the_randomised_optimum(tmp_path, budget):
    """Each reward model read back from the file, averaged by Storm on the chain the toolkit's
    optimal randomised policy induces, is the toolkit's own average (gain; the constraint's value)."""
    pytest.importorskip("stormpy")
    import stormpy

    sc, mdp, cs = budget
    d = parse_drn(save_drn(mdp, tmp_path / "b.drn", scenario=sc).read_text())
    probs = np.asarray(cs.policy, dtype=float)
    assert probs.shape == (mdp.n_pairs,) and 0 < cs.randomized_states.size
    # the induced chain, from the file's own arrays: P_pi = E_pi P, r_pi = E_pi r
    E = sp.csr_matrix((probs, (d["s_indices"], np.arange(mdp.n_pairs))), shape=(mdp.n_states, mdp.n_pairs))
    rewards = {name: E @ values for name, values in d["rewards"].items()}
    chain = storm_dtmc((E @ d["P"]).tocsr(), rewards, initial_state(mdp))
    got = {}
    for name in rewards:
        res = stormpy.model_checking(chain, stormpy.parse_properties(f'R{{"{name}"}}=? [LRA]')[0])
        got[name] = res.get_value(initial_state(mdp))
    assert got["cost"] == pytest.approx(cs.gain, rel=STORM_RTOL * 10)
    (report,) = cs.constraints
    assert got["send_rate_remote"] == pytest.approx(report.value, rel=STORM_RTOL * 10, abs=1e-9)
    assert got["send_rate_remote"] <= 0.2 + 1e-6


def test_reward_models_refuse_bad_extra_rewards(budget):
    sc, mdp, _ = budget
    ok = reward_models(mdp, sc, {"energy": np.ones(mdp.n_pairs)})
    assert list(ok) == ["cost", "send_rate_remote", "energy"]
    for rewards, words in [({"two words": np.ones(mdp.n_pairs)}, "identifier"),
                           ({"cost": np.ones(mdp.n_pairs)}, "given twice"),
                           ({"e": np.ones(3)}, f"expected {mdp.n_pairs} values"),
                           ({"e": -np.ones(mdp.n_pairs)}, ">= 0")]:
        with pytest.raises(ExportError, match=words):
            reward_models(mdp, sc, rewards)
    with pytest.raises(ExportError, match="no \\[\\[constraint\\]\\] table"):
        multi_objective_property(wncs_lp.load_scenario(P12, ["tau_cap=8"]))


def test_solve_out_saves_policy_and_bias(tmp_path, capsys):
    out = tmp_path / "sol.npz"
    assert main(["solve", P12, "--set", "tau_cap=8", "--method", "pi", "--out", str(out), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["out"] == str(out)
    sc = wncs_lp.load_scenario(P12, ["tau_cap=8"])
    mdp = wncs_lp.build(sc)
    sol = wncs_lp.solve(mdp, "pi")
    with np.load(out, allow_pickle=False) as z:
        np.testing.assert_allclose(z["bias"], sol.bias, rtol=1e-12, atol=1e-9)
        np.testing.assert_array_equal(z["sigma"], sol.sigma)
        np.testing.assert_array_equal(z["tau"], mdp.states.tau)
        assert float(z["gain"]) == pytest.approx(sol.gain, rel=1e-12) and str(z["status"]) == "optimal"
        assert float(z["gain_lower"]) <= float(z["gain"]) <= float(z["gain_upper"])
    probs = load_policy_npz(out, mdp)  # the policy part is a policy-npz file
    np.testing.assert_array_equal(np.flatnonzero(probs), sol.policy)


def test_constrained_solve_out_saves_the_randomised_policy(tmp_path, capsys):
    out = tmp_path / "c.npz"
    budget = str(wncs_lp.scenario_path("paper_p12_cloud_budget"))
    assert main(["solve", budget, "--set", "tau_cap=8", "--out", str(out), "--json"]) == 0
    capsys.readouterr()
    with np.load(out, allow_pickle=False) as z:
        assert "bias" not in z.files and z["policy"].dtype == np.float64
        assert np.all((z["sigma"] == -1) == np.isin(np.arange(z["sigma"].size), z["randomized_states"]))


@pytest.mark.parametrize("command", [["export", "--format", "drn"], ["export"], ["solve"]])
def test_out_in_a_missing_folder_fails_first_and_creates_nothing(tmp_path, command, capsys):
    missing = tmp_path / "nonexistent" / "dir"
    rc = main([command[0], P12, "--set", "tau_cap=8", *command[1:], "--out", str(missing / "x.npz")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "does not exist" in err and "Traceback" not in err
    assert not (tmp_path / "nonexistent").exists()
