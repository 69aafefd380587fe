"""Start-up and end-to-end time of ``wncs-lp solve ... --json``, against Storm on the same model.

    python benchmarks/startup.py                                  # this tree; Storm when stormpy imports
    python benchmarks/startup.py --baseline /tmp/wncs_base        # and an older tree, in the same run
    python benchmarks/startup.py --scenario paper_p12 --cap 30 --repeat 5 --json /tmp/startup.json

What one run measures (every number the best of ``--repeat`` fresh processes, after one warm-up
run that also fills numba's cache; the machine is shared, so the ratios of one run are steadier
than its seconds):

The commands of the trees run in turn (A, B, A, B, ...), so a change of load hits them alike.

* ``python -c pass``: the interpreter's own start-up, the floor of any command;
* ``import wncs_lp.cli``: what the command line imports before it parses its arguments, and
  ``wncs-lp --version`` as a whole (the floor of ``--help`` and of a bad-input error);
* ``solve --json``: the whole command, wall time of the process, with its own account (``JSON:
  build_seconds``, ``solve_seconds``) and the heavy packages it imported (cvxpy, matplotlib,
  clarabel, numba...);
* Storm (when ``stormpy`` imports): the same MDP exported with ``wncs-lp export --format drn``,
  loaded by ``stormpy.build_model_from_drn`` and solved by ``R{"cost"}min=? [LRA]``: its whole
  process, and the model checking alone (Storm's solve), twice: with stormpy 2.0's default
  environment for a floating-point model (``stormpy.environments.sound()``: Storm then picks
  value iteration for long-run averages "to guarantee sound results") and with a plain
  ``stormpy.Environment()`` (Storm's default LRA method for nondeterministic models, also value
  iteration, ``--lra:nondetmethod vi``, precision 1e-6 relative, not sound). stormpy 2.0 exposes
  no LRA method or precision on its environments. Storm stops at 1e-6 relative; ours at a
  certified 1e-9.

``--baseline DIR`` times a second tree (e.g. ``git archive HEAD | tar -x -C DIR`` of an older
commit) the same way, run from that folder so that its package is the one imported.
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
HEAVY = ("cvxpy", "matplotlib", "clarabel", "numba", "llvmlite", "scipy", "numpy", "tqdm", "dask", "pandas", "stormpy")

_SOLVE_AND_LIST = """
import contextlib, io, json, sys
from wncs_lp.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    rc = main(sys.argv[1:])
print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & set(%r))))
""" % (HEAVY,)

_STORM = """
import json, sys, time
t0 = time.perf_counter()
import stormpy
t1 = time.perf_counter()
model = stormpy.build_model_from_drn(sys.argv[1])
t2 = time.perf_counter()
prop = stormpy.parse_properties('R{"cost"}min=? [LRA]')[0]
res = stormpy.model_checking(model, prop)
t3 = time.perf_counter()
plain = stormpy.model_checking(model, prop, environment=stormpy.Environment())
t4 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "load": t2 - t1, "check": t3 - t2, "check_plain": t4 - t3,
                  "gain": res.get_value(model.initial_states[0]), "gain_plain": plain.get_value(model.initial_states[0]),
                  "states": model.nr_states}))
"""


def _env(tree: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    env.pop("WNCS_LP_NO_NUMBA", None)
    return env


def _run(cmd: list[str], cwd: Path, env: dict | None = None) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return dt, proc.stdout


def _best_interleaved(jobs: dict[str, tuple[list[str], Path, dict | None]], repeat: int,
                      runs: dict[str, list[str]] | None = None) -> dict[str, tuple[float, str]]:
    """Best wall time of each job, the jobs run in turn (A, B, A, B, ...) so that a change of the
    machine's load hits them alike; one warm-up run each first (page cache, numba's on-disk cache).
    ``runs``, when given, collects every timed run's output per job."""
    for cmd, cwd, env in jobs.values():
        _run(cmd, cwd, env)
    best: dict[str, tuple[float, str]] = {}
    for _ in range(repeat):
        for name, (cmd, cwd, env) in jobs.items():
            dt, out = _run(cmd, cwd, env)
            if runs is not None:
                runs.setdefault(name, []).append(out)
            if name not in best or dt < best[name][0]:
                best[name] = (dt, out)
    return best


