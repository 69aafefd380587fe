"""Issue 33: every relaxation's certified bound below the exact optimum on random small systems.

    python benchmarks/bounds_fuzz.py --seed 1 --cases 60 --out benchmarks/bounds_fuzz.csv

The tests check validity on fixed shapes (tests/bounds/test_bound_validity.py and the relaxations'
own tests); this draws many more shapes: two to four scalar processes (A in {1.02, ..., 1.5},
weights 0.5-2, caps 3-9, smaller with more processes), one to three servers with random delays
U, D in {0, 1}, processing times 1-2 per process, per-server link probabilities or the scenario's
one, idling allowed or not. For each system g* is the exact solver's certified gain on the
enumerated MDP (an independent solver of the whole system), and each of relaxations 1-5
(``lower_bound(system, r)``, its defaults) is run; a bound above g* (relative 1e-9) is a
**violation** and the script exits 1. A relaxation that refuses (relaxation 5's memory guard, a
model a relaxation does not take) is recorded with its error, not counted as a violation.

Per row: the case, its shape, the MDP's states, g*, and per relaxation the looseness
(g* - LB) / g* in percent, its status and CPU seconds.
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from wncs_lp import solve  # noqa: E402
from wncs_lp.bounds.lower import lower_bound  # noqa: E402
from wncs_lp.errors import WncsError  # noqa: E402
from wncs_lp.models import build  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.scenario import scenario_from_dict  # noqa: E402

RELAXATIONS = (1, 2, 3, 4, 5)


def random_scenario(rng: np.random.Generator) -> dict:
    """One random small system as a scenario dict (the module docstring's ranges)."""
    n = int(rng.integers(2, 5))
    procs = [{"A": [[float(rng.choice([1.02, 1.05, 1.1, 1.2, 1.3, 1.5]))]],
              "weight": float(rng.choice([1.0, 2.0, 0.5])),
              "tau_cap": int(rng.integers(3, 10 if n <= 2 else 8 if n == 3 else 6))} for _ in range(n)]
    servers = []
    for m in range(int(rng.integers(1, 4))):
        s = {"name": f"s{m}", "uplink_delay": int(rng.integers(0, 2)), "downlink_delay": int(rng.integers(0, 2)),
             "processing_time": [int(rng.integers(1, 3)) for _ in range(n)]}
        if rng.random() < 0.5:
            s["p_up"] = float(rng.choice([0.6, 0.8, 0.95, 1.0]))
            s["p_down"] = float(rng.choice([0.7, 0.9, 1.0]))
        servers.append(s)
    return {"model": {"kind": "wncs", "allow_idle": bool(rng.random() < 0.4)},
            "channel": {"success_probability": float(rng.choice([0.7, 0.8, 0.9]))},
            "process": procs, "server": servers}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=60)
    ap.add_argument("--max-states", type=int, default=300_000, help="skip systems whose MDP is larger")
    ap.add_argument("--out", default=None, help="CSV file of the rows")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    rng = np.random.default_rng(args.seed)
    rows, violations = [], 0
    for i in range(args.cases):
        d = random_scenario(rng)
        sc = scenario_from_dict(d, source=f"<case {i}>")
        mdp = build(sc)
        if mdp.n_states > args.max_states:
            print(f"{i}: skipped, {mdp.n_states:,} states", flush=True)
            continue
        g = solve(mdp).gain_upper
        system = System.from_scenario(sc)
        row = {"case": i, "processes": len(d["process"]), "servers": len(d["server"]),
               "idle": d["model"]["allow_idle"], "states": mdp.n_states, "g_star": g}
        bad = []
        for r in RELAXATIONS:
            t = time.process_time()
            try:
                res = lower_bound(system, r)
            except WncsError as e:
                row[f"r{r}_looseness_pct"], row[f"r{r}_status"] = "", f"{type(e).__name__}: {str(e)[:80]}"
            else:
                row[f"r{r}_looseness_pct"] = 100.0 * (g - res.lower_bound) / g
                row[f"r{r}_status"] = str(getattr(res.status, "value", res.status))
                if res.lower_bound > g * (1 + 1e-9) + 1e-12:
                    bad.append(r)
            row[f"r{r}_cpu_s"] = round(time.process_time() - t, 3)
        violations += bool(bad)
        row["violation"] = ",".join(map(str, bad))
        rows.append(row)
        shown = " ".join(f"{r}:{row[f'r{r}_looseness_pct']:.4f}%" if row[f"r{r}_looseness_pct"] != "" else f"{r}:refused"
                         for r in RELAXATIONS)
        print(f"{i}: {row['processes']} processes, {row['servers']} servers, idle {row['idle']}, "
              f"{mdp.n_states:,} states, g* {g:.8g}; {shown}{'  VIOLATION ' + row['violation'] if bad else ''}",
              flush=True)
    if args.out and rows:
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(args.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)
    print(f"{len(rows)} systems, {violations} with a bound above g*")
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
