"""Issue 33: calibration in the many-sensors-per-server regime -- where the certified gap at sixteen
processes comes from, measured where g* is exact.

    python benchmarks/calibration_load.py --out benchmarks/calibration_load.csv      # the default table
    python benchmarks/calibration_load.py --instances edge:3:30,cloud:3:25 --out /tmp/c.csv
    python benchmarks/calibration_load.py --instances edge:5:25 --no-rollout         # one large instance
    python benchmarks/calibration_load.py --compare-optimum edge:3:30                # where the greedy policy errs
    python benchmarks/calibration_load.py --tables edge:4:30                         # policies on relaxations 2 and 4

At sixteen processes on two servers (``bounds_lab16``: an edge and a cloud server, p = 0.8) many
sensors queue for each server, and the certified gap is 10-12%; g* is out of reach there. The
instances here keep that load on ONE server with few enough states for the exact matrix-free
solver: the lab's scalar sensors (A = 1.05, 1.1, 1.15, 1.2, 1.3 in turn, R = 1, p = 0.8) on the
edge server alone (U = D = 0, T = 2), the cloud server alone (U = D = 1, T = 1) or both
(``bounds_lab16``'s pair), N = 2..5 of them (``formulations/calib_edge5.toml`` is the largest,
shipped; the others are its first N sensors). An instance is ``SERVER:N:CAP``, SERVER one of
``edge``, ``cloud``, ``both``.

For every instance, each in its own process (its peak memory its own):

* g* by certified matrix-free value iteration (bracket 1e-9) and the optimum's time at the cap,
  per sensor (:func:`~wncs_lp.solvers.matrix_free.matrix_free_cap_masses`, certified upper ends):
  the cap is chosen so that it stays below ~1% for every sensor;
* every relaxation's certified bound: 1 (private servers), 2 (joint configuration, solved whole by
  its interior point: ``method="ipm"``), 3 (groups sharing private servers), 4 (pairs of ages kept
  jointly), and its looseness (g* - LB) / g*;
* the policies on relaxation 2's tables (its greedy policy ``bound``, the two-step ``lookahead``,
  the ``rollout``), the ``index`` policy, relaxation 1's greedy policy, the paper's ``suboptimal``
  policy and the ``static`` / ``greedy`` baselines, each evaluated exactly (certified matrix-free
  evaluation, :func:`~wncs_lp.bounds.gaps.policy_gaps` with ``exact=True``), and its loss
  (g_pi - g*) / g*.

One CSV row per quantity and a markdown table (``--md``) with one line per instance: sensors per
server, g*, each bound's looseness, each policy's loss. The machine is shared: each row records
the 1-minute load average when it started (2 cores).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import wncs_lp  # noqa: E402
from bounds import load1, peak_gib  # noqa: E402  (benchmarks/bounds.py)
from wncs_lp.bounds import bound_policy, lower_bound, policy_gaps  # noqa: E402
from wncs_lp.files import atomic_write_csv, atomic_write_text  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_cap_masses, matrix_free_value_iteration  # noqa: E402
from wncs_lp.solvers.matrix_free.layout import layout_states  # noqa: E402

COLUMNS = ["instance", "server", "sensors", "cap", "states", "row", "how", "value", "value_lower", "value_upper",
           "vs_optimum", "cap_mass_max", "seconds", "cpu_seconds", "peak_gib", "load1", "note"]
#: The shipped five sensors on the edge server alone; the N-sensor instances are its first N sensors,
#: the cloud instances the same sensors on the cloud server (``SERVERS``).
SCENARIO = "calib_edge5"
SERVERS = {"edge": {"uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2},
           "cloud": {"uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1}}
#: (server, sensors, cap): caps at which the optimum's time at the cap is below ~1% for every sensor
#: (the cap masses are in the CSV) but the five edge sensors at cap 25 (49.6M states, the longest:
#: ~16 min of CPU, 6.7 GiB), where the optimum abandons the cheapest sensor at its cap.
DEFAULT = [("edge", 2, 30), ("edge", 3, 30), ("edge", 4, 40), ("edge", 5, 25), ("cloud", 2, 30), ("cloud", 3, 30),
           ("cloud", 4, 25), ("both", 3, 25), ("both", 4, 20)]
#: The load: slots between two deliveries of a sensor when the server is always busy and serves the
#: sensors in turn, N * SLOTS_PER_DELIVERY (p = 0.8 on both links). The edge (U = 0, T = 2) spends 1
#: slot on an update lost on the uplink and T slots on one that arrives, and delivers p^2 of its
#: attempts: (1 - p + p T) / p^2 = 2.8125 slots a delivery. The cloud (U = D = 1, T = 1) accepts an
#: update every slot (the one in service leaves it as the next arrives): 1 / p^2 = 1.5625. At
#: bounds_lab16 the two together deliver 1/2.8125 + 1/1.5625 = 1.0 update a slot to 16 sensors: 16
#: slots a delivery, about the edge with 5-6 sensors or the cloud with 10.
SLOTS_PER_DELIVERY = {"edge": 1.8 / 0.64, "cloud": 1 / 0.64, "both": 1 / (0.64 / 1.8 + 0.64)}
RELAXATIONS = ((1, "private-servers", {}), (2, "joint-configuration", {"method": "ipm"}),
               (3, "grouped-private-servers", {}), (4, "joint-pairs", {}))
#: Relaxation 5 (every pair's ages on the joint configuration, its LP solved whole): only where asked
#: (``--tables ... --relaxations 2,4,5``); its LP on two servers takes minutes an iteration.
ALL_PAIRS = (5, "joint-all-pairs", {})


def system_for(server: str, sensors: int, cap: int) -> System:
    """The shipped five edge sensors' first ``sensors`` sensors on ``server`` alone (``"both"``: on
    the cloud and the edge server, bounds_lab16's pair), at cap ``cap``."""
    if server not in (*SERVERS, "both"):
        raise ValueError(f"server must be one of {sorted(SERVERS)} or 'both', got {server!r}")
    import tomllib

    raw = tomllib.loads(wncs_lp.scenario_path(SCENARIO).read_text())
    if not 1 <= sensors <= len(raw["process"]):
        raise ValueError(f"sensors must be 1..{len(raw['process'])}, got {sensors}")
    raw["process"] = raw["process"][:sensors]
    raw["server"] = [{"name": m, **SERVERS[m]} for m in (("cloud", "edge") if server == "both" else (server,))]
    raw["model"]["tau_cap"] = cap
    return System.from_scenario(wncs_lp.scenario_from_dict(raw, f"{SCENARIO} ({sensors} sensors, {server}, cap {cap})"))


