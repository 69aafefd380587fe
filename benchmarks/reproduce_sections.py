"""Seconds per section of ``wncs-lp reproduce``, cold (fresh cache folder), one section group at a time.

    python benchmarks/reproduce_sections.py --sections C6 --profile default
    python benchmarks/reproduce_sections.py --sections C3,C6,B1 --src /tmp/old_tree --csv /tmp/old.csv
    python benchmarks/reproduce_sections.py --groups "C3,C6;B1" --repeat-load

Each group of sections (``;`` between groups, ``,`` within one) runs as one partial reproduction
(:func:`wncs_lp.reproduce.run_reproduction` with ``claims=``) into a fresh output folder, so nothing
is reused from an earlier run; sections inside one group share the run's in-memory instances as
they do in the full job. ``--src DIR`` imports the package from another source tree (e.g. a
``git archive`` of an older commit) to time it before and after in the same sitting; numba's
compiled kernels are cached per tree, so run each tree once on the quick profile first (or pass
``--warm``) when comparing compiled code cold against warm would mislead.

Prints one line per section (seconds, verdict) with the load average before and after, and
writes them to ``--csv`` when given. The machine is usually shared: compare ratios between trees
timed in the same sitting, not seconds between sittings.
"""
from __future__ import annotations

import argparse
import csv
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sections", default=None, help="comma-separated sections, one group (default: every one)")
    ap.add_argument("--groups", default=None, help="groups of sections: 'C3,C6;B1;B2' (each its own cold run)")
    ap.add_argument("--profile", default="default")
    ap.add_argument("--src", default=None, help="import wncs_lp from this source tree")
    ap.add_argument("--warm", action="store_true", help="run the quick profile of each group first (numba caches)")
    ap.add_argument("--keep", default=None, help="write the output folders under this folder (default: a temp dir)")
    ap.add_argument("--csv", default=None)
    args = ap.parse_args(argv)
    if args.src:
        sys.path.insert(0, str(Path(args.src).resolve()))
    import wncs_lp
    from wncs_lp.reproduce import CLAIMS, run_reproduction
    from wncs_lp.reproduce.beyond import BEYOND

    if args.groups:
        groups = [g.split(",") for g in args.groups.split(";") if g]
    elif args.sections:
        groups = [args.sections.split(",")]
    else:
        groups = [list(CLAIMS) + list(BEYOND)]
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="reproduce_sections_"))
    root.mkdir(parents=True, exist_ok=True)
    print(f"wncs_lp from {Path(wncs_lp.__file__).parent}; profile {args.profile}; output under {root}", flush=True)
    rows = []
    for i, group in enumerate(groups):
        if args.warm:
            warm = root / f"warm{i}"
            run_reproduction(warm, "quick", claims=group, progress=False)
            shutil.rmtree(warm, ignore_errors=True)
        out = root / f"group{i}"
        shutil.rmtree(out, ignore_errors=True)
        load0 = _load()
        t0 = time.perf_counter()
        res = run_reproduction(out, args.profile, claims=group, progress=False)
        total = time.perf_counter() - t0
        load1 = _load()
        for c in res["claims"] + res["beyond"]:
            if c["id"] not in group:
                continue
            row = {"tree": str(Path(wncs_lp.__file__).parent.parent), "profile": args.profile, "group": ",".join(group),
                   "section": c["id"], "seconds": round(float(c.get("seconds", 0.0)), 2),
                   "verdict": c.get("verdict", "-"), "load_before": load0, "load_after": load1}
            rows.append(row)
            print(f"{row['section']:>4} {row['seconds']:9.1f} s  {row['verdict']:8s} load {load0} -> {load1}",
                  flush=True)
        print(f"group {','.join(group)}: {total:.1f} s", flush=True)
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
