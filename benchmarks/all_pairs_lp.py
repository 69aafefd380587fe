"""Issue 33, a prototype: the second-order ("all pairs at once") relaxation, solved as one LP.

    python benchmarks/all_pairs_lp.py --out /tmp/ap.csv    # edge 2-4 sensors at caps 12-20, cloud 3, 4 at cap 16
    python benchmarks/all_pairs_lp.py --instances edge:3:30,edge:4:40 --known benchmarks/calibration_load.csv
    python benchmarks/all_pairs_lp.py --count lab16                    # only the LP's size at bounds_lab16

The instances are benchmarks/calibration_load.py's (``SERVER:N:CAP``: the lab's scalar sensors on
one server). Every relaxation of the toolkit keeps the ages of at most one group of processes
jointly; here EVERY pair {k, l} keeps its own: an occupation measure x_kl over the pair's private
system (relaxation 3's chain of the group (k, l): state (tau_k, tau_l, C_kl), idling allowed),

* x_kl stationary (the balance equations of the pair chain) and a probability law;
* consistency: the marginal of x_kl on k's private state-action (tau_k, C_k, a_k) equals y_k, an
  occupation measure over k's private chain (relaxation 1's), for every l (and the same for l);
* capacity: sum_k E_{y_k}[claim_{m,k}] = 1 on every server (<= 1 where relaxation 1 reads the
  inequality off the automaton);

minimising sum_k E_{y_k}[q_k]. Under any stationary policy of the real system the real stationary
law projects onto every pair's private system consistently (relaxation 3's argument), so the LP's
optimum is a lower bound on g*; it is at least relaxation 3's with any partition into pairs (those
constraints are a subset). The LP's optimum is **not certified** (a HiGHS floating-point solution:
its residuals are reported); g* by certified matrix-free value iteration, relaxations 3 and 4
certified as the toolkit computes them.

The pair -> member map is built from the pair chain's own model (``project`` of its configurations,
``project_labels`` of its actions onto its member i) and checked on every pair-chain state-action
before the LP is posed: the member's AoI cost and claims add up to the pair's, and the pair's
transition law, projected on the member's private states, is exactly the member's transition law
under the projected action.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bounds import load1, peak_gib  # noqa: E402  (benchmarks/bounds.py)
from calibration_load import system_for  # noqa: E402
from wncs_lp.bounds import lower_bound  # noqa: E402
from wncs_lp.bounds.grouped import PrivateChains  # noqa: E402
from wncs_lp.bounds.private import PrivateChain, chain_key, private_bound  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "g_star", "lb_all_pairs", "looseness_all_pairs", "lb_3", "looseness_3", "lb_4",
           "looseness_4", "lp_rows", "lp_cols", "lp_nonzeros", "lp_seconds", "primal_residual", "dual_residual",
           "duality_gap", "pair_states", "status", "load1", "peak_gib"]
DEFAULT = [("edge", 2, 12), ("edge", 3, 12), ("edge", 3, 16), ("edge", 3, 20), ("edge", 4, 12), ("edge", 4, 16),
           ("edge", 4, 20), ("cloud", 3, 16), ("cloud", 4, 16)]


def member_map(pair: PrivateChain, i: int, member: PrivateChain) -> np.ndarray:
    """(L_pair,) index, among the member chain's state-action pairs, of the projection of every
    state-action pair of the pair chain onto its member i (0 or 1): (tau_i, C_i, a_i)."""
    pm, mm = pair.model, member.model
    # configurations: the pair's projected onto member i is a configuration of member's chain
    col = np.array([member.config_index[pm.project(cfg, i)] for cfg in pm.automaton.configs], np.int64)
    # actions: (pair config, local action) -> member's local action in the projected configuration
    acts = pm.automaton.actions
    m_index = [{tuple(a): j for j, a in enumerate(mm.automaton.actions[c])} for c in range(member.n_configs)]
    amax = max(len(a) for a in acts)
    act = np.full((len(acts), amax), -1, np.int64)
    for c, a in enumerate(acts):
        lab = pm.project_labels(np.asarray(a, np.int64).reshape(len(a), -1), i)
        act[c, : len(a)] = [m_index[col[c]][tuple(int(x) for x in row)] for row in lab]
    # member states (C_i, tau_i) -> state index
    mst = member.mdp.states
    m_state = np.full((member.n_configs, member.cap + 1), -1, np.int64)
    m_state[np.asarray(mst.config), np.asarray(mst.tau)[:, 0]] = np.arange(member.mdp.n_states)
    mdp = pair.mdp
    s = mdp.s_indices
    j = np.arange(mdp.n_pairs) - mdp.pair_ptr[s]
    cfg = np.asarray(mdp.states.config)[s]
    tau = np.asarray(mdp.states.tau)[s, i]
    ms = m_state[col[cfg], tau]
    if np.any(ms < 0) or np.any(act[cfg, j] < 0):
        raise RuntimeError("a pair state-action projects onto no state-action of the member's private chain")
    out = member.mdp.pair_ptr[ms] + act[cfg, j]
    # the projected transition law: P_pair projected on member states == P_member at the image
    proj_state = sp.csr_matrix((np.ones(mdp.n_states), (np.arange(mdp.n_states),
                                m_state[col[np.asarray(mdp.states.config)], np.asarray(mdp.states.tau)[:, i]])),
                               shape=(mdp.n_states, member.mdp.n_states))
    diff = abs(mdp.P @ proj_state - member.mdp.P[out]).max()
    if diff > 1e-12:
        raise RuntimeError(f"the pair chain's transition law does not project onto the member's (max diff {diff:.3g})")
    return out


def all_pairs_lp(system, capacity: str, method: str = "highs-ipm") -> dict:
    """Pose and solve the all-pairs LP of ``system``; its value, size, time and residuals."""
    n, M = system.n_processes, system.n_servers
    chains = PrivateChains(system.model)
    singles = [chains.of((k,)) for k in range(n)]
    pairs = list(itertools.combinations(range(n), 2))
    pchains = [chains.of(p) for p in pairs]
    # variable blocks: x_p for every pair, then y_k for every process
    sizes = [c.mdp.n_pairs for c in pchains] + [c.mdp.n_pairs for c in singles]
    off = np.concatenate([[0], np.cumsum(sizes)])
    ycol = {k: off[len(pairs) + k] for k in range(n)}
    rows, b, nrow = [], [], 0

    def add(block: sp.spmatrix, col0: int, rhs) -> None:
        nonlocal nrow
        coo = block.tocoo()
        rows.append((coo.row + nrow, coo.col + col0, coo.data))
        b.append(np.broadcast_to(np.asarray(rhs, float), (block.shape[0],)))

    for t, ((k, l), ch) in enumerate(zip(pairs, pchains)):
        mdp = ch.mdp
        L = mdp.n_pairs
        E = sp.csr_matrix((np.ones(L), (mdp.s_indices, np.arange(L))), shape=(mdp.n_states, L))
        add(E - mdp.P.T, off[t], 0.0); nrow += mdp.n_states                       # balance
        add(sp.csr_matrix(np.ones((1, L))), off[t], 1.0); nrow += 1              # probability
        maps = [member_map(ch, i, singles[member]) for i, member in enumerate((k, l))]
        for mp, member in zip(maps, (k, l)):                                       # consistency
            Lm = singles[member].mdp.n_pairs
            add(sp.csr_matrix((np.ones(L), (mp, np.arange(L))), shape=(Lm, L)), off[t], 0.0)
            add(-sp.identity(Lm, format="csr"), ycol[member], 0.0); nrow += Lm
            b.pop()  # the two blocks share their rows and right-hand side
        # costs and claims of the pair are the sums of its members' at the images
        m0, m1 = maps
        if (abs(ch.aoi_cost - singles[k].aoi_cost[m0] - singles[l].aoi_cost[m1]).max() > 1e-9
                or abs(ch.claims - singles[k].claims[m0] - singles[l].claims[m1]).max() > 1e-12):
            raise RuntimeError(f"pair {(k, l)}: costs or claims are not the members' sums")
    r = np.concatenate([x[0] for x in rows]); cidx = np.concatenate([x[1] for x in rows])
    data = np.concatenate([x[2] for x in rows])
    A_eq = sp.csr_matrix((data, (r, cidx)), shape=(nrow, off[-1]))
    b_eq = np.concatenate(b)
    cap = sp.lil_matrix((M, off[-1]))
    c = np.zeros(off[-1])
    for k in range(n):
        sl = slice(ycol[k], ycol[k] + singles[k].mdp.n_pairs)
        c[sl] = singles[k].aoi_cost
        for m in range(M):
            cap[m, sl] = singles[k].claims[:, m]
    cap = cap.tocsr()
    kw = {"A_eq": sp.vstack([A_eq, cap]).tocsr(), "b_eq": np.concatenate([b_eq, np.ones(M)])} \
        if capacity == "equality" else {"A_eq": A_eq, "b_eq": b_eq, "A_ub": cap, "b_ub": np.ones(M)}
    t0 = time.perf_counter()
    res = linprog(c, bounds=(0, None), method=method, **kw)
    secs = time.perf_counter() - t0
    A_all = kw["A_eq"] if "A_ub" not in kw else sp.vstack([kw["A_eq"], kw["A_ub"]]).tocsr()
    out = {"status": f"{method}: {res.message}", "lp_rows": A_all.shape[0], "lp_cols": A_all.shape[1], "lp_nonzeros": A_all.nnz,
           "lp_seconds": round(secs, 2), "pair_states": [int(ch.mdp.n_states) for ch in pchains]}
    if res.status != 0:
        return {**out, "lb_all_pairs": float("nan")}
    x = res.x
    # residuals: primal (equalities, inequalities, x >= 0), dual (reduced costs >= 0), duality gap
    prim = max(abs(kw["A_eq"] @ x - kw["b_eq"]).max(), max(-x.min(), 0.0),
               max((kw["A_ub"] @ x - kw["b_ub"]).max(), 0.0) if "A_ub" in kw else 0.0)
    y = res.eqlin.marginals
    red = c - kw["A_eq"].T @ y
    dual_obj = kw["b_eq"] @ y
    if "A_ub" in kw:
        red -= kw["A_ub"].T @ res.ineqlin.marginals
        dual_obj += kw["b_ub"] @ res.ineqlin.marginals
    return {**out, "lb_all_pairs": float(res.fun), "primal_residual": float(prim),
            "dual_residual": float(max(-red.min(), 0.0)), "duality_gap": float(abs(c @ x - dual_obj))}


def from_csv(path: str, instance: str) -> dict | None:
    """g* and relaxations 3 and 4 of ``instance`` as calibration_load.py's CSV ``path`` has them."""
    import csv

    with open(path) as f:
        rows = [r for r in csv.DictReader(f) if r["instance"] == instance]
    got = {r["row"][:4] if r["row"].startswith("LB") else r["row"]: float(r["value"]) for r in rows}
    if not {"optimum g*", "LB 3", "LB 4"} <= set(got):
        return None
    return {"g": got["optimum g*"], 3: got["LB 3"], 4: got["LB 4"]}


