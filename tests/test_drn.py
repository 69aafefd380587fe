"""Results other tools read (issue 16): ``solve --out`` saves the policy and the bias; ``export
--format drn`` writes Storm's explicit format, checked here by an independent parser written from
Storm's format description and, when stormpy is installed, by Storm itself."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.export import initial_state, load_policy_npz, save_drn
from wncs_lp.mdp import MDP

P12 = str(wncs_lp.scenario_path("paper_p12"))
PRE = str(wncs_lp.scenario_path("paper_preemption_p12"))


def parse_drn(text: str) -> dict:
    """A plain reader of Storm's DRN for MDPs (header sections, ``state``/``action`` lines,
    ``target : probability`` lines), independent of the writer."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("//")]
    head: dict[str, str] = {}
    i = 0
    while lines[i] != "@model":
        ln = lines[i]
        if ln.startswith("@type: "):
            head["type"] = ln[len("@type: "):]
        elif ln in ("@reward_models", "@nr_states", "@nr_choices"):
            i += 1
            head[ln[1:]] = lines[i]
        elif ln == "@parameters":
            pass  # an empty parameter line (skipped above as blank)
        else:
            raise AssertionError(f"unexpected header line {ln!r}")
        i += 1
    n, L = int(head["nr_states"]), int(head["nr_choices"])
    s_idx, names, cost, rows, cols, vals, labels = [], [], [], [], [], [], {}
    state = -1
    for ln in lines[i + 1:]:
        if ln.startswith("state "):
            parts = ln.split()
            state += 1
            assert int(parts[1]) == state, "state ids must be consecutive from 0"
            labels[state] = parts[2:]
        elif ln.startswith("\taction "):
            m = re.fullmatch(r"\taction (\S+) \[([^\]]+)\]", ln)
            assert m, ln
            s_idx.append(state)
            names.append(m.group(1))
            cost.append(float(m.group(2)))
        else:
            m = re.fullmatch(r"\t\t(\d+) : (\S+)", ln)
            assert m, ln
            rows.append(len(s_idx) - 1)
            cols.append(int(m.group(1)))
            vals.append(float(m.group(2)))
    assert state + 1 == n and len(s_idx) == L
    P = sp.csr_matrix((vals, (rows, cols)), shape=(L, n))
    return dict(head=head, s_indices=np.array(s_idx), names=names, cost=np.array(cost), P=P, labels=labels,
                cols=cols, rows=rows)


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
    assert d["names"] == [f"a{a}" for a in mdp.a_indices]
    np.testing.assert_array_equal(d["cost"], mdp.cost)  # exact doubles
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
    actions = np.array([int(name[1:]) for name in d["names"]])
    back = MDP.from_arrays(d["s_indices"], actions, d["cost"], d["P"], mdp.n_states)
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
