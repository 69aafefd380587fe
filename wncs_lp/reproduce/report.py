"""Write the reproduction report: report.md, a self-contained report.html, report.json.

Both human-readable reports open with a table of contents that is also the table of verdicts
(each claim linked to its section, its verdict, the caps it rests on and a warning when the
deciding cap leans on the truncation). Numbers are shown in tables, formatted for reading
(:func:`fmt`: no Python ``None``/dict text); every number is also in ``report.json``. The HTML
page embeds its figures (PNG data URIs) with captions, colours the verdicts, and ends with the
provenance (date, commit, versions, timings).
"""
from __future__ import annotations

import base64
import html
import json
import math
import re
from pathlib import Path
from typing import Any, Sequence

from ..files import atomic_write_text, json_ready
from ..truncation import CAP_MASS_WARN
from ..verify.verdict import CLOSE, MUCH, RULE, SIGNIFICANT
from .context import ClaimResult, Table

#: The paper's own sentences for each claim (math in plain text), quoted at the head of its section.
QUOTES = {
    "C1": ("Sec. V, Fig. 3", "Fig. 3 is the optimal scheduling policy when only process 1 and process 4 in system. It is "
           "obvious that all the actions are a = (1, 4), which means the status information from process 1 always "
           "send to remote controller and the status information from process 4 always send to edge server."),
    "C2": ("Sec. V, Fig. 4", "Fig. 4 is the optimal scheduling policy when only process 1 and process 2 in system. "
           "Different from Fig. 3, there are different actions in different states, and a* = (2, 1) appears in the "
           "upper left corner of Fig. 4."),
    "C3": ("Sec. V, Fig. 5", "Compared with the greedy baseline policy, the performance of optimal policy is greatly "
           "improved. While for the static policy, it is vastly improved only when the transmission success "
           "probability is low. [...] When the transmission success probability is 1, these states will not be "
           "reached at all."),
    "C4": ("Sec. V, Figs. 6-7", "There are four regions in the graph. It is a threshold policy, which is similar to the "
           "optimal policy in a two-dimensional case. When the action is given, the set of actions in the optimal "
           "policy is a simply connected region."),
    "C5": ("Sec. II and Sec. V, Figs. 8-9", "when the status information of process k is transmitting to the remote "
           "server, or the remote server is computing the status information of process k, the edge server will serve "
           "other processes except process k."),
    "C6": ("Sec. V, Fig. 10", "It can be observed that compared with the greedy baseline policy, the proposed optimal "
           "policy still has a significant improvement. When the transmission success probability is closer to 1, the "
           "performance of optimal policy, sub-optimal policy, and static policy tend to be the same. It is also "
           "observed that the performance of sub-optimal policy is close to optimal policy."),
    "C7": ("Sec. II, Theorem 1", "For any state s^1 = (tau^1, C_r^1, C_e^1), s^2 = (tau^2, C_r^2, C_e^2), satisfy that "
           "tau_1^1 >= tau_1^2, tau_2^1 >= tau_2^2, tau_3^1 >= tau_3^2, C_e^2 = C_e^1 and C_r^2 = C_r^1, we have "
           "V(s^1) >= V(s^2)."),
    "C8": ("Sec. II, Theorem 2", "For the state s = (tau, C_r, C_e) which satisfies C_r = 0 and C_e = 0 have the "
           "following type policy: If pi*(s) = (k_1, k_2), then pi*(s') = (k_1, k_2). Where k_1 != k_2 and s' is the "
           "same with s except tau'_k1 = tau_k1 + z, tau'_k2 = tau_k2 + z. z is any positive integer number."),
    "C9": ("Sec. V, Figs. 11-12", "Fig. 11 and Fig. 12 are the optimal preemption policy when the remote server "
           "processes the tasks of process 1 and process 2, respectively. It is a threshold policy, which is the same "
           "as the theory in Section IV."),
    "C10": ("Sec. IV, Theorem 3", "Theorem 3 shows that the process status will not be preempted until it is processed "
            "completely when the server takes the optimal action a*(t) = pi*(s) = i, i = 1, 2 successfully."),
    "C11": ("Sec. V, Fig. 13", "It can be found that the higher transmission success probability, the more minor "
            "performance improvement, and the overall performance improvement is not significant. [...] although the "
            "preemption mechanism will not reduce system performance, it will not significantly improve the system "
            "performance."),
    "C12": ("Sec. V, end", "the performance of the optimal policy is the same as that of the static policy when the "
            "wireless channel is perfect [...]. This is because the optimal policy is the same as static policy when "
            "the wireless channel is perfect, and the AoI of all processes will change periodically. (Sec. V: \"The "
            "static policy means that each process will only transmit the status information to the corresponding "
            "controller and will not transmit it to other controllers.\")"),
    "C13": ("Sec. III", "So we proposed a suboptimal policy, which sacrifices a small amount of performance in exchange "
            "for a significant reduction in computational complexity. [...] the proposed suboptimal algorithm is "
            "superior to other random algorithms."),
    "C14": ("Sec. V", "Since the optimal policy in case 1 is entirely equal to the static policy, performance simulation "
            "is only performed for case 2."),
    "C15": ("Sec. V", "This is because the optimal policy in Fig. 4, only the upper left corner is different from the "
            "static policy, and the lower the transmission success probability, the easier it is to reach these "
            "different states. When the transmission success probability is 1, these states will not be reached at "
            "all."),
    "C16": ("Sec. IV", "The controller may be idle if only one status is allowed to send the state to controller at a "
            "slot. [...] Work with the preemption mechanism, it can significantly reduce the idle time of the server "
            "without reducing the system performance."),
}

