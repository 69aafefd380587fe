"""Issues 17 and 34: the matrix-free certified solver against the stored-matrix one, alone at
scale, and its sweeps against the memory bandwidth (before / after a change, in one run).

    python benchmarks/matrix_free.py --out benchmarks/matrix_free.csv         # ~40 min on 2 cores
    python benchmarks/matrix_free.py --quick --out /tmp/mf.csv                # ~2 min
    python benchmarks/matrix_free.py --sections big --caps 20 --out /tmp/mf20.csv
    python benchmarks/matrix_free.py --sections big --caps 40 --policies "" --no-extrapolate   # largest
    # sweeps and GB/s of this tree and of an older one (git archive <commit> | tar -x -C /tmp/base)
    python benchmarks/matrix_free.py --sections sweeps --baseline /tmp/base \
        --instances paper_p1234:20,paper_p1234:30,bounds_mix6:10 --out /tmp/sweeps.csv
    # options of this tree against each other (the first the reference), e.g. the coarse correction
    python benchmarks/matrix_free.py --sections sweeps --instances paper_p1234:12,paper_p1234:20 \
        --variants '{"plain": {}, "aggregate": {"aggregate": true}}' --out /tmp/agg.csv
    # the certified time at the cap of the optimal policy, the commands' settings against the old
    # ones in turn, on solutions kept in a folder (solved and saved there when missing)
    python benchmarks/matrix_free.py --sections capmass --instances paper_p1234:20,paper_p1234:30 \
        --solutions /tmp/mfsol --repeats 2 --out /tmp/capmass.csv

Sections (one CSV row per measurement, a table on stdout):

* ``compare`` -- instances where both run (processes 1, 2 at caps 12-40; 1-3 at 12-18; 1-4 at
  6-10): ``build`` + ``solve(mdp, "vi")`` (numba MPI, certificate passes on ``--threads``
  threads) against ``matrix_free_value_iteration`` (1 and ``--threads`` threads), both to a
  relative bracket of 1e-9. Checked: each gain lies in the other's bracket and the two agree to
  1e-9 relative. ``ratio`` = stored seconds (build + solve) / matrix-free seconds.
* ``big`` -- processes 1-4 (``formulations/paper_p1234.toml``) at ``--caps`` (default 20, 25,
  30), each in its own process (so the peak RSS, ``resource.getrusage``, is that case's): the
  optimal gain certified to 1e-9 (and the time at which the bracket first reached 1e-6), then
  the exact (certified) gains of the ``--policies`` (default suboptimal, static, greedy) by
  matrix-free policy evaluation, and their gaps to the optimum.

* ``sweeps`` -- ``--instances`` (scenario:cap), each solved by ``matrix_free_value_iteration``
  with its defaults (or ``--options``) in a fresh process per tree: this one and, with
  ``--baseline DIR``, an older tree, in turn (A, B per instance, so a change of load hits both).
  Each worker first measures the machine's copy bandwidth (``np.copyto`` of 400 MB, bytes read +
  written, best of 5) and then solves; the row gives the passes over the layout (improvement
  sweeps and certificates + evaluation sweeps), seconds per pass, the bytes a pass must move at
  least (the value vector read and written, the policy byte written: 17 bytes a state) and the
  GB/s that makes, beside the copy bandwidth: ``floor_ratio`` = seconds per pass / (bytes per
  pass / copy bandwidth), the factor over the bandwidth floor. The ``ratio`` column of a
  baseline row is baseline seconds / this tree's seconds (its note adds the CPU and passes
  ratios). After the solve the worker times one pass of each kind on the solution (improvement
  sweep over every action and, where the tree has them, over the candidate actions;
  certificate; evaluation sweep): wall and CPU seconds, CPU ns a state and the factor over the
  bandwidth floor, in the row's note; and, timed inside the solve, each kind's passes, least
  and median wall seconds and CPU / wall (2: both threads busy all along), with the CPU seconds
  the machine's other processes used meanwhile (``/proc/stat``): the median against the least
  is what other jobs cost a threaded pass. Beside the bytes, the work: the outcome terms a state
  of each pass kind (``outcome_terms``: one product p * h[successor] added into a row), the G
  terms a CPU second each pass achieved, and what numba's compiled row loop alone sustains on one
  core at the layout's mean row length and the kind's outcomes a row (``term_rate``; on rows of
  1,024 states too, its per-row costs amortised). ``--variants '{"label": {options}, ...}'`` runs this tree
  once per variant instead (each with its options on top of ``--options``; the ratios against the
  first), e.g. the coarse correction (``{"aggregate": true}``) against the defaults; ``--repeats``
  alternates them that many rounds, ``--no-profile`` skips the one-pass timings (e.g. a phase to
  ``{"tol": 0.01}``), and ``{"gain_hint": "relaxation1"}`` passes relaxation 1's lower bound
  (computed in the worker, its CPU counted) as the solve's ``gain_hint``. The row's note gives the
  relative width at each of the first certificates and a coarse start's solve (``coarse_ratio``).

* ``capmass`` -- ``--instances`` (scenario:cap): the optimal policy (read from ``--solutions``
  / NAME_CAP.npz, or solved with the defaults and saved there), then
  ``matrix_free_cap_mass`` of it with each setting of ``CAPMASS_VARIANTS`` in turn,
  ``--repeats`` times (A, B, A, B: a change of load hits both): the Jacobi warm start and an
  absolute width of 1e-7 (the commands' settings until issue 34) against the commands' now
  (in-place sweeps from h = 0, ``CAP_COUNT_ATOL``). ``ratio`` is seconds / the first
  variant's in the same round (the note adds CPU and passes).

The machine is shared: every row records the 1-minute load average when it started (2 cores;
a load above ~1 means another job competed for them), and the CPU seconds of the worker.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import subprocess
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# a sweeps worker of another tree (--baseline) imports that tree's package
sys.path.insert(0, os.environ.get("WNCS_LP_BENCH_TREE", str(ROOT)))

import wncs_lp  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.workflow import make_policy  # noqa: E402
from wncs_lp.solvers.matrix_free import (  # noqa: E402
    matrix_free_evaluate,
    matrix_free_value_iteration,
)

COLUMNS = ["section", "instance", "cap", "states", "method", "threads", "seconds", "seconds_to_1e-6", "sweeps",
           "eval_sweeps", "gain", "gain_lower", "gain_upper", "rel_gap", "gap_to_optimum", "ratio",
           "peak_rss_gib", "load1", "status", "note", "tree", "cpu_seconds", "passes", "seconds_per_pass",
           "bytes_per_pass", "gb_per_s", "copy_gb_per_s", "floor_ratio"]

COMPARE = [("paper_p12", c) for c in (12, 16, 20, 24, 28, 32, 36, 40)] + \
          [("paper_p123", c) for c in (12, 14, 16, 18)] + [("paper_p1234", c) for c in (6, 8, 10)]
COMPARE_QUICK = [("paper_p12", 12), ("paper_p12", 24), ("paper_p123", 12), ("paper_p1234", 6), ("paper_p1234", 8)]


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # ru_maxrss is in KiB on Linux


def time_to(history, rel) -> float | None:
    for _, _, t, lo, hi in history:
        if hi - lo <= rel * abs(0.5 * (lo + hi)):
            return round(t, 2)
    return None


def scenario(name, cap):
    return wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])


def row(**kw):
    out = {c: "" for c in COLUMNS}
    out.update({k: v for k, v in kw.items() if k in out})
    return out


# ----------------------------------------------------------------------------- compare
def warm_up(threads):
    """Load (or compile) the kernels of both solvers before anything is timed."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = scenario("paper_p12", 8)
        wncs_lp.solve(wncs_lp.build(sc), "vi", threads=threads)
        for th in sorted({1, threads}):  # a thread count given is used at any size
            matrix_free_value_iteration(sc, threads=th)
            matrix_free_evaluate(sc, make_policy("greedy", System.from_scenario(sc)), threads=th)


