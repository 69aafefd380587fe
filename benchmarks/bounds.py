"""Issues 24 and 33: certified lower bounds and the policies they give, against the optimum where it is known.

    python benchmarks/bounds.py --out benchmarks/bounds.csv                  # the calibration table + 8 processes
    python benchmarks/bounds.py --quick --out /tmp/bounds.csv                # ~2 min (short Monte Carlo)
    python benchmarks/bounds.py --instances paper_p1234:20 --out /tmp/b.csv
    python benchmarks/bounds.py --instances bounds_p1234_twice:20 --bounds-only
    python benchmarks/bounds.py --ipm-scan --out /tmp/ipm.csv                # relaxation 2's interior point: time model
    python benchmarks/bounds.py --write-b3-tables bounds_mix6:10             # the report's shipped tables (B3)
    python benchmarks/bounds.py --candidates bounds_lab16:2000               # the lookahead's candidate rule

For every instance (default: the calibration instances -- the 5-process shape and the 6-process
mix at cap 10, processes 1-4 at caps 12, 20, 30, whose g* is known -- and the paper's four types
twice, 8 processes, at cap 20), each in its own process (its peak memory is its own):

* the bound of every relaxation -- 1 (private servers), 2 (joint configuration: ``auto``'s search,
  the interior point where it is predicted to fit, on the LP reduced by interchangeable
  processes), 3 (pairs sharing their private servers, from three processes on) -- with its time,
  and ``auto``'s choice among them;
* the optimum g* where known (``KNOWN``: processes 1-4 from the matrix-free solves of issue 17, the
  calibration optima from the report's shipped reference data, B3's ``b3_reference.json``), the
  bound's looseness (g* - LB) / g* and each policy's loss (g_pi - g*) / g*;
* the gains of the policies -- each relaxation's greedy policy, the paper's suboptimal policy, the
  static policy -- exactly (certified matrix-free evaluation, upper end of its bracket) when the
  AoI box has at most ``--exact-max-states`` states, else by Monte Carlo (``--reps`` x
  ``--slots``, seeded; the one-sided 95% upper confidence limit is what the gap uses);
* the certified gaps (upper - LB) / LB against auto's bound.

``--ipm-scan`` solves relaxation 2's LP by the interior point alone on a list of instances (each in
its own process: CPU and wall seconds, iterations, peak memory, LP size; the value its duals' tables
certify, and in the note the value the lumped chains at its coupling duals certify)
and fits the time model
of ``wncs_lp.bounds.joint_ipm.IPM_TIME_MODEL`` (CPU time, so the load of the machine does not enter).

``--candidates NAME:STATES`` measures the rule of ``wncs_lp.bounds.lookahead.auto_candidates``: on
STATES states of one simulated path of relaxation 1's greedy policy (seed 1, after 500 slots), the
two-step lookahead on its tables with every action and with the k best greedy candidates
(k = 32, 16, 8, 4, 2): the CPU seconds of each and the share of states where it takes the full
lookahead's action.

One CSV row per quantity and a table on stdout. The machine is shared: every row records the
1-minute load average when it started (2 cores; above ~1 another job competed).
"""
from __future__ import annotations

import argparse
import io
import json
import os
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import wncs_lp  # noqa: E402
from wncs_lp.bounds import bound_policy, lower_bound, policy_gaps  # noqa: E402
from wncs_lp.bounds.lower import AUTO_SEARCH, auto_pick, runs_grouped  # noqa: E402
from wncs_lp.files import atomic_write_csv, atomic_write_text  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.reproduce.beyondexact import reference  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "processes", "servers", "row", "how", "value", "value_upper", "gap_auto",
           "gap_optimum", "seconds", "cpu_seconds", "peak_gib", "load1", "note"]
#: g* of processes 1-4 from the matrix-free solves of issue 17 (certified to 1e-9); the calibration
#: optima past four processes are the report's shipped reference data (B3, :func:`reference`).
KNOWN = {("paper_p1234", 20): 1572.4473862, ("paper_p1234", 30): 1628.3374066,
         # solved by this benchmark on 2026-12-01 (certified matrix-free value iteration, bracket 1e-9)
         ("paper_p1234", 12): 1169.1063487}
DEFAULT = [("bounds_mix5", 10), ("bounds_mix6", 10), ("paper_p1234", 12), ("paper_p1234", 20), ("paper_p1234", 30),
           ("bounds_p1234_twice", 20)]
