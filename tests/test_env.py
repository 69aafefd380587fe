"""The Gymnasium environment (:mod:`wncs_lp.env`): Gymnasium's own checker, seeded resets, and
the long-run average cost of fixed policies run through ``env.step`` against their exact
evaluation on the enumerated MDP (a different code path: the MDP's sparse matrix and a
stationary-law solve), within Monte Carlo error."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import wncs_lp
from wncs_lp.evaluate import evaluate
from wncs_lp.policies import GreedyPolicy, OptimalPolicy

gymnasium = pytest.importorskip("gymnasium")  # in the test extra; skipped only where it cannot be installed
from gymnasium.utils.env_checker import check_env  # noqa: E402

from wncs_lp.env import ENV_ID, EnvError, WncsEnv  # noqa: E402

P12, PRE = "paper_p12", "paper_preemption_p12"
CAP = ["tau_cap=7"]


@pytest.mark.parametrize("name", [P12, PRE])
@pytest.mark.parametrize("render_mode", [None, "ansi"])
def test_gymnasium_check_env_passes(name, render_mode):
    # made through the registry, so the checker also tries the other render mode (it needs a spec)
    env = gymnasium.make(ENV_ID, scenario=name, overrides=CAP, render_mode=render_mode).unwrapped
    assert isinstance(env, WncsEnv)
    check_env(env)  # raises on any breach of the API (spaces, seeding, determinism, data reuse)
    obs, info = env.reset(seed=3)
    assert obs["tau"].tolist() == [7, 7] and obs["config"] == env.system.initial_config
    assert info["action_mask"].sum() == env.system.n_actions[env.system.initial_config]


def test_gymnasium_make_knows_the_environment():
    env = gymnasium.make(ENV_ID, scenario=P12, overrides=CAP, max_episode_steps=5)
    env.reset(seed=0)
    flags = [env.step(0)[3] for _ in range(5)]
    assert flags == [False] * 4 + [True]


def _trajectory(env: WncsEnv, seed: int, steps: int) -> list:
    """Masked random actions from a generator of their own; the states visited."""
    rng = np.random.default_rng(99)
    obs, _ = env.reset(seed=seed)
    out = []
    for _ in range(steps):
        action = int(rng.choice(np.flatnonzero(env.action_masks())))
        obs, reward, terminated, truncated, info = env.step(action)
        assert not terminated and not truncated and not info["invalid_action"]
        out.append((obs["tau"].tolist(), int(obs["config"]), reward))
    return out


def test_the_seed_fixes_the_trajectory():
    env = WncsEnv(P12, CAP)
    assert _trajectory(env, 5, 300) == _trajectory(env, 5, 300)
    assert _trajectory(env, 5, 300) != _trajectory(env, 6, 300)


def _action_table(policy, mdp) -> dict:
    """(tau tuple, config) -> the policy's action, for every state of the MDP (one vectorised call)."""
    tau = np.asarray(mdp.states.tau, dtype=np.int64)
    cfg = np.asarray(mdp.states.config, dtype=np.int64)
    acts = policy.act(tau, cfg, np.random.default_rng(0))
    return {(tuple(t), int(c)): int(a) for t, c, a in zip(tau.tolist(), cfg.tolist(), acts.tolist())}


def _batch_means(env: WncsEnv, table: dict, seed: int, burn_in: int, batches: int, size: int) -> np.ndarray:
    """Average cost (minus the reward) of each of ``batches`` consecutive batches of ``size`` steps."""
    obs, _ = env.reset(seed=seed)
    costs = np.empty(burn_in + batches * size)
    for t in range(costs.size):
        obs, reward, _, _, _ = env.step(table[(tuple(obs["tau"].tolist()), int(obs["config"]))])
        costs[t] = -reward
    return costs[burn_in:].reshape(batches, size).mean(axis=1)


@pytest.mark.parametrize("name", [P12, PRE])
def test_a_fixed_policy_averages_its_exact_gain(name):
    """Optimal and greedy policies: the env's time-average cost within 4.5 batch-means standard
    errors of the exact gain (each an independent check of the dynamics and the reward)."""
    env = WncsEnv(name, CAP)
    mdp = wncs_lp.build(env.system.scenario)
    optimal = OptimalPolicy(mdp, env.optimum(), env.system)
    assert env.optimum().status == "optimal"
    for k, policy in enumerate([optimal, GreedyPolicy(env.system)]):
        exact = evaluate(mdp, policy).gain
        means = _batch_means(env, _action_table(policy, mdp), seed=10 + k, burn_in=200, batches=25, size=1000)
        se = means.std(ddof=1) / np.sqrt(means.size)
        assert abs(means.mean() - exact) <= 4.5 * se, (policy.name, means.mean(), exact, se)
        assert se < 0.002 * exact  # sharp (measured 2.4e-4..5.7e-4): a wrong reward or transition would show


