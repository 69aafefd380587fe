"""One command for the performance numbers of issue 8: builder, DP, LP, auto, peers.

    python benchmarks/run.py --out benchmarks/results.csv            # ~15 minutes
    python benchmarks/run.py --quick --out /tmp/quick.csv            # ~2 minutes, small sizes

Every ratio is against a baseline run in the same command on the same machine (the machine is
shared, so absolute seconds drift; ratios less so). DP/builder timings are the best of
``--repeats`` runs. Peers that are not installed are reported as unavailable (``pip install
'wncs_lp[bench]'``). Sections:

* builder -- vectorised ``build_aoi_mdp`` vs the original loop ``build_aoi_mdp_loop`` (same
  automaton), pairs/second, tracemalloc peak of the assembly, and the process peak RSS.
* dp      -- our certified value iteration (numba MPI, numba Jacobi RVI, scipy Jacobi RVI =
  the baseline) vs stormpy LRA and pymdptoolbox RVI; every gain compared with the reference
  (our tightest certificate); bandwidth floor = bytes per sweep / copy bandwidth x sweeps.
* lp      -- plain primal occupation LP on Clarabel (baseline) vs the reduced LP, the dual
  (gain-bias) LP, qdldl instead of faer, iterative refinement off, and HiGHS via scipy.
* auto    -- ``solve(method="auto")``: which method it picked and whether the cross-check agreed.
"""
from __future__ import annotations

import argparse
import csv
import gc
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))  # the independent reference builders (tests/reference/)
sys.path.insert(0, str(Path(__file__).resolve().parent))

import peers  # noqa: E402
from reference.loop_builder import build_aoi_mdp_loop  # noqa: E402
from wncs_lp.models import build  # noqa: E402
from wncs_lp.models.assemble import build_aoi_mdp  # noqa: E402
from wncs_lp.models.cost import cost_tables  # noqa: E402
from wncs_lp.models.preemption import preemption_automaton  # noqa: E402
from wncs_lp.models.wncs import wncs_automaton  # noqa: E402
from wncs_lp.scenario import load_scenario  # noqa: E402
from wncs_lp import solve  # noqa: E402
from wncs_lp.solvers import evaluate_policy, relative_value_iteration, value_iteration  # noqa: E402
from wncs_lp.solvers.kernels import numba_available, prepare  # noqa: E402
from wncs_lp.solvers.lp import solve_lp  # noqa: E402

F = ROOT / "formulations"
ROWS: list[dict] = []
FIELDS = ["section", "instance", "states", "pairs", "nnz", "method", "seconds", "ratio", "iterations", "gain",
          "gain_rel_err", "rel_gap", "status", "note"]


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def add(**kw) -> dict:
    row = {k: kw.get(k, "") for k in FIELDS}
    ROWS.append(row)
    g = row["gain"]
    err = row["gain_rel_err"]
    print(f"  {row['section']:<7} {row['instance']:<22} {row['method']:<30} {row['seconds']:>9.3f} s"
          f"  ratio {row['ratio'] if row['ratio'] == '' else format(row['ratio'], '7.2f')}"
          f"  gain {'' if g == '' else format(g, '.10g')}"
          f"  err {'' if err == '' else format(err, '.1e')}  {row['status']} {row['note']}", flush=True)
    return row


def best_of(fn, repeats: int):
    best, out = np.inf, None
    for _ in range(repeats):
        gc.collect()
        t = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t
        if dt < best:
            best = dt
    return best, out


def copy_bandwidth(nbytes: int = 400_000_000, repeats: int = 5) -> float:
    """Streaming bandwidth in bytes/s from a numpy copy (bytes read + bytes written)."""
    a = np.ones(nbytes // 8)
    b = np.empty_like(a)
    np.copyto(b, a)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t)
    return 2 * a.nbytes / best


def scenario(name: str, sets: list[str]):
    return load_scenario(F / name, sets)


