"""A 20-point trade-off curve: warm-started HiGHS re-solves against 20 cold solves (issue 18).

    python benchmarks/tradeoff_warm.py                          # caps 12 and 16, 20 bounds in [0, 0.3]
    python benchmarks/tradeoff_warm.py --caps 12 --points 20 --csv /tmp/t.csv

Processes 1, 2 (``formulations/paper_p12_cloud_budget.toml``), remote send rate <= b for
``--points`` bounds evenly spaced over [0, 0.3], in increasing order. Three ways, in the same run
(the machine is shared: compare the ratios, not the seconds):

* ``cold-clarabel`` -- ``solve_constrained_lp`` per point: Clarabel interior point, HiGHS
  crossover on the pairs left in play, certificate (what ``tradeoff(..., warm=False)`` does);
* ``cold-highs``    -- ``WarmConstrainedLP.solve(..., warm=False)`` per point: HiGHS interior
  point + crossover from scratch, certificate (separates the backend from the warm start);
* ``warm``          -- one ``WarmConstrainedLP``: the first point cold (HiGHS), each next one a
  dual simplex re-solve from the previous basis, certificate (what ``tradeoff`` does by default).

Per point: ``seconds`` (the whole certified solve), ``lp_seconds`` (the LP solver alone: Clarabel
+ crossover, or the HiGHS run), iterations, gain, multiplier. Summary lines: totals, the speed-up
of warm over each cold way (total and LP alone), and the largest differences warm vs cold
Clarabel in gain (relative) and multiplier (relative, with the bound where it occurs: at a kink of
the curve the multiplier is not unique, any value between the two slopes is optimal).
"""
from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

FIELDS = ["cap", "states", "pairs", "mode", "bound", "seconds", "lp_seconds", "iterations", "gain", "multiplier",
          "randomized", "status", "method"]


def log(msg: str) -> None:
    print(msg, flush=True)


def run_cap(cap: int, bounds: np.ndarray, modes: list[str]) -> list[dict]:
    import wncs_lp
    from wncs_lp.constrained import constraints_for
    from wncs_lp.constrained.lp import solve_constrained_lp
    from wncs_lp.constrained.warm import WarmConstrainedLP
    from wncs_lp.errors import InfeasibleConstraintsError

    sc = wncs_lp.load_scenario(ROOT / "formulations" / "paper_p12_cloud_budget.toml", [f"tau_cap={cap}"])
    mdp = wncs_lp.build(sc)
    (c,) = constraints_for(mdp, sc.constraints)
    log(f"cap {cap}: {mdp.n_states:,} states, {mdp.n_pairs:,} pairs")
    rows = []
    for mode in modes:
        solver = None
        if mode != "cold-clarabel":
            solver = WarmConstrainedLP(mdp, [c.with_bounds(max=float(bounds[0]))])
        for b in bounds:
            cons = [c.with_bounds(max=float(b))]
            t0 = time.perf_counter()
            try:
                if mode == "cold-clarabel":
                    sol = solve_constrained_lp(mdp, cons)
                else:
                    sol = solver.solve(cons, warm=mode == "warm")
            except InfeasibleConstraintsError:
                rows.append({"cap": cap, "states": mdp.n_states, "pairs": mdp.n_pairs, "mode": mode, "bound": b,
                             "seconds": time.perf_counter() - t0, "status": "infeasible"})
                continue
            dt = time.perf_counter() - t0
            st = sol.stats
            # LP time: Clarabel + its crossover, or the HiGHS run plus any abandoned warm restart
            lp_s = float(st.get("solve_time", 0.0)) + float(st.get("crossover_seconds", 0.0)) \
                + float(st.get("warm_abandoned_seconds", 0.0))
            rows.append({"cap": cap, "states": mdp.n_states, "pairs": mdp.n_pairs, "mode": mode, "bound": float(b),
                         "seconds": dt, "lp_seconds": lp_s, "iterations": int(st.get("solver_iterations", 0)),
                         "gain": sol.gain, "multiplier": float(sol.multipliers[0]), "randomized": sol.n_randomized,
                         "status": sol.status, "method": sol.method})
            r = rows[-1]
            log(f"  {mode:>13} b={b:.4f} {dt:7.2f} s (LP {lp_s:6.2f} s, {r['iterations']:>6} it) gain {sol.gain:.10g} "
                f"lambda {r['multiplier']:.8g} {sol.method} {sol.status}")
    return rows