def test_policy_action_is_the_policys_act():
    env = WncsEnv(P12, CAP)
    greedy = GreedyPolicy(env.system)
    obs, _ = env.reset(seed=0)
    for _ in range(50):
        j = env.policy_action(greedy, obs)
        assert j == greedy.act(obs["tau"][None, :], np.array([obs["config"]]))[0] and env.action_masks()[j]
        obs, *_ = env.step(j)
    with pytest.raises(EnvError, match="another System"):
        env.policy_action(GreedyPolicy(WncsEnv(P12, CAP).system), obs)


def test_reference_values_bracket_the_optimum():
    env = WncsEnv(P12, CAP)
    opt, bound = env.optimum(), env.lower_bound()
    assert opt.gain_lower <= opt.gain <= opt.gain_upper
    assert bound.lower_bound <= opt.gain_upper  # a certified lower bound on g*


def test_an_action_outside_the_mask():
    """By default it is the configuration's action 0 (same draw, same next state); with
    invalid_action="raise" an error naming the configuration and its actions."""
    env = WncsEnv(PRE, CAP)  # the initial configuration has one action of three
    env.reset(seed=1)
    assert env.action_masks().tolist() == [True, False, False]
    obs_bad, r_bad, _, _, info = env.step(2)
    env.reset(seed=1)
    obs_0, r_0, _, _, info_0 = env.step(0)
    assert info["invalid_action"] and not info_0["invalid_action"]
    assert obs_bad["tau"].tolist() == obs_0["tau"].tolist() and obs_bad["config"] == obs_0["config"] and r_bad == r_0
    strict = WncsEnv(PRE, CAP, invalid_action="raise")
    strict.reset(seed=1)
    with pytest.raises(EnvError, match=r"action 2 is not feasible in configuration 0 .* actions 0\.\.0"):
        strict.step(2)


def test_bad_inputs_are_one_clear_error():
    env = WncsEnv(P12, CAP)
    env.reset(seed=0)
    for action in (7, -1, 1.5, "1", True):
        with pytest.raises(EnvError, match="action"):
            env.step(action)
    with pytest.raises(EnvError, match="reset option 'tau' must be 2 integers with 1 <= tau_k <= cap"):
        env.reset(options={"tau": [0, 3]})
    assert env.reset(options={"tau": np.array([2, 3])})[0]["tau"].tolist() == [2, 3]
    with pytest.raises(EnvError, match="invalid_action must be one of first, raise"):
        WncsEnv(P12, CAP, invalid_action="ignore")
    with pytest.raises(EnvError, match="max_steps must be a positive integer"):
        WncsEnv(P12, CAP, max_steps=0)
    with pytest.raises(EnvError, match="expected a Scenario, a System"):
        WncsEnv(42)
    with pytest.raises(wncs_lp.ScenarioError, match="cannot be read"):
        WncsEnv("no_such_scenario")


def test_without_gymnasium_the_import_says_what_to_install():
    code = "import sys; sys.modules['gymnasium'] = None; import wncs_lp.env"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "needs the optional package 'gymnasium'" in proc.stderr and "pip install 'wncs_lp[interop]'" in proc.stderr


def test_the_optimum_of_a_constrained_scenario_is_the_environments():
    """The environment has no constraints: its optimum is the unconstrained one (here by the LP
    route, checked against policy iteration on the built MDP); the constrained optimum, asked for,
    is dearer."""
    env = WncsEnv("paper_p12_cloud_budget", CAP)
    free, held = env.optimum(), env.optimum(constrained=True)
    assert free.status == held.status == "optimal"
    pi = wncs_lp.solve(wncs_lp.build(env.system.scenario), "pi")
    assert free.gain == pytest.approx(pi.gain, rel=1e-9)
    assert held.gain_lower > free.gain_upper
    assert env.optimum() is free  # kept


def test_the_papers_full_scale_runs_without_enumeration():
    """Four processes at cap 30 (2.5e8 states, never built): the checker passes and the rewards
    are minus the sum of the processes' costs, which grow with the AoI."""
    env = WncsEnv("paper_p1234", ["tau_cap=30"])
    check_env(env)
    obs, _ = env.reset(seed=0, options={"tau": [1, 2, 3, 4]})
    _, r_low, *_ = env.step(0)
    env.reset(seed=0)
    _, r_cap, *_ = env.step(0)
    assert r_cap < r_low < 0
