"""How the reproduction judges a claim and writes it down, without computing a model.

The verdict helpers (sub-claims over caps, the caps a verdict rests on and its truncation flag, the
Monte Carlo agreement rule) are checked on hand-made numbers whose answers are worked out here;
the report writer on made-up claims whose numbers hold None, NaN, dicts and negative zeros, parsed
back as HTML: every table-of-contents link lands on a section, verdicts are coloured, figures are
captioned, and no Python repr reaches the page.
"""
from __future__ import annotations

import re

import pytest

from wncs_lp.reproduce.context import ClaimResult, Table, cap_basis, evidence, subclaims_verdict
from wncs_lp.reproduce.performance import MC_FLOOR, mc_agrees
from wncs_lp.reproduce.report import COLOURS, fmt, write_report
from wncs_lp.reproduce.structural import across, pct
from wncs_lp.truncation import CAP_MASS_WARN


# ============================================================================ verdicts over caps
def test_subclaims_verdict():
    assert subclaims_verdict({"a": {12: True, 20: True}, "b": {12: True, 20: None}}) == "HOLDS"
    # the least truncated cap decides: false at cap 12 only is a caveat, false at cap 20 a failure
    assert subclaims_verdict({"a": {12: False, 20: True}, "b": {12: True, 20: True}}) == "HOLDS"
    assert subclaims_verdict({"a": {12: True, 20: False}, "b": {12: True, 20: True}}) == "FAILS"
    assert subclaims_verdict({"a": {12: False, 20: False}, "b": {12: True, 20: True}}) == "FAILS"
    assert subclaims_verdict({"a": {12: False, 20: None}}) == "FAILS"  # checked at cap 12 only: cap 12 decides
    assert across(["HOLDS", "HOLDS"]) == "HOLDS" and across(["FAILS", "HOLDS"]) == "DEPENDS"


def _ev(sc, cap, mass, v):
    return evidence(f"{sc} at cap {cap}", cap, mass, v, sc)


def test_cap_basis_decides_at_the_least_truncated_instance_and_keeps_the_others_as_caveats():
    ev = [_ev("p12", 12, 0.168, "FAILS"), _ev("p12", 20, 0.0076, "HOLDS"), _ev("p12", 30, 0.00003, "HOLDS")]
    b = cap_basis(ev)  # cap 30 decides: HOLDS; the failing cap 12 is a caveat, never the verdict
    assert b["verdict"] == "HOLDS" and b["deciding"] == ["p12 at cap 30"] and not b["flag"]
    assert [c["label"] for c in b["caveats"]] == ["p12 at cap 12"] and b["caveats"][0]["verdict"] == "FAILS"
    assert b["caps"] == [12, 20, 30] and b["threshold"] == CAP_MASS_WARN
    assert cap_basis(ev, "FAILS")["verdict"] == "FAILS"  # a verdict the claim decided itself is kept
    # the largest cap of each scenario decides, whatever the masses; the worst of them flags
    ev2 = [_ev("p12", 30, 0.0001, "HOLDS"), _ev("p123", 12, 0.39, "HOLDS"), _ev("p123", 20, 0.019, "HOLDS")]
    b = cap_basis(ev2)
    assert sorted(b["deciding"]) == ["p12 at cap 30", "p123 at cap 20"] and b["verdict"] == "HOLDS"
    assert b["deciding_mass"] == 0.019 and b["flag"] and b["caveats"] == []
    assert not cap_basis([_ev("p12", 30, CAP_MASS_WARN, "HOLDS")])["flag"]  # at the threshold: no flag
    # a scenario's deciding instance that fails decides the claim (any FAILS), the other scenario holding
    b = cap_basis([_ev("p12", 30, 0.0, "FAILS"), _ev("p14", 30, 0.0, "HOLDS"), _ev("p14", 12, 0.7, "DEPENDS")])
    assert b["verdict"] == "FAILS" and [c["label"] for c in b["caveats"]] == ["p14 at cap 12"]
    # a FAILS leans on the truncation only when every failing deciding instance does
    b = cap_basis([_ev("p12", 30, 0.00003, "FAILS"), _ev("p123", 20, 0.019, "FAILS")])
    assert b["verdict"] == "FAILS" and b["deciding_mass"] == 0.00003 and not b["flag"]
    b = cap_basis([_ev("p12", 30, 0.00003, "HOLDS"), _ev("p123", 20, 0.019, "FAILS")])
    assert b["verdict"] == "FAILS" and b["deciding_mass"] == 0.019 and b["flag"]
    # a verdict the claim gives (from sub-claims reading both instances together): the largest mass
    b = cap_basis([_ev("pre", 25, 0.02, "FAILS"), _ev("non", 25, 0.036, "FAILS")], "FAILS")
    assert b["deciding_mass"] == 0.036 and b["flag"]
    nod = cap_basis(ev, "HOLDS", note="cap-free", decides=False)
    assert nod["deciding"] == [] and not nod["flag"] and nod["note"] == "cap-free" and nod["verdict"] == "HOLDS"


