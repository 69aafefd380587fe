"""Any finite average-cost MDP: a machine-replacement problem solved three ways.

State = machine wear 0..4; action 0 = keep (cost grows with wear, wear may increase),
action 1 = replace (cost 6, back to wear 0). Not a WNCS model: the solvers are generic.

    python examples/04_custom_mdp.py
"""
import numpy as np

import wncs_lp

n = 5
P = np.zeros((n, 2, n))
cost = np.zeros((n, 2))
for s in range(n):
    P[s, 0, min(s + 1, n - 1)] += 0.6
    P[s, 0, s] += 0.4
    cost[s, 0] = s**2
    P[s, 1, 0] = 1.0
    cost[s, 1] = 6.0
mdp = wncs_lp.MDP.from_dense(P, cost)
for method in ("lp", "rvi", "pi"):
    sol = wncs_lp.solve(mdp, method=method)
    print(f"{method:>4}: gain {sol.gain:.10f} in [{sol.gain_lower:.10f}, {sol.gain_upper:.10f}], "
          f"replace when wear >= {int(np.argmax(sol.actions(mdp) == 1))}")
