"""Issue 35: what a researcher's own fields cost -- random arrivals against sampling at will, and
the checks where a System enters the bounds against relaxation 1 itself.

    python benchmarks/own_systems.py                       # ~3 min on a quiet machine
    python benchmarks/own_systems.py --csv benchmarks/own_systems.csv

* ``arrivals``: the paper's processes 1 and 4 on remote + edge (``formulations/own_arrivals.toml``)
  at cap ``--cap``, process 1's arrival probability lambda in ``--lambdas``: configurations,
  states, pairs, transition nonzeros, the seconds of the build and of the certified value
  iteration, and g*; ``ratio`` = the seconds (build + solve) over lambda = 1's, in the same run.
  Per-link probabilities and cost families change no size: the same MDP, other numbers.
* ``bound entry``: on ``--bound-scenarios`` (name:cap), relaxation 1 on a Scenario, and apart the
  two checks it now runs -- ``bound_system`` (a System's fields) and ``check_private_chains``
  (every private chain against the joint transitions); ``ratio`` = their seconds over relaxation
  1's, which includes them.

The machine is shared: the load average is printed and written with every row.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import wncs_lp  # noqa: E402
from wncs_lp import load_scenario, scenario_path  # noqa: E402
from wncs_lp.bounds.inputs import bound_system, check_private_chains  # noqa: E402
from wncs_lp.bounds.private import private_bound, private_chains  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402


def _load() -> str:
    return "%.1f" % os.getloadavg()[0]


def arrivals(cap: int, lambdas: list[float]) -> list[dict]:
    rows = []
    for lam in lambdas:
        sc = load_scenario(scenario_path("own_arrivals"), [f"tau_cap={cap}", f"process.1.arrival_probability={lam}"])
        t0 = time.perf_counter()
        mdp = wncs_lp.build(sc)
        t_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        sol = wncs_lp.solve(mdp, "vi")
        t_solve = time.perf_counter() - t0
        rows.append({"case": "arrivals", "instance": f"own_arrivals cap {cap} lambda {lam:g}",
                     "configs": mdp.meta["n_configs"], "states": mdp.n_states, "pairs": mdp.n_pairs,
                     "nnz": mdp.P.nnz, "seconds": round(t_build + t_solve, 3), "build_s": round(t_build, 3),
                     "solve_s": round(t_solve, 3), "gain": sol.gain, "status": sol.status, "load": _load()})
        print(rows[-1], flush=True)
    base = next(r["seconds"] for r in rows if r["instance"].endswith("lambda 1"))
    for r in rows:
        r["ratio"] = round(r["seconds"] / base, 2)
    return rows


def bound_entry(specs: list[str]) -> list[dict]:
    rows = []
    for spec in specs:
        name, cap = spec.split(":")
        sc = load_scenario(scenario_path(name), [f"tau_cap={cap}"])
        system = System.from_scenario(sc)
        t0 = time.perf_counter()
        res = private_bound(system)
        t_bound = time.perf_counter() - t0
        t0 = time.perf_counter()
        bound_system(system)
        t_sys = time.perf_counter() - t0
        chains, which = private_chains(system.model)
        cols = res.tables.column
        t0 = time.perf_counter()
        check_private_chains(system, [(k,) for k in range(len(which))], [chains[i] for i in which], cols, "relaxation 1")
        t_check = time.perf_counter() - t0
        rows.append({"case": "bound entry", "instance": f"{name} cap {cap}", "configs": system.n_configs,
                     "seconds": round(t_sys + t_check, 3), "check_system_s": round(t_sys, 3),
                     "check_chains_s": round(t_check, 3), "relaxation1_s": round(t_bound, 3),
                     "ratio": round((t_sys + t_check) / t_bound, 3), "gain": res.lower_bound, "load": _load()})
        print(rows[-1], flush=True)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cap", type=int, default=10)
    ap.add_argument("--lambdas", default="1,0.9,0.5,0.2")
    ap.add_argument("--bound-scenarios", default="paper_p1234:12,bounds_mix5:10")
    ap.add_argument("--csv", default=None)
    args = ap.parse_args()
    print(f"load average {_load()} (2 cores shared)")
    rows = arrivals(args.cap, [float(x) for x in args.lambdas.split(",")])
    rows += bound_entry(args.bound_scenarios.split(","))
    if args.csv:
        keys = sorted({k for r in rows for k in r})
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
