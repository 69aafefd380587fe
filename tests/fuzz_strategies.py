"""Hypothesis strategies for scenario fuzzing, shared by tests/test_fuzz.py and
benchmarks/fuzz_scenarios.py (which runs >= 10,000 cases).

Cases are valid scenarios, subtly invalid ones (one field broken: NaN, inf, negative delays, empty
process list, A of the wrong shape, R not symmetric or not PSD, probabilities of exactly 0 or 1,
duplicate names, wrong types, absurd sizes...), TOML text of random structure and random bytes.
The contract checked: loading either succeeds or raises the toolkit's own ScenarioError whose
message names a field.
"""
from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from wncs_lp.errors import ScenarioError
from wncs_lp.scenario import load_scenario, parse_overrides, apply_overrides, scenario_from_dict

FIELD_RE = re.compile(r": (field|override) '.+': .+")

finite = st.floats(min_value=-3, max_value=3, allow_nan=False, allow_infinity=False)
weird_number = st.one_of(
    st.just(float("nan")),
    st.just(float("inf")),
    st.just(-float("inf")),
    st.just(0),
    st.just(1),
    st.just(0.0),
    st.just(1.0),
    st.just(-1),
    st.just(10**12),
    st.just(True),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**6), max_value=10**6),
)
weird_value = st.one_of(
    weird_number,
    st.text(max_size=8),
    st.lists(finite, max_size=3),
    st.lists(st.lists(finite, max_size=3), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
    st.none(),
)


@st.composite
def matrix(draw, n: int | None = None) -> list[list[float]]:
    n = draw(st.integers(1, 3)) if n is None else n
    return [[draw(finite) for _ in range(n)] for _ in range(n)]


@st.composite
def valid_raw(draw) -> dict[str, Any]:
    """A valid raw scenario dictionary (small)."""
    kind = draw(st.sampled_from(["wncs", "preemption"]))
    n_proc = draw(st.integers(1, 3))
    procs = []
    for k in range(n_proc):
        n = draw(st.integers(1, 3))
        p: dict[str, Any] = {"name": f"p{k}", "A": draw(matrix(n))}
        if draw(st.booleans()):
            p["weight"] = draw(st.floats(0.1, 5))
        if draw(st.booleans()):
            p["tau_cap"] = draw(st.integers(1, 20))
        if draw(st.booleans()):
            p["R"] = "identity"
        elif draw(st.booleans()):
            d = [draw(st.floats(0, 3)) for _ in range(n)]
            p["R"] = [[d[i] if i == j else 0.0 for j in range(n)] for i in range(n)]
        if draw(st.booleans()):  # cost families (docs/scenarios.md); a table covers every cap drawn (<= 20)
            p["cost"] = draw(st.one_of(st.sampled_from(["mse", "aoi", {"power": 2.0}, {"power": 0.5}]),
                                       st.lists(st.floats(0, 10), min_size=20, max_size=25).map(sorted)))
        if draw(st.booleans()):
            p["arrival_probability"] = draw(st.sampled_from([1.0, 0.5, 0.05]))
        procs.append(p)
    n_srv = 1 if kind == "preemption" else draw(st.integers(1, 3))
    servers = []
    for m in range(n_srv):
        s: dict[str, Any] = {
            "name": f"s{m}",
            "uplink_delay": draw(st.integers(0, 3)),
            "downlink_delay": draw(st.integers(0, 3)),
        }
        if draw(st.booleans()):
            s["slots_per_dimension"] = draw(st.integers(1, 3))
        else:
            s["processing_time"] = [draw(st.integers(1, 5)) for _ in range(n_proc)]
        for key in ("p_up", "p_down"):
            if draw(st.booleans()):
                s[key] = draw(st.sampled_from([0.0, 1.0, 0.5, 0.9]))
            elif draw(st.booleans()):  # per-link: one per process
                s[key] = [draw(st.sampled_from([0.0, 1.0, 0.5, 0.9])) for _ in range(n_proc)]
        servers.append(s)
    model = {"kind": kind, "tau_cap": draw(st.integers(1, 20))}
    for key in ("allow_idle", "distinct", "preemptive"):
        if draw(st.booleans()):
            model[key] = draw(st.booleans())
    return {
        "model": model,
        "channel": {"success_probability": draw(st.sampled_from([0.0, 1.0, 0.3, 0.9]))},
        "process": procs,
        "server": servers,
    }


def _paths(raw: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(raw, dict):
        for k, v in raw.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(raw, list):
        for i, v in enumerate(raw):
            out += _paths(v, prefix + (i,))
    return out


@st.composite
def mutated_raw(draw) -> dict[str, Any]:
    """A valid scenario with one or two fields replaced, deleted or added."""
    raw = draw(valid_raw())
    for _ in range(draw(st.integers(1, 2))):
        paths = _paths(raw)
        path = draw(st.sampled_from(paths))
        parent = raw
        for key in path[:-1]:
            parent = parent[key]
        op = draw(st.sampled_from(["replace", "delete", "add", "empty"]))
        last = path[-1]
        if op == "replace":
            parent[last] = draw(weird_value)
        elif op == "delete":
            del parent[last]
        elif op == "add" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["extra", "wieght", "p", "T", "name"]))] = draw(weird_value)
        elif op == "empty":
            parent[last] = [] if isinstance(parent[last], list) else {}
        if not isinstance(raw, dict):
            break
    return raw


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int,)):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f'"{k}" = {_toml_value(x)}' for k, x in v.items()) + "}"
    return '"?"'


