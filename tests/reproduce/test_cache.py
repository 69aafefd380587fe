"""The reproduction's step cache (issue 27 §8, §14): an entry is reused only when it reads back whole
and its checksum holds; damaged, hand-edited or foreign entries are recomputed, never trusted."""
from __future__ import annotations

import json

import numpy as np
import pytest

from wncs_lp.reproduce.cache import StepCache


class Counter:
    """A step that counts its computations and returns a known result."""

    def __init__(self, gain: float = 1078.548921698):
        self.calls = 0
        self.gain = gain

    def __call__(self):
        self.calls += 1
        return {"gain": self.gain, "name": "static"}, {"policy": np.arange(6, dtype=np.int64), "bias": np.linspace(0, 1, 6)}


PARAMS = {"fingerprint": "abc123", "policy": "static"}


def _prime(tmp_path):
    cache, step = StepCache(tmp_path), Counter()
    cache.get_or_compute("evaluate", PARAMS, step)
    jpath, npath = cache._paths(cache.key("evaluate", PARAMS))
    assert jpath.exists() and npath.exists() and step.calls == 1
    return cache, step, jpath, npath


def test_an_intact_entry_is_reused_with_its_arrays(tmp_path):
    cache, step, _, _ = _prime(tmp_path)
    res, arr = StepCache(tmp_path).get_or_compute("evaluate", PARAMS, step)
    assert step.calls == 1 and res["gain"] == step.gain
    np.testing.assert_array_equal(arr["policy"], np.arange(6))


def _edit_gain(jpath, npath):
    doc = json.loads(jpath.read_text())
    doc["result"]["gain"] = 1.0  # the C12 "static -99.775%"
    jpath.write_text(json.dumps(doc))


def _foreign(jpath, npath):
    # another step's entry copied under this name (a hand-merged cache folder)
    other = StepCache(jpath.parent / "other")
    other.store("evaluate", {"fingerprint": "zzz", "policy": "static"}, {"gain": 5.0, "name": "static"},
                {"policy": np.arange(6, dtype=np.int64), "bias": np.linspace(0, 1, 6)})
    src = other._paths(other.key("evaluate", {"fingerprint": "zzz", "policy": "static"}))
    jpath.write_bytes(src[0].read_bytes())
    npath.write_bytes(src[1].read_bytes())


DAMAGE = {
    "edited gain": _edit_gain,
    "edited array": lambda j, n: np.savez_compressed(n, policy=np.zeros(6, np.int64), bias=np.linspace(0, 1, 6)),
    "truncated npz": lambda j, n: n.write_bytes(n.read_bytes()[: n.stat().st_size // 2]),
    "missing npz": lambda j, n: n.unlink(),
    "npz without an array": lambda j, n: np.savez_compressed(n, policy=np.arange(6, dtype=np.int64)),
    "no result": lambda j, n: j.write_text(json.dumps({k: v for k, v in json.loads(j.read_text()).items()
                                                       if k != "result"})),
    "null result": lambda j, n: j.write_text(json.dumps({**json.loads(j.read_text()), "result": None})),
    "not json": lambda j, n: j.write_text("{oops"),
    "a list": lambda j, n: j.write_text("[1, 2]"),
    "empty": lambda j, n: j.write_text(""),
    "foreign entry": _foreign,
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_or_edited_entry_is_recomputed(tmp_path, damage):
    _, step, jpath, npath = _prime(tmp_path)
    DAMAGE[damage](jpath, npath)
    cache = StepCache(tmp_path)
    res, arr = cache.get_or_compute("evaluate", PARAMS, step)
    assert step.calls == 2, "the damaged entry was trusted"
    assert res["gain"] == step.gain and cache.rejected == [jpath.name]
    np.testing.assert_array_equal(arr["policy"], np.arange(6))
    # and the recomputed entry is whole again
    again = StepCache(tmp_path)
    assert again.get_or_compute("evaluate", PARAMS, step)[0]["gain"] == step.gain and step.calls == 2


def test_the_reproduction_recomputes_a_hand_edited_evaluation(tmp_path, monkeypatch):
    """End to end through the context: the exact gain of a static policy cached by ``evaluate``,
    edited by hand, comes back as the value a fresh evaluation computes."""
    from wncs_lp import load_scenario, scenario_path
    from wncs_lp.reproduce.context import PROFILES, Context

    ctx = Context(tmp_path, PROFILES["quick"])
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=7"])
    truth = ctx.evaluate(sc, "static")["gain"]
    (entry,) = [f for f in (tmp_path / "cache").glob("evaluate-*.json")]
    doc = json.loads(entry.read_text())
    doc["result"]["gain"] = 1.0
    entry.write_text(json.dumps(doc))
    fresh = Context(tmp_path, PROFILES["quick"])
    assert fresh.evaluate(sc, "static")["gain"] == pytest.approx(truth, rel=1e-12) and truth > 1.0
    assert fresh.cache.rejected == [entry.name]
