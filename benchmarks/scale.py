"""Issue 33 item 5 and issue 39: bounds and policies at 12-32 processes, their time and peak memory.

    python benchmarks/scale.py --out benchmarks/scale.csv                       # the shipped instances
    python benchmarks/scale.py --instances bounds_lab16 --relaxation 1 --out /tmp/s.csv
    python benchmarks/scale.py --instances lab:32,p1234:8 --compare greedy --out /tmp/s.csv
    python benchmarks/scale.py --search ascent,smooth --steps 40 --instances bounds_lab16 --out /tmp/r2.csv
    python benchmarks/scale.py --levers pdlp,warm,prices,pairs,tables --instances bounds_p1234_x4 --out /tmp/l.csv
    python benchmarks/scale.py --levers ipm --ipm-tol 1e-2 --instances bounds_lab16 --out /tmp/ipm.csv
    python benchmarks/scale.py --levers pairs-ipm --compare bound --instances bounds_lab16 --out /tmp/p.csv
    python benchmarks/scale.py --levers clarabel --clarabel-time-limit 300 --instances bounds_p1234_x4 --out /tmp/c.csv

Every instance runs as ``wncs-lp bound INSTANCE --policy --json`` in its own process (so its peak
resident memory is its own: ``ru_maxrss`` of the child), with the command's defaults unless told:
relaxation ``auto``, the bound's policy and the command's comparators (lookahead, suboptimal,
static, greedy) simulated 20 x 40,000 slots (seed 0), the gap against the one-sided 95% upper
confidence limit. Instances: the shipped scenarios
``bounds_p1234_x4`` (16 processes, cap 40), ``bounds_lab16`` (16 sensors), ``bounds_fog12`` (12
processes on three servers, explored lazily), and generated ones: ``lab:N`` (N sensors of the lab
shape, cap 20) and ``p1234:R`` (the paper's four processes R times, cap 40), written to a
temporary folder.

``--search`` compares relaxation 2's searches on the lumped chains instead (``joint_bound(system,
method=M, max_iter=--steps, time_limit=None)`` for each method M, in turn in one process; relaxation
1 and the symmetry check are in every row's time): the certified bound, the gain over the start
(relaxation 1's prices on the lumped chains) and the CPU seconds, with each method's ratio of CPU
and of gain to the first's.

``--levers`` measures what might bring relaxation 2 nearer its optimum at sixteen processes, or the
policy onto better tables (docs/bounds.md, "Sixteen processes: the levers measured"), one row each:
``ipm`` HiGHS's interior point IPX (no crossover, tolerance ``--ipm-tol``) on relaxation 2's LP reduced
by symmetry (:func:`~wncs_lp.bounds.joint_ipm.ipm_tables`, what ``method="ipm"`` runs), the LP's size,
IPX's iterations and CPU seconds, its raw duals' tables certified and the lumped chains at its
coupling duals certified (the repair of ``method="ipm"``);
``clarabel`` the same LP by Clarabel (z >= 0 as a nonnegative cone, tolerances ``--ipm-tol``, no
presolve, ``--clarabel-time-limit`` seconds), then the same two certificates;
``pdlp`` HiGHS's first-order solver (``solver="pdlp"``, ``--pdlp-iterations`` iterations, a count so
that a loaded machine does not change the result; tolerance 1e-4) on relaxation 2's LP reduced by symmetry, its raw duals' tables certified and the lumped chains
at its coupling duals certified; ``warm`` the reduced LP at cap ``--warm-cap`` by the interior point,
its coupling duals (prices on orbits of (C, a), the same at every cap) priced into the full cap's
lumped chains; ``prices`` relaxation 2's lumped Lagrangian along relaxation 1's own family of prices
mu(lambda) = lambda . claims, lambda scaled per server; ``pairs`` relaxation 4's predicted CPU and
memory (``pairs_size`` and ``auto``'s rule); ``pairs-ipm`` relaxation 4 run (not predicted) from relaxation 2
by IPX at ``--ipm-tol``, ``--pair-steps`` bundle steps, and the ``--compare`` policies on its pair tables;
``tables`` the ``--compare`` policies on the tables of
relaxation 2's lumped start (what ``auto`` computes beyond the LP's reach), 20 x 40,000 slots.

One CSV row per policy (and one for the bound) with the seconds of the whole command, its CPU
seconds, its peak memory and the 1-minute load average when it started: the machine is shared
(2 cores), so the wall time is worth only as much as the load says; the CPU time is the cost.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wncs_lp import load_scenario, scenario_path  # noqa: E402
from wncs_lp.bounds.gaps import DEFAULT_POLICIES  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402

COLUMNS = ["instance", "processes", "explored", "relaxation", "row", "gain", "upper", "gap", "lower_bound",
           "seconds", "cpu_seconds", "peak_gib", "load1", "note"]
DEFAULT = ["bounds_p1234_x4", "bounds_lab16", "bounds_fog12"]
A_LAB = [1.05, 1.1, 1.15, 1.2, 1.3]
TYPES = ["[[1.02, 1, 0, 1], [0, 1, 0.2, 0], [0, 0, 1, 0], [0, 0, 0, 1.01]]", "[[1, 1, 0], [0, 1.02, 0], [0, 0, 1]]",
         "[[1.02, 1], [0, 1]]", "[[1.02]]"]


def _generated(spec: str, folder: Path) -> Path:
    """``lab:N`` or ``p1234:R`` as a TOML file in ``folder`` (the servers of the shipped lab16 / x4)."""
    kind, _, n = spec.partition(":")
    n = int(n)
    base = scenario_path("bounds_lab16" if kind == "lab" else "bounds_p1234_x4").read_text()
    head, _, rest = base.partition("[[process]]")
    servers = rest[rest.index("[[server]]"):]
    if kind == "lab":
        procs = [(f"sensor-{i + 1:02d}", f"[[{A_LAB[i % 5]}]]") for i in range(n)]
    elif kind == "p1234":
        procs = [(f"process-{t + 1}{chr(97 + r)}", TYPES[t]) for r in range(n) for t in range(4)]
    else:
        raise SystemExit(f"unknown instance {spec!r}: expected a shipped name, lab:N or p1234:R")
    text = head + "".join(f'[[process]]\nname = "{a}"\nA = {b}\nR = "identity"\n\n' for a, b in procs) + servers
    path = folder / f"{kind}{n}.toml"
    path.write_text(text)
    return path


def run(instance: str, args, folder: Path) -> list[dict]:
    path = _generated(instance, folder) if ":" in instance else scenario_path(instance)
    cmd = [sys.executable, "-m", "wncs_lp", "bound", str(path), "--policy", "--json", "--relaxation", args.relaxation,
           "--compare", args.compare, "--slots", str(args.slots), "--reps", str(args.reps)]
    load = round(os.getloadavg()[0], 2)
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as fo, tempfile.TemporaryFile("w+") as fe:
        child = subprocess.Popen(cmd, stdout=fo, stderr=fe, text=True)
        _, status, usage = os.wait4(child.pid, 0)  # this child's own CPU time and peak resident memory
        child.returncode = os.waitstatus_to_exitcode(status)
        fo.seek(0)
        fe.seek(0)
        stdout, stderr = fo.read(), fe.read()
    seconds = time.perf_counter() - t0
    common = {"instance": instance, "seconds": round(seconds, 1), "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 1),
              "peak_gib": round(usage.ru_maxrss / 2**20, 2), "load1": load}
    if child.returncode not in (0, 1):
        return [{**common, "row": "error", "note": (stderr.strip().splitlines() or ["?"])[-1][:300]}]
    data = json.loads(stdout)
    b = data["bound"]
    rows = [{**common, "processes": load_scenario(path).n_processes, "explored":
             data.get("explored", ""), "relaxation": b["relaxation"], "row": "bound", "lower_bound": b["lower_bound"],
             "note": f"{b['status']}; the bound in {b['seconds']:.1f} s; auto's bounds "
                     f"{b['stats'].get('auto_bounds', '')}"}]
    for p in data["policies"]["policies"]:
        rows.append({**common, "explored": data.get("explored", ""), "relaxation": b["relaxation"], "row": p["policy"],
                     "gain": p["gain"], "upper": p["gain_upper"], "gap": p["gap"], "lower_bound": b["lower_bound"],
                     "note": f"{p.get('seconds', 0):.1f} s"})
    for s in data["policies"].get("skipped", []):
        rows.append({**common, "row": s["policy"], "note": "not evaluated: " + s["reason"][:200]})
    return rows


SEARCH_COLUMNS = ["instance", "method", "steps", "lower_bound", "start", "gain", "cpu_seconds", "cpu_ratio",
                  "gain_ratio", "load1"]


def search(instance: str, methods: list[str], steps: int, folder: Path) -> list[dict]:
    """Relaxation 2's lumped searches on one instance, in turn (module docstring)."""
    from wncs_lp.bounds.joint import joint_bound

    path = _generated(instance, folder) if ":" in instance else scenario_path(instance)
    rows = []
    for m in methods:
        load = round(os.getloadavg()[0], 2)
        t0 = time.process_time()
        res = joint_bound(load_scenario(path), method=m, max_iter=steps, time_limit=None)
        cpu = time.process_time() - t0
        start = res.stats["ascent_start"]
        rows.append({"instance": instance, "method": m, "steps": steps, "lower_bound": res.lower_bound, "start": start,
                     "gain": res.lower_bound - start, "cpu_seconds": round(cpu, 1), "load1": load})
    for r in rows:
        r["cpu_ratio"] = round(r["cpu_seconds"] / max(rows[0]["cpu_seconds"], 1e-9), 3)
        r["gain_ratio"] = round(r["gain"] / rows[0]["gain"], 3) if rows[0]["gain"] > 0 else ""
    return rows