def label(name: str, sets: list[str]) -> str:
    short = name.replace(".toml", "").replace("paper_", "").replace("preemption_", "pre_")
    return short + ("" if not sets else "@" + ",".join(s.split("=")[1] for s in sets))


# ------------------------------------------------------------------------------- builder
def bench_builder(cases, repeats: int, loop_max_pairs: int) -> None:
    log("== builder")
    for name, sets, expect in cases:
        sc = scenario(name, sets)
        inst = label(name, sets)
        make_auto = preemption_automaton if sc.model.kind == "preemption" else wncs_automaton
        t_auto, auto = best_of(lambda: make_auto(sc), repeats)
        q = cost_tables(sc)
        t_new, mdp = best_of(lambda: build_aoi_mdp(auto, sc.tau_caps, q), repeats)
        L, n = mdp.n_pairs, mdp.n_states
        if expect is not None:
            ok = (n, L) == expect
            note = f"counts {'match' if ok else 'DIFFER from'} the reference {expect[0]:,}/{expect[1]:,}"
        else:
            note = ""
        tracemalloc.start()
        build_aoi_mdp(auto, sc.tau_caps, q)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        t_old = None
        if L <= loop_max_pairs:
            t_old, old = best_of(lambda: build_aoi_mdp_loop(auto, sc.tau_caps, q), 1)
            same = (np.array_equal(old.P.indices, mdp.P.indices) and np.array_equal(old.P.data, mdp.P.data)
                    and np.array_equal(old.s_indices, mdp.s_indices))
            add(section="builder", instance=inst, states=n, pairs=L, nnz=mdp.P.nnz, method="loop builder (baseline)",
                seconds=t_auto + t_old, ratio=1.0, note=f"identical MDP: {same}")
            del old
        add(section="builder", instance=inst, states=n, pairs=L, nnz=mdp.P.nnz, method="vectorised builder",
            seconds=t_auto + t_new, ratio="" if t_old is None else (t_auto + t_old) / (t_auto + t_new),
            note=f"{L / (t_auto + t_new):,.0f} pairs/s end to end ({L / t_new:,.0f} assembly); automaton "
                 f"{t_auto:.2f} s; tracemalloc peak {peak / 2**20:,.0f} MiB; {note}")
        del mdp, auto
        gc.collect()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    log(f"   process peak RSS so far: {rss:,.0f} MiB")