def _cpu_timed(fn, *args, **kw):
    t0, c0, l0 = time.perf_counter(), time.process_time(), load1()
    res = fn(*args, **kw)
    return res, time.perf_counter() - t0, time.process_time() - c0, l0


def run_instance(server: str, sensors: int, cap: int, rollout: bool = True) -> list[dict]:
    """g*, the cap masses, every relaxation's bound and every policy's exact gain on one instance."""
    system = system_for(server, sensors, cap)
    states = layout_states(system, "hull")
    base = {"instance": f"{server}:{sensors}:{cap}", "server": server, "sensors": sensors, "cap": cap, "states": states}
    rows = []
    sol, secs, cpu, l0 = _cpu_timed(matrix_free_value_iteration, system, tol=1e-9)
    g = float(sol.gain)
    masses, _, mcpu, _ = _cpu_timed(matrix_free_cap_masses, system, sol)
    per = [float(m.gain_upper) for m in masses]
    rows.append({**base, "row": "optimum g*", "how": str(sol.status), "value": g, "value_lower": float(sol.gain_lower),
                 "value_upper": float(sol.gain_upper), "vs_optimum": 0.0, "cap_mass_max": max(per),
                 "seconds": round(secs, 2), "cpu_seconds": round(cpu, 2), "load1": l0,
                 "note": f"matrix-free value iteration, {sol.iterations} sweeps; time at the cap per sensor "
                         f"{[round(m, 5) for m in per]} ({mcpu:.1f} s of CPU)"})
    found = {}
    for number, name, kw in RELAXATIONS:
        res, secs, cpu, l0 = _cpu_timed(lower_bound, system, number, **kw)
        found[number] = res
        rows.append({**base, "row": f"LB {number} {name}", "how": str(res.status), "value": float(res.lower_bound),
                     "vs_optimum": (float(res.lower_bound) - g) / g, "seconds": round(secs, 2),
                     "cpu_seconds": round(cpu, 2), "load1": l0, "note": f"{res.iterations} iterations"})
    policies = ["bound", "lookahead"] + ["rollout"] * rollout + ["index", bound_policy(found[1], system), "suboptimal",
                                                                "static", "greedy"]
    l0, c0 = load1(), time.process_time()
    report = policy_gaps(found[2], system, policies, exact=True)
    for r in report.rows:
        rows.append({**base, "row": r.policy, "how": r.how, "value": r.gain, "value_lower": r.detail.get("gain_lower"),
                     "value_upper": r.gain_upper, "vs_optimum": (r.gain - g) / g, "seconds": round(r.seconds, 2),
                     "load1": l0, "note": f"on relaxation 2's tables (LB {found[2].lower_bound:.10g})"})
    rows[-1]["cpu_seconds"] = round(time.process_time() - c0, 2)
    peak = peak_gib()
    return [{**r, "peak_gib": peak} for r in rows]


