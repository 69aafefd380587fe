"""End to end: `wncs-lp reproduce --profile quick` writes a verdict for every claim and every figure."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

CLAIMS = [f"C{i}" for i in range(1, 14)]
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("repro")
    proc = subprocess.run([sys.executable, "-m", "wncs_lp", "reproduce", "--out", str(out), "--profile", "quick",
                           "--json"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads(proc.stdout)


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
