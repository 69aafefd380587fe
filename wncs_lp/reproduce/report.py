"""Write the reproduction report: report.md, a self-contained report.html, report.json."""
from __future__ import annotations

import base64
import html
import json
import re
from pathlib import Path
from typing import Any

from ..files import atomic_write_text, json_ready
from .context import ClaimResult

#: The paper's statement of each claim (the specification's claims C1-C13), shown beside the verdict.
STATEMENTS = {
    "C1": "Processes 1 and 4: the optimal action in idle-server states is always (1 to remote, 4 to edge).",
    "C2": "Processes 1 and 2: mostly (1, 2), with (2, 1) in the upper-left corner (small tau_1, large tau_2).",
    "C3": "Processes 1 and 2, p in [0.8, 1]: optimal better than static and much better than greedy; the gap to "
          "static larger at low p; optimal equal to static at p = 1.",
    "C4": "Processes 1, 2, 3: on the plane tau_1 + tau_2 + tau_3 = const, the optimal policy has four regions, "
          "each simply connected (threshold type).",
    "C5": "Processes 1, 2, 3: optimal policy of one server while the other is busy (edge busy with process 3 / "
          "remote busy with process 1); the free server serves the other processes.",
    "C6": "Processes 1, 2, 3, p in [0.8, 1]: optimal <= suboptimal <= static <= greedy in average MSE, suboptimal "
          "close to optimal, all but greedy equal at p = 1.",
    "C7": "Theorem 1: the value function is nondecreasing in each tau_k with the server states fixed.",
    "C8": "Theorem 2: in idle-server states, if pi*(s) = (k1, k2) then the same action at s + z(e_k1 + e_k2) "
          "for every z >= 1.",
    "C9": "Preemption: the optimal preemption policy while the server processes process 2's (Fig. 11) or "
          "process 1's (Fig. 12) job is of threshold type.",
    "C10": "Theorem 3: once the optimal policy starts a job by preempting, it is not preempted again before it "
           "completes.",
    "C11": "Preemption never hurts, and helps less as p grows; overall not significant.",
    "C12": "With a perfect channel (p = 1) the optimal policy is static and the AoI is periodic.",
    "C13": "The suboptimal policy costs no more than its base policy and far less to compute.",
}

DEPARTURES = """\
| paper | this reproduction | why |
|---|---|---|
| Sec. II text: edge U = D = 1, remote U = D = 2 | Table 1: remote U = D = 1, T_r,k = n_k; edge U = D = 0, T_e,k = 2 n_k | Table 1 agrees with the loop lengths (6, 8, 5, 6) of Sec. V |
| eq. (9): the edge's new job takes T_r | T_e | typo |
| eqs. (7)-(9): one joint success event | uplink and downlink losses are separate, in the spec's step order | exact reading (spec/model.md) |
| Q_k is a matrix | q_k = trace(Q_k) (weights 1) | the MDP needs a scalar cost |
| tau_hat "arbitrarily large" | finite caps, every cap-sensitive claim at several caps | truncation, not part of the model |
| Figs. 5, 10, 13: link of p unspecified | p on every uplink and downlink | spec section 4 |
| Fig. 7: plane tau_1 + tau_2 + tau_3 = 45 | the paper's plane 45 at cap 20, plus the planes 18 and 24 at caps 12 and 16 (1.5 x cap) | at caps below 15 the plane 45 lies outside the truncated box; the smaller planes show how the regions form as the cap grows |
| Figs. 8-9: "C_e = (3, 3)", "C_r = (1, 4)" | edge serving process 3 with 3 slots left; remote serving process 1 with 4 slots left | the paper's tuples read as (job, remaining slots) |
| Sec. IV | one remote server, arrivals every slot per process, LIFO stack of preempted jobs, cancellation of an obsolete same-process job | spec/model.md section 3 |
"""