def measure_trees(trees: dict[str, Path], scenario: str, cap: int, repeat: int,
                  drn: Path | None = None) -> dict[str, dict]:
    py = sys.executable
    jobs: dict[str, tuple[list[str], Path, dict | None]] = {"floor": ([py, "-c", "pass"], ROOT, None)}
    if drn is not None:
        jobs["storm"] = ([py, "-c", _STORM, str(drn)], ROOT, None)
    for name, tree in trees.items():
        env = _env(tree)
        scen = str(tree / "formulations" / f"{scenario}.toml")
        jobs[f"{name}/import"] = ([py, "-c", "import wncs_lp.cli"], tree, env)
        jobs[f"{name}/version"] = ([py, "-m", "wncs_lp", "--version"], tree, env)
        jobs[f"{name}/solve"] = ([py, "-m", "wncs_lp", "solve", scen, "--set", f"tau_cap={cap}", "--json"], tree, env)
    runs: dict[str, list[str]] = {}
    best = _best_interleaved(jobs, repeat, runs)
    rows = {"floor": {"seconds": best["floor"][0]}}
    if drn is not None:  # Storm's whole process: its fastest run; each of its parts: its fastest
        wall, out = best["storm"]
        every = [json.loads(o) for o in runs["storm"]]
        rows["storm"] = {"wall": wall, **json.loads(out), "bytes": drn.stat().st_size,
                         **{k: min(r[k] for r in every) for k in ("import", "load", "check", "check_plain")}}
    for name, tree in trees.items():
        env = _env(tree)
        payload = json.loads(best[f"{name}/solve"][1])
        args = ["solve", str(tree / "formulations" / f"{scenario}.toml"), "--set", f"tau_cap={cap}", "--json"]
        _, mods = _run([py, "-c", _SOLVE_AND_LIST, *args], tree, env)
        rows[name] = {"tree": str(tree), "import_cli": best[f"{name}/import"][0], "version": best[f"{name}/version"][0],
                      "e2e": best[f"{name}/solve"][0], "build_seconds": payload["build_seconds"],
                      "solve_seconds": payload["solve_seconds"], "in_process_seconds": payload["seconds"],
                      "gain": payload["gain"], "method": payload.get("auto_choice", payload["method"]),
                      "states": payload["states"], "heavy_imports": json.loads(mods.strip().splitlines()[-1])}
    return rows


def export_drn(scenario: str, cap: int, folder: Path) -> Path | None:
    """The model as Storm's DRN (by this tree's ``wncs-lp export``), or None without stormpy."""
    try:
        import stormpy  # noqa: F401
    except ImportError:
        return None
    drn = folder / "model.drn"
    _run([sys.executable, "-m", "wncs_lp", "export", str(ROOT / "formulations" / f"{scenario}.toml"), "--set",
          f"tau_cap={cap}", "--format", "drn", "--out", str(drn)], ROOT, _env(ROOT))
    return drn


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenario", default="paper_p12", help="a file of formulations/ (default paper_p12)")
    ap.add_argument("--cap", type=int, default=30, help="tau_cap (default 30)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per measurement, best kept (default 3)")
    ap.add_argument("--baseline", type=Path, default=None, help="another tree to time the same way")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers to this file")
    args = ap.parse_args(argv)

    trees = {"this tree": ROOT}
    if args.baseline is not None:
        trees["baseline"] = args.baseline.resolve()
    with tempfile.TemporaryDirectory() as tmp:
        drn = export_drn(args.scenario, args.cap, Path(tmp))
        rows = measure_trees(trees, args.scenario, args.cap, args.repeat, drn)
    floor = rows.pop("floor")["seconds"]
    storm = rows.pop("storm", None)

    print(f"{args.scenario} at cap {args.cap}: {rows['this tree']['states']:,} states; python -c pass {floor:.3f} s")
    print(f"{'tree':<10} {'import cli':>10} {'--version':>9} {'solve --json':>12} {'build':>7} {'solve':>7}  "
          "heavy modules imported by solve")
    for name, r in rows.items():
        print(f"{name:<10} {r['import_cli']:>10.3f} {r['version']:>9.3f} {r['e2e']:>12.3f} {r['build_seconds']:>7.3f} "
              f"{r['solve_seconds']:>7.3f}  {', '.join(r['heavy_imports'])}")
    now = rows["this tree"]
    if "baseline" in rows:
        b = rows["baseline"]
        print(f"end to end: {b['e2e']:.3f} s -> {now['e2e']:.3f} s ({b['e2e'] / now['e2e']:.2f}x); "
              f"import of the command line: {b['import_cli']:.3f} s -> {now['import_cli']:.3f} s")
    print(f"our end to end / our solve alone: {now['e2e'] / now['solve_seconds']:.2f}x "
          f"({now['e2e'] - now['solve_seconds']:.3f} s outside the solver)")
    if storm is None:
        print("Storm: stormpy is not installed (pip install stormpy): not compared")
    else:
        print(f"Storm on the exported DRN ({storm['bytes'] / 1e6:.1f} MB): whole process {storm['wall']:.3f} s "
              f"(import {storm['import']:.3f}, parse {storm['load']:.3f}, LRA solve {storm['check']:.3f}, each in its "
              f"fastest runs); gain "
              f"{storm['gain']:.10g} vs ours {now['gain']:.10g} (relative difference "
              f"{abs(storm['gain'] - now['gain']) / abs(now['gain']):.1e}); with a plain Environment() "
              f"(unsound value iteration) its solve {storm['check_plain']:.3f} s, gain {storm['gain_plain']:.10g}")
        print(f"ratios: our whole command / Storm's solve alone {now['e2e'] / storm['check']:.2f}x; "
              f"/ Storm's whole process {now['e2e'] / storm['wall']:.2f}x; our solve alone / Storm's solve alone "
              f"{now['solve_seconds'] / storm['check']:.2f}x")
    if args.json is not None:
        args.json.write_text(json.dumps({"floor": floor, "trees": rows, "storm": storm, "scenario": args.scenario,
                                         "cap": args.cap}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
