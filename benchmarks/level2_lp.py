"""Issue 33: the level-2 relaxation (every pair's ages on the joint configuration, all pairs at once)
measured against g* -- its LP solved whole, its duals certified by the LP-sized check.

    python benchmarks/level2_lp.py --out benchmarks/level2_lp.csv                    # the default list
    python benchmarks/level2_lp.py --instances edge:5:25,both:3:25 --known benchmarks/calibration_load.csv \\
        --out benchmarks/level2_calibration.csv                                      # g* from the calibration
    python benchmarks/level2_lp.py --instances edge:4:30 --lump none,20,15,10        # the lumping trade-off
    python benchmarks/level2_lp.py --instances both:3:16 --solver clarabel           # another LP solver
    python benchmarks/level2_lp.py --count bounds_lab16,bounds_p1234_twice --lump none,10,5   # sizes only
    python benchmarks/level2_lp.py --scan edge:5:30:none,both:3:12:none --out benchmarks/level2_time.csv
                                                                    # IPX's CPU time only (the time model)

The relaxation and its certificate are :mod:`wncs_lp.bounds.level2` (:func:`level2_bound`). An
instance is ``SERVER:SENSORS:CAP`` (``calibration_load.system_for``: the lab's scalar sensors on the
edge, the cloud or both servers); each (instance, lumping) runs in its own process, so its peak
memory is its own. Per row: g* (``--known``: read from the calibration CSV, with relaxations 1-4's
bounds; else certified matrix-free value iteration and relaxation 4's bound computed here), the
level-2 LP's size, the solver's objective and status, the certified bound, CPU seconds of the build,
the solve and the certificate, the looseness (g* - LB) / g* against the best relaxation's.

``--count`` gives the LP's rows, columns and nonzeros for shipped scenarios without building it
(:func:`~wncs_lp.bounds.level2.level2_layout`), for each ``--lump``, and an estimate with the
symmetry of interchangeable processes: one pair measure per orbit of pairs, on the orbits of (C, a)
pairs under the permutations that fix both members (:func:`symmetric_estimate`; the LP itself is not
reduced by the library).

``--scan`` times the solve alone (no g*, no other relaxation): per ``SERVER:SENSORS:CAP:LUMP`` (or
``SCENARIO@CAP:LUMP``, a shipped scenario) the
LP's size as :func:`~wncs_lp.bounds.all_pairs.all_pairs_size` counts it before anything is built,
the configurations, (C, a) pairs and outcomes, IPX's CPU seconds and iterations (stopped at
``--cpu-limit`` seconds of CPU: such a row certifies nothing and says so); the rows
:data:`~wncs_lp.bounds.all_pairs.ALL_PAIRS_TIME_MODEL` is fitted on (``--fit``: the least-squares fit
in logs on the CSV's finished rows, and each row's prediction by the fit without it).
"""
from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402

import wncs_lp  # noqa: E402
from bounds import load1, peak_gib  # noqa: E402  (benchmarks/bounds.py)
from calibration_load import system_for  # noqa: E402
from wncs_lp.bounds import lower_bound  # noqa: E402
from wncs_lp.bounds.joint_chains import JointData  # noqa: E402
from wncs_lp.bounds.joint_symmetry import orbit_labels, process_symmetry  # noqa: E402
from wncs_lp.bounds.level2 import level2_bound, level2_layout  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "lump", "solver", "g_star", "g_star_source", "lb_level2", "looseness_level2", "lp_value",
           "roundoff", "best_relaxation", "lb_best", "looseness_best", "lb_2", "looseness_2", "lb_4", "looseness_4",
           "rows", "cols", "nonzeros", "build_cpu_seconds", "lp_cpu_seconds", "certify_cpu_seconds", "iterations",
           "status", "load1", "peak_gib"]
DEFAULT = "edge:2:12,edge:3:12,edge:3:16,edge:3:20,edge:4:12,edge:4:16,edge:4:20,edge:4:30,edge:5:16,cloud:3:16"


def known_bounds(path: str, item: str) -> dict:
    """g* and relaxations 1-4's bounds of ``item`` from calibration_load.csv ({} when absent)."""
    out = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["instance"] != item:
                continue
            if r["row"] == "optimum g*":
                out["g"] = float(r["value"])
            elif r["row"].startswith("LB "):
                out[int(r["row"].split()[1])] = float(r["value"])
    return out if "g" in out else {}


