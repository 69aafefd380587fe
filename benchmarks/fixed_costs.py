"""Issue 28: the fixed costs of a small solve, end to end, against a baseline tree in the same run.

    python benchmarks/fixed_costs.py --baseline-rev d3dec86          # a commit, unpacked by git archive
    python benchmarks/fixed_costs.py --baseline /tmp/wncs_base --caps 4,12,30 --repeat 5
    python benchmarks/fixed_costs.py --baseline-rev main --repeat 5 --csv benchmarks/fixed_costs.csv
    python benchmarks/fixed_costs.py --crossover paper_p123:10,paper_p12:30,paper_p12:36,paper_p123:12,paper_p12:45

For each cap (default 4 and 30 of ``formulations/paper_p12.toml``) the command
``wncs-lp solve formulations/paper_p12.toml --set tau_cap=CAP --json`` is timed as a whole process,
this tree and the baseline in turn (A, B, A, B, ...: a change of the machine's load hits both
alike), the best of ``--repeat`` runs after a warm-up (which also fills numba's on-disk cache);
with the command's own account (build, solve), the kernel its value iteration used, and the heavy
packages it imported. Beside them: ``python -c pass`` (the floor of any command),
``python -c "import numba"`` (what a solve pays the first time it touches numba, before loading
any kernel), and Storm's solve of the same model when ``stormpy`` imports
(``benchmarks/startup.py`` does the measuring; Storm's solve with stormpy's default sound
environment and with a plain one, both value iteration). The ratios of one run are steadier than
its seconds: the machine is shared (the load average is printed, and written to ``--csv``: one
row per cap and tree).

``--crossover SCENARIO:CAP,...`` times instead the whole command of this tree on each instance
with value iteration on numba and on the scipy kernel (``kernels.NUMBA_MIN_STATES`` set to 0 or
to infinity before the command runs), in turn: where numba's load pays, which is what sets
``NUMBA_MIN_STATES``.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from startup import _best_interleaved, _env, _run, export_drn, measure_trees  # noqa: E402

_KERNEL = """
import json, sys, warnings
warnings.simplefilter("ignore")
import wncs_lp
sc = wncs_lp.load_scenario(sys.argv[1], ["tau_cap=" + sys.argv[2]])
sol = wncs_lp.solve(wncs_lp.build(sc), "auto")
print(json.dumps({"kernel": sol.stats.get("kernel"), "choice": sol.stats.get("auto_choice"),
                  "sweeps": sol.stats.get("sweeps"), "status": sol.status}))
"""

#: Where the whole command's time goes, phase by phase in one fresh process (the order the command
#: pays them in; scipy.sparse.csgraph brings scipy.sparse.linalg and scipy.linalg with it).
_PHASES = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
marks = [("start", time.perf_counter())]
def mark(name):
    marks.append((name, time.perf_counter()))
import numpy; mark("import numpy")
import scipy.sparse; mark("import scipy.sparse")
import scipy.sparse.csgraph; mark("import scipy.sparse.csgraph")
import wncs_lp.cli; mark("import wncs_lp.cli")
try:
    from wncs_lp.workflow import run_scenario
except ImportError:  # a baseline tree from before the route's step had its name
    from wncs_lp.workflow import solve_scenario as run_scenario
mark("import wncs_lp.workflow")
from wncs_lp.scenario import load_scenario
sc = load_scenario(sys.argv[1], ["tau_cap=" + sys.argv[2]]); mark("load the scenario")
run = run_scenario(sc, "auto"); mark("guard, build, solve")
from wncs_lp.truncation import policy_cap_mass
policy_cap_mass(run.mdp, run.solution.policy); mark("mass at the cap")
out = {b[0]: b[1] - a[1] for a, b in zip(marks, marks[1:])}
out.update(build=run.build_seconds, solve=run.solution.seconds)
print(json.dumps(out))
"""


def phases(tree: Path, scenario: str, cap: int, repeat: int) -> dict:
    """Each phase of :data:`_PHASES`: its fastest of ``repeat`` fresh processes."""
    best: dict = {}
    for _ in range(repeat):
        _, out = _run([sys.executable, "-c", _PHASES, str(tree / "formulations" / f"{scenario}.toml"), str(cap)],
                      tree, _env(tree))
        for k, v in json.loads(out.strip().splitlines()[-1]).items():
            best[k] = min(best.get(k, v), v)
    return best