def run(server: str, n: int, cap: int, csv_path: str | None = None, method: str = "highs-ipm") -> dict:
    """The all-pairs LP at one instance, beside g* and relaxations 3 and 4 at the same cap (computed,
    or read from calibration_load.py's CSV ``csv_path`` where it has the instance)."""
    system = system_for(server, n, cap)
    l0 = load1()
    known = from_csv(csv_path, f"{server}:{n}:{cap}") if csv_path else None
    capacity = private_bound(system).stats["capacity"]
    row = {"instance": f"{server}:{n}:{cap}", "cap": cap, "load1": l0, **all_pairs_lp(system, capacity, method)}
    print(f"  [{server}:{n}:{cap}] LP {row['lb_all_pairs']:.10g} in {row['lp_seconds']} s ({row['status']})",
          file=sys.stderr, flush=True)
    g = known["g"] if known else float(matrix_free_value_iteration(system, tol=1e-9).gain)
    row["g_star"], row["looseness_all_pairs"] = g, (g - row["lb_all_pairs"]) / g
    for number in (3, 4):
        lb = known[number] if known else float(lower_bound(system, number).lower_bound)
        row[f"lb_{number}"], row[f"looseness_{number}"] = lb, (g - lb) / g
    row["status"] += " (g*, LB 3, LB 4 from the CSV)" if known else ""
    row["peak_gib"] = peak_gib()
    return row