# ------------------------------------------------------------------------------- DP
def bench_dp(cases, repeats: int, bandwidth: float, pymdp_max_states: int) -> None:
    log("== dp")
    for name, sets in cases:
        sc = scenario(name, sets)
        inst = label(name, sets)
        mdp = build(sc)
        n, L, nnz = mdp.n_states, mdp.n_pairs, mdp.P.nnz
        ref = value_iteration(mdp, tol=1e-12, max_iter=200_000)  # the reference gain, certified
        g_ref = ref.gain
        rel = lambda g: abs(g - g_ref) / abs(g_ref)  # noqa: E731
        common = dict(section="dp", instance=inst, states=n, pairs=L, nnz=nnz)
        add(**common, method="reference: vi tol 1e-12", seconds=ref.seconds, gain=g_ref, rel_gap=ref.gap,
            status=ref.status, iterations=ref.iterations,
            note=f"certificate [{ref.gain_lower:.12g}, {ref.gain_upper:.12g}]")
        t_base, base = best_of(lambda: relative_value_iteration(mdp, tol=1e-9, kernel="scipy"), repeats)
        add(**common, method="rvi scipy (baseline)", seconds=t_base, ratio=1.0, iterations=base.iterations,
            gain=base.gain, gain_rel_err=rel(base.gain), rel_gap=base.gap, status=base.status)
        d = prepare(mdp)
        variants = []
        if numba_available():
            value_iteration(mdp, max_iter=2)  # compile / load the numba cache outside the timing
            variants += [("vi numba mpi (default)", dict(kernel="numba")),
                         ("vi numba mpi, tol 1e-6 (Storm's)", dict(kernel="numba", tol=1e-6)),
                         ("vi numba gauss-seidel", dict(kernel="numba", scheme="gs")),
                         ("rvi numba jacobi 1 thread", dict(kernel="numba", scheme="jacobi")),
                         ("rvi numba jacobi 2 threads", dict(kernel="numba", scheme="jacobi", threads=2))]
        variants += [("vi scipy (jacobi)", dict(kernel="scipy"))]
        for label_, kw in variants:
            t, s = best_of(lambda: value_iteration(mdp, **kw), repeats)
            sweeps = s.stats["sweeps"] + s.stats["eval_sweeps"]
            floor_plain = d.bytes_per_sweep_plain / bandwidth * sweeps
            floor_comp = d.bytes_per_sweep / bandwidth * sweeps
            add(**common, method=label_, seconds=t, ratio=t_base / t, iterations=sweeps, gain=s.gain,
                gain_rel_err=rel(s.gain), rel_gap=s.gap, status=s.status,
                note=f"{t / sweeps * 1e3:.2f} ms/sweep; floor x{t / floor_plain:.1f} (plain bytes "
                     f"{d.bytes_per_sweep_plain / 1e6:.1f} MB), x{t / floor_comp:.1f} (compact "
                     f"{d.bytes_per_sweep / 1e6:.1f} MB)")
        # exact evaluation of the certified-optimal policy: sparse LU vs BiCGSTAB, and PI on top of it
        t_lu, ev_lu = best_of(lambda: evaluate_policy(mdp, ref.policy, method="direct"), 1)
        add(**{**common, "section": "eval"}, method="evaluate_policy: sparse LU (baseline)", seconds=t_lu, ratio=1.0,
            gain=ev_lu.gain, gain_rel_err=rel(ev_lu.gain), status=ev_lu.solver, note=f"residual {ev_lu.residual:.1e}")
        t_it, ev_it = best_of(lambda: evaluate_policy(mdp, ref.policy, method="iterative"), repeats)
        add(**{**common, "section": "eval"}, method="evaluate_policy: bicgstab", seconds=t_it, ratio=t_lu / t_it,
            gain=ev_it.gain, gain_rel_err=rel(ev_it.gain), status=ev_it.solver,
            note=f"residual {ev_it.residual:.1e}; gain vs LU {abs(ev_it.gain - ev_lu.gain) / abs(ev_lu.gain):.1e}")
        t, s = best_of(lambda: solve(mdp, "pi", policy0=value_iteration(mdp, tol=1e-4).policy), 1)
        add(**common, method="pi from vi(1e-4) policy", seconds=t, ratio=t_base / t, iterations=s.iterations,
            gain=s.gain, gain_rel_err=rel(s.gain), rel_gap=s.gap, status=s.status,
            note="evaluate_policy(method='auto'): bicgstab from 50k states, else LU")
        # peers
        if peers.available("stormpy"):
            try:
                r = peers.storm_lra(mdp)
                add(**common, method="stormpy LRA (peer)", seconds=r["seconds"], ratio=t_base / r["seconds"],
                    gain=r["gain"], gain_rel_err=rel(r["gain"]), status="ok",
                    note=f"conversion {r['convert_seconds']:.2f} s not counted; Storm default precision")
            except Exception as exc:  # noqa: BLE001
                add(**common, method="stormpy LRA (peer)", seconds=float("nan"), status="error", note=str(exc)[:80])
        else:
            add(**common, method="stormpy LRA (peer)", seconds=float("nan"), status="unavailable")
        if peers.available("pymdptoolbox") and n <= pymdp_max_states:
            r = peers.mdptoolbox_rvi(mdp, g_ref)
            add(**common, method="pymdptoolbox RVI (peer)", seconds=r["seconds"], ratio=t_base / r["seconds"],
                iterations=r["iterations"], gain=r["gain"], gain_rel_err=rel(r["gain"]),
                status="ok" if r["converged"] else "max_iter",
                note=f"epsilon = 1e-9 g; conversion {r['convert_seconds']:.2f} s not counted")
        elif not peers.available("pymdptoolbox"):
            add(**common, method="pymdptoolbox RVI (peer)", seconds=float("nan"), status="unavailable")
        del mdp
        gc.collect()


