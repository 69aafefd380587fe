"""docs/reproduction.md's table of verdicts cannot go stale: it is the table rendered from the recorded
summary of the default run's report (docs/reproduction-verdicts.json), and every recorded verdict is
what the rules of wncs_lp.verify.verdict give from the recorded instances and sub-claims."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from wncs_lp.reproduce import CLAIMS
from wncs_lp.reproduce.verdicts import BEGIN, END, redecided, table_in, update_docs, verdict_summary, verdict_table

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "reproduction.md"
SUMMARY = ROOT / "docs" / "reproduction-verdicts.json"


@pytest.fixture(scope="module")
def recorded():
    return json.loads(SUMMARY.read_text())


def test_the_docs_table_is_the_one_rendered_from_the_recorded_report(recorded):
    page = PAGE.read_text()
    assert page.count(BEGIN) == 1 and page.count(END) == 1
    assert table_in(page) == verdict_table(recorded).strip()
    assert recorded["run"]["profile"] == "default"
    assert [c["id"] for c in recorded["claims"]] == list(CLAIMS)


def test_the_recorded_verdicts_are_what_the_rules_give(recorded):
    assert redecided(recorded) == {}
    # and the check can fail: a verdict that the rules do not give is caught
    bad = json.loads(json.dumps(recorded))
    c = next(c for c in bad["claims"] if c["id"] == "C8")
    c["verdict"] = "HOLDS" if c["verdict"] != "HOLDS" else "FAILS"
    assert "C8" in redecided(bad)


def test_the_table_is_rewritten_from_a_report(quick_reproduction, tmp_path):
    run = quick_reproduction
    assert run.code == 0, run.stderr[-3000:]
    report = json.loads((run.out / "report.json").read_text())
    page = tmp_path / "reproduction.md"
    page.write_text(f"# title\n\ntext before\n\n{BEGIN}\nold table\n{END}\n\ntext after\n")
    written = update_docs(run.out / "report.json", page)
    text = page.read_text()
    assert text.startswith("# title\n\ntext before\n\n") and text.endswith("\n\ntext after\n")
    assert "old table" not in text and table_in(text) == verdict_table(verdict_summary(report)).strip()
    summary = json.loads(written.read_text())
    assert [c["verdict"] for c in summary["claims"]] == [c["verdict"] for c in report["claims"]]
    assert redecided(summary) == {}  # the quick run's verdicts follow the rules from its own instances
