"""Min-max fairness: minimise the largest per-process average MSE, against the unconstrained optimum.

Paper processes 1 and 2 (paper_p12.toml), a server may be left idle, AoI cap 8 by default:

    python examples/05_fairness_minmax.py [cap]

The min-max optimum is not unique when one process dominates (every policy giving process 1
its least MSE is min-max optimal, whatever it does to process 2), and the interior point's
answer mixes them all. So a second, linear program takes the least total MSE among them.
"""
import sys

import cvxpy as cp

import wncs_lp
from wncs_lp.constrained import with_cost
from wncs_lp.constrained.convex import OccupationProgram

cap = int(sys.argv[1]) if len(sys.argv) > 1 else 8
sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["model.allow_idle=true", f"tau_cap={cap}"])
mdp = wncs_lp.build(sc)

prog = OccupationProgram(mdp)
mse = [prog.process_cost(k) for k in range(sc.n_processes)]
fair = prog.solve(cp.Minimize(cp.maximum(*mse)))                   # min over policies of max_k MSE_k
best = prog.solve(cp.Minimize(prog.cost()),                         # least total MSE among those policies
                  {f"MSE[{p.name}] <= max": m <= fair.gain * (1 + 1e-9) for p, m in zip(sc.processes, mse)})
opt = wncs_lp.solve(mdp, "vi")                                      # unconstrained optimum (certified VI)

print(f"paper_p12.toml, allow_idle = true, tau_cap = {cap}: {mdp.n_states} states, {mdp.n_pairs} pairs")
names = [p.name for p in sc.processes]
print(f"{'policy':<24}" + "".join(f"{'MSE ' + n:>18}" for n in names) + f"{'total MSE':>14}{'max MSE':>12}{'randomised':>12}")
for label, sol in (("unconstrained optimum", opt), ("min-max (Clarabel)", fair), ("min-max, least total", best)):
    per = [prog.value(m, sol) for m in mse]
    rnd = getattr(sol, "n_randomized", 0)
    print(f"{label:<24}" + "".join(f"{v:>18.6f}" for v in per) + f"{sum(per):>14.6f}{max(per):>12.6f}{rnd:>12d}")

LOWER = {"subgradient": "subgradient bound, certified value iteration",
         "solver_dual": "Clarabel's dual objective, not re-checked", "lagrangian": "Lagrangian bound"}
lower = max(wncs_lp.solve(with_cost(mdp, prog.vector("process_cost", process=k)), "vi").gain_lower
            for k in range(sc.n_processes))
print(f"certificate, unconstrained optimum: total MSE in [{opt.gain_lower:.9f}, {opt.gain_upper:.9f}], {opt.status} "
      f"(certified value iteration)")
print(f"certificate, min-max: max MSE in [{fair.gain_lower:.9f}, {fair.gain_upper:.9f}], {fair.status} "
      f"(lower: {LOWER[fair.stats['certificate']]}; upper: exact value of the policy; "
      f"Clarabel gap {fair.stats['duality_gap_abs']:.2e})")
print(f"certificate, min-max least total: total MSE in [{best.gain_lower:.9f}, {best.gain_upper:.9f}], {best.status} "
      f"(lower: Lagrangian bound; upper: exact value of the policy)")
print(f"lower bound on the max MSE, max over k of the least MSE_k of any policy: {lower:.9f}")
