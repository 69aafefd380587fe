"""Issue 33 item 4 / issue 36: how precise the Monte Carlo half of a certified gap is, and whether
its interval holds.

    python benchmarks/simulation.py --out benchmarks/simulation.csv        # ~1.5 hours on 2 cores, loaded
    python benchmarks/simulation.py --sections precision,cost --relaxation 1   # the bound in seconds
    python benchmarks/simulation.py --sections coverage --groups 100

Four sections, one CSV row per measured quantity (every row records the 1-minute load average when
it started: the machine is shared; compare rows of one run):

* ``precision``: at 8 processes (``bounds_p1234_twice``, cap 20) the bound (``--relaxation``,
  default 3 as ``auto`` picks it there), then :func:`wncs_lp.bounds.policy_gaps` by Monte Carlo
  with the reproduction's B3 settings (10 x 20,000 slots) and ``wncs-lp bound --policy``'s
  (20 x 40,000), each without and with the bound's tables as control variate: per policy the
  mean, the one-sided 95% upper limit, the statistical term (upper - mean) / mean, the certified
  gap, the variance reduction and the seconds.
* ``cost``: the CPU seconds of the bound's own policy over 10 replications of 20,000 and of 5,000
  slots, without and with the control variate, and the statistical term each gives.
* ``coverage``: on a 5-sensor system (five scalar processes A = 1.3, 1.2, 1.15, 1.1, 1.05 on a
  cloud server U = D = 1 and an edge server U = D = 0, p = 0.8, cap 8) with every policy's gain
  exact (certified matrix-free evaluation), ``--groups`` independent runs of 10 replications x
  20,000 slots (one vectorised simulation of groups x 10 replications): how often the one-sided
  95% upper limit, the lower one and the batch-means one cover the exact gain, the largest
  |mean - exact| / stderr, the runs beyond 3 standard errors, the grand mean's distance to the
  exact gain in its standard errors, the replication means' skewness and excess kurtosis, without
  and with relaxation 1's tables as control variate.
* ``seeds``: the same system at caps 8 and 10, 20 seeds of 10 x 20,000 slots of each of five
  policies (relaxation 1's, suboptimal, greedy, max-age-first, max-cost-first), against the exact
  gain: the largest |mean - exact| / stderr and the runs beyond 3.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from wncs_lp.bounds import BoundPolicy, bound_policy, lower_bound, policy_gaps  # noqa: E402
from wncs_lp.files import atomic_write_csv  # noqa: E402
from wncs_lp.intervals import batch_means_interval, replication_interval  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.policies import Policy  # noqa: E402
from wncs_lp.workflow import make_policy  # noqa: E402
from wncs_lp.scenario import load_scenario, scenario_from_dict  # noqa: E402
from wncs_lp.formulations import scenario_path  # noqa: E402
from wncs_lp.simulate import simulate  # noqa: E402

COLUMNS = ["section", "instance", "policy", "setting", "control", "reps", "slots", "mean", "upper", "stat_pct",
           "gap_pct", "variance_reduction", "exact", "cover_upper", "cover_lower", "cover_batch_means", "max_abs_z",
           "beyond_3", "grand_z", "skew", "excess_kurtosis", "seconds", "load1"]
#: (reps, slots) of the reproduction's B3 and of ``wncs-lp bound --policy``.
SETTINGS = {"b3": (10, 20_000), "bound-cli": (20, 40_000)}

LAB5 = {
    "model": {"kind": "wncs", "tau_cap": 8, "allow_idle": False, "distinct": True},
    "channel": {"success_probability": 0.8},
    "process": [{"name": f"s{i + 1}", "A": [[a]], "R": "identity"} for i, a in enumerate((1.3, 1.2, 1.15, 1.1, 1.05))],
    "server": [{"name": "cloud", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1},
               {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2}],
}


def load1() -> float:
    return round(os.getloadavg()[0], 2)


def precision(args, emit) -> None:
    sc = load_scenario(scenario_path("bounds_p1234_twice"), [f"tau_cap={args.cap}"])
    system = System.from_scenario(sc)
    t0 = time.perf_counter()
    bound = lower_bound(system, args.relaxation)
    print(f"{bound.relaxation} bound {bound.lower_bound:.10g} in {time.perf_counter() - t0:.1f} s", flush=True)
    policies = ["bound", "suboptimal", "static"]
    if bound.relaxation != "private-servers":
        policies.insert(1, BoundPolicy(lower_bound(system, 1), system))
    for setting, (reps, slots) in SETTINGS.items():
        for control in (False, True):
            l1 = load1()
            rep = policy_gaps(bound, system, policies, exact=False, slots=slots, reps=reps, seed=0, burn_in=1000,
                              control=control)
            for r in rep.rows:
                emit({"section": "precision", "instance": f"bounds_p1234_twice:{args.cap}", "policy": r.policy,
                      "setting": setting, "control": control, "reps": reps, "slots": slots, "mean": r.gain,
                      "upper": r.gain_upper, "stat_pct": 100 * (r.gain_upper - r.gain) / r.gain,
                      "gap_pct": 100 * r.gap, "variance_reduction": r.detail["variance_reduction"],
                      "seconds": r.seconds, "load1": l1})


def cost(args, emit) -> None:
    """CPU seconds of the bound's own policy, 10 replications at 20,000 and 5,000 slots, without and
    with the control variate (process time: the machine's load inflates the wall clock, not this)."""
    sc = load_scenario(scenario_path("bounds_p1234_twice"), [f"tau_cap={args.cap}"])
    system = System.from_scenario(sc)
    bound = lower_bound(system, args.relaxation)
    pol = bound_policy(bound, system)
    for slots in (20_000, 5_000):
        for control in (False, True):
            l1, c0, t0 = load1(), time.process_time(), time.perf_counter()
            res = simulate(pol, slots=slots, reps=10, seed=0, burn_in=1000, control=bound.tables if control else None,
                           progress=False)
            cpu = time.process_time() - c0
            ci = res.interval()
            emit({"section": "cost", "instance": f"bounds_p1234_twice:{args.cap}", "policy": pol.name,
                  "setting": f"10 x {slots}, CPU seconds {cpu:.2f}", "control": control, "reps": 10, "slots": slots,
                  "mean": res.mean, "upper": ci.upper, "stat_pct": 100 * (ci.upper - ci.estimate) / ci.estimate,
                  "variance_reduction": res.variance_reduction, "seconds": time.perf_counter() - t0, "load1": l1})


def coverage(args, emit) -> None:
    from wncs_lp.solvers.matrix_free import matrix_free_evaluate

    system = System.from_scenario(scenario_from_dict(LAB5))
    bound = lower_bound(system, 1)
    reps = 10
    for name in ("bound", "suboptimal", "greedy"):
        pol = bound_policy(bound, system) if name == "bound" else make_policy(name, system)
        g = float(matrix_free_evaluate(system, pol).gain)
        for control in (False, True):
            l1, t0 = load1(), time.perf_counter()
            res = simulate(pol, slots=20_000, reps=args.groups * reps, seed=7, burn_in=1000,
                           control=bound.tables if control else None, progress=False)
            y = np.asarray(res.rep_means).reshape(args.groups, reps)
            up = [replication_interval(v, 0.95, "upper") for v in y]
            lo = [replication_interval(v, 0.95, "lower") for v in y]
            bs = res.batch_sums.reshape(args.groups, reps, -1)
            bm = [batch_means_interval(bs[i], res.batch_sizes, 0.95, "upper") for i in range(args.groups)]
            z = np.array([(ci.estimate - g) / ci.stderr for ci in up])
            emit({"section": "coverage", "instance": "5 sensors, cap 8, p = 0.8", "policy": pol.name,
                  "setting": f"{args.groups} runs of 10 x 20000", "control": control, "reps": reps, "slots": 20_000,
                  "mean": res.mean, "exact": g, "variance_reduction": res.variance_reduction,
                  "cover_upper": np.mean([c.contains(g) for c in up]),
                  "cover_lower": np.mean([c.contains(g) for c in lo]),
                  "cover_batch_means": np.mean([c.contains(g) for c in bm]),
                  "max_abs_z": float(np.abs(z).max()), "beyond_3": int((np.abs(z) > 3).sum()),
                  "grand_z": (res.mean - g) / res.stderr, "skew": float(stats.skew(res.rep_means)),
                  "excess_kurtosis": float(stats.kurtosis(res.rep_means)), "seconds": time.perf_counter() - t0,
                  "load1": l1})


def seeds(args, emit) -> None:
    """20 seeds of 10 x 20,000 slots per policy at caps 8 and 10 of the 5-sensor system: how far each
    run's mean lies from the exact gain, in its own standard errors."""
    from wncs_lp.solvers.matrix_free import matrix_free_evaluate

    for cap in (8, 10):
        system = System.from_scenario(scenario_from_dict({**LAB5, "model": {**LAB5["model"], "tau_cap": cap}}))
        bound = lower_bound(system, 1)
        pols = [bound_policy(bound, system), make_policy("suboptimal", system), make_policy("greedy", system),
                MaxAgeFirst(system), MaxCostFirst(system)]
        for pol in pols:
            l1, t0 = load1(), time.perf_counter()
            g = float(matrix_free_evaluate(system, pol).gain)
            z = np.array([(r.mean - g) / r.stderr for r in
                          (simulate(pol, slots=20_000, reps=10, seed=seed, burn_in=1000, progress=False)
                           for seed in range(20))])
            emit({"section": "seeds", "instance": f"5 sensors, cap {cap}, p = 0.8", "policy": pol.name,
                  "setting": "20 seeds of 10 x 20000", "control": False, "reps": 10, "slots": 20_000, "exact": g,
                  "max_abs_z": float(np.abs(z).max()), "beyond_3": int((np.abs(z) > 3).sum()),
                  "seconds": time.perf_counter() - t0, "load1": l1})


class MaxAgeFirst(Policy):
    """Send the processes of largest AoI: the action maximising the summed AoI of the processes it sends."""

    name = "max-age-first"

    def __init__(self, system):
        super().__init__(system)
        S = np.zeros((system.n_configs, system.max_actions, system.n_processes))
        for c, acts in enumerate(system.automaton.actions):
            for j, label in enumerate(acts):
                for k in label:
                    if k > 0:
                        S[c, j, k - 1] += 1
        self.S = S

    def weights(self, tau):
        return tau.astype(float)

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        v = np.einsum("rak,rk->ra", self.S[c], self.weights(tau))
        v[~self.system.action_valid[c]] = -np.inf
        return np.argmax(v, axis=1).astype(np.int64)


class MaxCostFirst(MaxAgeFirst):
    """The same with each process's current MSE q_k(tau_k) instead of its AoI."""

    name = "max-cost-first"

    def weights(self, tau):
        return np.stack([self.system.q[k][tau[:, k] - 1] for k in range(self.system.n_processes)], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", default="precision,cost,coverage,seeds")
    ap.add_argument("--relaxation", default="3", help="the 8-process bound's relaxation (default 3)")
    ap.add_argument("--cap", type=int, default=20)
    ap.add_argument("--groups", type=int, default=200, help="coverage: independent runs (default 200)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    args.relaxation = int(args.relaxation) if args.relaxation.isdigit() else args.relaxation
    rows = []

    def emit(row):
        rows.append(row)
        print("  ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)

    for section in args.sections.split(","):
        {"precision": precision, "cost": cost, "coverage": coverage, "seeds": seeds}[section](args, emit)
    if args.out:
        atomic_write_csv(args.out, rows, COLUMNS)


if __name__ == "__main__":
    main()