def run(item: str, lump, solver: str, known: str, time_limit: float | None) -> dict:
    server, sensors, cap = item.split(":")
    system = system_for(server, int(sensors), int(cap))
    l0 = load1()
    ref = known_bounds(known, item) if known else {}
    if ref:
        g, source = ref["g"], "calibration CSV"
        lbs = {k: v for k, v in ref.items() if k != "g"}
    else:
        g, source = float(matrix_free_value_iteration(system, tol=1e-9).gain), "matrix-free value iteration"
        lbs = {4: float(lower_bound(system, 4).lower_bound)}
    res = level2_bound(system, lump=lump, solver=solver, time_limit=time_limit)
    best = max(lbs, key=lbs.get)
    rel = lambda v: (g - v) / g if v is not None and np.isfinite(v) else ""  # noqa: E731
    return {"instance": item, "cap": int(cap), "lump": "none" if lump is None else lump, "solver": solver,
            "g_star": g, "g_star_source": source, "lb_level2": res.lower_bound, "looseness_level2": rel(res.lower_bound),
            "lp_value": res.lp_value, "roundoff": res.certificate.roundoff if res.certificate else "",
            "best_relaxation": best, "lb_best": lbs[best], "looseness_best": rel(lbs[best]),
            "lb_2": lbs.get(2, ""), "looseness_2": rel(lbs.get(2)), "lb_4": lbs.get(4, ""), "looseness_4": rel(lbs.get(4)),
            "rows": res.rows, "cols": res.cols, "nonzeros": res.nnz, "build_cpu_seconds": round(res.build_cpu, 2),
            "lp_cpu_seconds": round(res.solve_cpu, 2), "certify_cpu_seconds": round(res.certify_cpu, 3),
            "iterations": res.iterations, "status": res.status, "load1": l0, "peak_gib": peak_gib()}


SCAN_COLUMNS = ["instance", "lump", "configurations", "pairs_ca", "outcomes", "rows", "cols", "nnz", "lp_rows",
                "lp_nnz", "predicted_cpu_seconds", "build_cpu_seconds", "lp_cpu_seconds", "iterations", "status",
                "lower_bound", "load1", "peak_gib"]


def scan(item: str, cpu_limit: float | None) -> dict:
    """One timed solve of the level-2 LP for the time model: ``SERVER:SENSORS:CAP:LUMP`` (a calibration
    system) or ``SCENARIO@CAP:LUMP`` (a shipped scenario at that cap)."""
    from wncs_lp.bounds.all_pairs import all_pairs_seconds, all_pairs_size

    if "@" in item:  # a shipped scenario at a cap: SCENARIO@CAP:LUMP
        name, rest = item.split("@")
        cap, lump = rest.split(":")
        system = System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"]))
        label = f"{name}:{system.n_processes}:{cap}"
    else:
        server, sensors, cap, lump = item.split(":")
        system = system_for(server, int(sensors), int(cap))
        label = f"{server}:{sensors}:{cap}"
    lump = _lump(lump)
    size = all_pairs_size(system, lump)
    l0 = load1()
    res = level2_bound(system, lump=lump, cpu_limit=cpu_limit)
    return {"instance": label, "lump": "none" if lump is None else lump,
            "configurations": size["configurations"], "pairs_ca": size["pairs_ca"], "outcomes": size["outcomes"],
            "rows": size["rows"], "cols": size["cols"], "nnz": size["nnz"], "lp_rows": res.rows, "lp_nnz": res.nnz,
            "predicted_cpu_seconds": round(all_pairs_seconds(size), 2), "build_cpu_seconds": round(res.build_cpu, 2),
            "lp_cpu_seconds": round(res.solve_cpu, 2), "iterations": res.iterations, "status": res.status,
            "lower_bound": res.lower_bound, "load1": l0, "peak_gib": peak_gib()}


def _mean_lump(row: dict) -> float:
    """The mean lumping threshold of a scan row (its instance's cap where nothing is lumped; the
    calibration systems have one cap for every sensor)."""
    cap = int(row["instance"].split(":")[2])
    return float(cap if row["lump"] == "none" else min(int(row["lump"]), cap))


