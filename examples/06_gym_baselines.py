"""Baseline policies run through the Gymnasium environment, against the certified optimum g*.

An RL agent plugs in where ``act`` is: it sees the observation (AoI vector and configuration id)
and the action mask, and its long-run average reward is minus its average cost. Here three
baselines (a masked random agent, the greedy rule, the separable suboptimal policy) run for
``steps`` slots; each average cost is compared with the certified optimal gain g* and with a
certified lower bound on g* (what one has when the scenario is too large to solve exactly).

    python examples/06_gym_baselines.py [steps] [tau_cap]
"""
import sys

import numpy as np

from wncs_lp.env import WncsEnv
from wncs_lp.policies import GreedyPolicy, SuboptimalPolicy

steps = int(sys.argv[1]) if len(sys.argv) > 1 else 20_000
cap = int(sys.argv[2]) if len(sys.argv) > 2 else 10
env = WncsEnv("paper_p12", [f"tau_cap={cap}"])
opt, bound = env.optimum(), env.lower_bound()
print(f"paper_p12 at cap {cap}: observation {env.observation_space}, action {env.action_space}")
print(f"certified optimum g* = {opt.gain:.4f} in [{opt.gain_lower:.6f}, {opt.gain_upper:.6f}] ({opt.status}); "
      f"certified lower bound {bound.lower_bound:.4f} ({bound.relaxation})")


def masked_random(obs, rng):
    return int(rng.choice(np.flatnonzero(env.action_masks())))


def run(act, seed: int, burn_in: int = 500, batches: int = 20) -> tuple[float, float]:
    """Average cost over ``steps`` slots after ``burn_in``, and its batch-means standard error."""
    rng = np.random.default_rng(seed)
    obs, _ = env.reset(seed=seed)
    costs = []
    for _ in range(burn_in + steps):
        obs, reward, terminated, truncated, info = env.step(act(obs, rng))
        costs.append(-reward)
    means = np.asarray(costs[burn_in:][: steps // batches * batches]).reshape(batches, -1).mean(axis=1)
    return float(means.mean()), float(means.std(ddof=1) / np.sqrt(batches))


agents = {
    "random (masked)": masked_random,
    "greedy": lambda obs, rng, p=GreedyPolicy(env.system): env.policy_action(p, obs),
    "suboptimal": lambda obs, rng, p=SuboptimalPolicy(env.system): env.policy_action(p, obs),
}
print(f"{'agent':>16}  {'average cost':>14}  {'gap to g*':>10}")
for seed, (name, act) in enumerate(agents.items()):
    mean, se = run(act, seed)
    print(f"{name:>16}  {mean:8.3f} +- {se:4.2f}  {100 * (mean / opt.gain - 1):9.2f}%")