QUICK = [("paper_p1234", 8), ("paper_p1234", 10), ("bounds_mix6", 8)]
#: ``--ipm-scan``'s default instances: LPs of 0.24M-1.9M nonzeros (the symmetry-reduced count)
SCAN = [("paper_p1234", 8), ("bounds_p1234_twice", 3), ("paper_p1234", 12), ("bounds_mix5", 4), ("bounds_mix6", 4),
        ("bounds_p1234_twice", 4), ("bounds_mix5", 6), ("paper_p1234", 20), ("bounds_mix6", 6),
        ("bounds_p1234_twice", 6), ("bounds_mix5", 10), ("bounds_p1234_twice", 8), ("bounds_mix6", 8),
        ("paper_p1234", 30), ("bounds_mix6", 10), ("bounds_mix5", 12), ("bounds_p1234_twice", 20)]


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def peak_gib() -> float:
    """This process's peak resident memory (Linux: ru_maxrss in KiB)."""
    return round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3)


def _rel(value, ref):
    return "" if value in ("", None) or ref in ("", None) else (value - ref) / ref


def _system(name, cap):
    """The scenario's System at cap ``cap`` (None: the scenario's own)."""
    edits = [] if cap is None else [f"tau_cap={cap}"]
    return System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name), edits))


def _timed(fn, *args, **kw):
    t0, c0, l0 = time.perf_counter(), time.process_time(), load1()
    res = fn(*args, **kw)
    return res, time.perf_counter() - t0, time.process_time() - c0, l0


def _bounds(system, args):
    """Every relaxation (1, 2 with auto's search, 3 from three processes on) and auto's choice."""
    from wncs_lp.bounds.joint import joint_bound

    out = {"private-servers": _timed(lower_bound, system, 1)}
    search = {**AUTO_SEARCH, **{k: v for k, v in {"time_limit": args.joint_time_limit, "max_iter": args.joint_max_iter,
                                                   "method": args.joint_method}.items() if v is not None}}
    out["joint-configuration"] = _timed(joint_bound, system, **search)
    if system.n_processes >= 3 and not args.no_grouped:
        out["grouped-private-servers"] = _timed(lower_bound, system, 3, relaxation_1=out["private-servers"][0])
    found = [out["joint-configuration"][0]]
    if "grouped-private-servers" in out and runs_grouped(system, found[0]):
        found.append(out["grouped-private-servers"][0])
    best = auto_pick(found + [out["private-servers"][0]])
    return out, best


def _bound_note(res, auto):
    st = res.stats
    mark = "auto's choice; " if res.relaxation == auto.relaxation else ""
    if res.relaxation == "grouped-private-servers":
        return f"{mark}{res.iterations} iterations; groups {[tuple(k + 1 for k in g) for g in st['groups']]}"
    if res.relaxation != "joint-configuration":
        return f"{mark}{res.iterations} iterations"
    parts = [f"{mark}method {st.get('auto_method', st.get('method'))}"]
    plan = st.get("ipm_plan")
    if plan:
        parts.append(f"predicted {plan['predicted_seconds']:.0f} s CPU, {plan['lp_nnz']:,} nnz"
                     + (f", classes {plan['classes']}" if plan["classes"] else ""))
    if "ipm_iterations" in st:
        parts.append(f"IPX {st['ipm_iterations']} its {st['ipm_cpu_seconds']:.0f} s CPU ({st['ipm_status']}, its objective "
                     f"{st.get('ipm_objective', float('nan')):.10g})")
    parts.append(f"{st.get('bundle_steps', 0)} bundle steps; best from {st.get('found_in')}")
    return "; ".join(parts)


def _optimum(name, cap, system):
    """g* where known or solvable (the paper's instances), else None."""
    if (name, cap) in KNOWN:
        return KNOWN[(name, cap)], 0.0, "matrix-free value iteration, certified 1e-9 (issue 17; cap 12 an earlier run here)"
    ref = reference("optima", f"{name}.toml", cap)
    if ref is not None:
        return ref["gain"], 0.0, f"shipped reference [{ref['gain_lower']:.10g}, {ref['gain_upper']:.10g}]: {ref['command']}"
    if not name.startswith("paper_"):
        return None, 0.0, ""
    t0 = time.perf_counter()
    sol = matrix_free_value_iteration(system, tol=1e-9)
    return sol.gain, time.perf_counter() - t0, f"solved here: [{sol.gain_lower:.10g}, {sol.gain_upper:.10g}]"