def to_toml(raw: dict[str, Any]) -> str:
    """Serialise a raw scenario dict (as generated above) to TOML text."""
    lines = []
    for key, val in raw.items():
        if isinstance(val, dict):
            lines.append(f"[{key}]")
            lines += [f'"{k}" = {_toml_value(v)}' for k, v in val.items() if v is not None]
        elif isinstance(val, list) and all(isinstance(e, dict) for e in val) and val:
            for e in val:
                lines.append(f"[[{key}]]")
                lines += [f'"{k}" = {_toml_value(v)}' for k, v in e.items() if v is not None]
        elif val is not None:
            lines.insert(0, f'"{key}" = {_toml_value(val)}')
    return "\n".join(lines) + "\n"


override_key = st.one_of(
    st.sampled_from(["p", "tau_cap", "model.kind", "model.tau_cap", "channel.success_probability",
                     "process.1.weight", "process.1.A", "process.2.R", "server.1.p_up", "server.s0.uplink_delay",
                     "server.1.processing_time", "process.x.weight", "server.9.p_up", "foo", "model.bar",
                     "process.1.cost", "process.2.arrival_probability", "server.1.p_down"]),
    st.text(alphabet="abcdefghijklmnopqrstuvwxyz.0123456789_", max_size=20),
)
override_value = st.one_of(
    st.sampled_from(["0.8", "1.2", "-1", "nan", "inf", "true", "[[1.1]]", "[[1,2],[3,4]]", "preemption", "\"x\"",
                     "[1, 2]", "0", "1", "1e400", "[", "{}", "aoi", "{power=2}", "{power=-1}", "[2, 1]",
                     "[0.9, 0.5, 0.1]"]),
    st.text(max_size=10),
)


def check_case(kind: str, payload: Any, tmpdir: Path | None = None) -> str:
    """Run one fuzz case; return "ok" or "error". Any other exception propagates (a bug)."""
    try:
        if kind == "dict":
            scenario_from_dict(payload)
        elif kind in ("toml", "bytes"):
            assert tmpdir is not None
            f = tmpdir / "case.toml"
            f.write_bytes(payload if isinstance(payload, bytes) else payload.encode("utf-8", "surrogatepass"))
            load_scenario(f)
        elif kind == "override":
            raw, items = payload
            scenario_from_dict(apply_overrides(raw, parse_overrides(items)))
        else:  # pragma: no cover
            raise AssertionError(kind)
    except ScenarioError as exc:
        msg = str(exc)
        if not FIELD_RE.search(msg):
            raise AssertionError(f"error message names no field: {msg!r}") from exc
        return "error"
    return "ok"


