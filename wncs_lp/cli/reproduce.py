"""``wncs-lp reproduce``: every figure and claim of the paper into a report."""
from __future__ import annotations

import argparse

from .common import Command, add_threads_arg, emit_json, output_folder


def cmd_reproduce(args: argparse.Namespace) -> int:
    from ..reproduce import run_reproduction
    from ..reproduce.report import basis_words

    output_folder(args.out)  # before any work
    result = run_reproduction(args.out, args.profile, force=args.recompute,
                              claims=[c.strip().upper() for c in args.claims.split(",")] if args.claims else None,
                              progress=not args.json, threads=args.threads)
    if args.json:
        emit_json({"files": result["files"], "seconds": result["seconds"], "errors": result["errors"],
                   "claims": [{**{k: c[k] for k in ("id", "verdict", "summary")},
                               "rests_on": basis_words(c.get("basis") or {}),
                               "leans_on_truncation": bool((c.get("basis") or {}).get("flag")),
                               "solves_not_optimal": c.get("solver_notes", [])}
                              for c in result["claims"]],
                   "beyond": [{k: e.get(k) for k in ("id", "title", "status", "summary")} for e in result["beyond"]]})
    else:
        for c in result["claims"]:
            print(f"{c['id']:>4} {c['verdict']:<8} [{basis_words(c.get('basis') or {})}] {c['summary']}")
            for note in c.get("solver_notes", []):
                print(f"{'':>4} {'':<8} not optimal: {note}")
        for e in result["beyond"]:
            word = "ERROR" if e.get("status") == "ERROR" else "done"
            print(f"{e['id']:>4} {word:<8} {e['title']}" + (f": {e['summary']}" if word == "ERROR" else ""))
        print(f"report: {result['files']['md']} and {result['files']['html']} ({result['seconds']:.0f} s)")
    if result["errors"]:
        import sys

        claims = [i for i in result["errors"] if i.startswith("C")]
        sections = [i for i in result["errors"] if not i.startswith("C")]
        parts = ([f"{len(claims)} claim(s) could not be computed ({', '.join(claims)})"] if claims else []) + (
            [f"{len(sections)} section(s) beyond the paper could not be computed ({', '.join(sections)})"]
            if sections else [])
        print(f"error: {'; '.join(parts)}; see the report", file=sys.stderr)
        return 1
    return 0


def _configure_reproduce(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output folder (figures, tables, report.md/.html/.json, cache)")
    p.add_argument("--profile", default="default", choices=["quick", "default", "full"],
                   help="quick: small caps and grids; default: caps 12/20/30 where the size allows; full: default "
                        "plus the paper's four processes at caps 25 and 30 (the estimate of each is printed "
                        "before the first section)")
    p.add_argument("--recompute", action="store_true", help="recompute every step instead of using the cache")
    # the old name, kept working: --force means "build past the size guard" on every other command
    p.add_argument("--force", dest="recompute", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--claims", default="", help="only these claims, e.g. C1,C7 (default: all)")
    add_threads_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")


COMMANDS = [
    Command("reproduce", "reproduce every figure and claim of the paper into a report (cached, resumable)",
            _configure_reproduce, cmd_reproduce),
]