#: What each claim is checked as (the specification's claims C1-C13, and C14-C16: statements of Secs. IV-V with no
#: figure of their own), shown under the conclusion.
STATEMENTS = {
    "C1": "Processes 1 and 4: the optimal action in idle-server states is always (1 to remote, 4 to edge).",
    "C2": "Processes 1 and 2: mostly (1, 2), with (2, 1) in the upper-left corner (small tau_1, large tau_2).",
    "C3": "Processes 1 and 2, p in [0.8, 1]: optimal better than static and much better than greedy; the gap to "
          "static larger at low p, and vast there; optimal equal to static at p = 1.",
    "C4": "Processes 1, 2, 3: on the plane tau_1 + tau_2 + tau_3 = const, the optimal policy has four regions, "
          "each simply connected (threshold type).",
    "C5": "Processes 1, 2, 3: optimal policy of one server while the other is busy (edge busy with process 3 / "
          "remote busy with process 1); the free server serves the other processes.",
    "C6": "Processes 1, 2, 3, p in [0.8, 1]: optimal <= suboptimal <= static <= greedy in average MSE, suboptimal "
          "close to optimal, all but greedy tending to the same value as p nears 1.",
    "C7": "Theorem 1: the value function is nondecreasing in each tau_k with the server states fixed.",
    "C8": "Theorem 2: in idle-server states, if pi*(s) = (k1, k2) then the same action at s + z(e_k1 + e_k2) "
          "for every z >= 1.",
    "C9": "Preemption: the optimal preemption policy while the server processes process 2's (Fig. 11) or "
          "process 1's (Fig. 12) job is of threshold type.",
    "C10": "Theorem 3: once the optimal policy starts a job by preempting, it is not preempted again before it "
           "completes.",
    "C11": "Preemption never hurts, and helps less as p grows; overall not significant.",
    "C12": "With a perfect channel (p = 1) the optimal policy is static (each process to a fixed server; and equal to "
           "a static rule) and the AoI is periodic.",
    "C13": "The suboptimal policy costs no more than its base policy and far less to compute.",
    "C14": "Processes 1 and 4 (case 1), p = 0.9: the optimal policy is the static policy (1 to remote, 4 to edge): the "
           "same average cost, and the static action optimal in every state it visits.",
    "C15": "Processes 1 and 2, p = 0.9: the optimal policy differs from the static policy (1 to remote, 2 to edge) only "
           "in the upper-left corner of Fig. 4's idle-server map; those states are reached less as p grows.",
    "C16": "Preemption (processes 1, 2 on the remote server) reduces the server's idle time significantly, without "
           "raising the optimal average MSE.",
}


