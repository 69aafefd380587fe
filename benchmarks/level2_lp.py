"""Issue 33: a prototype of the level-2 joint relaxation -- every pair's ages on the joint configuration, all pairs at once.

    python benchmarks/level2_lp.py --out /tmp/level2.csv                          # the default one-server list
    python benchmarks/level2_lp.py --instances edge:3:16,edge:4:20 --out /tmp/l2.csv   # SERVER:SENSORS:CAP
    python benchmarks/level2_lp.py --count bounds_lab16,bounds_p1234_x4           # the LP's size only

Relaxation 4's dual keeps one occupation measure y_G(tau_G, C, a) per group G of a *partition*,
balanced on (tau_G, C), all with the same (C, a) marginal. This prototype takes **every** pair
{k, l} at once, y_kl(tau_k, tau_l, C, a), each balanced on (tau_k, tau_l, C), and makes them
consistent: for each sensor k, the marginal of y_kl on (tau_k, C, a) is the same for every l (one
variable z_k(tau_k, C, a) they all equal), and the z_k share the (C, a) marginal x. The objective is
sum_k <q_k, z_k>. Valid because the stationary law of any stationary policy of the real system,
projected onto (tau_k, tau_l, C, a), satisfies every pair's balance (the pair's ages and the joint
configuration move by the outcome of (C, a) alone) and these projections are marginals of one law;
so the LP's optimum is at most g*, and at least relaxation 4's with any partition into pairs (its
constraints are a subset of these). The LP is solved whole by HiGHS's interior point, and its
balance-row duals are certified by :func:`certify_level2`, a check over the whole AoI box (small
instances only; at scale a certificate would price the consistency rows and certify every pair's
chain, as relaxation 4 does its partition's).

Per instance (the lab's sensors on one server, ``calibration_load.system_for``): g* (certified
matrix-free value iteration), relaxation 4's certified bound (``lower_bound(system, 4)``), the LP's
size, objective, status and CPU seconds, and the certified bound from its duals. ``--count`` gives
the LP's columns for a shipped scenario without building it (:func:`layout`: sum over pairs of
tau_hat_k tau_hat_l |C x A|, plus the z_k and x).
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import wncs_lp  # noqa: E402
from bounds import load1, peak_gib  # noqa: E402  (benchmarks/bounds.py)
from calibration_load import system_for  # noqa: E402
from wncs_lp.bounds import lower_bound  # noqa: E402
from wncs_lp.bounds.joint_chains import JointData  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.iteration import gamma  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "g_star", "lb_level2", "looseness_level2", "lb_level2_certified", "looseness_certified",
           "certify_cpu_seconds", "lb_4", "looseness_4", "rows", "cols",
           "nonzeros", "lp_cpu_seconds", "status", "load1", "peak_gib"]
DEFAULT = "edge:2:12,edge:3:12,edge:3:16,edge:3:20,edge:4:12,edge:4:16,edge:4:20,cloud:3:16"


@dataclass(frozen=True)
class Layout:
    """Where the LP's pieces sit. Columns: every pair's y_kl(t_k, t_l, p) from ``y[k, l]`` at
    ``(t_k cap_l + t_l) P + p``, each z_k(t, p) from ``z[k]`` at ``t P + p``, x(p) from ``x``.
    Rows: pair (k, l)'s balance rows (t_k, t_l, C) from ``balance[k, l]`` at ``(t_k cap_l + t_l) |C| + C``,
    followed by its two consistency blocks (cap_k P and cap_l P rows); then each z_k's (C, a) rows, then
    the normalisation."""

    pairs: tuple
    y: dict
    z: dict
    x: int
    cols: int
    balance: dict


def layout(data: JointData) -> Layout:
    N, P, nC, caps = data.n_processes, int(data.act_ptr[-1]), data.n_configs, [int(c) for c in data.caps]
    pairs = tuple(itertools.combinations(range(N), 2))
    y, balance, cols, row = {}, {}, 0, 0
    for k, l in pairs:
        y[k, l], balance[k, l] = cols, row
        cols += caps[k] * caps[l] * P
        row += caps[k] * caps[l] * nC + (caps[k] + caps[l]) * P
    z = {}
    for k in range(N):
        z[k] = cols
        cols += caps[k] * P
    return Layout(pairs=pairs, y=y, z=z, x=cols, cols=cols + P, balance=balance)


def level2_lp(data: JointData):
    """(A, b, c) of the level-2 LP in the form min c z, A z = b, z >= 0 (:func:`layout`); under outcome
    e an age index t moves to min(t + 1, ``data.sat[e, k]``)."""
    N, P, nC, caps = data.n_processes, int(data.act_ptr[-1]), data.n_configs, data.caps
    lay = layout(data)
    R, C, V, b = [], [], [], []

    def add(r, c, v):
        R.append(np.asarray(r, np.int64).ravel()); C.append(np.asarray(c, np.int64).ravel())
        V.append(np.broadcast_to(np.asarray(v, float), np.shape(np.asarray(c).ravel())).copy())

    for k, l in lay.pairs:
        ck, cl = int(caps[k]), int(caps[l])
        tk, tl = (a.ravel() for a in np.meshgrid(np.arange(ck), np.arange(cl), indexing="ij"))
        base = lay.balance[k, l]
        row = base + ck * cl * nC
        b += [0.0] * (ck * cl * nC)
        for p in range(P):
            colp = lay.y[k, l] + (tk * cl + tl) * P + p
            add(base + (tk * cl + tl) * nC + data.pair_c[p], colp, 1.0)  # leaves (t, C)
            for e in range(data.out_ptr[p], data.out_ptr[p + 1]):  # enters (t', C')
                nk, nl = np.minimum(tk + 1, data.sat[e, k]), np.minimum(tl + 1, data.sat[e, l])
                add(base + (nk * cl + nl) * nC + data.out_nxt[e], colp, -data.out_prob[e])
        for who, t in ((k, tk), (l, tl)):  # the pair's marginal on (t_who, p) equals z_who
            cw = int(caps[who])
            for p in range(P):
                add(row + t * P + p, lay.y[k, l] + (tk * cl + tl) * P + p, 1.0)
                add(row + np.arange(cw) * P + p, lay.z[who] + np.arange(cw) * P + p, -1.0)
            row += cw * P
            b += [0.0] * (cw * P)
    for k in range(N):  # each z_k's (C, a) marginal is x
        ck = int(caps[k])
        for p in range(P):
            add(np.full(ck, row), lay.z[k] + np.arange(ck) * P + p, 1.0)
            add([row], [lay.x + p], -1.0)
            row += 1
            b.append(0.0)
    add(np.full(P, row), lay.x + np.arange(P), 1.0)
    row += 1
    b.append(1.0)
    A = sp.csr_matrix((np.concatenate(V), (np.concatenate(R), np.concatenate(C))), shape=(row, lay.cols))
    c = np.zeros(lay.cols)
    for k in range(N):
        for p in range(P):
            c[lay.z[k] + np.arange(int(caps[k])) * P + p] = data.q[k]
    return A, np.asarray(b), c


def certify_level2(data: JointData, duals: np.ndarray) -> float:
    """A certified lower bound from the LP's balance-row duals h_kl(t_k, t_l, C), by brute force.

    For any tables h_kl, g(h) = min over every (tau, C, a) of the box of
    sum_k q_k(tau_k) + sum_o P(o | C, a) sum_kl h_kl(tau'_kl, C'_o) - sum_kl h_kl(tau_kl, C)
    is a lower bound on g* (the approximate-LP argument: averaged over the optimal policy's stationary
    law the tables cancel), and at the LP's optimal duals it equals the LP's value up to its
    tolerance (summing the dual constraints of the pair, singleton and (C, a) columns gives exactly
    this inequality). As in :func:`wncs_lp.bounds.joint_chains.certificate_of`, each table is first
    shifted by a constant (which changes the inequality only by the outcome tables' defect from
    stochastic, ``data.prob_defect``), and a bound on the round-off (Higham's gamma) is subtracted.
    The box has prod_k tau_hat_k |C| states: a check for the small instances only.
    """
    N, P, nC, caps = data.n_processes, int(data.act_ptr[-1]), data.n_configs, [int(c) for c in data.caps]
    lay = layout(data)
    tables = {}
    for k, l in lay.pairs:
        h = duals[lay.balance[k, l]:lay.balance[k, l] + caps[k] * caps[l] * nC].reshape(caps[k], caps[l], nC)
        tables[k, l] = h - 0.5 * (h.max() + h.min())
    tau = [g.ravel() for g in np.meshgrid(*[np.arange(c) for c in caps], indexing="ij")]
    cost = sum(np.asarray(data.q[k])[tau[k]] for k in range(N))
    best = np.inf
    for p in range(P):
        c = data.pair_c[p]
        here = sum(tables[k, l][tau[k], tau[l], c] for k, l in lay.pairs)
        nxt = np.zeros_like(cost)
        for e in range(data.out_ptr[p], data.out_ptr[p + 1]):
            new = [np.minimum(tau[k] + 1, data.sat[e, k]) for k in range(N)]
            nxt += data.out_prob[e] * sum(tables[k, l][new[k], new[l], data.out_nxt[e]] for k, l in lay.pairs)
        best = min(best, float((cost + nxt - here).min()))
    hk = sum(float(np.abs(h).max()) for h in tables.values())
    terms = data.max_outcomes * len(lay.pairs) + len(lay.pairs) + N + 2
    err = gamma(terms) * (sum(float(np.abs(q).max()) for q in data.q) + 2.0 * hk) + data.prob_defect * hk
    return best - err


def run(item: str) -> dict:
    from scipy.optimize import linprog

    server, sensors, cap = item.split(":")
    system = system_for(server, int(sensors), int(cap))
    l0 = load1()
    g = float(matrix_free_value_iteration(system, tol=1e-9).gain)
    lb4 = float(lower_bound(system, 4).lower_bound)
    data = JointData.from_system(system)
    A, b, c = level2_lp(data)
    c0 = time.process_time()
    res = linprog(c, A_eq=A, b_eq=b, bounds=(0, None), method="highs-ipm")
    cpu = time.process_time() - c0
    lb = float(res.fun) if res.status == 0 else float("nan")
    c0 = time.process_time()
    cert = certify_level2(data, res.eqlin.marginals) if res.status == 0 else float("nan")
    cert_cpu = time.process_time() - c0
    return {"instance": item, "cap": int(cap), "g_star": g, "lb_level2": lb, "looseness_level2": (g - lb) / g,
            "lb_level2_certified": cert, "looseness_certified": (g - cert) / g, "certify_cpu_seconds": round(cert_cpu, 2),
            "lb_4": lb4, "looseness_4": (g - lb4) / g, "rows": A.shape[0], "cols": A.shape[1], "nonzeros": A.nnz,
            "lp_cpu_seconds": round(cpu, 2), "status": res.message, "load1": l0, "peak_gib": peak_gib()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--instances", default=DEFAULT, help="SERVER:SENSORS:CAP,... (default: %(default)s)")
    ap.add_argument("--count", default="", help="shipped scenarios: print the LP's columns, build nothing")
    ap.add_argument("--out", default="", help="CSV to write")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.count:
        for name in args.count.split(","):
            system = System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name)))
            print(f"{name}: {layout(JointData.from_system(system)).cols:,} columns")
        return 0
    rows = []
    for item in args.instances.split(","):
        r = run(item)
        print(f"{item:12s} g* {r['g_star']:.6f}  level 2 {r['lb_level2']:.6f} ({100 * r['looseness_level2']:.3f}%)  "
              f"certified {r['lb_level2_certified']:.6f} ({100 * r['looseness_certified']:.3f}%)  "
              f"relaxation 4 {100 * r['looseness_4']:.3f}%  LP {r['rows']}x{r['cols']} {r['lp_cpu_seconds']} s  "
              f"load {r['load1']}", flush=True)
        rows.append(r)
        if args.out:
            atomic_write_csv(args.out, rows, COLUMNS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
