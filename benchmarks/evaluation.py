"""Issue 36: exact evaluation of a fixed policy, the sparse LU against the iterative solves, across sizes.

    python benchmarks/evaluation.py                                  # the default instances, ~5 min
    python benchmarks/evaluation.py --instances lab:4:random,paper_p12:30:greedy --csv /tmp/eval.csv
    python benchmarks/evaluation.py --lu-max 30000 --csv benchmarks/evaluation.csv

For each instance (scenario, cap, policy) the policy's chain on the enumerated MDP is built once,
its recurrent class found, and the class's stationary law solved by

* ``lu``: the sparse LU of the bordered system (``wncs_lp.chain.class_stationary(method="lu")``),
  skipped above ``--lu-max`` states (its fill-in grows fast: minutes past ~20,000 states);
* ``iterative``: BiCGSTAB on the same system, restarted until the true residual passes
  (``method="iterative"``; the power iteration and the LU only if it misses);
* ``power``: the power iteration on the lazy chain alone (the former default from 20,000 states);
* ``certified``: the certified value iteration of the policy's chain (``value_iteration`` on the
  one-action MDP of P_pi: the solve's own driver and kernels), for the gain's certified bracket;
* ``matrix-free``: the certified matrix-free evaluation (``matrix_free_evaluate``, the driver of
  ``bound --policy``) over the AoI box without the stored matrix (not for round robin's memory).

Each is the best of ``--repeat`` runs after one warm-up (numba's compilation is not counted),
with the gain it gives (the LU's is the reference). ``ratio`` = LU seconds / iterative seconds:
above 1 the iterative solve wins. The crossover sets ``wncs_lp.chain.ITERATIVE_MIN_STATES``. The
machine is shared: the load average is printed and written with every row.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: scenario:cap:policy; "lab" is formulations/lab_5sensors.toml
DEFAULT = ("paper_p12:7:greedy,paper_p12:7:random,paper_p12:9:greedy,paper_p12:9:random,paper_p12:12:greedy,"
           "paper_p12:12:random,paper_p12:20:random,paper_p12:30:greedy,paper_p12:30:random,"
           "paper_p123:8:greedy,paper_p123:8:random,paper_p123:10:random,paper_p123:12:greedy,"
           "lab_5sensors:3:greedy,lab_5sensors:3:random,lab_5sensors:3:round_robin,lab_5sensors:4:greedy,"
           "lab_5sensors:4:random,lab_5sensors:4:round_robin,lab_5sensors:5:greedy,lab_5sensors:5:random")


def _best(fn, repeat: int):
    fn()  # warm-up
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def measure(name: str, cap: int, policy: str, repeat: int, lu_max: int) -> list[dict]:
    import scipy.sparse as sp

    import wncs_lp.chain as chain
    from wncs_lp import build, load_scenario, scenario_path
    from wncs_lp.evaluate import memory_chain
    from wncs_lp.mdp import MDP
    from wncs_lp.models.system import System
    from wncs_lp.workflow import make_policy
    from wncs_lp.solvers.dp import value_iteration

    sc = load_scenario(scenario_path(name)).with_overrides({"tau_cap": cap})
    system, mdp = System.from_scenario(sc), build(sc)
    pol = make_policy(policy, system, mdp)
    if hasattr(pol, "act_memory"):
        P, pairs = memory_chain(mdp, pol)
        c = np.tile(np.asarray(mdp.cost, float)[pairs[0]], pol.memory_size)
    else:
        P, c = chain.policy_matrices(mdp, pol.on_mdp(mdp))
    (cl,) = chain.recurrent_classes(P)
    m = cl.size
    Pc = sp.csr_matrix(P)[cl][:, cl].tocsr()
    rows = []
    head = {"instance": f"{name}:{cap}", "policy": policy, "states": int(P.shape[0]), "class": int(m),
            "nnz": int(Pc.nnz), "load": os.getloadavg()[0]}

    def law(method):
        return lambda: chain.class_stationary(P, cl, method)[0] @ c[cl]

    def power():
        pi = chain._power_stationary(Pc)
        return float("nan") if pi is None else pi @ c[cl]

    def certified():
        one = MDP.from_arrays(np.arange(P.shape[0]), np.zeros(P.shape[0], dtype=np.int64), c, sp.csr_matrix(P))
        sol = value_iteration(one, tol=1e-10)
        return sol.gain

    def matrix_free():
        from wncs_lp.solvers.matrix_free import matrix_free_evaluate

        return matrix_free_evaluate(system, pol, tol=1e-10).gain

    ref = None
    times = {}
    for method, fn in (("lu", law("lu")), ("iterative", law("iterative")), ("power", power), ("certified", certified),
                       ("matrix-free", matrix_free)):
        if (method == "lu" and m > lu_max) or (method == "matrix-free" and hasattr(pol, "act_memory")):
            continue
        sec, gain = _best(fn, repeat)
        times[method] = sec
        ref = gain if method == "lu" else ref
        rows.append({**head, "method": method, "seconds": sec, "gain": float(gain),
                     "rel_err": "" if ref is None else abs(gain - ref) / abs(ref)})
    for r in rows:
        r["ratio"] = times["lu"] / r["seconds"] if "lu" in times else ""
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--instances", default=DEFAULT, help="comma list of scenario:cap:policy")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--lu-max", type=int, default=30_000, help="largest class solved by the LU")
    ap.add_argument("--csv", default=None)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    out = []
    print(f"{'instance':<18} {'policy':<12} {'states':>8} {'class':>7} {'method':<10} {'seconds':>9} {'LU/it':>7} "
          f"{'rel err':>9} load", flush=True)
    for item in args.instances.split(","):
        name, cap, policy = item.split(":")
        for r in measure(name, int(cap), policy, args.repeat, args.lu_max):
            ratio = f"{r['ratio']:.2f}" if r["ratio"] != "" else ""
            err = f"{r['rel_err']:.1e}" if r["rel_err"] != "" else ""
            print(f"{r['instance']:<18} {r['policy']:<12} {r['states']:>8} {r['class']:>7} {r['method']:<10} "
                  f"{r['seconds']:>9.3f} {ratio:>7} {err:>9} {r['load']:.1f}", flush=True)
            out.append(r)
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(out[0]))
            w.writeheader()
            w.writerows(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