def run_instance(name, cap, args):
    system = _system(name, cap)
    sc = system.scenario
    base = {"instance": name, "cap": cap, "processes": sc.n_processes, "servers": sc.n_servers}
    bounds, best = _bounds(system, args)
    g_star, t_opt, how_opt = _optimum(name, cap, system)
    rows = []
    for rel, (res, secs, cpu, l0) in bounds.items():
        rows.append({**base, "row": f"LB {rel}", "how": res.status, "value": res.lower_bound,
                     "gap_optimum": _rel(res.lower_bound, g_star), "seconds": round(secs, 2),
                     "cpu_seconds": round(cpu, 2), "load1": l0, "note": _bound_note(res, best)})
    if g_star is not None:
        rows.append({**base, "row": "optimum g*", "value": g_star, "seconds": round(t_opt, 2), "load1": load1(),
                     "note": how_opt})
    if not args.bounds_only:
        policies = [bound_policy(res, system) for res, _, _, _ in bounds.values()] + ["suboptimal", "static"]
        l0 = load1()
        report = policy_gaps(best, system, policies, exact_max_states=args.exact_max_states,
                             slots=args.slots, reps=args.reps, seed=args.seed)
        for r in report.rows:
            rows.append({**base, "row": r.policy, "how": r.how, "value": r.gain, "value_upper": r.gain_upper,
                         "gap_auto": r.gap, "gap_optimum": _rel(r.gain, g_star), "seconds": round(r.seconds, 2),
                         "load1": l0, "note": f"{report.states:,} states"})
    peak = peak_gib()
    return [{**r, "peak_gib": peak} for r in rows]


def _in_child(flag, item, args_list):
    """Run one instance in a child process (its peak memory its own); its rows from its last line."""
    cmd = [sys.executable, str(Path(__file__).resolve()), flag, item] + args_list
    out = subprocess.run(cmd, capture_output=True, text=True)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("ROWS ")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"{item}: child failed ({out.returncode}): {out.stderr[-2000:]}")
    return json.loads(lines[-1][5:])


# ------------------------------------------------------------------------------ the interior point alone
def ipm_one(name, cap, tol):
    """Relaxation 2's LP by IPX alone (symmetry-reduced): size, CPU and wall time, peak memory."""
    from wncs_lp.bounds.joint import ipm_plan
    from wncs_lp.bounds.joint_chains import JointData, Kernels, certify_tables
    from wncs_lp.bounds.joint_ipm import ipm_tables
    from wncs_lp.bounds.joint_symmetry import lumped_chains, process_symmetry, spread_orbit_tables

    system = _system(name, cap)
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    plan = ipm_plan(data, sym)
    l0 = load1()
    run = ipm_tables(data, symmetry=sym, tol=tol)
    cert = certify_tables(data, run.tables).lower_bound if run.tables is not None else float("nan")
    lumped, lumped_cpu = float("nan"), float("nan")
    if run.prices is not None:  # the lumped chains at the coupling duals, their tables certified
        c0 = time.process_time()
        _, sols = lumped_chains(sym, data).lagrangian(run.prices, Kernels("auto"), tol=1e-8)
        lumped = certify_tables(data, spread_orbit_tables(sym, data, [s.h for s in sols])).lower_bound
        lumped_cpu = round(time.process_time() - c0, 2)
    return [{"instance": name, "cap": cap, "processes": system.n_processes, "servers": system.n_servers,
             "row": "IPX", "how": run.status, "value": cert, "value_upper": run.objective,
             "seconds": round(run.seconds, 2), "cpu_seconds": round(run.cpu_seconds, 2), "peak_gib": peak_gib(),
             "load1": l0, "note": json.dumps({"iterations": run.iterations, "lp_nnz_count": plan["lp_nnz"],
                                              "lp_shape": run.shape, "predicted_seconds": round(plan["predicted_seconds"], 1),
                                              "classes": plan["classes"], "tol": tol,
                                              "lumped_chains_bound": lumped, "lumped_chains_cpu": lumped_cpu})}]


