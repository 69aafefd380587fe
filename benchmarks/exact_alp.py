"""Issue 33 probe: approximate LPs checked over the *whole* state space, on systems small enough to
enumerate -- how tight pair value functions are when their check is exact, and what aggregate queue
features add.

    python benchmarks/exact_alp.py --instances edge:3:12,edge:3:20,edge:4:12,edge:4:16 --out FILE

For each instance (``calibration_load.system_for``: the lab's first N sensors on one server, cap C)
the Section II MDP is enumerated and the average-cost approximate LP

    maximise g  s.t.  g + (Phi w)(s) <= c(s, a) + sum_s' P(s' | s, a) (Phi w)(s')   for every pair (s, a)

is solved by HiGHS (``scipy.optimize.linprog``, the interior point, the dual simplex if it fails) for
feature sets Phi built from the state (tau, C):

* ``sep``: h_k(tau_k, C) -- relaxation 2's value functions (its LP's optimum);
* ``count``: phi_t(#{k : tau_k >= t}, C) for every age t -- how many sensors are at least t old;
* ``rank``: h_k(tau_k, #{l != k : tau_l > tau_k}, C) -- sensor k's place in an age-ordered queue;
* ``pairs``: h_kl(tau_k, tau_l, C) for every pair -- relaxation 5's value functions.

Every feasible (g, w) is a Bellman sub-solution, so each optimum is a lower bound on g*; the value is
HiGHS's floating-point optimum, not certified, and the LP has a row per state-action pair, so this
runs only where the MDP can be enumerated. What it measures: with pair features the only difference
from relaxation 5 (the level-2 LP) is the check -- here over every state, there over the pairs'
marginals (the local consistency of the pair measures) -- so the distance between the two is what
the local check costs; ``count`` and ``rank`` ask whether a cheap summary of the queue helps.
One CSV row per instance and feature set: the value, g* (the certified matrix-free optimum, solved
in the run), the looseness, the LP's size and CPU seconds.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

sys.path.insert(0, str(Path(__file__).resolve().parent))
import wncs_lp  # noqa: E402
from calibration_load import system_for  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

KINDS = ("sep", "count", "rank", "pairs")


def features(tau: np.ndarray, cfg: np.ndarray, n_configs: int, cap: int, kinds: list[str]) -> sp.csr_matrix:
    """Phi: one indicator column per value of each feature (module docstring), unused columns dropped."""
    n, N = tau.shape
    blocks = []
    if "sep" in kinds:
        blocks += [((tau[:, k] - 1) * n_configs + cfg, cap * n_configs) for k in range(N)]
    if "count" in kinds:
        blocks += [((tau >= t).sum(1) * n_configs + cfg, (N + 1) * n_configs) for t in range(2, cap + 1)]
    if "rank" in kinds:
        blocks += [((((tau[:, k] - 1) * N + (tau > tau[:, [k]]).sum(1)) * n_configs + cfg), cap * N * n_configs)
                   for k in range(N)]
    if "pairs" in kinds:
        blocks += [(((tau[:, k] - 1) * cap + tau[:, l] - 1) * n_configs + cfg, cap * cap * n_configs)
                   for k in range(N) for l in range(k + 1, N)]
    offsets = np.cumsum([0] + [size for _, size in blocks])
    cols = np.stack([idx + off for (idx, _), off in zip(blocks, offsets)], 1).ravel()
    phi = sp.csr_matrix((np.ones(cols.size), (np.repeat(np.arange(n), len(blocks)), cols)), shape=(n, offsets[-1]))
    return phi[:, np.unique(phi.indices)]


def alp_value(mdp, kinds: list[str], cap: int) -> dict:
    """The approximate LP's optimum for one feature set, with its size and CPU seconds."""
    S = mdp.states
    phi = features(S.tau, S.config, len(S.configs), cap, kinds)
    m = (phi[mdp.s_indices] - mdp.P @ phi).tocsr()
    a = sp.hstack([sp.csr_matrix(np.ones((m.shape[0], 1))), m]).tocsr()
    c = np.zeros(a.shape[1])
    c[0] = -1.0
    c0 = time.process_time()
    for method in ("highs-ipm", "highs-ds"):
        res = linprog(c, A_ub=a, b_ub=mdp.cost, bounds=[(None, None)] * a.shape[1], method=method)
        if res.status == 0:
            break
    return {"features": "+".join(kinds), "value": -res.fun if res.status == 0 else float("nan"),
            "lp_rows": a.shape[0], "lp_columns": a.shape[1], "lp_nonzeros": a.nnz, "method": method,
            "status": res.message, "cpu_seconds": round(time.process_time() - c0, 2)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--instances", default="edge:3:12,edge:3:20,edge:4:12,edge:4:16",
                    help="SERVER:SENSORS:CAP, comma-separated (calibration_load.system_for)")
    ap.add_argument("--features", default="sep,sep+count+rank,sep+pairs",
                    help=f"feature sets, comma-separated, each of {KINDS} joined by '+'")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    sets = [f.split("+") for f in args.features.split(",")]
    for kinds in sets:
        if not kinds or any(k not in KINDS for k in kinds):
            ap.error(f"--features: each set is made of {KINDS} joined by '+', got {'+'.join(kinds)!r}")
    rows = []
    for inst in args.instances.split(","):
        server, sensors, cap = inst.split(":")
        system = system_for(server, int(sensors), int(cap))
        mdp = wncs_lp.build(system.scenario)
        gstar = float(matrix_free_value_iteration(system, tol=1e-9).gain)
        print(f"{inst}: {mdp.n_states:,} states, {mdp.s_indices.size:,} pairs, g* {gstar:.9g}", flush=True)
        for kinds in sets:
            row = {"instance": inst, "states": mdp.n_states, "g_star": gstar, **alp_value(mdp, kinds, int(cap))}
            row["looseness"] = (gstar - row["value"]) / gstar
            rows.append(row)
            print(f"  {row['features']:18s} {row['value']:.6f}  looseness {100 * row['looseness']:.3f}%  "
                  f"({row['lp_columns']:,} columns, {row['cpu_seconds']} s, {row['method']})", flush=True)
    atomic_write_csv(args.out, rows, list(rows[0]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