def compare(instances, threads, tol):
    rows = []
    warm_up(threads)
    for name, cap in instances:
        sc = scenario(name, cap)
        ld = load1()
        t = time.perf_counter()
        mdp = wncs_lp.build(sc)
        t_build = time.perf_counter() - t
        t = time.perf_counter()
        vi = wncs_lp.solve(mdp, "vi", tol=tol, threads=threads)
        t_vi = time.perf_counter() - t
        stored = t_build + t_vi
        n = mdp.n_states
        del mdp
        rows.append(row(section="compare", instance=name, cap=cap, states=n, method="stored vi", threads=threads,
                        seconds=round(stored, 3), sweeps=vi.stats["sweeps"], eval_sweeps=vi.stats["eval_sweeps"],
                        gain=vi.gain, gain_lower=vi.gain_lower, gain_upper=vi.gain_upper, rel_gap=vi.gap,
                        load1=ld, status=vi.status, note=f"build {t_build:.3f} s + solve {t_vi:.3f} s"))
        for th in sorted({1, threads}):
            ld = load1()
            mf = matrix_free_value_iteration(sc, tol=tol, threads=th)
            slack = 1e-12 * abs(mf.gain)
            inside = (vi.gain_lower - slack <= mf.gain <= vi.gain_upper + slack
                      and mf.gain_lower - slack <= vi.gain <= mf.gain_upper + slack)
            rel = abs(mf.gain - vi.gain) / abs(vi.gain)
            rows.append(row(section="compare", instance=name, cap=cap, states=mf.stats["n_states"],
                            method="matrix-free", threads=th, seconds=round(mf.seconds, 3), sweeps=mf.stats["sweeps"],
                            eval_sweeps=mf.stats["eval_sweeps"], gain=mf.gain, gain_lower=mf.gain_lower,
                            gain_upper=mf.gain_upper, rel_gap=mf.gap, ratio=round(stored / mf.seconds, 2), load1=ld,
                            status=mf.status,
                            note=f"|g - g_vi|/g = {rel:.1e}; {'agree' if inside and rel <= 1e-9 else 'DISAGREE'}; "
                                 f"solve-only ratio {t_vi / mf.seconds:.2f}; "
                                 f"layout {mf.stats['n_states']:,} vs {n:,} reachable"))
            print(f"compare {name} cap {cap} ({n:,} states): stored {t_build:.2f} + {t_vi:.2f} s, matrix-free "
                  f"{th} thread(s) {mf.seconds:.2f} s (ratio {stored / mf.seconds:.2f}, solve only "
                  f"{t_vi / mf.seconds:.2f}), |dg|/g {rel:.1e} {'ok' if inside else 'BRACKETS DISJOINT'}, "
                  f"load {ld}", flush=True)
    return rows