# ------------------------------------------------------------------------------ the lookahead's candidates
def candidates_one(name, states):
    """The lookahead restricted to k greedy candidates against the full one on simulated states."""
    from wncs_lp.bounds.lookahead import LookaheadPolicy
    from wncs_lp.simulate import simulate

    system = _system(name, None)
    base = bound_policy(lower_bound(system, "private-servers"), system)
    path = simulate(base, slots=states, reps=1, burn_in=500, path=states, seed=1).path
    tau, cfg = np.asarray(path.tau), np.asarray(path.config)
    l0 = load1()
    rows, full, full_cpu = [], None, None
    for k in (None, 32, 16, 8, 4, 2):
        pol = LookaheadPolicy(base, candidates=k, threads=1)
        pol.act(tau[:1], cfg[:1])  # the kernel compiled before the clock starts
        c0 = time.process_time()
        act = pol.act(tau, cfg)
        cpu = time.process_time() - c0
        full, full_cpu = (act, cpu) if k is None else (full, full_cpu)
        rows.append({"instance": name, "cap": int(max(system.caps)), "processes": system.n_processes,
                     "servers": system.n_servers, "row": f"lookahead candidates {k or 'all'}",
                     "how": f"{tau.shape[0]} states", "value": float(np.mean(act == full)),
                     "cpu_seconds": round(cpu, 3), "load1": l0, "peak_gib": peak_gib(),
                     "note": f"CPU {cpu / full_cpu:.3f} of the full lookahead's; value: share of states agreeing"})
    return rows


def fit_time_model(rows):
    """Least squares in logs: cpu = coef (nnz / 1e6)^a (cap / 10)^b (cap: the mean cap)."""
    X = np.array([[1.0, np.log(json.loads(r["note"])["lp_nnz_count"] / 1e6), np.log(r["cap"] / 10)] for r in rows])
    y = np.log([r["cpu_seconds"] for r in rows])
    c = np.linalg.lstsq(X, y, rcond=None)[0]
    worst = float(np.exp(np.max(np.abs(y - X @ c))))
    return {"coef": round(float(np.exp(c[0])), 2), "a": round(float(c[1]), 3), "b": round(float(c[2]), 3),
            "worst_factor": round(worst, 2)}


# ------------------------------------------------------------------------------ the report's shipped tables
def write_b3_tables(name, cap, tol=1e-4):
    """Relaxation 2 by the interior point (then the priced chains, as ``auto`` does), its tables
    written in orbit form to wncs_lp/reproduce/data/ and listed in b3_reference.json."""
    from wncs_lp.bounds.joint import joint_bound
    from wncs_lp.bounds.joint_chains import JointData
    from wncs_lp.bounds.joint_symmetry import orbit_tables, process_symmetry

    system = _system(name, cap)
    res, secs, cpu, l0 = _timed(joint_bound, system, method="ipm", ipm_tol=tol, time_limit=None, max_iter=0)
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    folder = ROOT / "wncs_lp" / "reproduce" / "data"
    fname = f"b3_tables_{name}_cap{cap}.npz"
    buf = io.BytesIO()
    np.savez_compressed(buf, classes=np.array(json.dumps([list(c) for c in sym.classes])),
                        **{f"h{i}": h for i, h in enumerate(orbit_tables(sym, data, res.tables.h))})
    (folder / fname).write_bytes(buf.getvalue())
    ref_path = folder / "b3_reference.json"
    ref = json.loads(ref_path.read_text())
    entry = {"scenario": f"{name}.toml", "cap": cap, "processes": system.n_processes, "file": fname,
             "lower_bound": res.lower_bound, "ipm_objective": res.stats.get("ipm_objective"),
             "ipm_iterations": res.stats.get("ipm_iterations"), "seconds": round(secs, 1), "cpu_seconds": round(cpu, 1),
             "machine": f"2 shared cores, load {l0}", "date": time.strftime("%Y-%m-%d"),
             "ipm_tol": tol, "command": f"python benchmarks/bounds.py --write-b3-tables {name}:{cap} --ipm-tol {tol:g}"}
    ref["tables"] = [t for t in ref["tables"] if (t["scenario"], t["cap"]) != (entry["scenario"], cap)] + [entry]
    atomic_write_text(ref_path, json.dumps(ref, indent=1) + "\n")
    return entry