def count(scenario: str) -> dict:
    """The all-pairs LP's size at a shipped scenario, with symmetry by type: identical processes
    share one single chain and one pair chain per pair of types (the LP is invariant under
    permuting identical processes, so its optimum can be taken symmetric)."""
    import wncs_lp
    from wncs_lp.models import model_for

    model = model_for(wncs_lp.load_scenario(wncs_lp.scenario_path(scenario)))
    n = model.scenario.n_processes
    kind = [chain_key(model.private_scenario(k)) for k in range(n)]
    first = {}
    for k, key in enumerate(kind):
        first.setdefault(key, k)
    types = sorted(first.values())
    chains, out = PrivateChains(model), {"types": len(types), "type_pairs": [], "cols": 0, "rows": 0, "nnz": 0}
    # a pair of two processes of the same type: the type's first two processes
    second = {key: next((k for k in range(n) if kind[k] == key and k != first[key]), None) for key in first}
    for a, b in itertools.combinations_with_replacement(types, 2):
        pair = (a, b) if a != b else (a, second[kind[a]])
        if pair[1] is None:
            continue
        ch = chains.of(tuple(sorted(pair)))
        singles = [chains.of((k,)).mdp.n_pairs for k in pair]
        out["type_pairs"].append((pair, int(ch.mdp.n_states), int(ch.mdp.n_pairs), int(ch.mdp.P.nnz)))
        out["cols"] += ch.mdp.n_pairs
        out["rows"] += ch.mdp.n_states + 1 + sum(singles)
        out["nnz"] += ch.mdp.P.nnz + ch.mdp.n_pairs * 3 + ch.mdp.n_pairs  # balance, two marginals, probability
        print(f"pair {pair}: {ch.mdp.n_states:,} states, {ch.mdp.n_pairs:,} pairs, {ch.mdp.P.nnz:,} transitions "
              f"(peak {peak_gib()} GiB, load {load1()})", flush=True)
    out["cols"] += sum(chains.of((k,)).mdp.n_pairs for k in types)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--instances", default=None, help="SERVER:SENSORS:CAP,... (calibration_load.py's instances)")
    ap.add_argument("--out", default=None, help="CSV file (written after every instance)")
    ap.add_argument("--known", default=None, metavar="CSV",
                    help="calibration_load.py's CSV: g*, LB 3 and LB 4 read from it where it has the instance")
    ap.add_argument("--method", default="highs-ipm", choices=("highs", "highs-ds", "highs-ipm"),
                    help="scipy's HiGHS method for the LP (default: the interior point, with crossover)")
    ap.add_argument("--count", default=None, metavar="SCENARIO",
                    help="only the LP's size at a shipped scenario (symmetry by type), e.g. bounds_lab16")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.count:
        c0 = time.process_time()
        got = count(args.count)
        print(f"{args.count} ({time.process_time() - c0:.1f} s of CPU): {got['types']} types, {len(got['type_pairs'])} type pairs; LP {got['rows']:,} rows x "
              f"{got['cols']:,} columns, ~{got['nnz']:,} nonzeros")
        return 0
    todo = DEFAULT if args.instances is None else [(s.split(":")[0], int(s.split(":")[1]), int(s.split(":")[2]))
                                                   for s in args.instances.split(",")]
    rows = []
    for server, n, cap in todo:
        row = run(server, n, cap, args.known, args.method)
        rows.append(row)
        print(f"{row['instance']:<12} g* {row['g_star']:.8g}  all pairs {row['lb_all_pairs']:.8g} "
              f"({100 * row['looseness_all_pairs']:.3f}%)  LB3 {100 * row['looseness_3']:.3f}%  "
              f"LB4 {100 * row['looseness_4']:.3f}%  LP {row['lp_rows']}x{row['lp_cols']} nnz {row['lp_nonzeros']} "
              f"{row['lp_seconds']} s  residuals {row.get('primal_residual', float('nan')):.1e} / "
              f"{row.get('dual_residual', float('nan')):.1e} / gap {row.get('duality_gap', float('nan')):.1e}  "
              f"load {row['load1']}", flush=True)
        if args.out:
            atomic_write_csv(args.out, rows, COLUMNS, extras="ignore")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