def test_monte_carlo_agreement():
    assert mc_agrees(100.0, 103.9, 1.0) and not mc_agrees(100.0, 104.1, 1.0)
    # p = 1: identical replications, a standard error of round-off; the finite-horizon mean differs
    # from the long-run average by the unfinished cycle
    assert mc_agrees(586.7527, 586.7541, 2.6e-14)
    assert not mc_agrees(586.7527, 586.7527 * (1 + 2 * MC_FLOOR), 0.0)
    assert mc_agrees(float("nan"), 1.0, 0.1) is None


def test_formatting():
    assert pct(-1e-12, 3) == "0.000%" and pct(0.01234) == "1.23%" and pct(None) == "n/a"
    assert fmt(None) == "—" and fmt(float("nan")) == "—" and fmt(True) == "yes"
    assert fmt(749.834326444) == "749.8343264" and fmt(12345) == "12,345" and fmt(3.0) == "3"
    assert fmt([1, 2]) == "1, 2" and fmt({"a": None}) == "a: —" and fmt(2.5e-5) == "2.500e-05"


# ============================================================================ the report
@pytest.fixture()
def made_up(tmp_path):
    from wncs_lp.viz import subplots

    (tmp_path / "figures").mkdir()
    fig, ax = subplots()
    ax.plot([0, 1], [1, 0])
    fig.savefig(tmp_path / "figures" / "x.png")
    basis = cap_basis([_ev("p12", 12, 0.2, "HOLDS"), _ev("p12", 30, 0.05, "FAILS")], "FAILS")
    claims = [
        ClaimResult("C1", "Fig. 3", "", "HOLDS", "all good", {"a": None, "b": {"c": float("nan"), "d": [1, None]}},
                    ["figures/x.png"], [], basis=cap_basis([_ev("p14", 30, 0.0005, "HOLDS")], "HOLDS"),
                    shown=[Table("numbers", ["x", "y"], [[None, -0.0], [{"k": 1}, float("nan")]])],
                    captions={"figures/x.png": "a line"}),
        ClaimResult("C2", "Fig. 4", "", "FAILS", "bad", {"rows": [{"p": 0.8, "g": None}] * 20}, basis=basis),
        ClaimResult("C3", "Fig. 5", "", "DEPENDS", "it depends", {}),
        ClaimResult("C4", "Figs. 6-7", "", "ERROR", "could not be computed: ValueError: x", {"error": "trace"}),
    ]
    prov = {"date": "2026-01-01 00:00 UTC", "commit": "abc123", "profile": "test", "caps": {"two": [12, 30]},
            "timings_seconds": {"C1": 1.234}, "versions": {"numpy": "2"}}
    write_report(tmp_path, claims, prov, [{"id": "B1", "title": "extra", "summary": "s", "details": "| a | b |\n|---|---|\n| 1 | 2 |",
                                           "figures": [], "tables": [], "numbers": {"x": None}}])
    return tmp_path


def test_html_contents_links_colours_captions(made_up, html_check):
    parse, assert_readable = html_check
    html = (made_up / "report.html").read_text()
    page = parse(html)
    for cid in ("c1", "c2", "c3", "c4", "b1", "provenance", "contents", "departures"):
        assert cid in page.ids
    assert {"c1", "c2", "c3", "c4", "b1", "provenance"} <= set(page.links)
    assert_readable(page)
    # each verdict in its own colour, in the contents and in the section heading
    for v in ("HOLDS", "FAILS", "DEPENDS", "ERROR"):
        assert sum(COLOURS[v][0] in s for s in page.badges) >= 2
    assert page.figcaptions == 1 and "Figure C1.1." in html and "a line" in html
    assert "⚠" in html and "Leans on the truncation" in html  # C2 rests on a cap with 5% at the cap
    assert "Caveat, a more truncated instance that disagrees" in html and "p12 at cap 12 says HOLDS" in html
    text = " ".join(page.text)
    assert "2026-01-01 00:00 UTC" in text and "abc123" in text
    assert html.index('id="contents"') < html.index('id="c1"')  # the contents come first


def test_markdown_anchors_and_tables(made_up):
    md = (made_up / "report.md").read_text()
    for cid in ("c1", "c2", "c3", "c4"):
        assert f"[{cid.upper()}](#{cid})" in md and f'<a id="{cid}"></a>' in md
    assert not re.search(r"\bNone\b", md) and "{'" not in md
    assert "Rests on** caps 12, 30; deciding cap 30 (5.00% at the cap)" in md
    assert "*Figure C1.1. a line*" in md
    # each section: the paper's own sentence, then the conclusion, then what was checked
    c3 = md[md.index('<a id="c3"></a>'):md.index('<a id="c4"></a>')]
    assert c3.index("> \"Compared with the greedy baseline policy") < c3.index("**it depends**") < c3.index(
        "*Checked as:*")
    assert "it is vastly improved only when the transmission success probability is low" in c3
