"""Peak memory per transition of the stored-matrix value iteration, before and after issue 18.

Each measurement runs in its own process (peak RSS, ``ru_maxrss``, is per process and never goes
down): build the MDP of a scenario at a cap, build the compact sweep arrays
(:func:`wncs_lp.solvers.kernels.prepare`), then run :func:`~wncs_lp.solvers.value_iteration` for a
few sweeps (which also makes the Solution: bias, greedy policy). It reports peak RSS over the
number of transitions (P's nonzeros), for the build alone and for the whole run.

"before" is the code of another checkout, e.g. the commit before the change::

    git worktree add /tmp/dp_before f21b4b5
    python benchmarks/dp_memory.py --before /tmp/dp_before --caps 16 18

(one measurement at a time; the "before" run at cap 18 needs ~14 GiB free). Rows go to
``benchmarks/dp_memory.csv``; the last lines say the largest cap of the scenario whose estimated
transitions (:func:`wncs_lp.models.guard.estimate_size`, an upper bound) times the measured peak
bytes per transition fit a memory size (24 GiB by default).
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CSV = HERE / "dp_memory.csv"
COLUMNS = ["code", "scenario", "cap", "states", "pairs", "nnz", "build_s", "prepare_s", "vi_s",
           "rss_after_build_gib", "peak_build_gib", "peak_gib", "build_peak_bytes_per_nnz", "rss_after_build_bytes_per_nnz",
           "peak_bytes_per_nnz"]


def child(root: str, scenario: str, cap: int, sweeps: int) -> dict:
    """One measurement, in this (fresh) process, with the wncs_lp of ``root``."""
    import resource
    import time

    sys.path.insert(0, root)
    import wncs_lp
    from wncs_lp.models import build
    from wncs_lp.solvers import value_iteration
    from wncs_lp.solvers.kernels import prepare

    def peak() -> int:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # KiB on Linux

    def rss() -> int:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) * 1024 for line in f if line.startswith("VmRSS:"))

    assert Path(wncs_lp.__file__).resolve().is_relative_to(Path(root).resolve()), wncs_lp.__file__
    sc = wncs_lp.load_scenario(str(Path(root) / "formulations" / f"{scenario}.toml"), [f"tau_cap={cap}"])
    t = time.perf_counter()
    mdp = build(sc, force=True)  # past the size guard: measuring where memory goes is the point
    build_s = time.perf_counter() - t
    after_build, peak_build = rss(), peak()
    t = time.perf_counter()
    prepare(mdp)
    prepare_s = time.perf_counter() - t
    t = time.perf_counter()
    value_iteration(mdp, max_iter=sweeps)
    vi_s = time.perf_counter() - t
    return dict(states=mdp.n_states, pairs=mdp.n_pairs, nnz=int(mdp.P.nnz), build_s=build_s, prepare_s=prepare_s,
                vi_s=vi_s, rss_after_build=after_build, peak_build=peak_build, peak=peak())


def measure(root: str, scenario: str, cap: int, sweeps: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--child", root, scenario, str(cap), str(sweeps)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ""})
    if out.returncode != 0:
        raise RuntimeError(f"measurement {root} cap {cap} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def available() -> int:
    with open("/proc/meminfo") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith("MemAvailable:"))


def estimated_nnz(scenario: str, cap: int) -> int:
    """The size guard's upper bound on the transitions of ``scenario`` at ``cap`` (nothing is built)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import wncs_lp
    from wncs_lp.models.guard import estimate_size

    sc = wncs_lp.load_scenario(str(ROOT / "formulations" / f"{scenario}.toml"), [f"tau_cap={cap}"])
    return estimate_size(sc).nnz


