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
                     "server.1.processing_time", "process.x.weight", "server.9.p_up", "foo", "model.bar"]),
    st.text(alphabet="abcdefghijklmnopqrstuvwxyz.0123456789_", max_size=20),
)
override_value = st.one_of(
    st.sampled_from(["0.8", "1.2", "-1", "nan", "inf", "true", "[[1.1]]", "[[1,2],[3,4]]", "preemption", "\"x\"",
                     "[1, 2]", "0", "1", "1e400", "[", "{}"]),
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