def quote(cid: str) -> str:
    """The paper's sentence for a claim, in quotes with where it stands ("" for an unknown claim)."""
    where, text = QUOTES.get(cid, ("", ""))
    return f"\"{text}\" ({where})" if text else ""


READING = (
    "How to read a section: the paper's own sentence, then the conclusion with the numbers that decide it, then the "
    "detail. Where a verdict is decided: the cap is a truncation of the paper's unbounded AoI, so the least "
    "truncated instance computed (the largest cap of each scenario) decides; a more truncated instance that "
    "disagrees is printed as a caveat, never as the verdict. How to read a verdict. HOLDS: the claim holds at the "
    "deciding cap. FAILS: for a structural claim, a violation with a witness in states the optimal policy visits in "
    "the long run, each of weight, and away from the AoI cap (" + RULE + "; the same rule as `wncs-lp verify`), "
    "shown farthest from the cap with the stationary probability of its states (its weight); for a claim made of "
    "sub-claims, one sub-claim false at the deciding cap (the paper's words read with fixed bars, the report's own "
    f"reading where the paper gives no number: \"much better\" and \"vastly\" {MUCH:.0%} or more, \"close\" within "
    f"{CLOSE:.0%}, \"not significant\" below {SIGNIFICANT:.0%}; a trend in p broken only beyond the certificates). "
    "DEPENDS: violations only in transient states, in states of negligible weight or at the cap, or instances of "
    "the same truncation (planes, scenarios) that disagree. Each verdict names the instances it rests on with the "
    "share of the long-run time the optimal policy spends with some AoI at the cap, and is flagged (⚠) when its "
    f"deciding instance has more than {CAP_MASS_WARN:.0%} there."
)

DEPARTURES = """\
| paper | this reproduction | why |
|---|---|---|
| Sec. II text: edge U = D = 1, remote U = D = 2 | Table 1: remote U = D = 1, T_r,k = n_k; edge U = D = 0, T_e,k = 2 n_k | Table 1 agrees with the loop lengths (6, 8, 5, 6) of Sec. V |
| eq. (9): the edge's new job takes T_r | T_e | typo |
| eqs. (7)-(9): one joint success event | uplink and downlink losses are separate, in the spec's step order | exact reading (spec/model.md) |
| Q_k is a matrix | q_k = trace(Q_k) (weights 1) | the MDP needs a scalar cost |
| tau_hat "arbitrarily large" | finite caps, every cap-sensitive claim at several caps, the mass at the cap reported | truncation, not part of the model |
| Figs. 5, 10, 13: link of p unspecified | p on every uplink and downlink | spec section 4 |
| Fig. 7: plane tau_1 + tau_2 + tau_3 = 45 | the paper's plane 45 at cap 20, and the planes 18 to 36 at every cap they fit (up to 2.25 x cap) | at caps below 20 the plane 45 lies (almost) outside the truncated box; several planes per cap keep the plane's effect apart from the cap's |
| Figs. 8-9: "C_e = (3, 3)", "C_r = (1, 4)" | edge serving process 3 with 3 slots left; remote serving process 1 with 4 slots left | the paper's tuples read as (job, remaining slots) |
| Sec. V: static = "each process to its controller" | the spec's default assignment (largest process to its shortest-loop server, every other process to the other server); best static beside it | spec/policies.md |
| Sec. IV | one remote server, arrivals every slot per process, LIFO stack of preempted jobs, cancellation of an obsolete same-process job | spec/model.md section 3 |
"""

#: Verdict colours of the HTML report (background, text).
COLOURS = {"HOLDS": ("#d7f5dd", "#0b6623"), "FAILS": ("#fbd9d7", "#a4161a"), "DEPENDS": ("#fff0c2", "#8a5a00"),
           "ERROR": ("#e4e4e4", "#333333")}