#: The command as ``wncs-lp`` runs it, with ``auto``'s numba threshold set first (numba itself is
#: imported only when a kernel needs it, so this changes nothing else).
_WITH_THRESHOLD = """
import sys
from wncs_lp.solvers import kernels
kernels.NUMBA_MIN_STATES = float(sys.argv[1])
from wncs_lp.cli import main
sys.exit(main(sys.argv[2:]))
"""


def crossover(instances: list[tuple[str, int]], repeat: int) -> list[dict]:
    """The whole command on numba and on scipy at each (scenario, cap), best of ``repeat``, in turn."""
    rows = []
    for scenario, cap in instances:
        cmd = ["solve", str(ROOT / "formulations" / f"{scenario}.toml"), "--set", f"tau_cap={cap}", "--json"]
        jobs = {k: ([sys.executable, "-c", _WITH_THRESHOLD, t, *cmd], ROOT, _env(ROOT))
                for k, t in (("numba", "0"), ("scipy", "inf"))}
        best = _best_interleaved(jobs, repeat)
        out = {k: json.loads(v[1]) for k, v in best.items()}
        row = {"scenario": scenario, "cap": cap, "states": out["numba"]["states"], "load1": os.getloadavg()[0]}
        for k in ("numba", "scipy"):
            assert out[k]["stats"]["kernel"] == k, out[k]["stats"]
            row.update({f"{k}_whole_s": best[k][0], f"{k}_solve_s": out[k]["solve_seconds"],
                        f"{k}_sweeps": out[k]["stats"]["sweeps"], f"{k}_status": out[k]["status"]})
        rows.append(row)
        print(f"{scenario} cap {cap} ({row['states']:,} states, load {row['load1']:.1f}): whole command numba "
              f"{row['numba_whole_s']:.3f} s ({row['numba_sweeps']} sweeps), scipy {row['scipy_whole_s']:.3f} s "
              f"({row['scipy_sweeps']} sweeps): numba / scipy {row['numba_whole_s'] / row['scipy_whole_s']:.2f}x")
    return rows