def table(rows) -> str:
    def fmt(v, pct=False):
        if v in ("", None):
            return ""
        return f"{100 * v:.2f}%" if pct else (f"{v:.8g}" if isinstance(v, float) else str(v))

    rows = [{c: r.get(c, "") for c in COLUMNS} for r in rows]
    out = [f"{'instance':<20} {'cap':>3} {'row':<36} {'how':<11} {'value':>14} {'upper':>14} {'gap auto':>8} "
           f"{'vs g*':>8} {'s':>8} {'cpu s':>8} {'GiB':>6} {'load':>5}"]
    for r in rows:
        out.append(f"{r['instance']:<20} {r['cap']:>3} {r['row']:<36} {str(r['how']):<11} {fmt(r['value']):>14} "
                   f"{fmt(r['value_upper']):>14} {fmt(r['gap_auto'], True):>8} {fmt(r['gap_optimum'], True):>8} "
                   f"{fmt(r['seconds']):>8} {fmt(r['cpu_seconds']):>8} {fmt(r['peak_gib']):>6} {fmt(r['load1']):>5}")
    return "\n".join(out)


def write_csv(path, rows) -> None:
    atomic_write_csv(path, rows, COLUMNS, extras="ignore")


def _child_args(args) -> list[str]:
    out = ["--exact-max-states", str(args.exact_max_states), "--slots", str(args.slots), "--reps", str(args.reps),
           "--seed", str(args.seed), "--ipm-tol", str(args.ipm_tol)]
    out += ["--bounds-only"] * args.bounds_only + ["--no-grouped"] * args.no_grouped
    for flag, v in (("--joint-time-limit", args.joint_time_limit), ("--joint-max-iter", args.joint_max_iter),
                    ("--joint-method", args.joint_method)):
        if v is not None:
            out += [flag, str(v)]
    return out


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
                    help="seconds for relaxation 2's search (default auto's: none; certified whenever it stops)")
    ap.add_argument("--joint-max-iter", type=int, default=None, help="relaxation 2's bundle steps (default auto's 30)")
    ap.add_argument("--joint-method", default=None, help="relaxation 2's method (auto, ipm, bundle, ...)")
    ap.add_argument("--ipm-scan", action="store_true", help="relaxation 2's interior point alone, and its time model")
    ap.add_argument("--ipm-tol", type=float, default=1e-4,
                    help="IPX's tolerance in --ipm-scan and --write-b3-tables (auto's: 1e-4)")
    ap.add_argument("--write-b3-tables", default=None, metavar="NAME:CAP,...",
                    help="compute relaxation 2's tables by the interior point and ship them with the report (B3)")
    ap.add_argument("--candidates", default=None, metavar="NAME:STATES",
                    help="the lookahead with k greedy candidates against the full one on STATES simulated states")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--ipm-child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.child or args.ipm_child:  # one instance in this process; its rows on the last line
        name, cap = (args.child or args.ipm_child).split(":")
        rows = run_instance(name, int(cap), args) if args.child else ipm_one(name, int(cap), args.ipm_tol)
        print("ROWS " + json.dumps(rows, default=float), flush=True)
        return 0
    if args.candidates:
        name, states = args.candidates.split(":")
        rows = candidates_one(name, int(states))
        print(table(rows), flush=True)
        if args.out:
            write_csv(args.out, rows)
        return 0
    if args.write_b3_tables:
        for item in args.write_b3_tables.split(","):
            name, cap = item.split(":")
            print(json.dumps(write_b3_tables(name, int(cap), args.ipm_tol)), flush=True)
        return 0
    if args.instances:
        todo = [(s.split(":")[0], int(s.split(":")[1])) for s in args.instances.split(",")]
    else:
        todo = SCAN if args.ipm_scan else (QUICK if args.quick else DEFAULT)
    if args.quick:  # exact up to processes 1-4 at cap 10, short Monte Carlo beyond
        args.exact_max_states, args.reps, args.slots = min(args.exact_max_states, 2_000_000), 5, 5_000
    print(f"load {load1()} on {os.cpu_count()} cores", flush=True)
    rows = []
    flag = "--ipm-child" if args.ipm_scan else "--child"
    for name, cap in todo:
        rows += _in_child(flag, f"{name}:{cap}", _child_args(args))
        print(table([r for r in rows if (r["instance"], r["cap"]) == (name, cap)]), flush=True)
        if args.out:
            write_csv(args.out, rows)
    print("\n" + table(rows))
    if args.ipm_scan and len(rows) >= 3:
        print(f"\nIPX CPU time model (least squares in logs): {fit_time_model(rows)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