# ============================================================================ formatting
def fmt(v: Any) -> str:
    """A value as text for a table cell: no ``None``/``nan``, readable floats, yes/no."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}" if abs(v) >= 10_000 else str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "—"
        if v == 0:
            return "0"
        if v == int(v) and abs(v) < 1e6:
            return str(int(v))
        return f"{v:.10g}" if abs(v) >= 1e-3 else f"{v:.3e}"
    if isinstance(v, (list, tuple)):
        return ", ".join(fmt(x) for x in v) if v else "—"
    if isinstance(v, dict):
        return "; ".join(f"{k}: {fmt(x)}" for k, x in v.items()) if v else "—"
    return str(v)


def _md_cell(v: Any) -> str:
    return fmt(v).replace("|", "\\|").replace("\n", " ")


def md_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    out = ["| " + " | ".join(_md_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def _anchor(cid: str) -> str:
    return cid.lower()


def basis_words(basis: dict[str, Any]) -> str:
    """One line: the caps a verdict rests on, the deciding instance and its mass at the cap."""
    if not basis:
        return "—"
    caps = ", ".join(map(str, basis.get("caps", [])))
    if not basis.get("deciding"):
        return f"caps {caps}; not decided by the truncation"
    dec = ", ".join(map(str, basis.get("deciding_caps", [])))
    text = f"caps {caps}; deciding cap {dec} ({basis['deciding_mass']:.2%} at the cap)"
    return ("⚠ " + text) if basis.get("flag") else text


def basis_note(basis: dict[str, Any]) -> str:
    """The paragraph under a claim: what it rests on, and the warning when flagged."""
    if not basis:
        return ""
    text = f"**Rests on** {basis_words(basis).removeprefix('⚠ ')}."
    if basis.get("deciding"):
        text += " Deciding (the least truncated instance of each scenario): " + "; ".join(basis["deciding"]) + "."
    if basis.get("caveats"):
        text += (" Caveat, a more truncated instance that disagrees (it does not decide): "
                 + "; ".join(f"{c['label']} says {c['verdict']} ({c['mass']:.2%} at the cap)" for c in basis["caveats"])
                 + ".")
    if basis.get("note"):
        text += " " + basis["note"]
    if basis.get("flag"):
        text += (f"\n\n⚠ **Leans on the truncation:** the deciding instance spends {basis['deciding_mass']:.2%} of its "
                 f"long-run time with some AoI at the cap, above {basis['threshold']:.0%}; a larger cap may change "
                 "the numbers.")
    return text


def basis_table(basis: dict[str, Any]) -> Table | None:
    inst = basis.get("instances") or []
    if not inst:
        return None
    dec = set(basis.get("deciding", []))
    return Table("The instances this verdict rests on: the verdict of each, and the share of the optimal policy's "
                 "long-run time with some AoI at its cap (total and per process).",
                 ["instance", "its verdict", "mass at the cap", "per process", "deciding"],
                 [[e["label"], e["verdict"], f"{e['mass']:.3%}", ", ".join(f"{m:.2%}" for m in e.get("per_process", [])),
                   "yes" if e["label"] in dec else ""] for e in inst])


# ============================================================================ provenance
def provenance_rows(prov: dict[str, Any]) -> list[list[str]]:
    """Provenance as (field, value) rows; nested dicts become "k: v" lists."""
    order = ["date", "commit", "profile", "command", "caps", "p_grid", "monte_carlo", "solver", "scenario_files",
             "versions", "platform", "cache", "total_seconds", "timings_seconds"]
    keys = [k for k in order if k in prov] + [k for k in prov if k not in order]
    rows = []
    for k in keys:
        v = prov[k]
        if isinstance(v, dict):
            v = "; ".join(f"{a}: {fmt(round(b, 1) if isinstance(b, float) else b)}" for a, b in v.items())
        elif isinstance(v, float):
            v = f"{v:.1f}"
        rows.append([k.replace("_", " "), fmt(v)])
    return rows


# ============================================================================ writers
def write_report(out: Path, claims: list[ClaimResult], provenance: dict[str, Any],
                 extras: Sequence[dict[str, Any]] = ()) -> dict[str, str]:
    """Write the report; ``extras`` are the "beyond the paper" sections (no verdict, after the claims)."""
    out = Path(out)
    for c in claims:
        c.statement = c.statement or quote(c.id)
    doc = {"claims": [c.to_dict() for c in claims], "beyond": list(extras), "provenance": provenance}
    atomic_write_text(out / "report.json", json.dumps(json_ready(doc), indent=1))
    atomic_write_text(out / "report.md", _markdown(claims, provenance, list(extras)))
    atomic_write_text(out / "report.html", _html_page(claims, provenance, list(extras), out))
    return {"md": str(out / "report.md"), "html": str(out / "report.html"), "json": str(out / "report.json")}


TITLE = "Reproduction of \"On the Scheduling Policy for Multi-process WNCS under Edge Computing\""


def _headline(prov: dict[str, Any]) -> str:
    return (f"Run of {prov.get('date', 'unknown date')}, commit {prov.get('commit', 'unknown')}, profile "
            f"**{prov.get('profile', '?')}**. Every verdict is computed from the numbers beside it.")


def _toc_rows(claims: list[ClaimResult], link) -> list[list[str]]:
    return [[link(c), c.paper, f"**{c.verdict}**", basis_words(c.basis), c.summary + _notes_mark(c)] for c in claims]


def _notes_mark(c: ClaimResult) -> str:
    """The contents table's mark of a claim resting on solves that did not close their certificate."""
    n = len(c.solver_notes)
    return f" ⚠ {n} solve(s) not optimal: see the section." if n else ""