def compare_optimum(server: str, sensors: int, cap: int, slots: int = 200_000, seed: int = 0) -> list[dict]:
    """Where relaxation 2's greedy policy leaves the optimum: both policies' actions on the states of
    one simulated path of the optimal policy (``slots`` after 1,000 of burn-in, seed ``seed``: the
    optimum's stationary law), the slots where they differ grouped by (the optimum's process, the
    greedy policy's process), with the median ages there."""
    import numpy as np

    from wncs_lp.policies.matrix_free import MatrixFreePolicy
    from wncs_lp.simulate import simulate

    system = system_for(server, sensors, cap)
    sol = matrix_free_value_iteration(system, tol=1e-9)
    optimum = MatrixFreePolicy(system, sol.layout, sol.local_actions, solution=sol)
    greedy = bound_policy(lower_bound(system, 2, method="ipm"), system)
    path = simulate(optimum, slots=slots, reps=2, seed=seed, burn_in=1_000, path=slots, progress=False).path
    ours = greedy.act(path.tau, path.config)
    labels = system.labels[:, :, 0]  # one server: the process sent (1-based), 0 nothing
    sent_opt, sent_greedy = labels[path.config, path.action], labels[path.config, ours]
    rows = []
    differ = sent_opt != sent_greedy
    for a, b in sorted(set(zip(sent_opt[differ].tolist(), sent_greedy[differ].tolist()))):
        at = differ & (sent_opt == a) & (sent_greedy == b)
        rows.append({"optimum sends": a, "greedy sends": b, "share of slots": float(at.mean()),
                     "median ages": np.median(path.tau[at], axis=0).tolist()})
    rows.sort(key=lambda r: -r["share of slots"])
    return [{"instance": f"{server}:{sensors}:{cap}", "differ": float(differ.mean()),
             "mean ages": path.tau.mean(axis=0).round(2).tolist()}] + rows


def policies_on_tables(server: str, sensors: int, cap: int, names=("bound", "lookahead", "lookahead3", "rollout"),
                       relaxations=(2, 4)):
    """The policies ``names`` on the tables of ``relaxations`` (2: its interior point; 4: the pair
    tables; 5: every pair's tables), each evaluated exactly, against g*: whether the tighter
    relaxation's tables, or a deeper search on them, make the better policy. Each relaxation's
    certified bound is a row too. A generator: each row as soon as it is known (an exact
    evaluation at five sensors takes minutes)."""
    system = system_for(server, sensors, cap)
    g = float(matrix_free_value_iteration(system, tol=1e-9).gain)
    known = {number: (number, name, kw) for number, name, kw in (*RELAXATIONS, ALL_PAIRS)}
    for number, _, kw in (known[int(r)] for r in relaxations):
        c0 = time.process_time()
        bound = lower_bound(system, number, **kw)
        yield {"instance": f"{server}:{sensors}:{cap}", "tables": bound.relaxation, "policy": "(the bound)",
               "gain": float(bound.lower_bound), "loss": (float(bound.lower_bound) - g) / g,
               "cpu_seconds": round(time.process_time() - c0, 1)}
        for name in names:
            c0 = time.process_time()
            r = policy_gaps(bound, system, [name], exact=True).rows[0]
            yield {"instance": f"{server}:{sensors}:{cap}", "tables": bound.relaxation, "policy": r.policy,
                   "gain": r.gain, "loss": (r.gain - g) / g, "cpu_seconds": round(time.process_time() - c0, 1)}


def _in_child(item: str, extra: list[str]) -> list[dict]:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", item] + extra
    out = subprocess.run(cmd, capture_output=True, text=True)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("ROWS ")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"{item}: child failed ({out.returncode}): {out.stderr[-2000:]}")
    return json.loads(lines[-1][5:])