def fit(path: str) -> None:
    """The least-squares fit in logs of IPX's CPU seconds on the scan's finished rows of the calibration
    systems (``SERVER:...``), each of them predicted by the fit without it (leave one out), and the
    rows of shipped scenarios (``SCENARIO@CAP``) held out: predicted by the fit on the others."""
    from wncs_lp.bounds.all_pairs import time_features

    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if np.isfinite(float(r["lower_bound"] or "nan"))]  # certified
    cal = np.array([r["instance"].split(":")[0] in ("edge", "cloud", "both") for r in rows])
    cal &= np.array([float(r["lp_cpu_seconds"]) >= 0.5 for r in rows])  # fitted where timed above noise
    X = np.array([[1.0, *np.log(time_features({**{k: float(r[k]) for k in ("nnz", "pairs_ca", "outcomes")},
                                                "mean_lump": _mean_lump(r)}))] for r in rows])
    y = np.log([float(r["lp_cpu_seconds"]) for r in rows])
    beta = np.linalg.lstsq(X[cal], y[cal], rcond=None)[0]
    print(f"fit on {int(cal.sum())} rows: coef {np.exp(beta[0]):.4g}, exponents {', '.join(f'{b:.3f}' for b in beta[1:])}")
    for i, r in enumerate(rows):
        keep = cal & (np.arange(len(rows)) != i)
        pred = float(np.exp(X[i] @ np.linalg.lstsq(X[keep], y[keep], rcond=None)[0]))
        how = "left out" if cal[i] else ("held out" if r["instance"].split(":")[0] not in ("edge", "cloud", "both")
                                         else "not fitted: under 0.5 s")
        print(f"  {r['instance']:22s} lump {r['lump']:5s} nnz {int(r['nnz']):>9,} P {int(r['pairs_ca']):>5}  measured "
              f"{float(r['lp_cpu_seconds']):7.2f} s  predicted {pred:7.1f} s (x{pred / float(r['lp_cpu_seconds']):.2f}, {how})")


def _swap(sym, i: int, j: int) -> tuple:
    """(configuration map, pair map) of the transposition (i j) of one class, composed from the
    adjacent ones the symmetry keeps: (a c) = (a b)(b c)(a b)."""
    cl = sym.class_of(i)
    a, b = sorted((cl.index(i), cl.index(j)))
    if b == a + 1:
        return sym.transposition(cl[a], cl[b])
    x, y = _swap(sym, cl[a], cl[a + 1]), _swap(sym, cl[a + 1], cl[b])
    return x[0][y[0][x[0]]], x[1][y[1][x[1]]]


def symmetric_estimate(system: System, data: JointData, lump) -> dict:
    """Columns of the level-2 LP if reduced by the symmetry of interchangeable processes: one pair
    measure per orbit of pairs {k, l}, on the orbits of (C, a) pairs under the transpositions that
    fix k and l (their ages are the pair's own), plus relaxation 2's reduced z and x. An estimate:
    the reduction is not built."""
    sym = process_symmetry(system, data)
    lay = level2_layout(data, lump)
    P = lay.n_pairs_ca
    cls = {k: sym.classes.index(sym.class_of(k)) for k in range(data.n_processes)}
    seen, cols, orbits = set(), 0, 0
    for k, l in lay.pairs:
        key = tuple(sorted((cls[k], cls[l])))
        if key in seen:
            continue
        seen.add(key)
        gens = []
        for c in sym.classes:
            m = [x for x in c if x not in (k, l)]
            gens += [_swap(sym, u, v)[1] for u, v in zip(m[:-1], m[1:])]
        n_o, _ = orbit_labels(gens, P)
        cols += lay.lumps[k] * lay.lumps[l] * n_o
        orbits += 1
    return {"type_pairs": orbits, "pair_cols": cols, "classes": len(sym.classes)}


def count(names: str, lumps: list) -> None:
    for name in names.split(","):
        c0 = time.process_time()
        system = System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name)))
        data = JointData.from_system(system)
        print(f"{name}: {data.n_processes} processes, caps {sorted(set(int(c) for c in data.caps))}, "
              f"|C| = {data.n_configs:,}, |C x A| = {int(data.act_ptr[-1]):,}, {data.n_outcomes:,} outcomes", flush=True)
        for lump in lumps:
            lay = level2_layout(data, lump)
            est = symmetric_estimate(system, data, lump)
            print(f"  lump {lump}: {lay.rows:,} rows x {lay.cols:,} columns, <= {lay.nnz:,} nonzeros; "
                  f"with symmetry ({est['classes']} classes, {est['type_pairs']} orbits of pairs): "
                  f"~{est['pair_cols']:,} pair columns  ({time.process_time() - c0:.1f} s of CPU)", flush=True)


