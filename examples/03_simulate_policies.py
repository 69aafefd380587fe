"""All four paper processes at AoI cap 30 (never enumerated): the separable suboptimal policy
against the static and greedy baselines, by Monte Carlo.

    python examples/03_simulate_policies.py [slots] [reps]
"""
import sys

import wncs_lp
from wncs_lp.policies import GreedyPolicy, StaticPolicy, SuboptimalPolicy, System, default_assignment
from wncs_lp.simulate import simulate

slots = int(sys.argv[1]) if len(sys.argv) > 1 else 5_000
reps = int(sys.argv[2]) if len(sys.argv) > 2 else 8
scenario = wncs_lp.load_scenario("formulations/paper_p1234.toml", ["tau_cap=30"])
system = System.from_scenario(scenario)
sub = SuboptimalPolicy(system)
print(f"suboptimal tables {sub.table_sizes} built in {sub.build_seconds:.2f} s; "
      f"random base gain (Lemma 2) {sub.base_gain:.2f}")
for policy in (sub, StaticPolicy(system, default_assignment(scenario)), GreedyPolicy(system)):
    res = simulate(policy, slots=slots, reps=reps, seed=1, burn_in=500, progress=False)
    print(f"{policy.name:>12}: {res.mean:10.2f} +- {res.stderr:.2f}  ({res.seconds:.1f} s)")