# ------------------------------------------------------------------------------- LP
def bench_lp(cases, with_qdldl: set, with_dual: set, with_plain: set, with_highs: set, only_best: set = frozenset()) -> None:
    log("== lp")
    for name, sets in cases:
        sc = scenario(name, sets)
        inst = label(name, sets)
        mdp = build(sc)
        n, L, nnz = mdp.n_states, mdp.n_pairs, mdp.P.nnz
        ref = value_iteration(mdp, tol=1e-12, max_iter=200_000).gain
        rel = lambda g: abs(g - ref) / abs(ref)  # noqa: E731
        common = dict(section="lp", instance=inst, states=n, pairs=L, nnz=nnz)
        base_t = None
        variants = []
        # Clarabel's own defaults (iterative refinement on) and exact-evaluation polishing for
        # the baseline and the single-lever rows; solve_lp's defaults for the "default" row
        ir = {"iterative_refinement_enable": True}
        if inst in with_plain:
            variants.append(("plain primal + pi polish (baseline)", dict(formulation="primal", polish="pi", settings=ir)))
        variants += [
            ("reduced + pi polish", dict(formulation="reduced", polish="pi", settings=ir)),
            ("reduced, no IR, vi polish (solve_lp default)", dict(formulation="reduced")),
            ("reduced, tol 1e-6, no IR, vi polish", dict(formulation="reduced", tol=1e-6)),
            ("reduced, tol 1e-4, no IR, vi polish", dict(formulation="reduced", tol=1e-4)),
        ]
        if inst in only_best:  # too big for every variant inside the time budget
            variants = [v for v in variants if "(solve_lp default)" in v[0]]
        if inst in with_dual:
            variants.append(("dual gain-bias + pi polish", dict(formulation="dual", polish="pi", settings=ir)))
        if inst in with_qdldl:
            variants.append(("plain primal, qdldl", dict(formulation="primal", polish="pi",
                                                         settings={**ir, "direct_solve_method": "qdldl"})))
            variants.append(("plain primal, no cost scaling", dict(formulation="primal", polish="pi", settings=ir,
                                                                   _noscale=True)))
        for label_, kw in variants:
            noscale = kw.pop("_noscale", False)
            if noscale:
                import wncs_lp.solvers.lp as lpmod

                orig = lpmod.build_lp

                def unscaled(m, _orig=orig):
                    d = _orig(m)
                    return lpmod.LPData(d.A_eq, d.b_eq, d.q * d.cost_scale, 1.0, d.x_scale, d.dropped_state)

                lpmod.build_lp = unscaled
            try:
                s = solve_lp(mdp, **kw)
            finally:
                if noscale:
                    lpmod.build_lp = orig
            st = s.stats
            if base_t is None and "baseline" in label_:
                base_t = s.seconds
            add(**common, method=label_, seconds=s.seconds, ratio="" if base_t is None else base_t / s.seconds,
                iterations=st["solver_iterations"], gain=s.gain, gain_rel_err=rel(s.gain), rel_gap=s.gap,
                status=f"{s.status}/{st['solver_status']}",
                note=f"LP {st['lp_seconds']:.1f} s + polish {s.seconds - st['lp_seconds']:.1f} s, raw LP gain err {rel(st['lp_objective']):.1e}, "
                     f"{st['lp_rows']}x{st['lp_cols']}; full-LP residuals: balance {st['full_balance_residual']:.1e}, "
                     f"dual {st['full_dual_violation']:.1e}; polish changes {st.get('polish_changed_states')}")
        if inst in with_highs:
            r = peers.highs_lp(mdp)
            add(**common, method="HiGHS via scipy, sum x = n (peer)", seconds=r["seconds"],
                ratio="" if base_t is None else base_t / r["seconds"], iterations=r["iterations"], gain=r["gain"],
                gain_rel_err=rel(r["gain"]), status=r["status"], note="raw LP objective, no polish")
        del mdp
        gc.collect()


