"""End to end: `wncs-lp reproduce --profile quick` writes a verdict for every claim and every figure."""
from __future__ import annotations

import base64
import io
import json
import struct
import subprocess
import sys
from html.parser import HTMLParser

import pytest

CLAIMS = [f"C{i}" for i in range(1, 17)]
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def quick(quick_reproduction):
    # the session's quick reproduction (tests/conftest.py): interrupted once, then resumed, so
    # every test here also checks that a resumed run writes the whole report
    run = quick_reproduction
    assert run.code == 0, run.stderr[-3000:]
    return run.out, run.printed


def test_every_claim_has_a_verdict(quick):
    out, printed = quick
    report = json.loads((out / "report.json").read_text())
    ids = [c["id"] for c in report["claims"]]
    assert ids == CLAIMS
    for c in report["claims"]:
        assert c["verdict"] in ("HOLDS", "FAILS", "DEPENDS"), c
        assert c["summary"] and "could not be computed" not in c["summary"], c
        assert c["numbers"], c["id"]
    assert [c["id"] for c in printed["claims"]] == CLAIMS
    prov = report["provenance"]
    assert prov["profile"] == "quick" and prov["versions"]["numpy"] and prov["scenario_files"]


def test_every_figure_exists_and_is_an_image(quick):
    out, _ = quick
    report = json.loads((out / "report.json").read_text())
    figures = [f for c in report["claims"] for f in c["figures"]]
    assert len(figures) >= 16  # PNG + SVG of at least 8 figures
    for f in figures:
        data = (out / f).read_bytes()
        assert len(data) > 1000, f
        if f.endswith(".png"):
            assert data.startswith(PNG), f
        else:
            assert f.endswith(".svg") and b"<svg" in data[:2000], f
    for c in report["claims"]:
        for t in c["tables"]:
            assert (out / t).stat().st_size > 0


def test_report_md_and_html(quick):
    out, _ = quick
    md = (out / "report.md").read_text()
    html = (out / "report.html").read_text()
    for cid in CLAIMS:
        assert f"## {cid} " in md
    assert "departs from the paper" in md and "Provenance" in md
    assert html.startswith("<!DOCTYPE html>") and "data:image/png;base64," in html


