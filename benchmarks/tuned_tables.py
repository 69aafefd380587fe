"""Issue 33 (policy side): the bounds' tables tuned per class of processes (``wncs_lp.bounds.tuned``)
against the untuned policies on the same tables, against g* where it is known and by certified gap.

    python benchmarks/tuned_tables.py --out /tmp/tuned_small.csv     # processes 1-3 at caps 10, 12: exact
    python benchmarks/tuned_tables.py --instances bounds_mix6:10,bounds_mix5:14 --out /tmp/tuned_cal.csv
    (benchmarks/tuned_tables.csv: the first two, one after the other; docs/bounds.md "Tuned tables")
    python benchmarks/tuned_tables.py --instances bounds_p1234_x4:40,bounds_lab16:20 --out /tmp/tuned16.csv
    python benchmarks/tuned_tables.py --instances bounds_lab16:20 --relaxation auto --policies tuned_lookahead \
        --proxy none,greedy,2 --out /tmp/proxy16.csv      # tune cheap, use dear (``TUNE["proxy"]``)

For every instance: a bound (``--relaxation``, default 1: relaxation 1's tables in seconds at any
size, the tables tuning has the most to correct; ``auto``: ``lower_bound(system, "auto")``), then
``policy_gaps(bound, system, POLICIES, seed=0)``: the greedy policy, the two-step lookahead and
the rollout on the bound's tables, and the same three on the tables tuned for each
(``tuned``, ``tuned_lookahead``, ``tuned_rollout``: tuned on seed 2 by the package's defaults,
``TUNE``, evaluated on seed 0). Each policy is evaluated exactly (certified matrix-free evaluation)
where the AoI box has at most ``--exact-max-states`` states, else by Monte Carlo (``--reps`` x
``--slots``, the bound's tables as control variate, the one-sided 95% upper confidence limit).
Rows: the bound, then each policy's gain, upper value, certified gap, (g_pi - g*) / g* where g*
is known (``KNOWN``, or solved by the LP when the MDP has at most ``--lp-max-states`` states), the
CPU seconds of building (tuning included) and evaluating it, the tuned weights, the 1-minute load
when the row started and the peak memory of the process so far (2 shared cores).

``--proxy P1,P2,...``: each tuned policy once per proxy, the policy the tuning's search simulates
(``tune_tables(..., proxy=P)``: ``none`` the target itself, ``greedy``, a number of candidates, ``auto``
the package's default), the tuned policy then built as by name. With ``--relaxation auto`` the
policies take the tables the gap report would (``policy_source``), as ``wncs-lp bound --policy`` does.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import wncs_lp  # noqa: E402
from wncs_lp.bounds import lower_bound, policy_gaps  # noqa: E402
from wncs_lp.bounds.gaps import policy_by_name, policy_source  # noqa: E402
from wncs_lp.bounds.tuned import TUNE_SEED_OFFSET, TUNED_NAMES  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402

COLUMNS = ["instance", "cap", "processes", "tables", "row", "proxy", "how", "gain", "gain_upper", "gap_certified",
           "loss_optimum", "build_cpu", "eval_cpu", "weights", "load1", "peak_gib"]
#: Certified optima: the matrix-free solver's (bracket <= 1e-9 relative; docs/bounds.md, calibration).
KNOWN = {("bounds_mix6", 10): 1171.1406021, ("bounds_mix5", 14): 1365.5087359, ("bounds_mix5", 12): 1190.8146406,
         ("paper_p1234", 20): 1572.4473862}
DEFAULT = [("paper_p123", 10), ("paper_p123", 12)]
POLICIES = ("bound", "lookahead", "rollout", "tuned", "tuned_lookahead", "tuned_rollout")


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def peak_gib() -> float:
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3)


def _instances(text: str | None) -> list[tuple[str, int]]:
    if not text:
        return DEFAULT
    return [(name.strip(), int(cap)) for name, _, cap in (item.partition(":") for item in text.split(","))]


def _optimum(sc, name: str, cap: int, lp_max_states: int) -> float | None:
    if (name, cap) in KNOWN:
        return KNOWN[(name, cap)]
    from wncs_lp.models.guard import estimate_size

    if estimate_size(sc).states > lp_max_states:
        return None
    return float(wncs_lp.solve(sc).gain)


def _proxy(text: str) -> str | int | None:
    return None if text == "none" else int(text) if text.isdigit() else text


def run(args: argparse.Namespace) -> list[dict]:
    rows = []
    for name, cap in _instances(args.instances):
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])
        system = System.from_scenario(sc, explore="auto")
        g_star = _optimum(sc, name, cap, args.lp_max_states)
        base = {"instance": name, "cap": cap, "processes": system.n_processes}
        c0, load = time.process_time(), load1()
        bound = lower_bound(system, "auto" if args.relaxation == "auto" else int(args.relaxation))
        rows.append({**base, "tables": bound.relaxation, "row": "bound", "how": str(bound.status), "gain": bound.lower_bound,
                     "loss_optimum": "" if g_star is None else (bound.lower_bound - g_star) / g_star,
                     "build_cpu": round(time.process_time() - c0, 2), "load1": load, "peak_gib": peak_gib()})
        print(rows[-1], flush=True)
        source = policy_source(bound, system, seed=args.seed)[0] if args.relaxation == "auto" else bound
        runs = [(p, x) for p in args.policies.split(",") for x in
                ((args.proxy.split(",") if args.proxy else [None]) if p in TUNED_NAMES else [None])]
        for pname, proxy in runs:
            c0, load = time.process_time(), load1()
            tune = None if proxy is None else {"proxy": _proxy(proxy)}
            pol = policy_by_name(pname, source, system, tune_seed=args.seed + TUNE_SEED_OFFSET, tune=tune)
            c1 = time.process_time()
            rep = policy_gaps(bound, system, [pol], exact=None if args.exact_max_states else False,
                              exact_max_states=args.exact_max_states, slots=args.slots, reps=args.reps, seed=args.seed,
                              tables=source)
            r = rep.rows[0]
            tuning = getattr(pol, "tuning", None)
            rows.append({**base, "tables": source.relaxation, "row": r.policy, "how": r.how, "gain": r.gain,
                         "proxy": "" if tuning is None else tuning["proxy"],
                         "gain_upper": r.gain_upper, "gap_certified": r.gap,
                         "loss_optimum": "" if g_star is None else (r.gain - g_star) / g_star,
                         "build_cpu": round(c1 - c0, 2), "eval_cpu": round(time.process_time() - c1, 2),
                         "weights": "" if tuning is None else json.dumps([round(w, 4) for w in tuning["weights"]]),
                         "load1": load, "peak_gib": peak_gib()})
            print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", default=None, help="name:cap,... (default paper_p123:10,paper_p123:12)")
    ap.add_argument("--relaxation", default="1", help="1, 2, 3, 4 or auto (default 1)")
    ap.add_argument("--policies", default=",".join(POLICIES))
    ap.add_argument("--exact-max-states", type=int, default=5_000_000)
    ap.add_argument("--lp-max-states", type=int, default=300_000)
    ap.add_argument("--slots", type=int, default=40_000)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--proxy", default=None, help="the tuned policies once per proxy: none, greedy, auto, K, ... "
                                                  "(default: the package's TUNE['proxy'])")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore", wncs_lp.errors.ScenarioWarning)
    rows = run(args)
    if args.out:
        atomic_write_csv(args.out, rows, COLUMNS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