def errors_first(claims: list[ClaimResult], extras: list[dict[str, Any]]) -> list[tuple[str, str, str]]:
    """Every claim and section that could not be computed, as (id, title, why), claims first."""
    out = [(c.id, f"{c.id} ({c.paper})", c.summary) for c in claims if c.verdict == "ERROR"]
    out += [(e["id"], f"{e['id']}: {e.get('title', '')}", e.get("summary", "")) for e in extras
            if e.get("status") == "ERROR"]
    return out


def _errors_md(claims: list[ClaimResult], extras: list[dict[str, Any]]) -> list[str]:
    errs = errors_first(claims, extras)
    if not errs:
        return []
    md = [f"**ERROR: {len(errs)} part(s) of this report could not be computed** (the command exited with status 1; "
          "nothing below stands in for them):", ""]
    md += [f"{i + 1}. [{title}](#{_anchor(sid)}): {why}" for i, (sid, title, why) in enumerate(errs)]
    return md + [""]


def notes_text(notes: Sequence[str]) -> str:
    """The paragraph at the head of a section whose solves did not all close their certificate."""
    return ("⚠ **Not every solve of this section closed its certificate** (the numbers come from the bracket "
            "the solver ended with; the status says why it stopped): " + "; ".join(notes) + ".")


def _markdown(claims: list[ClaimResult], prov: dict[str, Any], extras: list[dict[str, Any]]) -> str:
    md = [f"# {TITLE}", "", _headline(prov), "", *_errors_md(claims, extras), "## Contents and verdicts", "",
          md_table(["claim", "paper", "verdict", "rests on", "numbers"],
                   _toc_rows(claims, lambda c: f"[{c.id}](#{_anchor(c.id)})")), ""]
    if extras:
        md += ["Beyond the paper: " + ", ".join(f"[{e['id']}](#{_anchor(e['id'])}) {e['title']}"
                                              + (" (**ERROR**)" if e.get("status") == "ERROR" else "")
                                              for e in extras), ""]
    md += [READING, ""]
    for c in claims:
        md += [f'<a id="{_anchor(c.id)}"></a>', "", f"## {c.id} ({c.paper}): {c.verdict}", "",
               f"> {c.statement}", "", f"**{c.summary}**", ""]
        if STATEMENTS.get(c.id):
            md += [f"*Checked as:* {STATEMENTS[c.id]}", ""]
        if c.solver_notes:
            md += [notes_text(c.solver_notes), ""]
        note = basis_note(c.basis)
        if note:
            md += [note, ""]
        if c.details:
            md += [c.details, ""]
        for t in c.shown + ([basis_table(c.basis)] if basis_table(c.basis) else []):
            md += [f"*{t.caption}*", "", md_table(t.header, t.rows), ""]
        n = 0
        for f in c.figures:
            if f.endswith(".png"):
                n += 1
                cap = c.captions.get(f, "")
                md += [f"![{c.id} figure {n}]({f})", "", f"*Figure {c.id}.{n}. {cap}*", ""]
        if c.tables:
            md += ["Tables (CSV): " + ", ".join(f"[{t}]({t})" for t in c.tables) + "; every number: `report.json`.", ""]
    md += _extras_md(extras)
    md += ["## Where the exact model departs from the paper's text", "", DEPARTURES, "",
           "## Provenance", "", md_table(["field", "value"], provenance_rows(prov)), ""]
    return "\n".join(md)