def _md_table(rows: list[list[Any]], header: list[str]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def write_report(out: Path, claims: list[ClaimResult], provenance: dict[str, Any],
                 extras: list[dict[str, Any]] = ()) -> dict[str, str]:
    """Write the report; ``extras`` are the "beyond the paper" sections (no verdict, after the claims)."""
    out = Path(out)
    for c in claims:
        c.statement = c.statement or STATEMENTS.get(c.id, "")
    # ---------------------------------------------------------------- JSON
    doc = {"claims": [c.to_dict() for c in claims], "beyond": list(extras), "provenance": provenance}
    atomic_write_text(out / "report.json", json.dumps(json_ready(doc), indent=1))
    # ---------------------------------------------------------------- Markdown
    md = [
        "# Reproduction of \"On the Scheduling Policy for Multi-process WNCS under Edge Computing\"",
        "",
        f"Profile **{provenance['profile']}**; caps used: {provenance['caps']}. "
        "Every verdict is computed from the numbers beside it; DEPENDS says on what.",
        "",
        "## Verdicts",
        "",
        _md_table([[c.id, c.paper, f"**{c.verdict}**", c.summary] for c in claims],
                  ["claim", "paper", "verdict", "numbers"]),
        "",
    ]
    for c in claims:
        md += [f"## {c.id} ({c.paper}): {c.verdict}", "", f"> {c.statement}", "", c.summary, ""]
        if c.details:
            md += [c.details, ""]
        checks = c.numbers.get("checks") if isinstance(c.numbers, dict) else None
        if checks:
            md += [_md_table([[k, {True: "yes", False: "**no**", None: "n/a"}[v]] for k, v in checks.items()],
                             ["check", "holds"]), ""]
        for f in c.figures:
            if f.endswith(".png"):
                md += [f"![{c.id}]({f})", ""]
        if c.tables:
            md += ["Tables: " + ", ".join(f"[{t}]({t})" for t in c.tables), ""]
        md += [f"<details><summary>numbers</summary>\n\n```json\n{json.dumps(json_ready(c.numbers), indent=1)[:6000]}\n```\n</details>", ""]
    md += _extras_md(extras)
    md += ["## Where the exact model departs from the paper's text", "", DEPARTURES, "",
           "## Provenance", "", "```json", json.dumps(json_ready(provenance), indent=1), "```", ""]
    text = "\n".join(md)
    atomic_write_text(out / "report.md", text)
    # ---------------------------------------------------------------- HTML (self-contained)
    atomic_write_text(out / "report.html", _html(text, out))
    return {"md": str(out / "report.md"), "html": str(out / "report.html"), "json": str(out / "report.json")}


def _extras_md(extras: list[dict[str, Any]]) -> list[str]:
    """The "beyond the paper" sections: extra results computed like the claims, without a verdict."""
    if not extras:
        return []
    md = ["## Beyond the paper", "", "Results the paper does not state, computed with the same certificates. "
          "They are not claims: no verdict.", ""]
    for e in extras:
        md += [f"### {e['id']}: {e['title']}", "", e["summary"], ""]
        if e.get("details"):
            md += [e["details"], ""]
        md += [f"![{e['id']}]({f})" for f in e.get("figures", []) if f.endswith(".png")] + [""]
        if e.get("tables"):
            md += ["Tables: " + ", ".join(f"[{t}]({t})" for t in e["tables"]), ""]
        md += [f"<details><summary>numbers</summary>\n\n```json\n"
               f"{json.dumps(json_ready(e.get('numbers', {})), indent=1)[:6000]}\n```\n</details>", ""]
    return md


def _inline(text: str) -> str:
    t = html.escape(text)
    t = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", t)
    t = re.sub(r"`(.+?)`", r"<code>\1</code>", t)
    t = re.sub(r"\[(.+?)\]\((.+?)\)", r'<a href="\2">\1</a>', t)
    return t


def _html(md: str, root: Path) -> str:
    """A small Markdown subset to HTML, with PNG figures embedded as data URIs."""
    lines = md.split("\n")
    body: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("```"):
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            body.append("<pre>" + html.escape("\n".join(lines[i + 1:j])) + "</pre>")
            i = j + 1
            continue
        if line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                if not re.match(r"^\|(---\|)+$", lines[i]):
                    rows.append([c.strip() for c in lines[i].strip("|").split(" | ")])
                i += 1
            head, *rest = rows
            body.append("<table><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>"
                        + "".join("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in rest)
                        + "</table>")
            continue
        m = re.match(r"!\[(.*?)\]\((.+?)\)", line)
        if m:
            p = root / m.group(2)
            if p.exists():
                data = base64.b64encode(p.read_bytes()).decode()
                body.append(f'<img alt="{html.escape(m.group(1))}" src="data:image/png;base64,{data}">')
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            body.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif line.startswith("> "):
            body.append(f"<blockquote>{_inline(line[2:])}</blockquote>")
        elif line.startswith("<details") or line.startswith("</details"):
            body.append(line)
        elif line.strip():
            body.append(f"<p>{_inline(line)}</p>")
        i += 1
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;line-height:1.45}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:4px 8px;vertical-align:top}"
             "img{max-width:100%;border:1px solid #eee}pre{background:#f6f6f6;padding:8px;overflow-x:auto;font-size:12px}"
             "blockquote{border-left:4px solid #ccc;margin:0;padding-left:1em;color:#444}")
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>wncs_lp reproduction report</title>"
            f"<style>{style}</style></head><body>" + "\n".join(body) + "</body></html>")