def unpack(rev: str, folder: Path) -> Path:
    """The tree of commit ``rev`` of this repository, unpacked into ``folder`` (git archive)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def one_cap(trees: dict[str, Path], cap: int, repeat: int, scenario: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        drn = export_drn(scenario, cap, Path(tmp))
        rows = measure_trees(trees, scenario, cap, repeat, drn)
    for name, tree in trees.items():
        _, out = _run([sys.executable, "-c", _KERNEL, str(tree / "formulations" / f"{scenario}.toml"), str(cap)],
                      tree, _env(tree))
        rows[name].update(json.loads(out.strip().splitlines()[-1]))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", type=Path, default=None, help="a tree to compare with")
    ap.add_argument("--baseline-rev", default=None, help="or a commit of this repository (git archive)")
    ap.add_argument("--caps", default="4,30")
    ap.add_argument("--scenario", default="paper_p12")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    ap.add_argument("--csv", type=Path, default=None, help="and as CSV (one row per cap and tree)")
    ap.add_argument("--crossover", default=None, metavar="SCENARIO:CAP,...",
                    help="instead: the whole command on numba against scipy on these instances")
    a = ap.parse_args(argv)
    if a.crossover is not None:
        pairs = [(x.split(":")[0], int(x.split(":")[1])) for x in a.crossover.split(",")]
        rows = crossover(pairs, a.repeat)
        if a.json is not None:
            a.json.write_text(json.dumps(rows, indent=2) + "\n")
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"this tree": ROOT}
        if a.baseline is not None:
            trees["baseline"] = a.baseline.resolve()
        elif a.baseline_rev is not None:
            trees["baseline"] = unpack(a.baseline_rev, Path(tmp))
        py = sys.executable
        floors = _best_interleaved({"pass": ([py, "-c", "pass"], ROOT, None),
                                    "numba": ([py, "-c", "import numba"], ROOT, None)}, a.repeat)
        print(f"load average {os.getloadavg()[0]:.2f} (2 cores); python -c pass {floors['pass'][0]:.3f} s, "
              f"import numba {floors['numba'][0]:.3f} s")
        result = {"floor": floors["pass"][0], "import_numba": floors["numba"][0], "caps": {},
                  "date": datetime.date.today().isoformat(), "load1_start": os.getloadavg()[0]}
        for cap in (int(c) for c in a.caps.split(",")):
            rows = one_cap(trees, cap, a.repeat, a.scenario)
            result["caps"][cap] = rows
            storm = rows.pop("storm", None)
            rows.pop("floor", None)
            if storm is not None:
                rows["storm_row"] = storm
            print(f"\n{a.scenario} at cap {cap} ({rows['this tree']['states']:,} states)")
            print(f"{'tree':<10} {'whole':>7} {'build':>7} {'solve':>7} {'method':>6} {'kernel':>6}  heavy imports")
            for name, r in ((k, v) for k, v in rows.items() if k != "storm_row"):
                print(f"{name:<10} {r['e2e']:>7.3f} {r['build_seconds']:>7.3f} {r['solve_seconds']:>7.3f} "
                      f"{str(r['choice']):>6} {str(r['kernel']):>6}  {', '.join(r['heavy_imports'])}")
            if "baseline" in rows:
                b, t = rows["baseline"]["e2e"], rows["this tree"]["e2e"]
                print(f"whole command: baseline / this tree = {b / t:.2f}x ({b - t:+.3f} s saved)")
            for name, tree in trees.items():
                ph = phases(tree, a.scenario, cap, a.repeat)
                rows[name]["phases"] = ph
                print(f"{name}, phase by phase (best of {a.repeat}): "
                      + ", ".join(f"{k} {v:.3f}" for k, v in ph.items()) + " s")
            if storm is not None:
                mine = rows["this tree"]["e2e"]
                print(f"Storm's LRA solve alone {storm['check']:.3f} s with stormpy's default (sound) environment, "
                      f"{storm['check_plain']:.3f} s with a plain one (whole process {storm['wall']:.3f} s); gain "
                      f"{storm['gain']:.10g} (plain {storm['gain_plain']:.10g})")
                print(f"our whole command / Storm's solve = {mine / storm['check']:.2f}x "
                      f"(/ its plain solve {mine / storm['check_plain']:.2f}x; / its whole process {mine / storm['wall']:.2f}x)")
        result["load1_end"] = os.getloadavg()[0]
        if a.json is not None:
            a.json.write_text(json.dumps(result, indent=2, default=str) + "\n")
        if a.csv is not None:
            write_csv(a.csv, result, a.scenario)
    return 0


CSV_FIELDS = ["date", "load1_start", "load1_end", "scenario", "cap", "states", "tree", "whole_s", "build_s", "solve_s",
              "kernel", "sweeps", "status", "gain", "heavy_imports", "python_pass_s", "import_numba_s", "storm_solve_s",
              "storm_solve_plain_s", "storm_whole_s", "storm_gain", "whole_over_storm_solve"]


def write_csv(path: Path, result: dict, scenario: str) -> None:
    """One row per cap and tree: the whole command, its own account, and Storm's solve beside it."""
    rows = []
    for cap, trees in result["caps"].items():
        storm = trees.get("storm_row")
        for name, r in trees.items():
            if name == "storm_row":
                continue
            rows.append({"date": result["date"], "load1_start": f"{result['load1_start']:.2f}",
                         "load1_end": f"{result['load1_end']:.2f}", "scenario": scenario, "cap": cap,
                         "states": r["states"], "tree": name, "whole_s": f"{r['e2e']:.3f}",
                         "build_s": f"{r['build_seconds']:.3f}", "solve_s": f"{r['solve_seconds']:.3f}",
                         "kernel": r["kernel"], "sweeps": r["sweeps"], "status": r["status"], "gain": repr(r["gain"]),
                         "heavy_imports": " ".join(r["heavy_imports"]), "python_pass_s": f"{result['floor']:.3f}",
                         "import_numba_s": f"{result['import_numba']:.3f}",
                         "storm_solve_s": f"{storm['check']:.3f}" if storm else "",
                         "storm_solve_plain_s": f"{storm['check_plain']:.3f}" if storm else "",
                         "storm_whole_s": f"{storm['wall']:.3f}" if storm else "",
                         "storm_gain": repr(storm["gain"]) if storm else "",
                         "whole_over_storm_solve": f"{r['e2e'] / storm['check']:.2f}" if storm else ""})
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, CSV_FIELDS)
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    raise SystemExit(main())