LEVER_COLUMNS = ["instance", "lever", "what", "value", "reference", "cpu_seconds", "load1", "note"]


def _certified_chains(sym, data, lumped, prices, kern) -> tuple[float, float]:
    """(L at ``prices``, the certified bound of the lumped chains' biases spread to every process)."""
    from wncs_lp.bounds.joint_chains import certify_tables
    from wncs_lp.bounds.joint_symmetry import spread_orbit_tables

    value, sols = lumped.lagrangian(prices, kern, tol=2e-6)
    return value, certify_tables(data, spread_orbit_tables(sym, data, [s.h for s in sols])).lower_bound


def levers(instance: str, which: list[str], args, folder: Path) -> list[dict]:
    """The levers of ``--levers`` on one instance (module docstring), each row as it is measured."""
    from dataclasses import replace

    import numpy as np

    from wncs_lp.bounds.gaps import policy_gaps
    from wncs_lp.bounds.inputs import bound_system
    from wncs_lp.bounds.joint import joint_bound, relaxation1_start
    from wncs_lp.bounds.joint_chains import JointData, Kernels, certify_tables
    from wncs_lp.bounds.joint_ipm import ipm_tables
    from wncs_lp.bounds.joint_symmetry import (coupling_prices, lumped_chains, process_symmetry, spread_tables,
                                               symmetric_lp)
    from wncs_lp.bounds.lower import AUTO_PAIRS_CPU_PER_WORK, AUTO_PAIRS_STEPS
    from wncs_lp.bounds.pairs import pairs_bound, pairs_size
    from wncs_lp.bounds.private import private_bound
    from wncs_lp.solvers.highs import solve_highs
    from wncs_lp.solvers.threads import resolve_threads

    path = _generated(instance, folder) if ":" in instance else scenario_path(instance)
    system = bound_system(load_scenario(path))
    data = JointData.from_system(system)
    sym = process_symmetry(system, data)
    lumped = lumped_chains(sym, data)
    kern = Kernels("auto", 1)
    r1 = private_bound(system)
    rows = []

    def row(lever, what, value, cpu, note="", reference=r1.lower_bound):
        rows.append({"instance": instance, "lever": lever, "what": what, "value": value, "reference": reference,
                     "cpu_seconds": round(cpu, 1), "load1": round(os.getloadavg()[0], 2), "note": note})
        print("  ".join(f"{k}={rows[-1][k]}" for k in LEVER_COLUMNS if rows[-1][k] not in (None, "")), flush=True)

    if "ipm" in which:
        c0 = time.process_time()
        ipm = ipm_tables(data, symmetry=sym, tol=float(args.ipm_tol))
        raw = certify_tables(data, ipm.tables).lower_bound if ipm.tables is not None else float("-inf")
        rows_, cols_, nnz_ = ipm.shape
        row("ipm", f"the raw duals' tables (IPX at {args.ipm_tol})", raw, time.process_time() - c0,
            f"HiGHS {ipm.status}, {ipm.iterations} iterations, {ipm.cpu_seconds:.1f} s of CPU in IPX and the build; "
            f"LP {rows_:,} x {cols_:,}, {nnz_:,} nonzeros; objective {ipm.objective:.10g} (not a bound)")
        if ipm.prices is not None:
            value, cert = _certified_chains(sym, data, lumped, ipm.prices, kern)
            row("ipm", "the lumped chains at its coupling duals", cert, time.process_time() - c0, f"L {value:.10g}")
    if "clarabel" in which:
        import clarabel
        import scipy.sparse as sp

        c0 = time.process_time()
        lp = symmetric_lp(sym, data)
        m, n = lp.A.shape
        st = clarabel.DefaultSettings()
        st.verbose, st.presolve_enable, st.time_limit = True, False, float(args.clarabel_time_limit)
        st.tol_gap_abs = st.tol_gap_rel = st.tol_feas = float(args.ipm_tol)
        sol = clarabel.DefaultSolver(sp.csc_matrix((n, n)), lp.c, sp.vstack([lp.A, -sp.identity(n)]).tocsc(),
                                     np.r_[lp.b, np.zeros(n)], [clarabel.ZeroConeT(m), clarabel.NonnegativeConeT(n)],
                                     st).solve()
        lam = np.zeros(lp.keep.size)
        lam[lp.keep] = -np.asarray(sol.z)[:m]  # Clarabel's sign: q + A^T z >= 0
        raw = certify_tables(data, spread_tables(sym, data, lp, lam)).lower_bound
        row("clarabel", f"the raw duals' tables (Clarabel at {args.ipm_tol})", raw, time.process_time() - c0,
            f"{sol.status}, {sol.iterations} iterations; LP {m:,} x {n:,}, {lp.A.nnz:,} nonzeros")
        value, cert = _certified_chains(sym, data, lumped, coupling_prices(lp, lam), kern)
        row("clarabel", "the lumped chains at its coupling duals", cert, time.process_time() - c0, f"L {value:.10g}")
    if "pdlp" in which:
        c0 = time.process_time()
        lp = symmetric_lp(sym, data)
        _, _, z, st = solve_highs(lp.A, lp.b, lp.c, tol=1e-4, max_iter=2**31 - 1, verbose=False,
                                  settings={"variant": "simplex", "solver": "pdlp", "pdlp_optimality_tolerance": 1e-4,
                                            "presolve": "off", "pdlp_iteration_limit": int(args.pdlp_iterations)})
        lam = np.zeros(lp.keep.size)
        lam[lp.keep] = -z
        raw = certify_tables(data, spread_tables(sym, data, lp, lam)).lower_bound
        note = (f"HiGHS {st['solver_status']} after {args.pdlp_iterations} iterations, primal objective "
                f"{st['obj_scaled']:.8g} (not a bound)")
        row("pdlp", "the raw duals' tables", raw, time.process_time() - c0, note)
        value, cert = _certified_chains(sym, data, lumped, coupling_prices(lp, lam), kern)
        row("pdlp", "the lumped chains at its coupling duals", cert, time.process_time() - c0, f"L {value:.10g}")
    if "warm" in which:
        c0 = time.process_time()
        small = bound_system(load_scenario(path, {"tau_cap": args.warm_cap}))
        d_s = JointData.from_system(small)
        ipm = ipm_tables(d_s, symmetry=process_symmetry(small, d_s), tol=1e-4)
        row("warm", f"the reduced LP at cap {args.warm_cap} (interior point; its objective)", ipm.objective,
            time.process_time() - c0, f"HiGHS {ipm.status}, {ipm.iterations} iterations")
        if d_s.n_pairs == data.n_pairs and np.array_equal(d_s.pair_c, data.pair_c):
            value, cert = _certified_chains(sym, data, lumped, ipm.prices, kern)
            row("warm", f"the lumped chains at cap {args.warm_cap}'s coupling duals", cert, time.process_time() - c0,
                f"L {value:.10g}")
    if "prices" in which:
        lam1 = np.asarray(r1.multipliers, float)
        h0 = None
        for f in [(1, 1), (1.1, 1), (0.9, 1), (1, 1.1), (1, 0.9), (1.2, 1.2), (0.8, 0.8)]:
            c0 = time.process_time()
            scale = np.resize(np.asarray(f, float), lam1.size).reshape(lam1.shape)
            _, mu = relaxation1_start(system, replace(r1, multipliers=lam1 * scale))
            value, sols = lumped.lagrangian(lumped.prices_from(mu), kern, tol=2e-6, h0=h0)
            h0 = [s.h for s in sols]
            row("prices", f"L at relaxation 1's lambda x {f}", value, time.process_time() - c0)
    if "pairs" in which:
        c0 = time.process_time()
        z = pairs_size(system)
        cpu = AUTO_PAIRS_CPU_PER_WORK * z["sweep_work"]
        row("pairs", "relaxation 4's start: predicted CPU seconds", cpu, time.process_time() - c0,
            f"{AUTO_PAIRS_STEPS} steps: {cpu * (1 + AUTO_PAIRS_STEPS / z['candidates']):.0f} s; "
            f"{z['memory_bytes'] / 2**30:.2f} GiB of tables; {z['candidates']} candidate partitions", reference="")
    if "pairs-ipm" in which:  # relaxation 4 run, not predicted: from IPX's relaxation 2, beyond auto's budget
        threads = resolve_threads(None)  # the machine's usable cores, as the command's default
        c0 = time.process_time()
        r2 = joint_bound(system, method="ipm", ipm_tol=float(args.ipm_tol), time_limit=None, threads=threads)
        row("pairs-ipm", f"relaxation 2 by IPX at {args.ipm_tol}, its chains' repair", r2.lower_bound,
            time.process_time() - c0)
        c0 = time.process_time()
        r4 = pairs_bound(system, start=r2, max_iter=args.pair_steps, time_limit=None, threads=threads)
        cpu = time.process_time() - c0
        starts = r4.stats["candidates"]
        row("pairs-ipm", "relaxation 4's start, the best partition", max(starts.values()), cpu,
            "; ".join(f"{g}: {v:.10g}" for g, v in starts.items()), reference=r2.lower_bound)
        row("pairs-ipm", f"relaxation 4 after {r4.stats.get('bundle_steps', 0)} bundle steps", r4.lower_bound, cpu,
            f"status {r4.status}", reference=r2.lower_bound)
        for name in args.compare.split(","):
            c0 = time.process_time()
            rep = policy_gaps(r4, system, [name], slots=args.slots, reps=args.reps)
            for g in rep.rows:
                row("pairs-ipm", f"{g.policy} on its tables: mean", g.gain, time.process_time() - c0,
                    f"95% upper limit {g.gain_upper:.8g}", reference=r4.lower_bound)
            for name_, why in rep.skipped:
                row("pairs-ipm", f"{name_} on its tables", "", time.process_time() - c0, f"not evaluated: {why}",
                    reference=r4.lower_bound)
    if "tables" in which:
        c0 = time.process_time()
        r2 = joint_bound(system, method="ascent", max_iter=1, time_limit=None)
        row("tables", "relaxation 2's lumped start", r2.lower_bound, time.process_time() - c0)
        for name in args.compare.split(","):
            c0 = time.process_time()
            for g in policy_gaps(r2, system, [name], slots=args.slots, reps=args.reps).rows:
                row("tables", f"{g.policy} on its tables: mean", g.gain, time.process_time() - c0,
                    f"95% upper limit {g.gain_upper:.8g}", reference=r2.lower_bound)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instances", default=",".join(DEFAULT))
    ap.add_argument("--relaxation", default="auto")
    # the command's own default comparators (the two-step lookahead included), so a row is what
    # ``wncs-lp bound INSTANCE --policy`` gives
    ap.add_argument("--compare", default=",".join(p for p in DEFAULT_POLICIES if p != "bound"))
    ap.add_argument("--slots", type=int, default=40_000)
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--search", default="", help="relaxation 2's lumped searches to compare (e.g. ascent,smooth)")
    ap.add_argument("--steps", type=int, default=40, help="steps (smoothed evaluations) of each --search method")
    ap.add_argument("--levers", default="", help="ipm,clarabel,pdlp,warm,prices,pairs,pairs-ipm,tables (module docstring)")
    ap.add_argument("--pair-steps", type=int, default=8, help="relaxation 4's bundle steps in --levers pairs-ipm")
    ap.add_argument("--pdlp-iterations", type=int, default=8000, help="PDLP's iterations in --levers pdlp")
    ap.add_argument("--warm-cap", type=int, default=10, help="the smaller cap of --levers warm")
    ap.add_argument("--ipm-tol", type=float, default=1e-2, help="IPX's tolerance in --levers ipm")
    ap.add_argument("--clarabel-time-limit", type=float, default=900.0, help="seconds of --levers clarabel")
    args = ap.parse_args()
    rows = []
    if args.levers:
        with tempfile.TemporaryDirectory() as tmp:
            for inst in args.instances.split(","):
                rows += levers(inst.strip(), args.levers.split(","), args, Path(tmp))
                atomic_write_csv(args.out, rows, LEVER_COLUMNS, extras="ignore")
        return 0
    if args.search:
        with tempfile.TemporaryDirectory() as tmp:
            for inst in args.instances.split(","):
                rows += search(inst.strip(), args.search.split(","), args.steps, Path(tmp))
                for r in rows[-len(args.search.split(",")):]:
                    print("  ".join(f"{k}={r[k]}" for k in SEARCH_COLUMNS if r.get(k) not in (None, "")), flush=True)
                atomic_write_csv(args.out, rows, SEARCH_COLUMNS, extras="ignore")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        for inst in args.instances.split(","):
            got = run(inst.strip(), args, Path(tmp))
            rows += got
            for r in got:
                print("  ".join(f"{k}={r[k]}" for k in COLUMNS if r.get(k) not in (None, "")), flush=True)
            # written after every instance: a long run keeps what it measured
            atomic_write_csv(args.out, rows, COLUMNS, extras="ignore")
    return 0


if __name__ == "__main__":
    sys.exit(main())
