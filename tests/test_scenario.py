"""Scenario loading, overrides and validation: every bad input gets one clear ScenarioError."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from wncs_lp.errors import ScenarioError, WncsError
from wncs_lp.scenario import load_scenario, parse_overrides, scenario_from_dict

FORMULATIONS = Path(__file__).resolve().parent.parent / "formulations"

GOOD = """
[model]
kind = "wncs"
tau_cap = 8

[channel]
success_probability = 0.9

[[process]]
name = "a"
A = [[1.1, 0], [0, 1]]

[[process]]
name = "b"
A = [[1.02]]
R = [[2.0]]
weight = 3.0
tau_cap = 5

[[server]]
name = "remote"
uplink_delay = 1
downlink_delay = 1
slots_per_dimension = 1

[[server]]
name = "edge"
uplink_delay = 0
downlink_delay = 0
processing_time = [4, 2]
p_up = 0.7
"""


def write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


def test_good_file_loads_into_typed_frozen_objects(tmp_path):
    sc = load_scenario(write(tmp_path, GOOD))
    assert sc.model.kind == "wncs" and sc.model.distinct and not sc.model.allow_idle
    assert [p.name for p in sc.processes] == ["a", "b"]
    assert sc.tau_caps == (8, 5)
    np.testing.assert_array_equal(sc.processes[0].R, np.eye(2))
    assert sc.processes[1].weight == 3.0
    # slots_per_dimension * n_k
    assert sc.servers[0].processing_time == (2, 1)
    assert sc.servers[1].processing_time == (4, 2)
    # per-link override vs channel default
    assert sc.servers[1].p_up == (0.7, 0.7) and sc.servers[1].p_down == (0.9, 0.9)  # one per process
    assert sc.servers[0].loop == (1 + 2 + 1, 1 + 1 + 1)
    with pytest.raises(Exception):
        sc.p = 0.5  # frozen
    with pytest.raises(ValueError):
        sc.processes[0].A[0, 0] = 5.0  # read-only array


@pytest.mark.parametrize("path", sorted(FORMULATIONS.glob("*.toml")), ids=lambda p: p.name)
def test_shipped_formulations_load(path):
    sc = load_scenario(path)
    assert sc.n_processes >= 1 and sc.n_servers >= 1


def test_paper_instances_match_spec_section5():
    sc = load_scenario(FORMULATIONS / "paper_p1234.toml")
    assert [p.dim for p in sc.processes] == [4, 3, 2, 1]
    remote, edge = sc.servers
    assert (remote.uplink_delay, remote.downlink_delay, remote.processing_time) == (1, 1, (4, 3, 2, 1))
    assert (edge.uplink_delay, edge.downlink_delay, edge.processing_time) == (0, 0, (8, 6, 4, 2))
    assert sc.p == 0.9 and sc.tau_caps == (12, 12, 12, 12)
    pre = load_scenario(FORMULATIONS / "paper_preemption_p12.toml")
    assert pre.model.kind == "preemption" and pre.n_servers == 1


def test_overrides(tmp_path):
    f = write(tmp_path, GOOD)
    sc = load_scenario(f, ["p=0.8", "tau_cap=15", "process.2.weight=2", "server.edge.p_down=0.5"])
    assert sc.p == 0.8
    assert sc.tau_caps == (15, 15)
    assert sc.processes[1].weight == 2.0
    assert sc.servers[0].p_up == (0.8, 0.8)  # follows the channel
    assert sc.servers[1].p_up == (0.7, 0.7)  # own value kept
    assert sc.servers[1].p_down == (0.5, 0.5)
    # with_overrides on a loaded scenario, and processing time forms replace each other
    sc2 = sc.with_overrides({"server.remote.processing_time": [3, 3], "process.a.A": [[1.5]]})
    assert sc2.servers[0].processing_time == (3, 3)
    assert sc2.processes[0].dim == 1 and sc2.processes[0].R.shape == (1, 1)
    assert sc.fingerprint() != sc2.fingerprint()
    assert sc.fingerprint() == load_scenario(f, {"p": 0.8, "tau_cap": 15, "process.2.weight": 2.0,
                                                  "server.edge.p_down": 0.5}).fingerprint()


def test_override_values_parse_as_toml():
    assert parse_overrides(["p=0.8", "model.kind=preemption", "process.1.A=[[1.1]]", "model.allow_idle=true"]) == {
        "p": 0.8,
        "model.kind": "preemption",
        "process.1.A": [[1.1]],
        "model.allow_idle": True,
    }


# (mutation of GOOD, field named in the message, words expected in the message)
BAD_CASES = [
    ("malformed", lambda t: t.replace("[channel]", "[channel"), "<file>", "malformed TOML"),
    ("non-square A", lambda t: t.replace("[[1.1, 0], [0, 1]]", "[[1.1, 0], [0]]"), "process[1].A", "square"),
    ("R wrong shape", lambda t: t.replace("R = [[2.0]]", "R = [[2.0, 0], [0, 1]]"), "process[2].R", "1x1"),
    ("R not PSD", lambda t: t.replace("R = [[2.0]]", "R = [[-1.0]]"), "process[2].R", "positive semi-definite"),
    ("R not symmetric", lambda t: t.replace('name = "a"\nA = [[1.1, 0], [0, 1]]',
                                            'name = "a"\nA = [[1.1, 0], [0, 1]]\nR = [[1, 0.5], [0, 1]]'),
     "process[1].R", "symmetric"),
    ("p above 1", lambda t: t.replace("success_probability = 0.9", "success_probability = 1.5"),
     "channel.success_probability", "probability in [0, 1]"),
    ("p_up negative", lambda t: t.replace("p_up = 0.7", "p_up = -0.1"), "server[2].p_up", "probability in [0, 1]"),
    ("p nan", lambda t: t.replace("success_probability = 0.9", "success_probability = nan"),
     "channel.success_probability", "finite"),
    ("processing time < 1", lambda t: t.replace("processing_time = [4, 2]", "processing_time = [4, 0]"),
     "server[2].processing_time[2]", "integer >= 1"),
    ("processing time wrong length", lambda t: t.replace("processing_time = [4, 2]", "processing_time = [4]"),
     "server[2].processing_time", "list of 2 integers"),
    ("both T forms", lambda t: t.replace("processing_time = [4, 2]", "processing_time = [4, 2]\nslots_per_dimension = 2"),
     "server[2].processing_time", "exactly one of"),
    ("negative delay", lambda t: t.replace("uplink_delay = 0", "uplink_delay = -1"), "server[2].uplink_delay", ">= 0"),
    ("unknown field", lambda t: t.replace("weight = 3.0", "weight = 3.0\nwieght = 1"), "process[2].wieght",
     "unknown field"),
    ("unknown table", lambda t: t + "\n[extra]\nx = 1\n", "<top>.extra", "unknown field"),
    ("missing A", lambda t: t.replace('name = "a"\nA = [[1.1, 0], [0, 1]]', 'name = "a"'), "process[1].A", "missing"),
    ("missing kind", lambda t: t.replace('kind = "wncs"', ""), "model.kind", "missing"),
    ("bad kind", lambda t: t.replace('kind = "wncs"', 'kind = "cloud"'), "model.kind", "expected one of"),
    ("weight zero", lambda t: t.replace("weight = 3.0", "weight = 0"), "process[2].weight", "> 0"),
    ("cap zero", lambda t: t.replace("tau_cap = 5", "tau_cap = 0"), "process[2].tau_cap", "integer >= 1"),
    ("cap float", lambda t: t.replace("tau_cap = 5", "tau_cap = 5.5"), "process[2].tau_cap", "integer"),
    ("bool as int", lambda t: t.replace("tau_cap = 8", "tau_cap = true"), "model.tau_cap", "integer"),
    ("duplicate names", lambda t: t.replace('name = "b"', 'name = "a"'), "process[2].name", "unique"),
    ("no servers", lambda t: t.split("[[server]]")[0], "server", "at least one"),
    ("preemption with two servers", lambda t: t.replace('kind = "wncs"', 'kind = "preemption"'), "server",
     "exactly one server"),
    ("A with a string", lambda t: t.replace("[[1.02]]", '[["x"]]'), "process[2].A[1]", "number"),
]


@pytest.mark.parametrize("case", BAD_CASES, ids=[c[0] for c in BAD_CASES])
def test_bad_input_raises_one_clear_error(tmp_path, case):
    _, mutate, field, words = case
    text = mutate(GOOD)
    assert text != GOOD
    f = write(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(f)
    msg = str(info.value)
    assert str(f) in msg, msg
    assert f"'{field}'" in msg, msg
    assert words in msg, msg
    assert isinstance(info.value, ValueError) and isinstance(info.value, WncsError)


@pytest.mark.parametrize(
    "override, field, words",
    [
        ("proces.1.weight=2", "override 'proces.1.weight'", "unknown key"),
        ("process.1.wieght=2", "override 'process.1.wieght'", "unknown key"),
        ("process.7.weight=2", "override 'process.7.weight'", "out of range"),
        ("server.cloud.p_up=0.5", "override 'server.cloud.p_up'", "no server named 'cloud'"),
        ("p=1.2", "field 'channel.success_probability'", "probability in [0, 1]"),
        ("tau_cap=-3", "field 'model.tau_cap'", "integer >= 1"),
        ("model.distinct=maybe", "field 'model.distinct'", "true or false"),
        ("nonsense", "override 'nonsense'", "KEY=VALUE"),
    ],
)
def test_bad_overrides(tmp_path, override, field, words):
    f = write(tmp_path, GOOD)
    with pytest.raises(ScenarioError) as info:
        load_scenario(f, [override])
    msg = str(info.value)
    assert field in msg and words in msg, msg



def test_unreadable_and_binary_files(tmp_path):
    with pytest.raises(ScenarioError, match="cannot be read"):
        load_scenario(tmp_path / "missing.toml")
    f = tmp_path / "bin.toml"
    f.write_bytes(bytes(range(256)))
    with pytest.raises(ScenarioError, match="UTF-8|malformed"):
        load_scenario(f)


def test_missing_channel_ok_when_every_link_has_its_own_p():
    raw = {
        "model": {"kind": "wncs", "tau_cap": 3},
        "process": [{"A": [[1.1]]}],
        "server": [{"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1], "p_up": 0.5, "p_down": 1.0}],
    }
    sc = scenario_from_dict(raw)
    assert sc.servers[0].p_up == (0.5,) and math.isnan(sc.p)
    raw["server"][0].pop("p_down")
    with pytest.raises(ScenarioError, match="channel.success_probability"):
        scenario_from_dict(raw)


def test_override_with_control_characters_gives_one_line():
    """Regression (found by the fuzzer): a key with a newline made a two-line message."""
    with pytest.raises(ScenarioError) as info:
        parse_overrides(["=\n"])
    assert "\n" not in str(info.value) and "override" in str(info.value)