def scratch_dir() -> Path:
    return Path(tempfile.mkdtemp(prefix="wncs_fuzz_"))


# ----------------------------------------------------------------------------- issue 27: hostile families
#: Override values a hostile user types: huge integers, deep nests, strange digits, broken TOML.
hostile_value = st.one_of(
    override_value,
    st.sampled_from(["9" * 400, "-" + "9" * 400, "9" * 5000, "[[" + "9" * 400 + "]]", "1e400", "-0", "0x10",
                     "[" * 2000 + "]" * 2000, "[" * 30 + "]" * 30, "[[1e308, 1e308], [1e308, 1e308]]",
                     "[[1e300]]", "[[3.0]]", '"²"', "١", "inf", "[[nan]]", "{a = 1}", "[[[1]]]"]),
)
#: Override keys: quoted selectors, non-ASCII digits, malformed quotes, empty parts.
hostile_key = st.one_of(
    override_key,
    st.sampled_from(['process."1".weight', 'process."p0".weight', "process.².weight", "process.١.weight",
                     'process."x.y".tau_cap', 'process."1.weight', "process..weight", "process.1.", ".p",
                     'server."s0".p_up', "server.00.p_up", "process.99999999999999999999.weight",
                     "constraint.1.max", 'constraint."1".max', "process.1.A", "process.1.tau_cap"]),
    st.text(alphabet='abcdefghijklmnopqrstuvwxyz.0123456789_"²١', max_size=20),
)


def check_override_forms(raw: dict[str, Any], pairs: list[tuple[str, str]], tmpdir: Path) -> str:
    """The same overrides as a list of strings, one string each (load_scenario) and a mapping of
    parsed values: each either loads or raises a ScenarioError naming a field. Returns "ok"/"error"."""
    items = [f"{k}={v}" for k, v in pairs]
    outcome = check_case("override", (raw, items))
    f = tmpdir / "base.toml"
    f.write_text(to_toml(raw))
    for one in items[:1]:
        try:
            load_scenario(f, one)
        except ScenarioError as exc:
            if not FIELD_RE.search(str(exc)):
                raise AssertionError(f"error message names no field: {exc}") from exc
    try:
        load_scenario(f, {k: v for k, v in pairs})
    except ScenarioError as exc:
        if not FIELD_RE.search(str(exc)):
            raise AssertionError(f"error message names no field: {exc}") from exc
    return outcome


# ----------------------------------------------------------------------------- npz files
def npz_bases(tmpdir: Path) -> dict[str, bytes]:
    """Small exported files to mutate: an MDP, a policy and a solve's solution (paper_p12, cap 7)."""
    from wncs_lp import build, scenario_path
    from wncs_lp.io import save_npz, save_policy_npz, save_solution_npz
    from wncs_lp import solve

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=7"])
    mdp = build(sc)
    sol = solve(mdp, "vi")
    paths = {"mdp": save_npz(mdp, tmpdir / "base_mdp.npz", scenario=sc),
             "policy": save_policy_npz(tmpdir / "base_policy.npz", mdp, sol, scenario=sc),
             "solution": save_solution_npz(tmpdir / "base_solution.npz", mdp, sol, scenario=sc)}
    return {k: p.read_bytes() for k, p in paths.items()}


random_array = st.one_of(
    st.builds(lambda n, v: __import__("numpy").full(n, v), st.integers(0, 400),
              st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True))),
    st.builds(lambda s: __import__("numpy").array(s), st.text(max_size=20)),
    st.builds(lambda x: __import__("numpy").array(x), st.one_of(st.integers(-10**9, 10**9), st.floats())),
    st.builds(lambda r, c: __import__("numpy").zeros((r, c), dtype="int64"), st.integers(0, 30), st.integers(0, 4)),
)


