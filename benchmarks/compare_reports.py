"""Compare the numbers of two reproduction reports (``report.json``), e.g. before and after a refactor.

    python benchmarks/compare_reports.py OLD/report.json NEW/report.json [--rtol 1e-9]

Walks both JSON trees in parallel (claims by id, rows by position) and prints: how many numbers
are bitwise equal, how many differ within ``--rtol`` (with the largest relative difference), and
every difference beyond it, every verdict that changed and every key present on one side only.
Timings (keys containing "seconds", "time", "timings", "hits", "misses") and provenance versions are
skipped. Exit status 1 when a verdict changed or a number differs beyond ``--rtol``.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

SKIP = ("seconds", "time", "timings", "hits", "misses", "versions", "platform", "cache", "error")


def walk(a, b, path, out):
    if any(s in path.rsplit("/", 1)[-1] for s in SKIP):
        return
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out["only"].append(f"{path}/{k} only in {'new' if k in b else 'old'}")
            else:
                walk(a[k], b[k], f"{path}/{k}", out)
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            out["only"].append(f"{path}: {len(a)} items old, {len(b)} new")
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out)
    elif isinstance(a, bool) or isinstance(b, bool) or not (isinstance(a, (int, float)) and isinstance(b, (int, float))):
        if a != b:
            out["text"].append(f"{path}: {a!r} -> {b!r}")
        else:
            out["same_text"] += 1
    else:
        if a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)):
            out["equal"] += 1
        else:
            rel = abs(a - b) / max(abs(a), abs(b), 1e-300)
            out["diff"].append((rel, path, a, b))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--rtol", type=float, default=1e-9)
    args = ap.parse_args(argv)
    old = {c["id"]: c for c in json.load(open(args.old))["claims"]}
    new = {c["id"]: c for c in json.load(open(args.new))["claims"]}
    out = {"equal": 0, "same_text": 0, "diff": [], "text": [], "only": []}
    verdicts = []
    for cid in sorted(set(old) | set(new), key=lambda c: int(c[1:])):
        if cid not in old or cid not in new:
            out["only"].append(f"claim {cid} only in {'new' if cid in new else 'old'}")
            continue
        if old[cid]["verdict"] != new[cid]["verdict"]:
            verdicts.append(f"{cid}: {old[cid]['verdict']} -> {new[cid]['verdict']}")
        walk(old[cid].get("numbers", {}), new[cid].get("numbers", {}), f"{cid}", out)
    within = [d for d in out["diff"] if d[0] <= args.rtol]
    beyond = [d for d in out["diff"] if d[0] > args.rtol]
    print(f"numbers: {out['equal']} bitwise equal, {len(within)} within rtol {args.rtol:g}"
          + (f" (largest relative difference {max(d[0] for d in within):.2e})" if within else "")
          + f", {len(beyond)} beyond; {out['same_text']} equal texts, {len(out['text'])} changed texts")
    for v in verdicts:
        print("verdict changed:", v)
    for rel, path, a, b in sorted(beyond, reverse=True):
        print(f"differs {rel:.3e}: {path}: {a!r} -> {b!r}")
    for t in out["text"]:
        print("text:", t)
    for o in out["only"]:
        print("only:", o)
    return 1 if verdicts or beyond else 0


if __name__ == "__main__":
    sys.exit(main())