def summary(rows: list[dict], cap: int) -> list[str]:
    """The summary lines of one cap (also usable on the rows read back from the CSV)."""
    by = {}
    for r in rows:
        by.setdefault(r["mode"], []).append(r)
    tot = {m: sum(r["seconds"] for r in rs) for m, rs in by.items()}
    lp = {m: sum(r.get("lp_seconds", 0.0) for r in rs) for m, rs in by.items()}
    out = [f"cap {cap}: " + ", ".join(f"{m} {tot[m]:.1f} s (LP {lp[m]:.1f} s)" for m in by)]
    if "warm" in by:
        for m in ("cold-clarabel", "cold-highs"):
            if m in by:
                out.append(f"cap {cap}: speed-up warm vs {m}: {tot[m] / tot['warm']:.1f}x total, "
                           f"{lp[m] / max(lp['warm'], 1e-9):.1f}x LP alone")
        if "cold-clarabel" in by:
            w = {r["bound"]: r for r in by["warm"]}
            dg, dl, at, dl_in = 0.0, 0.0, None, 0.0
            lo = min(r["bound"] for r in by["cold-clarabel"])
            pattern = all((r["status"] == "infeasible") == (w[r["bound"]]["status"] == "infeasible")
                          for r in by["cold-clarabel"])
            for r in by["cold-clarabel"]:
                q = w[r["bound"]]
                if r["status"] == "infeasible" or q["status"] == "infeasible":
                    continue
                dg = max(dg, abs(q["gain"] - r["gain"]) / abs(r["gain"]))
                d = abs(q["multiplier"] - r["multiplier"]) / max(abs(r["multiplier"]), 1e-9 * abs(r["gain"]))
                if d > dl:
                    dl, at = d, r["bound"]
                if r["bound"] > lo:  # b = 0: the end of the feasible range, any large enough lambda is optimal
                    dl_in = max(dl_in, d)
            ok = sum(r["status"] == "optimal" for r in by["warm"])
            out.append(f"cap {cap}: warm vs cold-clarabel: max gain rel diff {dg:.2e}, max multiplier rel diff "
                       f"{dl:.2e} (at b = {at}; {dl_in:.2e} for b > {lo:g}), same feasibility pattern: {pattern}; warm points optimal: "
                       f"{ok}/{len(by['warm'])}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--caps", default="12,16", help="tau caps (comma list; default 12,16)")
    ap.add_argument("--points", type=int, default=20, help="bounds per curve (default 20)")
    ap.add_argument("--lo", type=float, default=0.0)
    ap.add_argument("--hi", type=float, default=0.3)
    ap.add_argument("--modes", default="warm,cold-highs,cold-clarabel")
    ap.add_argument("--csv", default=str(ROOT / "benchmarks" / "tradeoff_warm.csv"))
    args = ap.parse_args(argv)
    bounds = np.linspace(args.lo, args.hi, args.points)
    log("warm-up (imports, numba kernels, HiGHS) at cap 6, off the clock")
    run_cap(6, bounds[:3], args.modes.split(","))
    rows, lines = [], []
    for cap in (int(c) for c in args.caps.split(",")):
        rs = run_cap(cap, bounds, args.modes.split(","))
        rows += rs
        lines += summary(rs, cap)
        for line in lines[-4:]:
            log(line)
    with open(args.csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS, lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in r.items()})
    log("\n".join(["", *lines, f"wrote {args.csv}"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
