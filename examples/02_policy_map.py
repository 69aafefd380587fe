"""Solve the paper's processes 1 and 2 and draw the optimal policy in idle-server states (Fig. 4).

    python examples/02_policy_map.py [out.png]
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import wncs_lp  # noqa: E402
from wncs_lp.viz import plot_policy_map  # noqa: E402
from wncs_lp.solvers import evaluate_policy  # noqa: E402

out = sys.argv[1] if len(sys.argv) > 1 else "policy_map_p12.png"
scenario = wncs_lp.load_scenario("formulations/paper_p12.toml", ["tau_cap=15"])
mdp = wncs_lp.build(scenario)
sol = wncs_lp.solve(mdp, method="pi")
stationary = evaluate_policy(mdp, sol.policy).stationary
ax = plot_policy_map(mdp, sol, "idle", axes=(1, 2), stationary=stationary, scenario=scenario)
ax.figure.savefig(out, dpi=120, bbox_inches="tight")
plt.close(ax.figure)
print(f"optimal average MSE {sol.gain:.6f}; map written to {out}")