def largest_cap(scenario: str, bytes_per_nnz: float, budget: float, start: int) -> tuple[int, int, float]:
    """The largest cap >= start whose estimated nnz x bytes_per_nnz fits ``budget`` bytes."""
    best = (start - 1, 0, 0.0)
    cap = start
    while True:
        nnz = estimated_nnz(scenario, cap)
        need = nnz * bytes_per_nnz
        if need > budget:
            return best
        best = (cap, nnz, need)
        cap += 1


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--child", nargs=4, metavar=("ROOT", "SCENARIO", "CAP", "SWEEPS"), help=argparse.SUPPRESS)
    ap.add_argument("--before", help="a checkout of the code before the change (e.g. git worktree of f21b4b5)")
    ap.add_argument("--scenario", default="paper_p1234")
    ap.add_argument("--caps", type=int, nargs="+", default=[16, 18])
    ap.add_argument("--sweeps", type=int, default=20, help="value-iteration sweeps after the build")
    ap.add_argument("--budget-gib", type=float, default=24.0)
    ap.add_argument("--append", action="store_true", help="append to the CSV instead of rewriting it")
    args = ap.parse_args()
    if args.child:
        root, scenario, cap, sweeps = args.child
        print(json.dumps(child(root, scenario, int(cap), int(sweeps))))
        return
    codes = ([("before", args.before)] if args.before else []) + [("after", str(ROOT))]
    for _, root in codes:  # numba's on-disk cache of each checkout, so no compilation is measured
        measure(root, args.scenario, 6, 2)
    rows = []
    for cap in args.caps:
        for code, root in codes:
            need = (70 if code == "before" else 45) * estimated_nnz(args.scenario, cap)  # B/nnz measured at cap 16
            if available() < need:
                print(f"skipped {code} cap {cap}: {available() / 2**30:.1f} GiB available, ~{need / 2**30:.1f} needed",
                      file=sys.stderr)
                continue
            r = measure(root, args.scenario, cap, args.sweeps)
            nnz = r["nnz"]
            row = dict(code=code, scenario=args.scenario, cap=cap, states=r["states"], pairs=r["pairs"], nnz=nnz,
                       build_s=round(r["build_s"], 1), prepare_s=round(r["prepare_s"], 1), vi_s=round(r["vi_s"], 1),
                       rss_after_build_gib=round(r["rss_after_build"] / 2**30, 2),
                       peak_build_gib=round(r["peak_build"] / 2**30, 2), peak_gib=round(r["peak"] / 2**30, 2),
                       build_peak_bytes_per_nnz=round(r["peak_build"] / nnz, 1),
                       rss_after_build_bytes_per_nnz=round(r["rss_after_build"] / nnz, 1),
                       peak_bytes_per_nnz=round(r["peak"] / nnz, 1))
            rows.append(row)
            print(f"{code:6s} cap {cap}: nnz {nnz:,}; peak {row['peak_gib']:.2f} GiB = {row['peak_bytes_per_nnz']} B/nnz "
                  f"(build alone {row['build_peak_bytes_per_nnz']}, after the build {row['rss_after_build_bytes_per_nnz']}); "
                  f"prepare {row['prepare_s']} s", flush=True)
    mode = "a" if args.append and CSV.exists() else "w"
    with open(CSV, mode, newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        if mode == "w":
            w.writeheader()
        w.writerows(rows)
    budget = args.budget_gib * 2**30
    for code in ("before", "after"):
        mine = [r for r in rows if r["code"] == code]
        if not mine:
            continue
        bpn = max(r["peak_bytes_per_nnz"] for r in mine)
        cap, nnz, need = largest_cap(args.scenario, bpn, budget, min(r["cap"] for r in mine))
        print(f"{code}: at {bpn} B/nnz (the largest measured), the largest cap of {args.scenario} fitting "
              f"{args.budget_gib:g} GiB is {cap} (estimated nnz {nnz:,}, ~{need / 2**30:.1f} GiB)")
    befores = {r["cap"]: r for r in rows if r["code"] == "before"}
    for r in rows:
        if r["code"] == "after" and r["cap"] in befores:
            b = befores[r["cap"]]
            print(f"cap {r['cap']}: peak {b['peak_bytes_per_nnz']} -> {r['peak_bytes_per_nnz']} B/nnz "
                  f"(x{b['peak_gib'] / r['peak_gib']:.2f} less), prepare {b['prepare_s']} -> {r['prepare_s']} s")


if __name__ == "__main__":
    main()