# ----------------------------------------------------------------------------- big (worker)
def big_worker(cap, threads, tol, policies, extrapolate=True):
    sc = scenario("paper_p1234", cap)
    system = System.from_scenario(sc)
    out = []
    ld = load1()
    sol = matrix_free_value_iteration(system, tol=tol, threads=threads, progress=True, extrapolate=extrapolate)
    rss_solve = rss_gib()
    g, glo, ghi = sol.gain, sol.gain_lower, sol.gain_upper
    out.append(row(section="big", instance="paper_p1234", cap=cap, states=sol.stats["n_states"], method="optimal",
                   threads=threads, seconds=round(sol.seconds, 2),
                   **{"seconds_to_1e-6": time_to(sol.stats["history"], 1e-6)},
                   sweeps=sol.stats["sweeps"], eval_sweeps=sol.stats["eval_sweeps"], gain=g, gain_lower=glo,
                   gain_upper=ghi, rel_gap=sol.gap, gap_to_optimum=0.0, peak_rss_gib=round(rss_solve, 2), load1=ld,
                   status=sol.status, note=f"setup {sol.stats['seconds_setup']:.1f} s; fallback {sol.stats['fallback']}; "
                                           f"{sol.stats['value_vectors']} value vector(s), "
                                           f"{sol.stats['extrapolations']} extrapolation(s)"))
    print(json.dumps(out[-1]), flush=True)
    del sol
    for pname in policies:
        ld = load1()
        t = time.perf_counter()
        pol = make_policy(pname, system)
        t_make = time.perf_counter() - t
        ev = matrix_free_evaluate(system, pol, tol=tol, threads=threads, progress=True)
        # the policy's exact gain lies in [ev.gain_lower, ev.gain_upper] and g* in [glo, ghi]:
        # its gap (g_pi - g*)/g* is bracketed too; the midpoint is reported
        gap = (ev.gain - g) / g
        gap_lo, gap_hi = (ev.gain_lower - ghi) / ghi, (ev.gain_upper - glo) / glo
        out.append(row(section="big", instance="paper_p1234", cap=cap, states=ev.stats["n_states"], method=pname,
                       threads=threads, seconds=round(ev.seconds + t_make, 2),
                       **{"seconds_to_1e-6": time_to(ev.stats["history"], 1e-6)}, sweeps=ev.iterations,
                       gain=ev.gain, gain_lower=ev.gain_lower, gain_upper=ev.gain_upper, rel_gap=ev.gap,
                       gap_to_optimum=gap, peak_rss_gib=round(rss_gib(), 2), load1=ld, status=ev.status,
                       note=f"gap in [{gap_lo:.4%}, {gap_hi:.4%}]; policy built in {t_make:.1f} s, "
                            f"table {ev.stats['seconds_setup']:.1f} s"))
        print(json.dumps(out[-1]), flush=True)
        del pol, ev
    return out


def big(caps, threads, tol, policies, extrapolate=True):
    rows = []
    for cap in caps:
        cmd = [sys.executable, __file__, "--worker", str(cap), "--threads", str(threads), "--tol", str(tol),
               "--policies", ",".join(policies)] + ([] if extrapolate else ["--no-extrapolate"])
        print(f"big: processes 1-4 at cap {cap} (load {load1()}) ...", flush=True)
        for r in worker_rows(cmd):
            rows.append(r)
            print(f"  {r['method']:10s} gain {float(r['gain']):.9f} [{float(r['gain_lower']):.9f}, "
                  f"{float(r['gain_upper']):.9f}] {r['seconds']} s (1e-6 at {r['seconds_to_1e-6']} s), "
                  f"sweeps {r['sweeps']}, peak {r['peak_rss_gib']} GiB, gap {float(r['gap_to_optimum']):.4%}, "
                  f"load {r['load1']}", flush=True)
    return rows


