"""Issue 33 (policy side) and 36 (the index policy): the policies of the bounds against the exact
optimum where it is known, and by certified gap beyond.

    python benchmarks/policies.py --out benchmarks/policies.csv               # processes 1-4 at caps 10, 20
    python benchmarks/policies.py --instances bounds_mix5:12,bounds_mix6:10 --relaxations 1,2 --out /tmp/p.csv
    python benchmarks/policies.py --instances bounds_p1234_twice:20 --relaxations 3 --out /tmp/p8.csv
    python benchmarks/policies.py --speed --instances bounds_p1234_twice:20    # per-decision cost only

For every instance and every relaxation asked for (1 = private servers, 2 = joint configuration
by the interior point, 3 = pairs sharing their private servers; computed by
``wncs_lp.bounds.lower_bound``), the policies

* ``greedy``: the greedy policy on the relaxation's tables (``bound_policy``),
* ``lookahead``: the two-step lookahead on the same tables (``LookaheadPolicy``),

and once per instance the index policy of relaxation 1's chains (``IndexPolicy``), each evaluated
exactly (certified matrix-free evaluation, upper end of its bracket; the policy's ``act`` runs once
per state of the AoI box) when the box has at most ``--exact-max-states`` states, else by Monte
Carlo (``--reps`` x ``--slots``, seed 0, the one-sided 95% upper confidence limit). Rows: the bound
(with its time), each policy's gain, its certified gap against the largest bound computed, and
(g_pi - g*) / g* where g* is known (``KNOWN``: certified matrix-free optima). ``--speed`` times
``act`` on 20,000 random states per policy (the ratio to the greedy policy's in the same run).

One CSV row per quantity and a table on stdout. The machine is shared: every row records the
1-minute load average when it started (2 cores; above ~1 another job competed).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

import wncs_lp  # noqa: E402
from wncs_lp.bounds import IndexPolicy, LookaheadPolicy, bound_policy, lower_bound, policy_gaps, whittle_indices  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402

COLUMNS = ["instance", "cap", "processes", "row", "how", "value", "value_upper", "gap_certified", "gap_optimum",
           "seconds", "load1", "note"]
#: Certified optima (matrix-free value iteration, bracket width <= 1e-9 relative): processes 1-4
#: at caps 20 and 30 (issue 17), cap 10 (`wncs-lp solve paper_p1234 --set tau_cap=10`, LP), the
#: 5-process shape at cap 12 (58 min, 0.66 GB) and the 6-process mix at cap 10 (156M states).
KNOWN = {("paper_p1234", 10): 859.3163879, ("paper_p1234", 20): 1572.4473862, ("paper_p1234", 30): 1628.3374066,
         ("bounds_mix5", 12): 1190.8146406, ("bounds_mix6", 10): 1171.1406021}
DEFAULT = [("paper_p1234", 10), ("paper_p1234", 20)]
RELAXATION_OPTIONS = {2: {"method": "ipm", "time_limit": 7200.0}}


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def _instances(text: str | None) -> list[tuple[str, int]]:
    if not text:
        return DEFAULT
    out = []
    for item in text.split(","):
        name, _, cap = item.partition(":")
        out.append((name.strip(), int(cap)))
    return out


def _speed(system: System, policies: dict, n: int = 20_000) -> dict:
    rng = np.random.default_rng(0)
    tau = np.stack([rng.integers(1, int(c) + 1, n) for c in system.caps], axis=1)
    cfg = rng.integers(0, system.n_configs, n)
    out = {}
    for name, pol in policies.items():
        pol.act(tau[:50], cfg[:50])  # compile
        t0 = time.perf_counter()
        pol.act(tau, cfg)
        out[name] = (time.perf_counter() - t0) / n
    return out


def run(args: argparse.Namespace) -> list[dict]:
    rows: list[dict] = []

    def add(inst, cap, n, row, how, value, upper=float("nan"), gap=float("nan"), opt=float("nan"), sec=0.0,
            note="", load=None):
        rows.append({"instance": inst, "cap": cap, "processes": n, "row": row, "how": how, "value": value,
                     "value_upper": upper, "gap_certified": gap, "gap_optimum": opt, "seconds": round(sec, 2),
                     "load1": load1() if load is None else load, "note": note})
        print(f"{inst}:{cap} {row:<46} {how:<11} {value:>14.7f} {upper:>14.7f} gap<={100 * gap:7.3f}% "
              f"opt{100 * opt:+8.3f}% {sec:8.1f}s load {rows[-1]['load1']}", flush=True)

    for name, cap in _instances(args.instances):
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])
        system = System.from_scenario(sc)
        g_star = KNOWN.get((name, cap), float("nan"))
        bounds = {}
        for r in args.relaxations:
            ld = load1()
            t0 = time.perf_counter()
            res = lower_bound(system, r, **RELAXATION_OPTIONS.get(r, {}))
            bounds[r] = res
            add(name, cap, system.n_processes, f"bound {res.relaxation}", "certified", res.lower_bound,
                sec=time.perf_counter() - t0, opt=(res.lower_bound - g_star) / g_star, note=res.status, load=ld)
        best = max(bounds.values(), key=lambda b: b.lower_bound)
        policies = {}
        for r, res in bounds.items():
            policies[f"greedy[{r}]"] = lambda res=res: bound_policy(res, system)
            policies[f"lookahead[{r}]"] = lambda res=res: LookaheadPolicy(bound_policy(res, system))
        if args.index:
            first = bounds.get(1) or lower_bound(system, 1)
            policies["index"] = lambda: IndexPolicy(system, whittle_indices(system, first))
        if args.speed:
            built = {k: f() for k, f in policies.items()}
            per = _speed(system, built)
            ref = next((v for k, v in per.items() if k.startswith("greedy")), None)
            for k, v in per.items():
                add(name, cap, system.n_processes, f"act {k}", "seconds/state", v, sec=v * 20_000,
                    note="" if ref is None else f"x{v / ref:.1f} the greedy policy's")
            continue
        for label, make in policies.items():
            ld = load1()
            t0 = time.perf_counter()
            pol = make()
            built = time.perf_counter() - t0
            rep = policy_gaps(best, system, [pol], exact_max_states=args.exact_max_states, slots=args.slots,
                              reps=args.reps, seed=0)
            r = rep.rows[0]
            add(name, cap, system.n_processes, f"{label} {r.policy}", r.how, r.gain, r.gain_upper, r.gap,
                (r.gain - g_star) / g_star, built + r.seconds, note=f"built in {built:.1f} s", load=ld)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--instances", default=None, help="name:cap,... (default paper_p1234:10,paper_p1234:20)")
    p.add_argument("--relaxations", default="1", help="relaxations whose tables the policies use (default 1)")
    p.add_argument("--no-index", dest="index", action="store_false", help="leave the index policy out")
    p.add_argument("--exact-max-states", type=int, default=200_000_000)
    p.add_argument("--slots", type=int, default=40_000)
    p.add_argument("--reps", type=int, default=20)
    p.add_argument("--speed", action="store_true", help="time act() per state instead of evaluating")
    p.add_argument("--out", default=None, help="CSV file to write")
    args = p.parse_args(argv)
    args.relaxations = [int(x) for x in args.relaxations.split(",")]
    warnings.simplefilter("ignore", wncs_lp.errors.ScenarioWarning)
    rows = run(args)
    if args.out:
        atomic_write_csv(args.out, rows, COLUMNS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
