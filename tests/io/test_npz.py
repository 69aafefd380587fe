"""``wncs_lp.io.npz``: the documented .npz format round-trips exactly, from the API and the CLI."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wncs_lp.cli import main
from wncs_lp.io import FORMAT, FORMAT_VERSION, ExportError, load_npz, save_npz
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp import solve

FORMULATIONS = Path(__file__).resolve().parents[2] / "formulations"

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


# ----------------------------------------------------------------------------- issue 27: hostile files
from wncs_lp.io import load_policy_npz, save_policy_npz, save_solution_npz  # noqa: E402


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A small MDP, its .npz export, a policy file and a solution file."""
    tmp = tmp_path_factory.mktemp("hostile")
    sc = load_scenario(FORMULATIONS / "paper_p12.toml", ["tau_cap=7"])
    mdp = build(sc)
    sol = solve(mdp, "vi")
    return {"mdp": mdp, "sc": sc, "sol": sol,
            "mdp.npz": save_npz(mdp, tmp / "m.npz", scenario=sc),
            "policy.npz": save_policy_npz(tmp / "p.npz", mdp, sol, scenario=sc),
            "solution.npz": save_solution_npz(tmp / "s.npz", mdp, sol, scenario=sc)}


def _edited(src: Path, dst: Path, **changes) -> Path:
    with np.load(src, allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v
    np.savez(dst, **d)
    return dst


def test_column_indices_beyond_the_states_are_refused(exported, tmp_path):
    mdp = exported["mdp"]
    idx = mdp.P.indices.copy()
    idx[3] = mdp.n_states + 7  # solve used to read out of bounds and return a number
    bad = _edited(exported["mdp.npz"], tmp_path / "b.npz", P_indices=idx)
    for validate in (True, False):
        with pytest.raises(ExportError, match="'P_indices': expected values <= "):
            load_npz(bad, validate=validate)


@pytest.mark.parametrize("entry, value, words", [
    ("s_indices", lambda m: np.r_[m.s_indices[:-1], m.n_states], "'s_indices': expected values <="),
    ("s_indices", lambda m: m.s_indices[::-1].copy(), "sorted by state"),
    ("a_indices", lambda m: np.r_[m.a_indices[:-1], 10_000], "not a row of 'action_table'"),
    ("cost", lambda m: np.r_[m.cost[:-1], np.inf], "'cost': expected finite"),
    ("cost", lambda m: np.r_[m.cost[:-1], 1e300], "'cost': expected values <= 1e\\+100"),
    ("cost", lambda m: m.cost.astype(str), "'cost': expected numbers"),
    ("cost", lambda m: m.cost[:-1], "'cost': expected shape"),
    ("P_data", lambda m: -m.P.data, "'P_data': expected values >= 0"),
    ("P_indptr", lambda m: m.P.indptr[:-1], "'P_indptr': expected shape"),
    ("pair_ptr", lambda m: m.pair_ptr[::-1].copy(), "'pair_ptr'"),
    ("n_states", lambda m: np.array(0), "'n_states': expected values >= 1"),
    ("n_states", lambda m: np.array("many"), "'n_states': expected integers"),
    ("tau", lambda m: m.states.tau * 100, "'tau': an AoI beyond its cap"),
    ("tau", lambda m: m.states.tau[:-1], "'tau': expected shape"),
    ("config", lambda m: m.states.config + 10_000, "'config': expected values <="),
    ("caps", lambda m: np.array([10**6, 10**6, 10**6]), "'caps': expected shape"),
    ("caps", lambda m: np.array([2**40, 2**40]), "lookup table"),
    ("meta_json", lambda m: np.array("{not json"), "'meta_json': expected JSON"),
    ("meta_json", lambda m: np.array("[1, 2]"), "expected a JSON object"),
    ("format_version", lambda m: np.array(7), "version 7 is not supported"),
    ("format_version", None, "without a format_version"),
    ("P_data", None, "without the entry P_data"),
    ("P_data", lambda m: m.P.data[::-1].copy(), "sum to .*, expected 1"),
    ("a_indices", lambda m: m.a_indices[::-1].copy(), "lists action .* more than once"),
])
def test_every_entry_of_an_mdp_file_is_checked(exported, tmp_path, entry, value, words):
    mdp = exported["mdp"]
    bad = _edited(exported["mdp.npz"], tmp_path / "b.npz", **{entry: None if value is None else value(mdp)})
    with pytest.raises(ExportError, match=words) as info:
        load_npz(bad)
    assert str(bad) in str(info.value)


@pytest.mark.parametrize("damage", ["empty", "truncated", "crc", "not a zip", "lone npy", "pickled"])
@pytest.mark.parametrize("which", ["mdp.npz", "policy.npz", "solution.npz"])
def test_damaged_files_are_one_error_naming_the_file(exported, tmp_path, damage, which):
    data = Path(exported[which]).read_bytes()
    bad = tmp_path / f"{damage.replace(' ', '_')}.npz"
    if damage == "empty":
        bad.write_bytes(b"")
    elif damage == "truncated":
        bad.write_bytes(data[: len(data) // 2])
    elif damage == "crc":  # flip a byte inside the first member's data: the CRC check fails on reading
        flipped = bytearray(data)
        flipped[200] ^= 0xFF
        bad.write_bytes(bytes(flipped))
    elif damage == "not a zip":
        bad.write_bytes(b"PK\x03\x04 certainly not a zip archive" * 10)
    elif damage == "lone npy":
        np.save(bad.with_suffix(".npy"), np.arange(3))
        bad.write_bytes(bad.with_suffix(".npy").read_bytes())
    else:
        np.savez(bad, format=np.array(["x", None], dtype=object))
    loader = load_npz if which == "mdp.npz" else load_policy_npz
    with pytest.raises(ExportError) as info:
        loader(bad)
    assert str(bad) in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("entry, value, words", [
    ("policy", lambda m, p: np.r_[p[:-1]], "'pair_ptr'"),
    ("policy", lambda m, p: np.full(p.size, 255.0), "'policy': expected values <= 1"),
    ("policy", lambda m, p: np.full(p.size, 0.5), "sum to"),
    ("policy", lambda m, p: np.where(p > 0, np.nan, p), "'policy': expected finite"),
    ("pair_ptr", lambda m, p: m.pair_ptr + 1, "'pair_ptr'"),
    ("a_indices", lambda m, p: -np.ones(p.size, np.int64), "'a_indices': expected values >= 0"),
    ("n_states", lambda m, p: np.array(m.n_states + 5), "'pair_ptr': expected shape"),
    ("policy", None, "holds no policy"),
])
def test_every_entry_of_a_policy_file_is_checked(exported, tmp_path, entry, value, words):
    mdp = exported["mdp"]
    with np.load(exported["policy.npz"]) as z:
        probs = z["policy"]
    bad = _edited(exported["policy.npz"], tmp_path / "b.npz",
                  **{entry: None if value is None else value(mdp, probs)})
    for target in (None, mdp):
        with pytest.raises(ExportError, match=words):
            load_policy_npz(bad, target)


def test_the_shared_reader_names_missing_keys_and_bad_json(tmp_path):
    from wncs_lp.errors import PolicyError
    from wncs_lp.files import npz_json, read_npz

    f = tmp_path / "x.npz"
    np.savez(f, meta=np.array("{oops"), lo=np.arange(2))
    with pytest.raises(PolicyError, match="missing the entries dims, policy"):
        read_npz(f, required=("meta", "dims", "policy"), error=PolicyError)
    with pytest.raises(PolicyError, match="entry 'meta': expected JSON"):
        npz_json(read_npz(f), "meta", f, error=PolicyError)
    with pytest.raises(PolicyError, match="no such file"):
        read_npz(tmp_path / "missing.npz", error=PolicyError)