def worker_rows(cmd, **kw):
    """The JSON rows a worker process prints on stdout (its stderr passes through), in order."""
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=None, text=True, **kw)
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0:
        print(f"  worker failed with exit code {proc.returncode}", flush=True)
    return rows


# ----------------------------------------------------------------------------- sweeps (worker)
#: Bytes a pass must move per state at least: the float64 value read and written, the policy byte.
FLOOR_BYTES_PER_STATE = 17


def copy_bandwidth(nbytes=400 << 20, repeats=5) -> float:
    """GB/s of ``np.copyto`` (bytes read + written), best of ``repeats``."""
    import numpy as np

    a = np.ones(nbytes // 8)
    b = np.empty_like(a)
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        np.copyto(b, a)
        best = min(best, time.perf_counter() - t)
    return 2 * a.nbytes / best / 1e9


# ----------------------------------------------------------------------------- the work floor (terms)
def outcome_terms(op, pol, cand=None) -> dict:
    """Outcome terms per pass kind, as (contiguous, saturated) counts over the layout.

    A term is one product p * h[successor] added into a row of the kernels' scratch: contiguous
    where it reads h[b + i] along the successor row, saturated past the row's split (the last
    AoI stays at its cap: one broadcast value). Kinds: ``all actions`` (an improvement sweep over
    every action; a certificate computes the same), ``candidates`` (the actions the bit sets
    ``cand`` allow), ``evaluation`` (what the fixed-policy kernel computes: each action used on a
    row, over the whole row) and ``policy`` (the policy's own outcomes only: the least an
    evaluation sweep must compute)."""
    import numpy as np

    N = op.N
    out = {k: np.zeros(2) for k in ("all actions", "candidates", "evaluation", "policy")}
    for c in range(op.off.size - 1):
        L = int(op.dims[c, N - 1])
        rows = int(op.off[c + 1] - op.off[c]) // L
        loN = int(op.lo[c, N - 1])
        a0 = int(op.act_ptr[c])
        pc = pol[op.off[c]:op.off[c + 1]].reshape(rows, L)
        for j in range(int(op.act_ptr[c + 1]) - a0):
            ob, oe = int(op.out_ptr[a0 + j]), int(op.out_ptr[a0 + j + 1])
            sp = np.clip(op.e_m[ob:oe, N - 1] - loN, 0, L)
            per_row = np.array([sp.sum(), (L - sp).sum()], float)
            out["all actions"] += rows * per_row
            if cand is None or j >= 64 or (int(cand[c]) >> j) & 1:
                out["candidates"] += rows * per_row
            hit = pc == j
            out["evaluation"] += int(hit.any(axis=1).sum()) * per_row
            at = np.concatenate([[0], np.cumsum(hit.sum(axis=0))])  # states taking j at row positions < i
            contig = float(at[sp].sum())
            out["policy"] += np.array([contig, float(at[-1]) * (oe - ob) - contig])
    return out


def _row_kernel():
    from numba import njit, uint64

    @njit(boundscheck=False, fastmath={"contract"})
    def rows(h, B, p, L, sp, tgt, reps):
        """The kernels' row loop: per row, outcome o adds p[o] * h[B[r, o] + i] on i < sp and
        p[o] * h[B[r, o] + sp] past it (the first outcome assigns), then the row goes back into
        h (as an in-place sweep writes it: no work can be hoisted out of the repetitions)."""
        nrow, nO = B.shape
        for _ in range(reps):
            for r in range(nrow):
                for o in range(nO):
                    b = uint64(B[r, o])
                    po = p[o]
                    v = po * h[b + uint64(sp)]
                    if o == 0:
                        for i in range(sp):
                            tgt[i] = po * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] = v
                    else:
                        for i in range(sp):
                            tgt[i] += po * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] += v
                w = uint64(B[r, 0])
                for i in range(L):
                    h[w + uint64(i)] = tgt[i]
    return rows


def term_rate(L, n_out, h_doubles=1 << 16, nrow=2048, seconds=0.3, seed=0) -> float:
    """Outcome terms a CPU second (one thread) of the kernels' row loop on rows of ``L`` states
    (the last one saturated, as in 86% of the outcome rows of processes 1-4) with ``n_out``
    outcomes each, the successor rows at random offsets of an ``h`` of ``h_doubles`` float64
    (512 KiB by default: in the L2 cache, so the loop's arithmetic and loads, not the memory)."""
    import numpy as np

    f = _row_kernel()
    rng = np.random.default_rng(seed)
    h = rng.random(h_doubles)
    B = rng.integers(0, h_doubles - L - 1, (nrow, n_out)).astype(np.int64)
    p = rng.random(n_out)
    p /= 1.01 * p.sum()  # a substochastic row: h stays bounded through the repetitions
    tgt = np.zeros(L)
    f(h, B, p, L, L - 1, tgt, 1)
    reps = 1
    while True:
        c = time.process_time()
        f(h, B, p, L, L - 1, tgt, reps)
        dt = time.process_time() - c
        if dt >= seconds:
            break
        reps = max(2 * reps, int(reps * 1.2 * seconds / max(dt, 1e-6)))
    best = dt
    for _ in range(2):
        c = time.process_time()
        f(h, B, p, L, L - 1, tgt, reps)
        best = min(best, time.process_time() - c)
    return reps * nrow * n_out * L / best