@st.composite
def npz_mutation(draw) -> tuple:
    """(which file, how: ("bytes", positions/values) | ("truncate", n) | ("entry", key, array or None))."""
    which = draw(st.sampled_from(["mdp", "policy", "solution"]))
    how = draw(st.sampled_from(["bytes", "truncate", "entry", "entry", "scale"]))
    if how == "bytes":
        flips = draw(st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=4))
        return which, ("bytes", flips)
    if how == "truncate":
        return which, ("truncate", draw(st.floats(0, 1)))
    key = draw(st.sampled_from(["n_states", "s_indices", "a_indices", "cost", "pair_ptr", "P_data", "P_indices",
                                "P_indptr", "action_table", "tau", "config", "config_descriptions", "caps",
                                "meta_json", "format", "format_version", "policy", "sigma", "bias",
                                "scenario_fingerprint", "randomized_states", "name"]))
    if how == "scale":  # a plausible edit: the same entry, shifted or permuted
        return which, ("scale", key, draw(st.sampled_from(["+1", "-1", "*255", "reverse", "drop last", "nan"])))
    return which, ("entry", key, draw(st.one_of(st.none(), random_array)))


def apply_npz_mutation(base: bytes, mutation: tuple, dst: Path) -> Path:
    import io

    import numpy as np

    how = mutation[0]
    if how == "bytes":
        data = bytearray(base)
        for pos, val in mutation[1]:
            data[pos % len(data)] ^= val
        dst.write_bytes(bytes(data))
        return dst
    if how == "truncate":
        dst.write_bytes(base[: int(mutation[1] * len(base))])
        return dst
    with np.load(io.BytesIO(base), allow_pickle=False) as z:
        d = {k: z[k] for k in z.files}
    key = mutation[1]
    if how == "entry":
        if mutation[2] is None:
            d.pop(key, None)
        else:
            d[key] = mutation[2]
    elif key in d:
        a, op = d[key], mutation[2]
        if op == "reverse" or a.dtype.kind not in "iuf":
            d[key] = a[::-1].copy() if a.ndim else a
        elif op == "drop last":
            d[key] = a[:-1] if a.ndim else a
        elif op == "nan":
            d[key] = np.where(np.arange(a.size).reshape(a.shape) == 0, np.nan, a.astype(float)) if a.size else a
        else:
            d[key] = {"+1": a + 1, "-1": a - 1, "*255": a * 255}[op]
    np.savez(dst, **d)
    return dst


def check_npz_case(kind: str, path: Path) -> str:
    """Load a (mutated) exported file: it loads, or raises one WncsError naming the file. A loaded
    MDP is solved by value iteration and by the LP: when both certify optimality they agree (an
    independent check that nothing read out of bounds); a loaded policy is a distribution per state.
    Returns "ok" or "error"; anything else propagates (a bug)."""
    import numpy as np

    from wncs_lp.errors import WncsError
    from wncs_lp.io import load_npz, load_policy_npz
    from wncs_lp import solve

    try:
        if kind == "mdp":
            mdp = load_npz(path)
            a, b = solve(mdp, "vi"), solve(mdp, "lp")
            if a.ok and b.ok:
                assert abs(a.gain - b.gain) <= 1e-6 * max(1.0, abs(a.gain)), (a.gain, b.gain)
        else:
            probs = load_policy_npz(path)
            assert np.all(np.isfinite(probs)) and probs.min() >= 0 and probs.max() <= 1
    except WncsError as exc:
        msg = str(exc)
        if str(path) not in msg or "\n" in msg:
            raise AssertionError(f"error message does not name the file in one line: {msg!r}") from exc
        return "error"
    return "ok"


# ----------------------------------------------------------------------------- reproduction caches
CACHE_TRUTH = ({"gain": 1078.548921698, "name": "static", "assignment": [1, 2]},
               {"policy": __import__("numpy").arange(12, dtype="int64"),
                "bias": __import__("numpy").linspace(-1.0, 3.0, 12)})


