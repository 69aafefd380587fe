"""A lab's five sensors against the field's baselines, with the answer without the AoI cap.

    python examples/07_lab_baselines.py                 # cap 12: 22 million states (docs/evaluation.md)
    python examples/07_lab_baselines.py 6 4000 8        # cap, simulated slots, replications: a quick look

The system is ``formulations/lab_5sensors.toml`` (five scalar sensors, an edge and a cloud server,
p = 0.8). At the cap it prints

* the certified optimum g* (the matrix-free solver: no matrix is stored) and its time at the cap;
* every baseline's exact average cost (certified matrix-free evaluation; round robin, a policy with
  memory, on its per-process chains) and its certified gap to g*: (upper end - g*_lower) / g*_lower;
* every policy simulated without the cap (it sees the capped AoI, the true AoI is charged; one
  seed: common random numbers), and the interval for the optimum without the cap: the certified
  g* below, the least upper confidence limit of those policies above (Bonferroni over them).
"""
from __future__ import annotations

import sys
import warnings

import wncs_lp
from wncs_lp.errors import ScenarioWarning
from wncs_lp.policies import MatrixFreePolicy
from wncs_lp.workflow import make_policy
from wncs_lp.solvers.matrix_free import matrix_free_cap_mass, matrix_free_evaluate
from wncs_lp.truncation import CapCount
from wncs_lp.untruncated import untruncated_interval

BASELINES = ("greedy", "max_age", "max_weight", "round_robin", "static", "suboptimal", "random")


def main(cap: int = 12, slots: int = 40_000, reps: int = 20) -> None:
    warnings.simplefilter("ignore", ScenarioWarning)  # caps at the loop lengths, for a quick look
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("lab_5sensors"), [f"tau_cap={cap}"])
    sol = wncs_lp.solve(sc, "matrix-free")
    system = sol.system
    lo = sol.gain_lower
    print(f"lab_5sensors at cap {cap}: {sol.stats['n_states']:,} states; g* = {sol.gain:.10g} "
          f"(certified {sol.gain_lower:.10g} .. {sol.gain_upper:.10g}), {sol.seconds:.0f} s")
    print(f"  time at the cap: {CapCount.of(matrix_free_cap_mass(system, sol), system).message()}")
    policies, exact = [MatrixFreePolicy.from_solution(sol)], {"optimal": (sol.gain, 0.0)}
    for name in BASELINES:
        pol = make_policy(name, system)
        if hasattr(pol, "separable_evaluation"):  # round robin: its per-process chains
            gain = upper = pol.separable_evaluation().gain
        else:
            ev = matrix_free_evaluate(system, pol, name=name)
            gain, upper = ev.gain, ev.gain_upper
        policies.append(pol)
        exact[pol.name] = (gain, (upper - lo) / lo)
    # the optimal policy and every baseline without the cap, one seed for all (common random numbers)
    interval = untruncated_interval(lo, policies, slots=slots, reps=reps, seed=0,
                                    lower_from=f"the certified optimum at cap {cap}")
    print(f"{'policy':<22} {'exact gain':>12} {'gap to g*':>10} {'without the cap (simulated)':>30}")
    for c in interval.candidates:
        gain, gap = exact[c.policy]
        free = f"{c.mean:>16.6f} +- {c.stderr:<7.3g}" if not c.note else f"unbounded: {c.note}"
        print(f"{c.policy:<22} {gain:>12.6f} {gap:>9.1%} {free}")
    print(interval.message())


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:4]))