def _extras_md(extras: list[dict[str, Any]]) -> list[str]:
    """The "beyond the paper" sections: extra results computed like the claims, without a verdict."""
    if not extras:
        return []
    md = ["## Beyond the paper", "", "Results the paper does not state, computed with the same certificates. "
          "They are not claims: no verdict.", ""]
    for e in extras:
        error = " (ERROR: could not be computed)" if e.get("status") == "ERROR" else ""
        md += [f'<a id="{_anchor(e["id"])}"></a>', "", f"### {e['id']}: {e['title']}{error}", "", e["summary"], ""]
        if e.get("details"):
            md += [e["details"], ""]
        n = 0
        for f in e.get("figures", []):
            if f.endswith(".png"):
                n += 1
                md += [f"![{e['id']} figure {n}]({f})", "", f"*Figure {e['id']}.{n}. {e.get('title', '')}*", ""]
        if e.get("tables"):
            md += ["Tables (CSV): " + ", ".join(f"[{t}]({t})" for t in e["tables"]) + "; every number: `report.json`.",
                   ""]
    return md


# ============================================================================ HTML
def _inline(text: str) -> str:
    t = html.escape(text, quote=False)
    t = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", t)
    t = re.sub(r"`(.+?)`", r"<code>\1</code>", t)
    t = re.sub(r"(?<![\w*])\*(?!\s)(.+?)(?<!\s)\*(?![\w*])", r"<i>\1</i>", t)
    t = re.sub(r"\[(.+?)\]\((.+?)\)", r'<a href="\2">\1</a>', t)
    return t


def md_to_html(md: str) -> str:
    """A small Markdown subset (paragraphs, tables, code blocks, numbered lists, quotes, headings)."""
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
                if not re.match(r"^\|(\s*-+\s*\|)+$", lines[i]):
                    rows.append([c.strip() for c in re.split(r"(?<!\\)\|", lines[i].strip().strip("|"))])
                i += 1
            head, *rest = rows
            body.append(_table_html(head, rest, raw=True))
            continue
        if re.match(r"^\d+\. ", line):
            items = []
            while i < len(lines) and re.match(r"^\d+\. ", lines[i]):
                items.append(f"<li>{_inline(lines[i].split('. ', 1)[1])}</li>")
                i += 1
            body.append("<ol>" + "".join(items) + "</ol>")
            continue
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            body.append(f"<h{level + 1}>{_inline(line[level:].strip())}</h{level + 1}>")
        elif line.startswith("> "):
            body.append(f"<blockquote>{_inline(line[2:])}</blockquote>")
        elif line.strip():
            body.append(f"<p>{_inline(line)}</p>")
        i += 1
    return "\n".join(body)


def _cell_html(v: Any, raw: bool) -> str:
    text = v.replace("\\|", "|") if raw else fmt(v)
    if text in ("HOLDS", "FAILS", "DEPENDS", "ERROR") or re.fullmatch(r"(HOLDS|FAILS|DEPENDS|ERROR) \(.+\)", text):
        word = text.split()[0]
        return _badge(word, text)
    return _inline(text)


def _table_html(header: Sequence[Any], rows: Sequence[Sequence[Any]], caption: str = "", raw: bool = False) -> str:
    cap = f"<caption>{_inline(caption)}</caption>" if caption else ""
    return ("<table>" + cap + "<thead><tr>" + "".join(f"<th>{_inline(str(h))}</th>" for h in header)
            + "</tr></thead><tbody>"
            + "".join("<tr>" + "".join(f"<td>{_cell_html(c, raw)}</td>" for c in r) + "</tr>" for r in rows)
            + "</tbody></table>")


