"""The table of verdicts of ``docs/reproduction.md``, generated from a report so it cannot go stale.

``python -m wncs_lp.reproduce.verdicts results/report.json docs/reproduction.md`` reads a report
(the default profile's, normally), keeps what the table needs -- each claim's verdict, the
instances it rests on with their own verdicts and masses at the cap, its sub-claims, its conclusion
sentence -- in ``docs/reproduction-verdicts.json`` beside the page, and rewrites the table between
:data:`BEGIN` and :data:`END` in the page from it. The tests check that the page's table is the
one this module renders from that file, and that every recorded verdict is what the rules of
:mod:`wncs_lp.verify.verdict` give from the recorded instances and sub-claims
(:func:`redecided`): a change of the rules without a new run shows as a failing test.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any, Sequence

from ..files import atomic_write_text
from ..verify.verdict import decide, subclaims_verdict
from .report import basis_words, md_table

__all__ = ["BEGIN", "END", "verdict_summary", "verdict_table", "redecided", "update_docs", "main"]

BEGIN = ("<!-- the verdict table: generated from the default run's report by `python -m wncs_lp.reproduce.verdicts "
         "results/report.json docs/reproduction.md` (it keeps docs/reproduction-verdicts.json); do not edit by hand -->")
END = "<!-- end of the generated verdict table -->"

#: How each claim's verdict is reached from its instances (the rest: from its sub-claims, or given).
HOW = {"C1": "structural", "C2": "descriptive", "C4": "descriptive", "C5": "structural", "C7": "structural",
       "C8": "structural", "C9": "structural", "C10": "structural", "C15": "structural"}


def verdict_summary(report: dict[str, Any]) -> dict[str, Any]:
    """What the table needs from a report (``report.json`` read): per claim its verdict, conclusion,
    the instances it rests on (label, group, cap, mass at the cap, own verdict), the deciding ones,
    the caveats, the flag and the sub-claims; and the run's date, commit and profile."""
    prov = report.get("provenance", {})
    claims = []
    for c in report["claims"]:
        b = c.get("basis") or {}
        claims.append({
            "id": c["id"], "paper": c.get("paper", ""), "verdict": c["verdict"], "summary": c["summary"],
            "basis": {"caps": b.get("caps", []), "deciding": b.get("deciding", []),
                      "deciding_caps": b.get("deciding_caps", []), "deciding_mass": b.get("deciding_mass"),
                      "flag": bool(b.get("flag")), "note": b.get("note", ""),
                      "caveats": [{k: cv.get(k) for k in ("label", "verdict", "cap", "mass")} for cv in b.get("caveats", [])],
                      "instances": [{k: e.get(k) for k in ("label", "group", "cap", "mass", "verdict")}
                                    for e in b.get("instances", [])]},
            "subclaims": (c.get("numbers") or {}).get("subclaims"),
            "solver_notes": len(c.get("solver_notes") or []),
        })
    return {"run": {k: prov.get(k) for k in ("date", "commit", "profile", "total_seconds")}, "claims": claims}


def verdict_table(summary: dict[str, Any]) -> str:
    """The Markdown block of the page: the run it comes from, then one row per claim (verdict and ⚠
    when its deciding instance leans on the truncation, where it is decided, the conclusion)."""
    run = summary["run"]
    rows = [[f"{c['id']} {c['paper']}", c["verdict"] + (" ⚠" if c["basis"]["flag"] else ""),
             basis_words({**c["basis"], "flag": False}) if c["basis"]["caps"] else "—", c["summary"]]
            for c in summary["claims"]]
    return (f"From the `{run.get('profile')}` run of {run.get('date')} at commit {run.get('commit')} (the report "
            "itself is the authority, with every number; ⚠: the deciding instance spends more than 1% of its time "
            "with some AoI at the cap).\n\n" + md_table(["claim", "verdict", "decided at", "what decides it"], rows))


def redecided(summary: dict[str, Any]) -> dict[str, tuple[str, str]]:
    """The claims whose recorded verdict differs from the rules applied to their recorded
    instances or sub-claims: ``{id: (recorded, by the rules)}`` (empty when all agree)."""
    out = {}
    for c in summary["claims"]:
        if c["verdict"] == "ERROR":
            continue
        if c.get("subclaims"):
            subs = {k: {int(cap): v for cap, v in per.items()} for k, per in c["subclaims"].items()}
            again = subclaims_verdict(subs)
        elif c["id"] in HOW and c["basis"]["instances"]:
            inst = c["basis"]["instances"]
            again = decide([(e.get("group") or e["label"], e["cap"], e["verdict"]) for e in inst], HOW[c["id"]]).verdict
        else:
            continue
        if again != c["verdict"]:
            out[c["id"]] = (c["verdict"], again)
    return out


def update_docs(report_json: str | Path, docs_md: str | Path, summary_json: str | Path | None = None) -> Path:
    """Write the summary of ``report_json`` beside ``docs_md`` (default
    ``reproduction-verdicts.json``) and the table rendered from it between :data:`BEGIN` and
    :data:`END` in ``docs_md`` (which must hold both markers). Returns the summary's path."""
    docs_md = Path(docs_md)
    summary_json = Path(summary_json) if summary_json else docs_md.with_name("reproduction-verdicts.json")
    summary = verdict_summary(json.loads(Path(report_json).read_text()))
    page = docs_md.read_text()
    if BEGIN not in page or END not in page:
        raise ValueError(f"{docs_md}: no generated verdict table (the markers {BEGIN!r} and {END!r})")
    head, rest = page.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    atomic_write_text(summary_json, json.dumps(summary, indent=1, ensure_ascii=False) + "\n")
    atomic_write_text(docs_md, head + BEGIN + "\n\n" + verdict_table(summary) + "\n\n" + END + tail)
    return summary_json


def table_in(page: str) -> str:
    """The generated block of a page (between the markers, stripped)."""
    return page.split(BEGIN, 1)[1].split(END, 1)[0].strip()


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) != 2:
        print("usage: python -m wncs_lp.reproduce.verdicts REPORT.json DOCS.md", file=sys.stderr)
        return 2
    path = update_docs(args[0], args[1])
    print(f"wrote the verdict table of {args[1]} and {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
