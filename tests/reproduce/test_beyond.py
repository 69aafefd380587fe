"""The report's "beyond the paper" section B1 (trade-off of the MSE against the remote send rate).

Small caps through a custom profile; the findings are checked against hand-computed numbers on a
synthetic curve; the section must carry no verdict and a second run must come from the cache.
"""
from __future__ import annotations

import dataclasses
import json
import math

import pytest

from wncs_lp.studies.tradeoff import TradeoffPoint, TradeoffResult
from wncs_lp.reproduce import beyond
from wncs_lp.reproduce.context import PROFILES, Context
from wncs_lp.reproduce.report import write_report


def _curve(points, g0=100.0, r0=0.3) -> TradeoffResult:
    pts = tuple(TradeoffPoint(bound=b, gain=g, gain_lower=g, gain_upper=g, multiplier=lam,
                              randomized_states=1 if 0 < b < r0 else 0, status="optimal", method="lp")
                for b, g, lam in points)
    return TradeoffResult("send_rate[remote]", "send_rate", 0, "max", pts, g0, g0, g0, r0, 0.0)


def test_findings_on_a_hand_made_convex_curve():
    # g(b) = 100 + 400 (0.1 - b) for b <= 0.1, 100 + 0 ... slopes -400 then -100 then 0
    pts = [(0.0, 170.0, 400.0), (0.1, 130.0, 400.0), (0.15, 110.0, 400.0), (0.2, 105.0, 100.0),
           (0.25, 100.0, 100.0), (0.3, 100.0, 0.0)]
    f = beyond.tradeoff_findings(_curve(pts), half=0.15)
    assert f["nonincreasing"] and f["convex"]
    assert f["g_zero_over_g0"] == pytest.approx(1.7)
    assert f["half_increase_rel"] == pytest.approx(0.10)
    assert f["lambda_below_threshold"] == 100.0 and f["lambda_below_threshold_at"] == 0.25
    assert f["lambda_low"] == 400.0 and f["lambda_low_at"] == 0.1
    assert f["distinct_multipliers_inside"] == 2
    assert f["slope_between_multipliers_max_rel_violation"] == pytest.approx(0.0, abs=1e-12)
    bent = [(0.0, 170.0, 400.0), (0.1, 160.0, 400.0), (0.2, 100.0, 100.0), (0.3, 100.0, 0.0)]
    g = beyond.tradeoff_findings(_curve(bent))
    assert not g["convex"] and g["slope_between_multipliers_max_rel_violation"] > 0.1


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    prof = dataclasses.replace(PROFILES["quick"], name="tiny", caps_2p=(5, 6))
    out = tmp_path_factory.mktemp("beyond")
    ctx = Context(out, prof)
    extras = beyond.run_beyond(ctx, ["B1"])
    return out, prof, extras


def test_section_has_numbers_figure_table_and_no_verdict(tiny):
    out, _, (b1,) = tiny
    assert b1["id"] == "B1" and "verdict" not in b1
    assert "could not be computed" not in b1["summary"], b1["numbers"].get("error")
    assert "Halving that rate" in b1["summary"] and "cap 5" in b1["summary"] and "cap 6" in b1["summary"]
    for f in b1["figures"]:
        assert (out / f).stat().st_size > 1000
    (tab,) = b1["tables"]
    text = (out / tab).read_text()
    assert text.startswith("cap,bound,gain")
    found = b1["numbers"]["findings"]
    for cap in ("5", "6"):
        assert found[cap]["convex"] and found[cap]["nonincreasing"] and found[cap]["all_optimal"]
        curve = b1["numbers"]["curves"][cap]
        half = [p for p in curve["points"] if abs(p["bound"] - curve["threshold"] / 2) < 1e-9]
        assert len(half) == 1  # the halving point was solved exactly
    assert "| cap | bound b |" in b1["details"]


def test_second_run_comes_from_the_cache(tiny, monkeypatch):
    out, prof, (b1,) = tiny
    calls = []
    monkeypatch.setattr(beyond, "tradeoff", lambda *a, **k: calls.append(1))
    ctx = Context(out, prof)
    (again,) = beyond.run_beyond(ctx, ["B1"])
    assert calls == [] and ctx.cache.hits == 2 and ctx.cache.misses == 0
    assert again["summary"] == b1["summary"]


def test_report_renders_the_section_after_the_claims_without_a_verdict(tiny):
    out, _, extras = tiny
    files = write_report(out, [], {"profile": "tiny", "caps": {}}, extras)
    md = (out / "report.md").read_text()
    assert "## Beyond the paper" in md and "### B1:" in md
    assert md.index("## Beyond the paper") < md.index("## Where the exact model departs")
    doc = json.loads((out / "report.json").read_text())
    assert doc["claims"] == [] and doc["beyond"][0]["id"] == "B1"
    assert "<h3>B1:" in (out / "report.html").read_text()
    assert math.isfinite(doc["beyond"][0]["numbers"]["findings"]["5"]["g0"])
    assert set(files) == {"md", "html", "json"}