def cache_base(tmpdir: Path) -> tuple[bytes, bytes]:
    """The JSON and .npz bytes of one cache entry of the true result."""
    from wncs_lp.reproduce.cache import StepCache

    cache = StepCache(tmpdir / "cache_base")
    cache.store("evaluate", {"fingerprint": "f", "policy": "static"}, *CACHE_TRUTH)
    j, n = cache._paths(cache.key("evaluate", {"fingerprint": "f", "policy": "static"}))
    return j.read_bytes(), n.read_bytes()


@st.composite
def cache_mutation(draw) -> tuple:
    """An edit of the JSON text (a number, a key, a value), of its bytes, or of the arrays' bytes."""
    where = draw(st.sampled_from(["json-number", "json-key", "json-bytes", "npz-bytes", "npz-truncate",
                                  "json-value", "npz-missing"]))
    return where, draw(st.lists(st.tuples(st.integers(0, 10**6), st.integers(1, 255)), min_size=1, max_size=3)), \
        draw(st.one_of(weird_number, st.none(), st.text(max_size=5)))


def check_cache_case(base: tuple[bytes, bytes], mutation: tuple, tmpdir: Path) -> str:
    """A mutated cache entry is used only when it is still the true result; otherwise recomputed.
    Returns "reused" or "recomputed"; a wrong result or any exception is a bug."""
    import json as _json
    import shutil

    import numpy as np

    from wncs_lp.reproduce.cache import StepCache

    folder = tmpdir / "cache_case"
    shutil.rmtree(folder, ignore_errors=True)
    cache = StepCache(folder)
    params = {"fingerprint": "f", "policy": "static"}
    jpath, npath = cache._paths(cache.key("evaluate", params))
    jtext, nbytes = base
    where, flips, value = mutation
    if where == "json-number":
        doc = _json.loads(jtext)
        doc["result"]["gain"] = value if not isinstance(value, float) or math.isfinite(value) else 1.0
        jtext = _json.dumps(doc).encode()
    elif where == "json-key":
        doc = _json.loads(jtext)
        doc.pop(sorted(doc)[flips[0][0] % len(doc)])
        jtext = _json.dumps(doc).encode()
    elif where == "json-value":
        doc = _json.loads(jtext)
        doc[sorted(doc)[flips[0][0] % len(doc)]] = value
        jtext = _json.dumps(doc, allow_nan=True).encode()
    elif where in ("json-bytes", "npz-bytes"):
        data = bytearray(jtext if where == "json-bytes" else nbytes)
        for pos, val in flips:
            data[pos % len(data)] ^= val
        jtext, nbytes = (bytes(data), nbytes) if where == "json-bytes" else (jtext, bytes(data))
    elif where == "npz-truncate":
        nbytes = nbytes[: flips[0][0] % len(nbytes)]
    jpath.write_bytes(jtext)
    if where != "npz-missing":
        npath.write_bytes(nbytes)
    calls = []

    def compute():
        calls.append(1)
        return CACHE_TRUTH

    res, arrays = cache.get_or_compute("evaluate", params, compute)
    assert res == _json.loads(_json.dumps(CACHE_TRUTH[0])), res
    for k, v in CACHE_TRUTH[1].items():
        np.testing.assert_array_equal(arrays[k], v)
    return "recomputed" if calls else "reused"


# ----------------------------------------------------------------------------- sweep folders
def sweep_argv(out: Path, foreign: bool = False) -> list[str]:
    """A small sweep (paper_p12 at cap 7, two values, two policies); ``foreign``: another scenario."""
    from wncs_lp import scenario_path

    return ["sweep", str(scenario_path("paper_p12")), "--set", "tau_cap=7",
            *(["--set", "process.1.weight=2"] if foreign else []),
            "--values", "0.8,0.9", "--policies", "optimal,static", "--no-plot", "--out", str(out)]