def _badge(verdict: str, text: str | None = None) -> str:
    bg, fg = COLOURS.get(verdict, COLOURS["ERROR"])
    return (f'<span class="verdict v-{verdict.lower()}" style="background:{bg};color:{fg}">'
            f"{html.escape(text or verdict)}</span>")


def _figure(root: Path, path: str, label: str, caption: str) -> str:
    p = root / path
    if not p.exists():
        return f"<p>(figure {html.escape(path)} missing)</p>"
    data = base64.b64encode(p.read_bytes()).decode()
    svg = path[:-4] + ".svg"
    link = f' <a href="{html.escape(svg)}">SVG</a>' if (root / svg).exists() else ""
    return (f'<figure><img alt="{html.escape(label + ": " + caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption><b>{html.escape(label)}.</b> {_inline(caption)}{link}</figcaption></figure>")


def _flat(d: Any, prefix: str = "", out: list | None = None, limit: int = 400) -> list[list[str]]:
    """Nested numbers as (key path, value) rows for a collapsed table; long lists are referred to the JSON."""
    out = [] if out is None else out
    if len(out) >= limit:
        return out
    if isinstance(d, dict):
        for k, v in d.items():
            _flat(v, f"{prefix} / {k}" if prefix else str(k), out, limit)
    elif isinstance(d, (list, tuple)) and d and any(isinstance(x, (dict, list, tuple)) for x in d):
        if len(d) <= 8:
            for i, v in enumerate(d):
                _flat(v, f"{prefix} [{i + 1}]", out, limit)
        else:
            out.append([prefix, f"{len(d)} entries (see report.json)"])
    elif isinstance(d, (list, tuple)) and len(d) > 16:
        out.append([prefix, f"{len(d)} values (see report.json)"])
    else:
        out.append([prefix, fmt(d)])
    return out


STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",sans-serif;max-width:1180px;margin:1.5em auto;padding:0 1em;
line-height:1.45;color:#1d1d1f}
h1{font-size:1.55em;margin-bottom:.2em}h2{margin-top:2.2em;border-bottom:2px solid #ddd;padding-bottom:.2em}
table{border-collapse:collapse;margin:.8em 0 1.2em;font-size:13px}td,th{border:1px solid #c8c8c8;padding:3px 7px;
vertical-align:top}th{background:#f2f2f2;text-align:left}caption{caption-side:top;text-align:left;font-style:italic;
padding:4px 0;color:#444}
.toc td:nth-child(5){max-width:560px}.toc td{font-size:13px}.toc td:nth-child(3){white-space:nowrap}
.verdict{display:inline-block;padding:1px 8px;border-radius:10px;font-weight:600;font-size:12px;white-space:nowrap}
.flag{color:#8a5a00;font-weight:600}
figure{margin:1em 0 1.6em}figure img{max-width:100%;border:1px solid #eee}figcaption{font-size:13px;color:#333;
margin-top:.3em}
pre{background:#f6f6f6;padding:8px;overflow-x:auto;font-size:12px}
blockquote{border-left:4px solid #ccc;margin:0 0 .8em;padding-left:1em;color:#444}
.basis{background:#f7f7fb;border:1px solid #dde;padding:6px 10px;border-radius:4px;font-size:14px}
.basis.flagged{background:#fff7e0;border-color:#e6c36a}
.reading{font-size:13px;color:#444}
.errors{background:#fbd9d7;border:2px solid #a4161a;padding:4px 12px;border-radius:4px}
.notes{background:#fff7e0;border:1px solid #e6c36a;padding:6px 10px;border-radius:4px}
"""


def _html_page(claims: list[ClaimResult], prov: dict[str, Any], extras: list[dict[str, Any]], root: Path) -> str:
    b: list[str] = [f"<h1>{html.escape(TITLE)}</h1>", f"<p>{_inline(_headline(prov))}</p>"]
    errs = _errors_md(claims, extras)
    if errs:
        b.append('<div class="errors">' + md_to_html("\n".join(errs)) + "</div>")
    b.append('<h2 id="contents">Contents and verdicts</h2>')
    rows = []
    for c in claims:
        flag = ' <span class="flag" title="the deciding cap leans on the truncation">⚠</span>' \
            if c.basis.get("flag") else ""
        rows.append(f'<tr><td><a href="#{_anchor(c.id)}">{c.id}</a></td><td>{html.escape(c.paper)}</td>'
                    f"<td>{_badge(c.verdict)}{flag}</td><td>{_inline(basis_words(c.basis).removeprefix('⚠ '))}</td>"
                    f"<td>{_inline(c.summary + _notes_mark(c))}</td></tr>")
    b.append('<table class="toc"><thead><tr><th>claim</th><th>paper</th><th>verdict</th><th>rests on</th>'
             "<th>numbers</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table>")
    links = [f'<a href="#{_anchor(e["id"])}">{html.escape(e["id"])}: {html.escape(e["title"])}</a>'
             + (" " + _badge("ERROR") if e.get("status") == "ERROR" else "") for e in extras]
    links += ['<a href="#departures">Where the exact model departs from the paper</a>',
              '<a href="#provenance">Provenance</a>']
    b.append("<p>Also: " + " · ".join(links) + "</p>")
    b.append(f'<p class="reading">{_inline(READING)}</p>')
    for c in claims:
        b.append(f'<section id="{_anchor(c.id)}"><h2>{c.id} ({html.escape(c.paper)}) {_badge(c.verdict)}</h2>')
        b.append(f"<blockquote>{_inline(c.statement)}</blockquote><p><b>{_inline(c.summary)}</b></p>")
        if STATEMENTS.get(c.id):
            b.append(f"<p><i>Checked as:</i> {_inline(STATEMENTS[c.id])}</p>")
        if c.solver_notes:
            b.append(f'<p class="notes">{_inline(notes_text(c.solver_notes))}</p>')
        note = basis_note(c.basis)
        if note:
            cls = "basis flagged" if c.basis.get("flag") else "basis"
            b.append(f'<div class="{cls}">' + md_to_html(note) + "</div>")
        if c.details:
            b.append(md_to_html(c.details))
        for t in c.shown + ([basis_table(c.basis)] if basis_table(c.basis) else []):
            b.append(_table_html(t.header, t.rows, t.caption))
        n = 0
        for f in c.figures:
            if f.endswith(".png"):
                n += 1
                b.append(_figure(root, f, f"Figure {c.id}.{n}", c.captions.get(f, "")))
        if c.tables:
            b.append("<p>Tables (CSV): " + ", ".join(f'<a href="{html.escape(t)}">{html.escape(t)}</a>'
                                                    for t in c.tables) + "</p>")
        flat = _flat(c.numbers)
        if flat:
            b.append("<details><summary>All numbers of this claim</summary>"
                     + _table_html(["quantity", "value"], flat) + "</details>")
        b.append('<p><a href="#contents">back to the contents</a></p></section>')
    if extras:
        b.append('<h2 id="beyond">Beyond the paper</h2><p>Results the paper does not state, computed with the same '
                 "certificates. They are not claims: no verdict.</p>")
        for e in extras:
            badge = " " + _badge("ERROR") if e.get("status") == "ERROR" else ""
            b.append(f'<section id="{_anchor(e["id"])}"><h3>{html.escape(e["id"])}: {html.escape(e["title"])}{badge}'
                     f"</h3><p>{_inline(e['summary'])}</p>")
            if e.get("details"):
                b.append(md_to_html(e["details"]))
            n = 0
            for f in e.get("figures", []):
                if f.endswith(".png"):
                    n += 1
                    b.append(_figure(root, f, f"Figure {e['id']}.{n}", e.get("title", "")))
            flat = _flat(e.get("numbers", {}))
            if flat:
                b.append("<details><summary>All numbers of this section</summary>"
                         + _table_html(["quantity", "value"], flat) + "</details>")
            b.append('<p><a href="#contents">back to the contents</a></p></section>')
    b.append('<h2 id="departures">Where the exact model departs from the paper\'s text</h2>' + md_to_html(DEPARTURES))
    b.append('<h2 id="provenance">Provenance</h2>' + _table_html(["field", "value"], provenance_rows(prov)))
    return ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width, initial-scale=1'>"
            f"<title>wncs_lp reproduction report</title><style>{STYLE}</style></head><body>"
            + "\n".join(b) + "</body></html>")
