"""The estimate printed before a reproduction and the line printed after each section."""
from __future__ import annotations

import pytest

from wncs_lp.reproduce import CLAIMS
from wncs_lp.reproduce.beyond import BEYOND
from wncs_lp.reproduce.plan import ESTIMATE_SECONDS, Plan, duration


@pytest.mark.parametrize("seconds,text", [(0.2, "0 s"), (41.4, "41 s"), (125, "2 min 05 s"), (3720, "1 h 02 min")])
def test_duration(seconds, text):
    assert duration(seconds) == text


def test_every_profile_estimates_every_section():
    for profile, table in ESTIMATE_SECONDS.items():
        assert set(CLAIMS) | set(BEYOND) <= set(table), profile
        assert all(v > 0 for v in table.values()), profile


def test_the_time_left_rescales_the_estimates_by_the_finished_sections(monkeypatch):
    monkeypatch.setitem(ESTIMATE_SECONDS, "test", {"A": 10.0, "B": 20.0, "C": 30.0})
    plan = Plan("test", ["A", "B", "C"])
    assert plan.total() == 60.0
    assert "estimate about 1 min 00 s" in plan.opening(2, 2, 0)
    assert "3 step(s) already in the cache" in plan.opening(2, 2, 3)
    line = plan.finished("A", "HOLDS", 20.0, 20.0)  # twice its estimate: the rest is doubled, 2 x 50 s
    assert line == "[1/3] A HOLDS in 20 s; elapsed 20 s, about 1 min 40 s left"
    plan.finished("B", "FAILS", 10.0, 30.0)  # 30 s for 30 s estimated: the last section as estimated
    assert plan.left() == pytest.approx(30.0)
    assert plan.finished("C", "ERROR", 1.0, 31.0) == "[3/3] C ERROR in 1 s; elapsed 31 s"
