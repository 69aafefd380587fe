"""Issue 33: relaxation 4 (pairs of processes' ages kept jointly) against relaxation 2 and g*.

    python benchmarks/bounds_pairs.py --instances three:5,paper_p1234:12,paper_p1234:20 --out /tmp/pairs.csv
    python benchmarks/bounds_pairs.py --instances bounds_p1234_twice:20 --r2 shipped --max-iter 0 --policy \
        --out /tmp/pairs8.csv

For every instance (each in this process, one after the other): relaxation 2 (``lower_bound(x, 2)``,
its interior point where predicted to fit; ``--r2 shipped``: the report's shipped tables of B3,
``b3_reference.json``, certified on the system and their priced chains solved, as
``joint_bound_from_tables`` does; ``--r2 loose``: its interior point at ``AUTO_PAIRS_IPM_TOL``, what
``auto`` runs before the pairs where the interior point is slow), then relaxation 4 from it (``pairs_bound(x, start=r2)``, what
``lower_bound(x, 4, start=r2)`` runs, defaults unless ``--max-iter``; 0: the start only), with
the CPU seconds of each (this process's, so the load of the shared machine does not enter) and
the peak memory so far; g* where known (``KNOWN``, and the
toolkit's exact solver for the small ``three`` instance); with ``--policy`` the gains of relaxation
4's greedy policy and its two-step lookahead (exact where the AoI box has at most
``--exact-max-states`` states, else Monte Carlo ``--reps`` x ``--slots``, seed 0, with the tables as
control variate) and their certified gaps against relaxation 4's bound. Every row records the
1-minute load average when the instance started.

``--whole`` also runs the same search without the symmetry reduction (``symmetric=False``: every
pair priced on its own, the whole group chains) in the same process after the symmetric one, and
records ``whole_bound``, ``whole_cpu`` and ``cpu_ratio`` = whole / symmetric CPU seconds (the same
number of bundle steps: give ``--max-iter``; the time limit is lifted for both):

    python benchmarks/bounds_pairs.py --instances bounds_p1234_twice:20 --r2 shipped --max-iter 5 --whole

``--no-own-swap`` likewise runs the same search with each same-type pair's own swap left out of the
lumping (``own_swap=False``) after the default one, and records ``plain_bound``, ``plain_cpu`` and
``swap_ratio`` = plain / default CPU seconds:

    python benchmarks/bounds_pairs.py --instances bounds_p1234_twice:20 --r2 loose --max-iter 6 --no-own-swap

``--no-time-limit`` lets only ``--max-iter`` stop the search, as ``auto`` runs it (8 steps):

    python benchmarks/bounds_pairs.py --instances bounds_p1234_twice:20 --r2 shipped --max-iter 8 \
        --no-time-limit --policy
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wncs_lp.bounds import lower_bound, policy_gaps  # noqa: E402
from wncs_lp.bounds.joint import joint_bound_from_tables  # noqa: E402
from wncs_lp.bounds.joint_chains import JointData  # noqa: E402
from wncs_lp.bounds.joint_symmetry import process_symmetry, spread_orbit_tables  # noqa: E402
from wncs_lp.bounds.lower import AUTO_PAIRS_IPM_TOL  # noqa: E402
from wncs_lp.bounds.pairs import pairs_bound  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.reproduce.beyondexact import reference  # noqa: E402
from wncs_lp.scenario import load_scenario, scenario_from_dict  # noqa: E402

#: Certified optima (matrix-free value iteration, bracket 1e-9; benchmarks/bounds.py's ``KNOWN``).
KNOWN = {("paper_p1234", 12): 1169.1063487, ("paper_p1234", 20): 1572.4473862, ("paper_p1234", 30): 1628.3374066}
COLUMNS = ["instance", "cap", "load", "g_star", "r2_bound", "r2_cpu", "r2_from", "groups", "r4_start", "r4_bound",
           "r4_cpu", "r4_status", "bundle_steps", "peak_mib", "r2_looseness", "r4_looseness", "policy", "gain",
           "gain_upper", "gap_r4", "how", "whole_bound", "whole_cpu", "cpu_ratio", "plain_bound", "plain_cpu",
           "swap_ratio"]


def three(cap: int):
    """Three processes on an edge and a remote server (tests/bounds/joint_reference.py's)."""
    return scenario_from_dict({
        "model": {"kind": "wncs", "tau_cap": cap}, "channel": {"success_probability": 0.9},
        "process": [{"A": [[1.1]]}, {"A": [[1.05]]}, {"A": [[1.2]], "weight": 2.0}],
        "server": [{"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [1, 2, 1]},
                   {"name": "remote", "uplink_delay": 1, "downlink_delay": 1, "processing_time": [1, 1, 2]}],
    }, source="<three processes>")


def shipped_r2(system, name: str, cap: int):
    """Relaxation 2 from the report's shipped tables (each class representative's on its orbits)."""
    entry = reference("tables", f"{name}.toml", cap)
    if entry is None:
        raise SystemExit(f"no shipped relaxation-2 tables for {name} at cap {cap}")
    with resources.files("wncs_lp.reproduce").joinpath("data", entry["file"]).open("rb") as fh:
        z = np.load(fh)
        classes = json.loads(str(z["classes"]))
        per_orbit = [np.asarray(z[f"h{i}"], dtype=float) for i in range(len(classes))]
    data = JointData.from_system(system)
    tables = spread_orbit_tables(process_symmetry(system, data), data, per_orbit)
    return joint_bound_from_tables(system, tables, source=f"the shipped tables {entry['file']}")


def run(name: str, cap: int, args) -> list[dict]:
    load = os.getloadavg()[0]
    if name == "three":
        from wncs_lp.models import build
        from wncs_lp.solvers import solve

        sc = three(cap)
        g_star = float(solve(build(sc)).gain_upper)
    else:
        sc = load_scenario(ROOT / "formulations" / f"{name}.toml", {"tau_cap": cap})
        g_star = KNOWN.get((name, cap))
    system = System.from_scenario(sc)
    t = time.process_time()
    if args.r2 == "shipped":
        r2 = shipped_r2(system, name, cap)
    elif args.r2 == "loose":  # what auto runs before the pairs where the interior point is slow
        r2 = lower_bound(system, 2, ipm_tol=AUTO_PAIRS_IPM_TOL)
    else:
        r2 = lower_bound(system, 2)
    r2_cpu = time.process_time() - t
    t = time.process_time()
    opts = {} if args.max_iter is None else {"max_iter": args.max_iter}
    if args.whole or args.no_own_swap or args.no_time_limit:
        opts["time_limit"] = None
    r4 = pairs_bound(system, start=r2, progress=args.progress, **opts)
    r4_cpu = time.process_time() - t
    whole = {}
    if args.whole:
        t = time.process_time()
        w = pairs_bound(system, start=r2, progress=args.progress, symmetric=False, **opts)
        w_cpu = time.process_time() - t
        whole = {"whole_bound": w.lower_bound, "whole_cpu": round(w_cpu, 2), "cpu_ratio": round(w_cpu / r4_cpu, 3)}
    if args.no_own_swap:
        t = time.process_time()
        w = pairs_bound(system, start=r2, progress=args.progress, own_swap=False, **opts)
        w_cpu = time.process_time() - t
        whole.update(plain_bound=w.lower_bound, plain_cpu=round(w_cpu, 2), swap_ratio=round(w_cpu / r4_cpu, 3))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    loose = (lambda b: None if g_star is None else (g_star - b) / g_star)
    base = {"instance": name, "cap": cap, "load": round(load, 2), "g_star": g_star, "r2_bound": r2.lower_bound,
            "r2_cpu": round(r2_cpu, 2), "r2_from": args.r2,
            "groups": ";".join(",".join(str(k + 1) for k in g) for g in r4.tables.groups),
            "r4_start": max(r4.stats["candidates"].values()), "r4_bound": r4.lower_bound, "r4_cpu": round(r4_cpu, 2),
            "r4_status": r4.status, "bundle_steps": r4.stats.get("bundle_steps"), "peak_mib": round(peak),
            "r2_looseness": loose(r2.lower_bound), "r4_looseness": loose(r4.lower_bound), **whole}
    rows = [base]
    if args.policy:
        rep = policy_gaps(r4, system, ["bound", "lookahead"], exact_max_states=args.exact_max_states,
                          slots=args.slots, reps=args.reps, seed=0)
        for r in rep.rows:
            rows.append({**base, "policy": r.policy, "gain": r.gain, "gain_upper": r.gain_upper, "gap_r4": r.gap,
                         "how": rep.how})
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--instances", default="three:5,paper_p1234:12,paper_p1234:20")
    p.add_argument("--r2", choices=("solve", "shipped", "loose"), default="solve",
                   help="relaxation 2: solved (its defaults), B3's shipped tables, or its interior point at "
                        "auto's looser tolerance before the pairs (AUTO_PAIRS_IPM_TOL)")
    p.add_argument("--max-iter", type=int, default=None)
    p.add_argument("--policy", action="store_true")
    p.add_argument("--exact-max-states", type=int, default=0)
    p.add_argument("--slots", type=int, default=40_000)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--progress", action="store_true")
    p.add_argument("--no-time-limit", action="store_true", help="only --max-iter stops the search (as under auto)")
    p.add_argument("--whole", action="store_true", help="also the search without the symmetry reduction, and the ratio")
    p.add_argument("--no-own-swap", action="store_true",
                   help="also the search without each same-type pair's own swap, and the ratio")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    warnings.simplefilter("ignore")
    rows = []
    for item in args.instances.split(","):
        name, cap = item.split(":")
        for r in run(name, int(cap), args):
            rows.append(r)
            print(json.dumps(r, default=str), flush=True)
            if args.out:
                atomic_write_csv(args.out, rows, COLUMNS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