def _short(row: str) -> str:
    """A policy's column name: 'bound[joint-configuration]' -> 'bound', 'rollout-k4-...' -> 'rollout'."""
    for key, short in (("lookahead", "lookahead"), ("rollout", "rollout"), ("bound[private", "greedy of 1"),
                       ("bound[joint", "greedy of 2"), ("index", "index"), ("suboptimal", "suboptimal"),
                       ("static", "static"), ("greedy", "greedy")):
        if row.startswith(key):
            return short
    return row


def markdown(rows: list[dict]) -> str:
    """One line per instance: g*, the time at the cap, each bound's looseness and each policy's loss (%)."""
    order = ["LB 1", "LB 2", "LB 3", "LB 4", "greedy of 2", "lookahead", "rollout", "index", "greedy of 1", "static",
             "suboptimal"]
    head = ("| server, sensors, cap | slots a delivery | states | g* | max time at cap | " + " | ".join(
        f"{c} looseness" if c.startswith("LB") else f"{c} loss" for c in order) + " |")
    out = [head, "|" + "---|" * (5 + len(order))]
    by = {}
    for r in rows:
        by.setdefault(r["instance"], {})[r["row"][:4] if r["row"].startswith("LB") else _short(r["row"])] = r
    for inst, d in by.items():
        g = d["optimum g*"]
        cells = []
        for c in order:
            r = d.get(c)
            cells.append("" if r is None else f"{100 * abs(float(r['vs_optimum'])):.3f}%")
        load = int(g["sensors"]) * SLOTS_PER_DELIVERY[g["server"]]
        out.append(f"| {g['server']}, {g['sensors']}, {g['cap']} | {load:.1f} | {int(g['states']):,} | {float(g['value']):.6f} | "
                   f"{100 * float(g['cap_mass_max']):.2f}% | " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="CSV file (written after every instance)")
    ap.add_argument("--md", default=None, help="markdown table file")
    ap.add_argument("--instances", default=None, help="SERVER:SENSORS:CAP,... (e.g. edge:3:30,cloud:2:30)")
    ap.add_argument("--no-rollout", action="store_true", help="leave the rollout out (its exact evaluation is the slowest)")
    ap.add_argument("--compare-optimum", default=None, metavar="SERVER:SENSORS:CAP",
                    help="where relaxation 2's greedy policy acts otherwise than the optimum, on the optimum's path")
    ap.add_argument("--tables", default=None, metavar="SERVER:SENSORS:CAP",
                    help="the greedy policy, the lookahead (depth 2, 3) and the rollout on the tables of --relaxations")
    ap.add_argument("--relaxations", default="2,4", help="with --tables: whose tables (2, 4, 5; default %(default)s)")
    ap.add_argument("--policies", default="bound,lookahead,lookahead3,rollout",
                    help="with --tables: the policies (default %(default)s)")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    if args.tables:
        server, n, cap = args.tables.split(":")
        for row in policies_on_tables(server, int(n), int(cap), relaxations=args.relaxations.split(","),
                                      names=tuple(args.policies.split(","))):
            print(json.dumps(row), flush=True)
        return 0
    if args.compare_optimum:
        server, n, cap = args.compare_optimum.split(":")
        for row in compare_optimum(server, int(n), int(cap)):
            print(json.dumps(row))
        return 0
    if args.child:
        server, n, cap = args.child.split(":")
        print("ROWS " + json.dumps(run_instance(server, int(n), int(cap), not args.no_rollout), default=float), flush=True)
        return 0
    todo = DEFAULT if args.instances is None else [(s.split(":")[0], int(s.split(":")[1]), int(s.split(":")[2]))
                                                   for s in args.instances.split(",")]
    print(f"load {load1()}", flush=True)
    rows: list[dict] = []
    for server, n, cap in todo:
        new = _in_child(f"{server}:{n}:{cap}", ["--no-rollout"] * args.no_rollout)
        rows += new
        for r in new:
            print(f"{r['instance']:<12} {r['row']:<44} {float(r['value']):>14.8g} {100 * float(r['vs_optimum']):>+9.4f}% "
                  f"{r.get('cpu_seconds') or '':>8} {r['peak_gib']:>6}", flush=True)
        if args.out:
            atomic_write_csv(args.out, rows, COLUMNS, extras="ignore")
        if args.md:
            atomic_write_text(args.md, markdown(rows) + "\n")
    print("\n" + markdown(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
