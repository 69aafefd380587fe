"""Issue 24: certified lower bounds and the policies they give, against the optimum where it is known.

    python benchmarks/bounds.py --out benchmarks/bounds.csv                  # ~30 min on 2 cores
    python benchmarks/bounds.py --quick --out /tmp/bounds.csv                # ~2 min (short Monte Carlo)
    python benchmarks/bounds.py --instances paper_p1234:20 --out /tmp/b.csv
    python benchmarks/bounds.py --instances bounds_p1234_twice:20 --bounds-only --joint-time-limit 540

For every instance (default: processes 1-4 at caps 12, 20, 30; the 6-process mix and the paper's
four types twice, 8 processes, at cap 20):

* the bound of relaxation 1 (private servers), when ``wncs_lp.bounds.joint`` is installed of
  relaxation 2 (joint configuration), and from three processes on of relaxation 3 (pairs sharing
  their private servers), with their times;
* the optimum g* where known: processes 1-4 at caps 20 and 30 from the matrix-free solve of issue
  17 (1572.4473862 and 1628.3374066), at smaller caps solved here (certified matrix-free value
  iteration);
* the gains of the policies -- each relaxation's greedy policy, the paper's suboptimal policy, the
  static policy -- exactly (certified matrix-free evaluation, upper end of its bracket) when the
  AoI box has at most ``--exact-max-states`` states, else by Monte Carlo (``--reps`` x
  ``--slots``, seeded; the one-sided 95% upper confidence limit is what the gap uses);
* the certified gaps (upper - LB) / LB against each bound, and (g_pi - g*) / g* where g* is known.

One CSV row per quantity and a table on stdout. The machine is shared: every row records the
1-minute load average when it started (2 cores; above ~1 another job competed).
"""
from __future__ import annotations

import argparse
import csv
import io
import os
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import wncs_lp  # noqa: E402
from wncs_lp.bounds import bound_policy, lower_bound, policy_gaps  # noqa: E402
from wncs_lp.files import atomic_write_text  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "processes", "servers", "row", "how", "value", "value_upper", "gap_lb1", "gap_lb2",
           "gap_lb3", "gap_optimum", "seconds", "load1", "note"]
#: g* of processes 1-4 from the matrix-free solves of issue 17 (certified to 1e-9).
KNOWN = {("paper_p1234", 20): 1572.4473862, ("paper_p1234", 30): 1628.3374066,
         # solved by this benchmark on 2026-12-01 (certified matrix-free value iteration, bracket 1e-9)
         ("paper_p1234", 12): 1169.1063487}
DEFAULT = [("paper_p1234", 12), ("paper_p1234", 20), ("paper_p1234", 30), ("bounds_mix6", 20),
           ("bounds_p1234_twice", 20)]
QUICK = [("paper_p1234", 8), ("paper_p1234", 10), ("bounds_mix6", 8)]


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def _joint_available() -> bool:
    try:
        import wncs_lp.bounds.joint  # noqa: F401
    except ModuleNotFoundError:
        return False
    return True


def _rel(value, ref):
    return "" if value in ("", None) or ref in ("", None) else (value - ref) / ref


def _bounds(system, relaxations, time_limit=None, max_iter=None, method=None):
    out = {}
    for rel in relaxations:
        t0, l0 = time.perf_counter(), load1()
        opts = {}
        if rel == "joint-configuration":
            given = {"time_limit": time_limit, "max_iter": max_iter, "method": method}
            opts = {k: v for k, v in given.items() if v is not None}
        res = lower_bound(system, rel, **opts)
        out[rel] = (res, time.perf_counter() - t0, l0)
    return out


def _bound_note(res):
    st = res.stats
    if res.relaxation == "grouped-private-servers":
        return f"{res.iterations} iterations; groups {[tuple(k + 1 for k in g) for g in st['groups']]}"
    if res.relaxation != "joint-configuration":
        return f"{res.iterations} iterations"
    parts = [f"method {st.get('auto_method', st.get('method'))}"]
    if "ipm_iterations" in st:
        parts.append(f"IPX {st['ipm_iterations']} its {st['ipm_seconds']:.0f} s ({st['ipm_status']}, its objective "
                     f"{st.get('ipm_objective', float('nan')):.10g}), LP nnz {st.get('lp_nnz', 0):,}")
    parts.append(f"{st.get('bundle_steps', 0)} bundle steps; best from {st.get('found_in')}")
    return "; ".join(parts)


def _optimum(name, cap, system):
    """g* where known or solvable (the paper's instances), else None."""
    if (name, cap) in KNOWN:
        return KNOWN[(name, cap)], 0.0, "matrix-free value iteration, certified 1e-9 (issue 17; cap 12 an earlier run here)"
    if not name.startswith("paper_"):
        return None, 0.0, ""
    t0 = time.perf_counter()
    sol = matrix_free_value_iteration(system, tol=1e-9)
    return sol.gain, time.perf_counter() - t0, f"solved here: [{sol.gain_lower:.10g}, {sol.gain_upper:.10g}]"


