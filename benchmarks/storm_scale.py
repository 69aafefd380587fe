"""Issue 34: our solves against Storm's value iteration at scale (0.5-2M states), one run.

    python benchmarks/storm_scale.py --out /tmp/storm_scale.csv                   # p123 caps 16, 18; p1234 cap 10
    python benchmarks/storm_scale.py --instances paper_p123:16 --repeat 3
    python benchmarks/storm_scale.py --instances paper_p123:16 --methods vi2,pi       # a subset

Per instance: the model built once (``wncs_lp.build``); then, ``--repeat`` times in turn, the
stored-matrix value iteration (``wncs_lp.solve(mdp, "vi")``, certified to a relative bracket of
1e-9; and with two evaluation sweeps per improvement sweep, the matrix-free default), Howard's
policy iteration (``wncs_lp.solve(mdp, "pi", tol=1e-9)``: each policy evaluated exactly, by BiCGSTAB
from 50,000 states on), the matrix-free solver (certified to 1e-9, no matrix) and Storm's long-run average
(``R{"cost"}min=? [LRA]`` through stormpy, on the same MDP: :func:`peers.storm_lra`; its
default precision 1e-6 relative, uncertified; the conversion to Storm's matrix is not counted).
Each row records its wall and CPU seconds and the 1-minute load; ``ratio`` = our seconds /
Storm's solve seconds of the same repeat (below 1: we are faster), ``cpu_ratio`` the same in CPU
seconds (Storm's solve is one thread; ours use ``--threads``, by default each solver's own choice:
the matrix-free solver takes one thread below 1M states, where a parallel region costs more than
a sweep, and the row's ``note`` says how many it used): on a shared machine the wall
seconds follow the load, the CPU seconds less. Storm's gain is checked
against our certificate (``storm_in_bracket``; its error is reported relative to g*).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import peers  # noqa: E402
import wncs_lp  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_value_iteration  # noqa: E402

COLUMNS = ["instance", "cap", "states", "transitions", "repeat", "method", "seconds", "cpu_seconds", "ratio",
           "cpu_ratio", "gain", "gain_lower", "gain_upper", "sweeps", "storm_in_bracket", "storm_rel_error", "load1",
           "status", "note"]


def storm_cpu_clock() -> dict:
    """Record the CPU seconds of Storm's model checking (the solve alone, in this process: stormpy
    runs in it) by wrapping ``stormpy.model_checking``, which :func:`peers.storm_lra` calls."""
    import stormpy

    clock = {"cpu": float("nan")}
    inner = stormpy.model_checking

    def model_checking(*args, **kwargs):
        c0 = time.process_time()
        try:
            return inner(*args, **kwargs)
        finally:
            clock["cpu"] = time.process_time() - c0

    stormpy.model_checking = model_checking
    return clock


def timed(fn):
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0, time.process_time() - c0


#: Our methods by their ``--methods`` key: (row label, solve of the MDP ``mdp`` / scenario ``sc``).
METHODS = {
    "vi": ("stored vi", lambda mdp, sc, threads: wncs_lp.solve(mdp, "vi", threads=threads)),
    "vi2": ("stored vi, eval_sweeps=2", lambda mdp, sc, threads: wncs_lp.solve(mdp, "vi", threads=threads,
                                                                               eval_sweeps=2)),
    "pi": ("stored pi", lambda mdp, sc, threads: wncs_lp.solve(mdp, "pi", tol=1e-9)),
    "mf": ("matrix-free", lambda mdp, sc, threads: matrix_free_value_iteration(sc, threads=threads)),
}


def run(instances, repeat, threads, methods=tuple(METHODS)):
    rows = []
    storm_clock = storm_cpu_clock()
    sc0 = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=8"])
    wncs_lp.solve(wncs_lp.build(sc0), "vi", threads=threads)  # numba's kernels loaded before timing
    matrix_free_value_iteration(sc0, threads=threads)
    for name, cap in instances:
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])
        mdp = wncs_lp.build(sc)
        n, nnz = mdp.n_states, mdp.P.nnz
        common = dict(instance=name, cap=cap, states=n, transitions=nnz)
        for r in range(repeat):
            ld = round(os.getloadavg()[0], 2)
            st, st_s, _ = timed(lambda: peers.storm_lra(mdp))
            storm_s, storm_cpu = st["seconds"], storm_clock["cpu"]
            rows.append(dict(common, repeat=r, method="storm LRA (solve)", seconds=round(storm_s, 3),
                             cpu_seconds=round(storm_cpu, 3), gain=st["gain"],
                             load1=ld, status="uncertified (1e-6)",
                             note=f"conversion {st['convert_seconds']:.2f} s not counted"))
            for key in methods:
                method, solve = METHODS[key]
                ld = round(os.getloadavg()[0], 2)
                sol, wall, cpu = timed(lambda: solve(mdp, sc, threads))
                inside = sol.gain_lower <= st["gain"] <= sol.gain_upper
                rows.append(dict(common, repeat=r, method=method, seconds=round(wall, 3), cpu_seconds=round(cpu, 3),
                                 ratio=round(wall / storm_s, 3), cpu_ratio=round(cpu / storm_cpu, 3), gain=sol.gain,
                                 gain_lower=sol.gain_lower,
                                 gain_upper=sol.gain_upper, sweeps=sol.stats.get("sweeps", sol.iterations),
                                 storm_in_bracket=inside,
                                 storm_rel_error=abs(st["gain"] - sol.gain) / abs(sol.gain), load1=ld,
                                 status=sol.status, note=f"threads {sol.stats.get('threads', 1)}"))
                print(f"{name} cap {cap} ({n:,} states, {nnz:,} transitions) repeat {r}: {method} "
                      f"({sol.stats.get('threads', 1)} thread(s)) {wall:.2f} s "
                      f"(CPU {cpu:.2f} s) against Storm's solve {storm_s:.2f} s (CPU {storm_cpu:.2f} s): ratio "
                      f"{wall / storm_s:.2f}, CPU ratio {cpu / storm_cpu:.2f}; "
                      f"g* {sol.gain:.9f} [{sol.gain_lower:.9f}, {sol.gain_upper:.9f}], Storm {st['gain']:.9f} "
                      f"({'inside' if inside else 'outside'}), load {ld}", flush=True)
        del mdp
    return rows


def main(argv=None):
    warnings.filterwarnings("ignore")
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--instances", default="paper_p123:16,paper_p123:18,paper_p1234:10")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--threads", type=int, default=None,
                    help="threads of our solvers (default: each solver's own choice)")
    ap.add_argument("--methods", default=",".join(METHODS),
                    help=f"ours to time against Storm, comma-separated among {', '.join(METHODS)}")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    if not peers.available("stormpy"):
        print("stormpy is not installed (pip install -e '.[bench]'): nothing to compare", file=sys.stderr)
        return 1
    inst = [(x.split(":")[0], int(x.split(":")[1])) for x in a.instances.split(",") if x]
    print(f"storm at scale: {os.cpu_count()} cores, load {os.getloadavg()}, threads {a.threads}", flush=True)
    methods = [m for m in a.methods.split(",") if m]
    bad = [m for m in methods if m not in METHODS]
    if bad:
        ap.error(f"unknown method {bad[0]!r}; expected some of {', '.join(METHODS)}")
    rows = run(inst, a.repeat, a.threads, methods)
    if a.out:
        atomic_write_csv(a.out, rows, COLUMNS)
        print(f"wrote {a.out} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