# ------------------------------------------------------------------------------- auto
def bench_auto(cases) -> None:
    log("== auto")
    for name, sets in cases:
        sc = scenario(name, sets)
        mdp = build(sc)
        s = solve(mdp, "auto")
        st = s.stats
        agree = st.get("cross_check_agree")
        add(section="auto", instance=label(name, sets), states=mdp.n_states, pairs=mdp.n_pairs, nnz=mdp.P.nnz,
            method=f"auto -> {st['auto_choice']}", seconds=s.seconds, gain=s.gain, rel_gap=s.gap, status=s.status,
            note=(f"cross-check {st.get('cross_check_method')}: agree={agree}, rel diff "
                  f"{st.get('cross_check_rel_diff', float('nan')):.1e}" if st.get("cross_check_method")
                  else st.get("cross_check_skipped", "")))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results.csv"))
    ap.add_argument("--quick", action="store_true", help="small instances only (~2 minutes)")
    ap.add_argument("--repeats", type=int, default=2, help="best-of repeats of builder and DP timings")
    ap.add_argument("--sections", default="builder,dp,lp,auto")
    args = ap.parse_args(argv)
    sections = set(args.sections.split(","))
    t0 = time.perf_counter()
    bw = copy_bandwidth()
    print(f"copy bandwidth {bw / 1e9:.1f} GB/s (bytes read + written / time, best of 5, 400 MB); "
          f"numba {'available' if numba_available() else 'NOT available'}; "
          f"stormpy {peers.available('stormpy')}, pymdptoolbox {peers.available('pymdptoolbox')}", flush=True)
    if args.quick:
        builder = [("paper_p123.toml", ["tau_cap=8"], None), ("preemption_p123_u0d0.toml", ["tau_cap=6"], None)]
        dp = [("paper_p12.toml", ["tau_cap=16"]), ("paper_preemption_p12.toml", ["tau_cap=12"])]
        lp = [("paper_p12.toml", ["tau_cap=8"]), ("paper_p12.toml", ["tau_cap=12"])]
        plain = dual = qd = highs = {"p12@8", "p12@12"}
        auto = [("paper_p14.toml", ["tau_cap=6"]), ("paper_p12.toml", [])]
        pymdp_max = 50_000
    else:
        builder = [("paper_p123.toml", ["tau_cap=15"], (462_978, 862_756)),
                   ("paper_p123.toml", ["tau_cap=18"], (934_494, 1_731_703)),
                   ("paper_preemption_p12.toml", ["tau_cap=25"], None),
                   ("preemption_p123_u0d0.toml", [], None)]
        dp = [("paper_p12.toml", ["tau_cap=30"]), ("paper_p123.toml", ["tau_cap=15"]),
              ("paper_preemption_p12.toml", ["tau_cap=25"])]
        lp = [("paper_p12.toml", []), ("paper_p12.toml", ["tau_cap=20"]), ("paper_p12.toml", ["tau_cap=30"])]
        plain = {"p12", "p12@20"}
        dual = {"p12"}
        qd = {"p12"}
        highs = {"p12", "p12@20"}
        auto = [("paper_p14.toml", []), ("paper_p12.toml", []), ("paper_preemption_p12.toml", []),
                ("paper_p123.toml", ["tau_cap=15"])]
        pymdp_max = 150_000
    if "builder" in sections:
        bench_builder(builder, args.repeats, loop_max_pairs=4_000_000)
    if "dp" in sections:
        bench_dp(dp, args.repeats, bw, pymdp_max)
    if "lp" in sections:
        bench_lp(lp, qd, dual, plain, highs, only_best=set() if args.quick else {"p12@30"})
    if "auto" in sections:
        bench_auto(auto)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        for r in ROWS:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"wrote {out} ({len(ROWS)} rows) in {time.perf_counter() - t0:.0f} s; peak RSS {rss:,.0f} MiB", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
