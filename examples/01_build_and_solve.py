"""Build a scenario in code, solve it by LP and by value iteration, and compare.

    python examples/01_build_and_solve.py
"""
import wncs_lp

scenario = wncs_lp.scenario_from_dict(
    {
        "model": {"kind": "wncs", "tau_cap": 10},
        "channel": {"success_probability": 0.85},
        "process": [
            {"name": "pendulum", "A": [[1.1, 0.1], [0.0, 1.05]]},
            {"name": "tank", "A": [[1.02]], "R": [[2.0]], "weight": 0.5},
        ],
        "server": [
            {"name": "cloud", "uplink_delay": 1, "downlink_delay": 1, "slots_per_dimension": 1},
            {"name": "edge", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 2, "p_up": 0.95},
        ],
    }
)
print(scenario.describe())
mdp = wncs_lp.build(scenario)
print(mdp)

lp = wncs_lp.solve(mdp, method="lp")
rvi = wncs_lp.solve(mdp, method="rvi")
for sol in (lp, rvi):
    print(f"{sol.method:>4}: gain {sol.gain:.10f}  certificate [{sol.gain_lower:.10f}, {sol.gain_upper:.10f}]"
          f"  status {sol.status}  {sol.seconds:.2f} s")
print(f"LP raw objective {lp.stats['lp_objective']:.10f}; |LP - RVI| / gain = {abs(lp.gain - rvi.gain) / rvi.gain:.1e}")
print("same policy in every state:", bool((lp.policy == rvi.policy).all()))