def _lump(text: str):
    return None if text == "none" else int(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", default=DEFAULT, help="SERVER:SENSORS:CAP,... (default: %(default)s)")
    ap.add_argument("--lump", default="none", help="lumping thresholds to run, 'none' or an integer, comma-separated")
    ap.add_argument("--solver", default="ipx", choices=("ipx", "clarabel", "pdlp"))
    ap.add_argument("--known", default="", help="calibration_load.csv: g* and relaxations 1-4 read, not computed")
    ap.add_argument("--time-limit", type=float, default=None, help="seconds of wall clock for the LP solver")
    ap.add_argument("--count", default="", help="shipped scenarios: print the LP's size, build nothing")
    ap.add_argument("--scan", default="", help="SERVER:SENSORS:CAP:LUMP,...: time IPX on the level-2 LP alone")
    ap.add_argument("--cpu-limit", type=float, default=600.0, help="--scan: CPU seconds of IPX at most (%(default)s)")
    ap.add_argument("--fit", default="", help="a --scan CSV: fit the time model, each row predicted without it")
    ap.add_argument("--out", default="", help="CSV to write (--scan: rows are appended to it when it exists)")
    ap.add_argument("--one", default="", help=argparse.SUPPRESS)  # INSTANCE/LUMP: one row as JSON (the subprocess)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    lumps = [_lump(x) for x in args.lump.split(",")]
    if args.count:
        count(args.count, lumps)
        return 0
    if args.fit:
        fit(args.fit)
        return 0
    if args.scan:
        return _scan_all(args)
    if args.one:
        item, lump = args.one.split("/")
        print(json.dumps(run(item, _lump(lump), args.solver, args.known, args.time_limit)))
        return 0
    rows = []
    for item in args.instances.split(","):
        for lump in lumps:
            cmd = [sys.executable, __file__, "--one", f"{item}/{'none' if lump is None else lump}", "--solver", args.solver]
            cmd += ["--known", args.known] if args.known else []
            cmd += ["--time-limit", str(args.time_limit)] if args.time_limit else []
            out = subprocess.run(cmd, capture_output=True, text=True)
            if out.returncode != 0:
                print(f"{item} lump {lump}: failed\n{out.stderr[-2000:]}", flush=True)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            pct = lambda v: f"{100 * v:.3f}%" if v != "" else "-"  # noqa: E731
            print(f"{item:12s} lump {r['lump']!s:5s} g* {r['g_star']:.6f}  level 2 {r['lb_level2']:.6f} "
                  f"({pct(r['looseness_level2'])})  best relaxation {r['best_relaxation']} {pct(r['looseness_best'])}  "
                  f"LP {r['rows']:,} x {r['cols']:,}, {r['nonzeros']:,} nnz, {r['lp_cpu_seconds']} s CPU "
                  f"({r['status']}), certificate {r['certify_cpu_seconds']} s, {r['peak_gib']} GiB, load {r['load1']}",
                  flush=True)
            rows.append(r)
            if args.out:
                atomic_write_csv(args.out, rows, COLUMNS)
    return 0


def _scan_all(args) -> int:
    if args.one:
        print(json.dumps(scan(args.one, args.cpu_limit)))
        return 0
    rows = []
    if args.out and Path(args.out).exists():
        with open(args.out, newline="") as f:
            rows = list(csv.DictReader(f))
    for item in args.scan.split(","):
        out = subprocess.run([sys.executable, __file__, "--scan", item, "--one", item, "--cpu-limit", str(args.cpu_limit)],
                             capture_output=True, text=True)
        if out.returncode != 0:
            print(f"{item}: failed\n{out.stderr[-2000:]}", flush=True)
            continue
        r = json.loads(out.stdout.strip().splitlines()[-1])
        print(f"{item:18s} {r['configurations']:>4} configurations, {r['rows']:,} x {r['cols']:,}, {r['nnz']:,} nnz: "
              f"{r['lp_cpu_seconds']} s CPU (predicted {r['predicted_cpu_seconds']}), {r['iterations']} iterations, "
              f"{r['status']}, {r['peak_gib']} GiB, load {r['load1']}", flush=True)
        rows.append(r)
        if args.out:
            atomic_write_csv(args.out, rows, SCAN_COLUMNS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