def run_cli(argv: list[str]) -> tuple[int, str, str]:
    """``wncs_lp.cli.main`` in-process, its stdout and stderr captured; any exception propagates."""
    import contextlib
    import io

    from wncs_lp.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def sweep_rows(folder: Path) -> dict[tuple[str, str], float]:
    import csv

    try:
        with open(folder / "sweep.csv", newline="", encoding="utf-8") as f:
            return {(r["value"], r["policy"]): float(r["gain"]) for r in csv.DictReader(f)
                    if r.get("gain") not in (None, "")}
    except (OSError, ValueError, KeyError, csv.Error):
        return {}


def sweep_base(tmpdir: Path) -> tuple[dict[str, bytes], dict, dict]:
    """The files of a finished sweep folder, and the true rows of the scenario and of a foreign one."""
    base, foreign = tmpdir / "sweep_base", tmpdir / "sweep_foreign"
    for folder, flag in ((base, False), (foreign, True)):
        code, _, err = run_cli(sweep_argv(folder, flag))
        assert code == 0, err
    files = {f.name: f.read_bytes() for f in base.iterdir() if f.is_file()}
    return files, sweep_rows(base), sweep_rows(foreign)


@st.composite
def sweep_mutation(draw) -> tuple:
    """(file, edit, rerun with the foreign scenario?)."""
    name = draw(st.sampled_from(["sweep.csv", "sweep.json", "sweep_meta.json"]))
    edit = draw(st.sampled_from(["delete", "truncate", "bytes", "number", "phantom row", "duplicate row",
                                 "negative states", "garble", "empty", "folder"]))
    return name, edit, draw(st.integers(0, 10**6)), draw(st.booleans())


def check_sweep_case(base: tuple[dict[str, bytes], dict, dict], mutation: tuple, tmpdir: Path) -> tuple[str, int]:
    """Rerun the sweep on a mutated copy of its folder: the command returns an exit status (0, 1 or
    2; no exception escapes). Returns (the outcome, the number of rows whose gain is not the true
    one of the scenario run: rows trusted from a damaged or foreign folder)."""
    import shutil

    files, truth, truth_foreign = base
    name, edit, seed, foreign = mutation
    folder = tmpdir / "sweep_case"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    for fname, data in files.items():
        (folder / fname).write_bytes(data)
    target = folder / name
    data = bytearray(files.get(name, b""))
    if edit == "delete":
        target.unlink(missing_ok=True)
    elif edit == "truncate":
        target.write_bytes(bytes(data[: seed % max(len(data), 1)]))
    elif edit == "bytes" and data:
        data[seed % len(data)] ^= 1 + seed % 255
        target.write_bytes(bytes(data))
    elif edit == "number":
        text = data.decode("utf-8", "replace")
        digits = [i for i, ch in enumerate(text) if ch.isdigit()]
        if digits:
            i = digits[seed % len(digits)]
            text = text[:i] + str((int(text[i]) + 1) % 10) + text[i + 1:]
        target.write_text(text)
    elif edit in ("phantom row", "duplicate row", "negative states") and name == "sweep.csv":
        lines = data.decode().splitlines()
        if edit == "phantom row":
            lines.append(lines[-1].replace("0.9", "0.85"))
        elif edit == "duplicate row":
            lines.append(lines[1].replace(lines[1].split(",")[3], "1.0"))
        else:
            cols = lines[1].split(",")
            cols[7] = "-5"
            lines[1] = ",".join(cols)
        target.write_text("\n".join(lines) + "\n")
    elif edit == "garble":
        target.write_bytes(b"\x00\xff{garbled" * 3)
    elif edit == "empty":
        target.write_bytes(b"")
    elif edit == "folder":
        target.unlink(missing_ok=True)
        target.mkdir()
    code, out, err = run_cli(sweep_argv(folder, foreign))
    assert code in (0, 1, 2), (code, err[-2000:])
    assert "Traceback" not in err, err[-2000:]
    if code == 2:
        assert err.count("error: ") == 1, err[-2000:]
        return "error", 0
    expected = truth_foreign if foreign else truth
    got = sweep_rows(folder)
    wrong = sum(1 for key, g in got.items() if key in expected and abs(g - expected[key]) > 1e-6 * abs(expected[key]))
    wrong += sum(1 for key in got if key not in expected)
    return ("ok" if code == 0 else "failed rows"), wrong


