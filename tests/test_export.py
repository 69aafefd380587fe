"""``wncs_lp.export``: the documented .npz format round-trips exactly, from the API and the CLI."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wncs_lp.cli import main
from wncs_lp.export import FORMAT, FORMAT_VERSION, ExportError, load_npz, save_npz
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp.solvers import solve

FORMULATIONS = Path(__file__).resolve().parent.parent / "formulations"

DOCUMENTED_KEYS = {
    "format", "format_version", "n_states", "s_indices", "a_indices", "cost", "pair_ptr", "P_data",
    "P_indices", "P_indptr", "action_table", "tau", "config", "config_descriptions", "caps",
    "process_names", "scenario_fingerprint", "scenario_source", "name", "meta_json",
}


def assert_same(a: MDP, b: MDP):
    assert (a.n_states, a.n_pairs) == (b.n_states, b.n_pairs)
    for f in ("s_indices", "a_indices", "cost", "pair_ptr", "action_table"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    for f in ("data", "indices", "indptr"):
        np.testing.assert_array_equal(getattr(a.P, f), getattr(b.P, f), err_msg=f)


@pytest.mark.parametrize("name, sets", [("paper_p12.toml", ["tau_cap=7"]), ("paper_preemption_p12.toml", ["tau_cap=6"])])
@pytest.mark.parametrize("compress", [False, True])
def test_round_trip(tmp_path, name, sets, compress):
    sc = load_scenario(FORMULATIONS / name, sets)
    mdp = build(sc)
    path = save_npz(mdp, tmp_path / "m", scenario=sc, compress=compress)
    assert path.suffix == ".npz" and path.exists()
    back = load_npz(path)
    assert_same(mdp, back)
    # decoded labels: tau, configuration ids and descriptions
    np.testing.assert_array_equal(back.states.tau, mdp.states.tau)
    np.testing.assert_array_equal(back.states.config, mdp.states.config)
    np.testing.assert_array_equal(back.states._lookup, mdp.states._lookup)
    for s in (0, mdp.n_states // 2, mdp.n_states - 1):
        assert back.state_label(s) == mdp.state_label(s)
        assert back.states.find(mdp.states.tau[s], int(mdp.states.config[s])) == s
    assert back.meta["fingerprint"] == sc.fingerprint()
    assert back.meta["format_version"] == FORMAT_VERSION
    # the same optimal gain from the file
    assert solve(back, "vi").gain == pytest.approx(solve(mdp, "vi").gain, rel=1e-9)


def test_file_is_plain_numpy_with_the_documented_keys(tmp_path):
    sc = load_scenario(FORMULATIONS / "paper_p14.toml", ["tau_cap=5"])
    mdp = build(sc)
    path = save_npz(mdp, tmp_path / "m.npz", scenario=sc)
    with np.load(path, allow_pickle=False) as z:
        assert set(z.files) == DOCUMENTED_KEYS
        assert str(z["format"]) == FORMAT and int(z["format_version"]) == 1
        L, n = z["s_indices"].size, int(z["n_states"])
        import scipy.sparse as sp

        P = sp.csr_matrix((z["P_data"], z["P_indices"], z["P_indptr"]), shape=(L, n))
        np.testing.assert_allclose(np.asarray(P.sum(axis=1)).ravel(), 1.0, atol=1e-12)
        assert z["tau"].shape == (n, 2) and z["config"].shape == (n,)
        assert list(z["process_names"]) == [p.name for p in sc.processes]
        assert json.loads(str(z["meta_json"]))["kind"] == "wncs"


def test_plain_mdp_without_state_space(tmp_path):
    mdp = MDP.from_arrays([0, 0, 1], [0, 1, 0], [1.0, 2.0, 0.5], [[0.5, 0.5], [0.0, 1.0], [1.0, 0.0]], 2)
    back = load_npz(save_npz(mdp, tmp_path / "plain.npz"))
    assert_same(mdp, back)
    assert back.states is None and back.action_table is None


def test_not_an_export(tmp_path):
    np.savez(tmp_path / "other.npz", x=np.arange(3))
    with pytest.raises(ExportError, match="not a wncs_lp.mdp-npz"):
        load_npz(tmp_path / "other.npz")
    (tmp_path / "junk.npz").write_text("hello")
    with pytest.raises(ExportError, match="not a readable"):
        load_npz(tmp_path / "junk.npz")


def test_cli_export(tmp_path, capsys):
    out = tmp_path / "cli.npz"
    rc = main(["export", str(FORMULATIONS / "paper_p12.toml"), "--set", "tau_cap=6", "--out", str(out), "--json"])
    assert rc == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["out"] == str(out) and payload["states"] > 0
    mdp = load_npz(out)
    assert (mdp.n_states, mdp.n_pairs, mdp.P.nnz) == (payload["states"], payload["pairs"], payload["nnz"])
    assert main(["export", str(FORMULATIONS / "paper_p12.toml"), "--set", "nonsense=1", "--out", str(out)]) == 2