def test_second_run_uses_the_cache(quick):
    out, _ = quick
    proc = subprocess.run([sys.executable, "-m", "wncs_lp", "reproduce", "--out", str(out), "--profile", "quick",
                           "--json", "--claims", "C7,C10"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    prov = json.loads((out / "report.json").read_text())["provenance"]
    assert prov["cache"]["misses"] == 0 and prov["cache"]["hits"] > 0


# ============================================================================ issue 15: where and against what
def test_every_verdict_says_which_caps_it_rests_on(quick):
    from wncs_lp.truncation import CAP_MASS_WARN

    out, printed = quick
    report = json.loads((out / "report.json").read_text())
    for c in report["claims"]:
        b = c["basis"]
        assert b["caps"] and b["instances"], c["id"]
        for e in b["instances"]:
            assert 0.0 <= e["mass"] <= 1.0 and e["cap"] in b["caps"]
        if b["deciding"]:
            masses = [e["mass"] for e in b["instances"] if e["label"] in b["deciding"]]
            if c["verdict"] == "FAILS":  # a structural counterexample decides: its own mass; sub-claims: the largest
                assert b["deciding_mass"] in masses
            else:
                assert b["deciding_mass"] == max(masses)
            assert b["flag"] == (b["deciding_mass"] > CAP_MASS_WARN)
            # the least truncated instance of each group decides
            for e in b["instances"]:
                group = [x["cap"] for x in b["instances"] if x.get("group") == e.get("group")]
                assert (e["label"] in b["deciding"]) == (e["cap"] == max(group)), (c["id"], e["label"])
    md = (out / "report.md").read_text()
    assert md.count("**Rests on** caps") == len(CLAIMS)
    flagged = [c for c in report["claims"] if c["basis"]["flag"]]
    assert flagged and md.count("Leans on the truncation") == len(flagged)  # quick caps are small
    assert {c["id"]: c["leans_on_truncation"] for c in printed["claims"]} == {
        c["id"]: c["basis"]["flag"] for c in report["claims"]}


def test_the_mass_at_the_cap_agrees_with_an_independent_computation(quick):
    from wncs_lp import scenario_path
    from wncs_lp.models import build
    from wncs_lp.scenario import load_scenario
    from wncs_lp import solve
    from wncs_lp.truncation import policy_cap_mass

    out, _ = quick
    c2 = next(c for c in json.loads((out / "report.json").read_text())["claims"] if c["id"] == "C2")
    inst = next(e for e in c2["basis"]["instances"] if e["cap"] == 8)
    mdp = build(load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=8"]))
    m = policy_cap_mass(mdp, solve(mdp, "rvi").policy)  # another solver, the chain's own stationary law
    assert inst["mass"] == pytest.approx(m.total, abs=1e-9)
    assert inst["per_process"] == pytest.approx(list(m.per_process), abs=1e-9)


def test_static_policies_are_named_and_best_static_shown(quick):
    out, _ = quick
    claims = {c["id"]: c for c in json.loads((out / "report.json").read_text())["claims"]}
    for cid in ("C3", "C6", "C12"):
        tables = claims[cid]["shown"]
        head = next(t for t in tables if "best static" in t["header"])
        rows = head["rows"]
        i = head["header"].index("assignment")
        assert all("\u2192" in r[i] for r in rows), cid  # e.g. 1→remote, 2→edge
    # the spec's default assignment for processes 1, 2, 3: (remote, edge, edge)
    assert claims["C6"]["numbers"]["exact_by_cap"][0]["static_assignment"] == "1\u2192remote, 2\u2192edge, 3\u2192edge"


def test_c10_is_judged_on_preempting_starts_and_split_by_start_type(quick):
    out, _ = quick
    c10 = next(c for c in json.loads((out / "report.json").read_text())["claims"] if c["id"] == "C10")
    split = c10["numbers"]["by_start_type"]
    assert {r["start"] for r in split} == {"preempting", "idle_server", "restarting_own"}
    for inst in c10["numbers"]["instances"]:
        own = next(r for r in split if r["cap"] == inst["cap"] and r["start"] == "preempting")
        assert (inst["checked"], inst["violations"]) == (own["checked"], own["violations"])
    md = (out / "report.md").read_text()
    assert "by preempting another process's job" in md and "on an idle server" in md


def test_verify_and_the_report_give_the_same_verdict_for_the_same_numbers(quick, capsys):
    from wncs_lp import scenario_path
    from wncs_lp.cli import main
    from wncs_lp.verify.verdict import verdict_of

    out, _ = quick
    claims = {c["id"]: c for c in json.loads((out / "report.json").read_text())["claims"]}
    for cap in (8, 10):
        rc = main(["verify", str(scenario_path("paper_preemption_p12.toml")), "--set", f"tau_cap={cap}", "--method", "pi",
                   "--json"])  # the solver of the reproduction at this size
        checks = {c["name"]: c for c in json.loads(capsys.readouterr().out)["checks"]}
        for cid, name in (("C7", "monotonicity"), ("C9", "threshold"), ("C10", "consistency")):
            inst = next(r for r in claims[cid]["numbers"]["instances"]
                        if r["scenario"] == "paper_preemption_p12" and r["cap"] == cap)
            c = checks[name]
            assert (c["checked"], c["violations"]) == (inst["checked"], inst["violations"]), (cid, cap)
            assert c["verdict"] == inst["verdict"] == verdict_of(c), (cid, cap)
        assert rc == (1 if "FAILS" in [c["verdict"] for c in checks.values()] else 0)


def test_html_report_is_readable_and_linked(quick, html_check):
    parse, assert_readable = html_check
    out, _ = quick
    html = (out / "report.html").read_text()
    page = parse(html)
    assert_readable(page)
    for cid in CLAIMS:
        assert cid.lower() in page.ids and cid.lower() in page.links
    assert page.figcaptions >= 8
    prov = json.loads((out / "report.json").read_text())["provenance"]
    assert prov["date"] in html and prov["commit"].split()[0] in html
    assert html.index('id="contents"') < html.index('id="c1"')


class _Structure(HTMLParser):
    """Every element of the page: tags balanced, the images and the links to files."""

    VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}

    def __init__(self):
        super().__init__()
        self.open, self.unbalanced, self.tags, self.images, self.files = [], [], [], [], []
        self.headings, self._heading, self.sections = {}, None, []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.images.append(a)
        if tag == "section":
            self.sections.append(a.get("id"))
        if tag == "a" and a.get("href") and not a["href"].startswith("#") and "://" not in a["href"]:
            self.files.append(a["href"])
        if tag in ("h1", "h2") and "id" in a:
            self._heading, self.headings[a["id"]] = a["id"], ""
        if tag not in self.VOID:
            self.open.append(tag)

    def handle_endtag(self, tag):
        if tag in ("h1", "h2"):
            self._heading = None
        if self.open and self.open[-1] == tag:
            self.open.pop()
        else:
            self.unbalanced.append((tag, self.getpos()))

    def handle_data(self, data):
        if self._heading:
            self.headings[self._heading] += data


def test_html_report_is_well_formed_and_its_images_and_files_load(quick):
    """What a browser needs to show the report: a well-formed document (every element closed in
    order), the contents heading and every claim's section, every figure an inline PNG that
    decodes to a non-blank image, every link to a file pointing at a file of the report."""
    from matplotlib.image import imread

    out, _ = quick
    html = (out / "report.html").read_text()
    page = _Structure()
    page.feed(html)
    page.close()
    assert not page.unbalanced and not page.open, (page.unbalanced[:5], page.open[-5:])
    assert page.tags[:3] == ["html", "head", "meta"] and {"title", "style", "body"} <= set(page.tags)
    assert page.headings["contents"] == "Contents and verdicts"
    assert [c.lower() for c in CLAIMS] == [i for i in page.sections if i and i.startswith("c")]
    assert len(page.images) >= 8 and len(page.images) == html.count("<figcaption>")
    for img in page.images:
        head, _, data = img["src"].partition(",")
        assert head == "data:image/png;base64" and img.get("alt"), head[:60]
        raw = base64.b64decode(data, validate=True)
        assert raw.startswith(PNG) and raw[12:16] == b"IHDR"
        width, height = struct.unpack(">II", raw[16:24])
        pixels = imread(io.BytesIO(raw), format="png")
        assert pixels.shape[:2] == (height, width) and width > 100 and height > 100
        assert pixels.std() > 0.01, img["alt"]  # a drawn figure, not a blank canvas
    assert page.files and all((out / f).is_file() for f in page.files), [f for f in page.files if not (out / f).is_file()]
