"""The library end to end, as in a notebook: the walk-through of docs/notebook.md (its numbers are
this script's output).

    python examples/06_notebook.py [tau_cap] [maps.png]

Each ``# %%`` cell is one notebook cell (VS Code, Spyder and Jupytext read them as such).
"""
# %% 1. A shipped scenario by name, its MDP
import sys

import numpy as np

import wncs_lp
from wncs_lp.evaluate import evaluate
from wncs_lp.policies import Policy, System, pairs_to_sigma, sigma_to_pairs
from wncs_lp.workflow import make_policy
from wncs_lp.simulate import simulate
from wncs_lp.solvers import laurent_terms
from wncs_lp.solvers.dp import evaluate_policy

cap = int(sys.argv[1]) if len(sys.argv) > 1 else 10
maps_png = sys.argv[2] if len(sys.argv) > 2 else None

scenario = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), [f"tau_cap={cap}"])
print(scenario.describe())
mdp = wncs_lp.build(scenario)
system = System.from_scenario(scenario)
print(f"{mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs, {system.n_configs} server configurations")

# %% 2. Solve, certified
sol = wncs_lp.solve(mdp)
print(sol)

# %% 3. The policy as a table: state -> action, bias
print(f"\n{'state (tau | servers)':<58} {'action':<8} {'bias':>9}")
for s in (0, 1, 2, mdp.n_states // 2, mdp.n_states - 1):
    print(f"{mdp.state_label(s):<58} {str(mdp.action_label(int(sol.policy[s]))):<8} {sol.bias[s]:9.2f}")

# %% 4. The policy forms: pair indices vs an action per state
assert np.array_equal(pairs_to_sigma(mdp, sol.policy), sol.sigma)
assert np.array_equal(sigma_to_pairs(mdp, sol.sigma), sol.policy)
print(f"\nsol.policy[:6] = {sol.policy[:6].tolist()} (pair indices), sol.sigma[:6] = {sol.sigma[:6].tolist()} "
      f"(rows of mdp.action_table: {[tuple(int(x) for x in mdp.action_table[a]) for a in sol.sigma[:6]]})")
print(f"evaluate(mdp, sigma=sol.sigma).gain = {evaluate(mdp, sigma=sol.sigma).gain:.10g}")


# %% 5. A policy of one's own, from a function of (tau, configuration)
def stalest_to_edge(tau, conf):
    """Send the stalest process to the edge and the other to the remote, where they accept;
    otherwise the first allowed action."""
    stalest = 1 if tau[0] >= tau[1] else 2
    for want in ((3 - stalest, stalest), (0, stalest), (3 - stalest, 0), (stalest, 0)):
        if want in conf.actions:
            return want
    return conf.actions[0]


mine = Policy.from_function(system, stalest_to_edge, name="stalest to edge")

# %% 6. Every policy evaluated exactly (stationary law of its chain)
rows = [evaluate(mdp, make_policy(name, system, mdp, solution=sol)) for name in
        ("optimal", "suboptimal", "static", "greedy")] + [evaluate(mdp, mine)]
names = rows[0].process_names + tuple(f"util {s}" for s in rows[0].server_names)
print(f"\n{'policy':<20} {'gain':>10} {'/ g*':>6} " + " ".join(f"{n:>12}" for n in names))
for ev in rows:
    cols = ev.mse + ev.utilisation
    print(f"{ev.policy:<20} {ev.gain:10.3f} {ev.gain / sol.gain:6.3f} " + " ".join(f"{v:12.4f}" for v in cols))

# %% 7. Simulation against the exact value
res = simulate(mine, slots=20_000, reps=10, seed=1, burn_in=500, progress=False)
exact = rows[-1].gain
print(f"\nsimulated {res.mean:.3f} +- {res.stderr:.3f} vs exact {exact:.3f}: "
      f"{abs(res.mean - exact) / res.stderr:.2f} standard errors apart")

# %% 8. Discounted solves and the average cost as beta -> 1
ev = evaluate_policy(mdp, sol)
print(f"\n{'beta':>7} {'status':>8} {'gap':>9} {'(1-b) min v':>12} {'(1-b) max v':>12} {'same policy':>12} "
      f"{'|(1-b)v - g|':>13} {'|v - g/(1-b) - h|':>18}")
for beta in (0.9, 0.99, 0.999, 0.9999):
    d = wncs_lp.solve(mdp, discount=beta)
    lt = laurent_terms(mdp, sol.policy, beta, gain=ev.gain, bias=ev.bias, stationary=ev.stationary)
    same = f"{np.mean(d.policy == sol.policy):.1%}"
    print(f"{beta:>7g} {d.status:>8} {d.gap:9.1e} {(1 - beta) * d.value.min():12.3f} {(1 - beta) * d.value.max():12.3f} "
          f"{same:>12} {lt['gain_error']:13.4g} {lt['bias_error']:18.4g}")

# %% 9. Two maps side by side (the legend of the first sits below it, not under the second)
if maps_png:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wncs_lp.viz import plot_policy_map

    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    plot_policy_map(mdp, sol, "idle", ax=axes[0])
    plot_policy_map(mdp, mine.on_mdp(mdp), "idle", ax=axes[1], title="stalest to edge, servers idle")
    fig.savefig(maps_png, dpi=70, bbox_inches="tight")
    print(f"\nmaps written to {maps_png}")