def run_instance(name, cap, args, joint):
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])
    system = System.from_scenario(sc)
    base = {"instance": name, "cap": cap, "processes": sc.n_processes, "servers": sc.n_servers}
    grouped = sc.n_processes >= 3 and not args.no_grouped
    rels = ["private-servers"] + (["joint-configuration"] if joint else []) + (["grouped-private-servers"] if grouped else [])
    bounds = _bounds(system, rels, args.joint_time_limit, args.joint_max_iter, args.joint_method)
    lb1 = bounds["private-servers"][0].lower_bound
    lb2 = bounds["joint-configuration"][0].lower_bound if joint else ""
    lb3 = bounds["grouped-private-servers"][0].lower_bound if grouped else ""
    g_star, t_opt, how_opt = _optimum(name, cap, system)
    rows = []
    for rel, (res, secs, l0) in bounds.items():
        rows.append({**base, "row": f"LB {rel}", "how": res.status, "value": res.lower_bound, "gap_optimum":
                     _rel(res.lower_bound, g_star), "seconds": round(secs, 2), "load1": l0,
                     "note": _bound_note(res)})
    if g_star is not None:
        rows.append({**base, "row": "optimum g*", "value": g_star, "seconds": round(t_opt, 2), "load1": load1(),
                     "note": how_opt})
    if args.bounds_only:
        return rows
    policies = [bound_policy(res, system) for res, _, _ in bounds.values()] + ["suboptimal", "static"]
    l0 = load1()
    report = policy_gaps(bounds["private-servers"][0], system, policies, exact_max_states=args.exact_max_states,
                         slots=args.slots, reps=args.reps, seed=args.seed)
    for r in report.rows:
        rows.append({**base, "row": r.policy, "how": r.how, "value": r.gain, "value_upper": r.gain_upper,
                     "gap_lb1": _rel(r.gain_upper, lb1), "gap_lb2": _rel(r.gain_upper, lb2),
                     "gap_lb3": _rel(r.gain_upper, lb3),
                     "gap_optimum": _rel(r.gain, g_star), "seconds": round(r.seconds, 2), "load1": l0,
                     "note": f"{report.states:,} states"})
    return rows


def table(rows) -> str:
    def fmt(v, pct=False):
        if v in ("", None):
            return ""
        return f"{100 * v:.2f}%" if pct else (f"{v:.8g}" if isinstance(v, float) else str(v))

    rows = [{c: r.get(c, "") for c in COLUMNS} for r in rows]
    out = [f"{'instance':<20} {'cap':>3} {'row':<36} {'how':<11} {'value':>14} {'upper':>14} {'gap LB1':>8} "
           f"{'gap LB2':>8} {'gap LB3':>8} {'vs g*':>8} {'s':>8} {'load':>5}"]
    for r in rows:
        out.append(f"{r['instance']:<20} {r['cap']:>3} {r['row']:<36} {str(r['how']):<11} {fmt(r['value']):>14} "
                   f"{fmt(r['value_upper']):>14} {fmt(r['gap_lb1'], True):>8} {fmt(r['gap_lb2'], True):>8} "
                   f"{fmt(r['gap_lb3'], True):>8} "
                   f"{fmt(r['gap_optimum'], True):>8} {fmt(r['seconds']):>8} {fmt(r['load1']):>5}")
    return "\n".join(out)


def write_csv(path, rows) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLUMNS)
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in COLUMNS})
    atomic_write_text(path, buf.getvalue())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="CSV file (written after every instance)")
    ap.add_argument("--quick", action="store_true", help="small instances only (~2 min)")
    ap.add_argument("--instances", default=None, help="NAME:CAP,... (e.g. paper_p1234:20,bounds_mix6:20)")
    ap.add_argument("--exact-max-states", type=int, default=50_000_000,
                    help="exact policy evaluation up to this many AoI states (default 5e7: processes 1-4 cap 20)")
    ap.add_argument("--slots", type=int, default=40_000)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bounds-only", action="store_true", help="the bounds (and g* where known) only, no policies")
    ap.add_argument("--no-grouped", action="store_true", help="leave relaxation 3 (pairs sharing private servers) out")
    ap.add_argument("--joint-time-limit", type=float, default=None,
                    help="seconds for relaxation 2's search (its bound is certified whenever it stops)")
    ap.add_argument("--joint-max-iter", type=int, default=None, help="relaxation 2's bundle steps (after the IPM)")
    ap.add_argument("--joint-method", default=None, help="relaxation 2's method (auto, ipm, bundle, ...)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.instances:
        todo = [(s.split(":")[0], int(s.split(":")[1])) for s in args.instances.split(",")]
    else:
        todo = QUICK if args.quick else DEFAULT
    if args.quick:  # exact up to processes 1-4 at cap 10, short Monte Carlo beyond
        args.exact_max_states, args.reps, args.slots = min(args.exact_max_states, 2_000_000), 5, 5_000
    joint = _joint_available()
    print(f"relaxation 2 {'installed' if joint else 'not installed (its columns stay empty)'}; "
          f"load {load1()} on {os.cpu_count()} cores", flush=True)
    rows = []
    for name, cap in todo:
        rows += run_instance(name, cap, args, joint)
        print(table([r for r in rows if (r["instance"], r["cap"]) == (name, cap)]), flush=True)
        if args.out:
            write_csv(args.out, rows)
    print("\n" + table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