# ----------------------------------------------------------------------------- issue 39: edited systems
def system_bases() -> dict[str, Any]:
    """The small systems an edit starts from (tests/reference/own_systems.py): the plain one and
    the per-link one, with their Systems and exact optima."""
    import wncs_lp
    from reference.own_systems import small_scenario
    from wncs_lp.models.system import System

    out = {}
    for field in ("none", "links"):
        sc = small_scenario(field)
        out[field] = (sc, System.from_scenario(sc), wncs_lp.solve(sc, "lp").gain_upper)
    return out


@st.composite
def system_edit(draw) -> tuple:
    """``(relaxation, field, value)``: one field of the plain System replaced by hand."""
    rel = draw(st.sampled_from([1, 2, 3]))
    field = draw(st.sampled_from(["q", "q", "q", "caps", "n_actions", "automaton", "model"]))
    if field == "q":
        which = draw(st.sampled_from(["power", "table", "bad"]))
        if which == "power":
            value = ("power", draw(st.floats(0.2, 3.0)))
        elif which == "table":
            value = ("table", sorted(draw(st.lists(st.floats(0, 50), min_size=5, max_size=5))))
        else:
            value = ("bad", draw(st.lists(st.one_of(finite, weird_number.filter(lambda x: isinstance(x, float))),
                                          min_size=0, max_size=7)))
    elif field in ("caps", "n_actions"):
        value = draw(st.integers(-2, 2).filter(bool))
    else:
        value = None
    return rel, field, value


def check_system_edit(bases: dict[str, Any], edit: tuple) -> str:
    """``lower_bound`` on an edited System: refused with one WncsError ("refused"), or a bound of
    the system the edit describes, at most its exact optimum ("honoured"); anything else raises."""
    import dataclasses

    import numpy as np

    import wncs_lp
    from wncs_lp.bounds import lower_bound
    from wncs_lp.errors import WncsError

    rel, field, value = edit
    sc, system, g_plain = bases["none"]
    truth = g_plain
    if field == "q":
        kind, x = value
        if kind == "power":
            q = tuple(np.arange(1, c + 1, dtype=float) ** x for c in system.caps)
        else:
            q = (np.asarray(x, dtype=float), system.q[1])
        edited = dataclasses.replace(system, q=q)
        ok = all(t.shape == (int(c),) and np.all(np.isfinite(t)) and np.all(t >= 0) and np.all(np.diff(t) >= 0)
                 for t, c in zip(q, system.caps))
        truth = (wncs_lp.solve(sc.replace(**{f"process.{k + 1}.{f}": v for k, t in enumerate(q)
                                            for f, v in (("cost", t.tolist()), ("weight", 1.0))}), "lp").gain_upper
                 if ok else None)
    elif field == "caps":
        edited = dataclasses.replace(system, caps=system.caps + value)
    elif field == "n_actions":
        edited = dataclasses.replace(system, n_actions=system.n_actions + value)
    else:
        links_sc, links_system, g_links = bases["links"]
        edited = dataclasses.replace(system, **{field: getattr(links_system, field)})
        truth = g_links if field == "automaton" else None
    try:
        bound = lower_bound(edited, rel).lower_bound
    except WncsError:
        return "refused"
    if truth is None or not bound <= truth * (1 + 1e-9):
        raise AssertionError(f"relaxation {rel} on a System with {field} edited ({value!r}) gave {bound!r}, "
                             f"above the optimum {truth!r} of the system it describes")
    return "honoured"