def work_floor(op, pol, cand) -> dict:
    """Terms a state per pass kind (:func:`outcome_terms`) and, for each, the microbenchmark's
    terms a CPU second at the layout's mean row length and the kind's mean outcomes a row; with
    the long-row rates (L = 1024, the loop without its per-row costs; h in L2 and in L1)."""
    n = int(op.off[-1])
    rows = int(sum(int(op.off[c + 1] - op.off[c]) // int(op.dims[c, op.N - 1]) for c in range(op.off.size - 1)))
    L = n / rows
    terms = outcome_terms(op, pol, cand)
    out = {"mean_row": round(L, 2), "long_row_gterms": round(term_rate(1024, 8) / 1e9, 2),
           "long_row_l1_gterms": round(term_rate(1024, 8, h_doubles=4096) / 1e9, 2)}
    for kind, v in terms.items():
        per_state = float(v.sum()) / n
        n_out = max(1, round(per_state))  # outcomes a row = terms a state (each covers the row)
        out[kind] = {"terms_per_state": round(per_state, 2), "saturated_share": round(float(v[1] / v.sum()), 3),
                     "micro_gterms": round(term_rate(max(2, round(L)), n_out) / 1e9, 2)}
    return out


def pass_profile(sol, threads, bw, repeats=2):
    """Seconds (wall and CPU) of one pass of each kind on the solution's bias and policy, best of
    ``repeats``: the improvement sweep over every action and over the candidate actions (where the
    tree has them), the certificate pass and the fixed-policy (evaluation) sweep; each kind's
    bytes a state at least (value read + written and policy byte: 17; a certificate only reads
    the value and writes the policy byte: 9) against the copy bandwidth."""
    import inspect

    import numpy as np

    from wncs_lp.solvers.matrix_free.operator import Operator, Reduce, Write
    from wncs_lp.solvers.matrix_free.sweeper import Sweeper

    op = Operator.build(sol.system, sol.layout)
    sw = Sweeper(op, threads, None)
    n = sol.layout.n_states
    h, pol = sol.bias, sol.local_actions  # no copies (memory): the solution is not used after
    kinds = [("improvement", 17,
              lambda: sw.all_actions(h, None, pol, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0)),
             ("certificate", 9, lambda: sw.all_actions(h, None, pol, None, Reduce.MIN, Write.NONE, True, 0.8, 0.0)),
             ("evaluation", 17, lambda: sw.fixed(h, None, pol, Write.IN_PLACE, 0.8, 0.0))]
    cand = None
    if "cand" in inspect.signature(sw.all_actions).parameters:
        cand = sw.used_actions(pol, np.zeros(sol.layout.n_configs, np.uint64))
        kinds.insert(1, ("improvement, candidates", 17, lambda: sw.all_actions(
            h, None, pol, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0, cand)))
    if hasattr(sw, "row_actions"):  # per-row candidates (the greedy policy's actions on each row)
        rcand = sw.row_actions(pol, np.zeros(sw.n_rows, np.uint64))
        kinds.insert(2, ("improvement, row candidates", 17, lambda: sw.all_actions(
            h, None, pol, None, Reduce.MIN, Write.IN_PLACE, True, 0.8, 0.0, rcand, True)))
    floor = work_floor(op, pol, cand)
    # a row's candidates are the actions the policy takes on it: the evaluation sweep's terms
    terms_of = {"improvement": "all actions", "improvement, candidates": "candidates", "certificate": "all actions",
                "evaluation": "evaluation", "improvement, row candidates": "evaluation"}
    out = {}
    for label, per_state, fn in kinds:
        wall = cpu = float("inf")
        for _ in range(repeats):
            c0, t0 = time.process_time(), time.perf_counter()
            fn()
            wall, cpu = min(wall, time.perf_counter() - t0), min(cpu, time.process_time() - c0)
        f = floor[terms_of[label]]
        gterms = f["terms_per_state"] * n / cpu / 1e9
        out[label] = {"wall": round(wall, 4), "cpu": round(cpu, 4), "ns_cpu_per_state": round(cpu / n * 1e9, 2),
                      "floor_ratio": round(wall / (per_state * n / (bw * 1e9)), 2),
                      "terms_per_state": f["terms_per_state"], "gterms_per_cpu_s": round(gterms, 2),
                      "micro_gterms": f["micro_gterms"], "micro_ratio": round(f["micro_gterms"] / gterms, 1)}
    out["floor"] = floor
    return out


def machine_cpu() -> float | None:
    """CPU seconds all processes of the machine have used since boot (/proc/stat), None off Linux."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
    except OSError:
        return None
    return (sum(v) - v[3] - v[4]) / os.sysconf("SC_CLK_TCK")


def timed_passes():
    """Record (kind, wall s, CPU s) of every pass the worker tree's Sweeper makes (its two pass
    methods wrapped); returns the log and the function that unwraps them."""
    from wncs_lp.solvers.matrix_free import sweeper as S

    log, saved = [], {}
    for meth in ("all_actions", "fixed"):
        saved[meth] = f = getattr(S.Sweeper, meth)

        def timed(self, *a, _f=f, _meth=meth, **k):
            c0, t0 = time.process_time(), time.perf_counter()
            out = _f(self, *a, **k)
            write = int(a[5]) if len(a) > 5 else int(k["write"])
            kind = "evaluation" if _meth == "fixed" else "improvement" if write == 1 else "certificate"
            log.append((kind, time.perf_counter() - t0, time.process_time() - c0))
            return out

        setattr(S.Sweeper, meth, timed)
    return log, lambda: [setattr(S.Sweeper, m, f) for m, f in saved.items()]


def pass_times_note(log) -> str:
    """Per pass kind in the solve: passes, least and median wall seconds, CPU / wall (2 = both threads busy)."""
    import numpy as np

    parts = []
    for kind in ("improvement", "certificate", "evaluation"):
        w = np.array([x[1] for x in log if x[0] == kind])
        c = np.array([x[2] for x in log if x[0] == kind])
        if w.size:
            parts.append(f"{kind} {w.size} passes, wall least {w.min():.4f} s / median {np.median(w):.4f} s, "
                         f"CPU/wall {c.sum() / w.sum():.2f}")
    return "; ".join(parts)


def sweeps_worker(name, cap, threads, options, profile=True):
    import numpy as np  # noqa: F401  (the worker's own tree is the one imported)

    from wncs_lp.solvers.matrix_free import matrix_free_value_iteration as mfvi

    mfvi(scenario("paper_p12", 6), threads=threads)  # compile (or load) the kernels before timing
    bw = copy_bandwidth()
    sc = scenario(name, cap)
    ld = load1()
    log, unwrap = timed_passes()
    m0 = machine_cpu()
    c0 = time.process_time()
    hint_note = ""
    if options.get("gain_hint") == "relaxation1":  # the solve's first shifts from relaxation 1's bound
        from wncs_lp.bounds import lower_bound

        b = lower_bound(System.from_scenario(sc), 1)
        options = {**options, "gain_hint": float(b.lower_bound)}
        hint_note = f"; gain_hint = relaxation 1's bound {b.lower_bound:.6g} ({time.process_time() - c0:.2f} s of CPU)"
    sol = mfvi(sc, threads=threads, progress=True, **options)
    cpu = time.process_time() - c0
    others = None if m0 is None else machine_cpu() - m0 - cpu
    unwrap()
    st = sol.stats
    n = st["n_states"]
    passes = st["sweeps"] + st["eval_sweeps"]
    per = (sol.seconds - st["seconds_setup"]) / passes
    nbytes = FLOOR_BYTES_PER_STATE * n
    out = row(section="sweeps", instance=name, cap=cap, states=n, method="optimal", threads=st["threads"],
              seconds=round(sol.seconds, 2), **{"seconds_to_1e-6": time_to(st["history"], 1e-6)},
              sweeps=st["sweeps"], eval_sweeps=st["eval_sweeps"], gain=sol.gain, gain_lower=sol.gain_lower,
              gain_upper=sol.gain_upper, rel_gap=sol.gap, peak_rss_gib=round(rss_gib(), 2), load1=ld,
              status=sol.status, cpu_seconds=round(cpu, 1), passes=passes, seconds_per_pass=round(per, 4),
              bytes_per_pass=nbytes, gb_per_s=round(nbytes / per / 1e9, 2), copy_gb_per_s=round(bw, 2),
              floor_ratio=round(per / (nbytes / (bw * 1e9)), 2),
              note=f"setup {st['seconds_setup']:.1f} s; {st.get('value_vectors')} value vector(s); "
                   f"{st.get('extrapolations')} extrapolation(s); {st.get('aggregations', 0)} aggregation(s); options {options or 'defaults'}; "
                   f"package {Path(wncs_lp.__file__).parent.parent}{hint_note}")
    co = st.get("coarse")
    if co:
        out["note"] += (f"; coarse solve at caps {co['caps']}: {co['sweeps']} + {co['eval_sweeps']} passes, "
                        f"{co['seconds']:.1f} s, gain {co['gain']:.6f} (passes above: the fine solve's)")
    out["note"] += "; relative widths " + " ".join(
        f"{u}:{(hi - lo) / abs(0.5 * (lo + hi)):.3g}" for u, _, _, lo, hi in st["history"][:12])
    out["note"] += (f"; in the solve: {pass_times_note(log)}; other processes' CPU during the solve "
                    f"{'?' if others is None else f'{others:.1f}'} s")
    if not profile:
        print(json.dumps(out), flush=True)
        return
    prof = pass_profile(sol, st["threads"], bw)
    floor = prof.pop("floor")
    out["note"] += "; one pass of each kind (wall s, CPU s, CPU ns a state, x floor): " + "; ".join(
        f"{k} {v['wall']} s, {v['cpu']} s, {v['ns_cpu_per_state']} ns, {v['floor_ratio']}x" for k, v in prof.items())
    out["note"] += (f"; outcome terms (mean row {floor['mean_row']} states; the row loop alone, one thread: "
                    f"{floor['long_row_gterms']} G terms/s on rows of 1024, {floor['long_row_l1_gterms']} "
                    f"with h in L1): " + "; ".join(
        f"{k} {v['terms_per_state']} a state, {v['gterms_per_cpu_s']} G terms a CPU s against "
        f"{v['micro_gterms']} in the row loop alone ({v['micro_ratio']}x)" for k, v in prof.items()) +
        "; policy's own outcomes " + f"{floor['policy']['terms_per_state']} a state")
    print(json.dumps(out), flush=True)


def sweeps(instances, threads, options, baseline, variants=None, profile=True, repeats=1):
    """Each instance by each run in turn: this tree with ``options`` (or, with ``variants``, this
    tree with each variant's options, the first the reference), then the ``baseline`` tree."""
    runs = ([(label, ROOT, {**options, **opt}) for label, opt in variants.items()] if variants
            else [("this", ROOT, options)])
    runs += [("baseline", Path(baseline).resolve(), options)] if baseline else []
    rows = []
    for name, cap in instances:
        mine = None
        for rep, (label, tree, opts) in [(r, x) for r in range(repeats) for x in runs]:
            env = dict(os.environ)
            env["WNCS_LP_BENCH_TREE"] = str(tree)
            cmd = [sys.executable, str(ROOT / "benchmarks" / "matrix_free.py"), "--sweeps-worker", f"{name}:{cap}",
                   "--threads", str(threads), "--options", json.dumps(opts)] + ([] if profile else ["--no-profile"])
            print(f"sweeps: {name} cap {cap}, {label}, round {rep + 1} (load {load1()}) ...", flush=True)
            for r in worker_rows(cmd, cwd=tree, env=env):
                r["tree"] = label
                if mine is None:
                    mine = (float(r["seconds"]), float(r["cpu_seconds"]), int(r["passes"]), label)
                else:
                    r["ratio"] = round(float(r["seconds"]) / mine[0], 2)
                    r["note"] = (f"{label} / {mine[3]}: wall {r['ratio']}, CPU {float(r['cpu_seconds']) / mine[1]:.2f}, "
                                 f"passes {int(r['passes']) / mine[2]:.2f}; ") + r["note"]
                rows.append(r)
                print(f"  {label:8s} {r['seconds']} s, {r['passes']} passes ({r['sweeps']} sweeps + "
                      f"{r['eval_sweeps']} evaluation), {r['seconds_per_pass']} s a pass = {r['gb_per_s']} GB/s "
                      f"of the floor's bytes against {r['copy_gb_per_s']} GB/s copy ({r['floor_ratio']}x the "
                      f"floor), g* {float(r['gain']):.10f} [{float(r['gain_lower']):.10f}, "
                      f"{float(r['gain_upper']):.10f}], peak {r['peak_rss_gib']} GiB, load {r['load1']}, "
                      f"CPU {r['cpu_seconds']} s\n    {r['note']}", flush=True)
    return rows


#: The settings of the time-at-cap evaluation compared by the capmass section (the first the reference).
CAPMASS_VARIANTS = {"warm, 1e-7": {"warm_start": True, "atol": 1e-7}, "cold, commands'": {"warm_start": False}}


def capmass(instances, threads, folder, repeats):
    """The certified time at the cap of each instance's optimal policy under each setting in turn."""
    from wncs_lp.solvers.matrix_free import load_solution, matrix_free_cap_mass
    from wncs_lp.truncation import CAP_COUNT_ATOL

    rows = []
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    small = System.from_scenario(scenario("paper_p12", 6))
    matrix_free_cap_mass(small, make_policy("greedy", small), threads=threads)  # compile the kernels first
    for name, cap in instances:
        system = System.from_scenario(scenario(name, cap))
        path = folder / f"{name}_{cap}.npz"
        if path.exists():
            sol = load_solution(path, system)
        else:
            print(f"capmass: solving {name} cap {cap} (load {load1()}) ...", flush=True)
            sol = matrix_free_value_iteration(system, threads=threads)
            sol.save(path)
        for rep in range(repeats):
            ref = None
            for label, opts in CAPMASS_VARIANTS.items():
                opts = {"atol": CAP_COUNT_ATOL, **opts}
                ld = load1()
                c0, w0 = time.process_time(), time.perf_counter()
                ev = matrix_free_cap_mass(system, sol, threads=threads, **opts)
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
                r = row(section="capmass", instance=name, cap=cap, states=ev.stats["n_states"], method=label,
                        threads=ev.stats["threads"], seconds=round(wall, 2), gain=ev.gain, gain_lower=ev.gain_lower,
                        gain_upper=ev.gain_upper, load1=ld, status=ev.status, cpu_seconds=round(cpu, 1),
                        passes=ev.iterations, peak_rss_gib=round(rss_gib(), 2),
                        note=f"round {rep + 1}; options {opts}; {ev.stats['checks']} certificates")
                if ref is None:
                    ref = (wall, cpu, ev.iterations)
                else:
                    r["ratio"] = round(wall / ref[0], 2)
                    r["note"] = (f"against the first: wall {r['ratio']}, CPU {cpu / ref[1]:.2f}, passes "
                                 f"{ev.iterations / ref[2]:.2f}; ") + r["note"]
                rows.append(r)
                print(f"  {name} cap {cap} {label:16s} {wall:.1f} s, CPU {cpu:.1f} s, {ev.iterations} passes, "
                      f"{ev.gain_lower:.9f} <= sum_k m_k <= {ev.gain_upper:.9f}, load {ld}; {r['note']}", flush=True)
    return rows


def main(argv=None):
    warnings.filterwarnings("ignore", message=".*is at most the shortest loop.*")
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="CSV to write")
    ap.add_argument("--sections", default="compare,big")
    ap.add_argument("--quick", action="store_true", help="a few small comparisons and the big case at cap 16")
    ap.add_argument("--caps", default=None, help="caps of the big section (default 20,25,30)")
    ap.add_argument("--policies", default="suboptimal,static,greedy")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--tol", type=float, default=1e-9)
    ap.add_argument("--no-extrapolate", action="store_true",
                    help="solve with one value vector (no extrapolation): the largest caps")
    ap.add_argument("--instances", default="paper_p1234:20,paper_p1234:30,bounds_mix6:10",
                    help="scenario:cap list of the sweeps section")
    ap.add_argument("--options", default="{}", help="JSON dict of matrix_free_value_iteration options (sweeps)")
    ap.add_argument("--baseline", default=None, help="an older source tree to time beside this one (sweeps)")
    ap.add_argument("--variants", default=None,
                    help='JSON {label: options} run on this tree in turn, ratios against the first (sweeps), '
                         'e.g. \'{"plain": {}, "aggregate": {"aggregate": true}}\'')
    ap.add_argument("--solutions", default="/tmp/wncs_mf_solutions",
                    help="folder of the optimal policies the capmass section reads (or solves and saves)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="rounds of the capmass section's settings, and of the sweeps section's variants (alternated)")
    ap.add_argument("--no-profile", action="store_true",
                    help="sweeps: no timing of one pass of each kind after the solve (e.g. a phase to tol 1e-2)")
    ap.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--sweeps-worker", default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    policies = [p for p in a.policies.split(",") if p]
    if a.worker is not None:
        big_worker(a.worker, a.threads, a.tol, policies, not a.no_extrapolate)
        return 0
    if a.sweeps_worker is not None:
        name, cap = a.sweeps_worker.split(":")
        sweeps_worker(name, int(cap), a.threads, json.loads(a.options), not a.no_profile)
        return 0
    sections = a.sections.split(",")
    caps = [int(c) for c in a.caps.split(",")] if a.caps else ([16] if a.quick else [20, 25, 30])
    print(f"matrix-free benchmark: {os.cpu_count()} cores, load {os.getloadavg()}, threads {a.threads}", flush=True)
    rows = []
    if "compare" in sections:
        rows += compare(COMPARE_QUICK if a.quick else COMPARE, a.threads, a.tol)
    if "big" in sections:
        rows += big(caps, a.threads, a.tol, policies, not a.no_extrapolate)
    if "sweeps" in sections:
        inst = [(x.split(":")[0], int(x.split(":")[1])) for x in a.instances.split(",") if x]
        rows += sweeps(inst, a.threads, json.loads(a.options), a.baseline,
                       json.loads(a.variants) if a.variants else None, not a.no_profile, a.repeats)
    if "capmass" in sections:
        inst = [(x.split(":")[0], int(x.split(":")[1])) for x in a.instances.split(",") if x]
        rows += capmass(inst, a.threads, a.solutions, a.repeats)
    if a.out:
        with open(a.out, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=COLUMNS)
            w.writeheader()
            w.writerows(rows)
        print(f"wrote {a.out} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
