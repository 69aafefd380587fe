r"""A scenario as a Gymnasium environment (``gymnasium`` is optional: ``pip install 'wncs_lp[interop]'``).

:class:`WncsEnv` steps the scenario's exact dynamics from its configuration automaton
(:class:`~wncs_lp.models.system.System`, no enumeration of the AoI box, so any scenario runs,
the paper's four processes at cap 30 included), the same dynamics the toolkit's MDP and
simulator use. In slot t, in state :math:`s_t = (\tau, C)`:

* **observation** ``{"tau": tau, "config": C}``: the AoI vector, each :math:`\tau_k` in
  :math:`1..\hat\tau_k` (``MultiDiscrete`` starting at 1), and the id of the configuration of
  the servers and pipelines (``Discrete(|C|)``; :meth:`WncsEnv.describe_config` says it in words);
* **action** a local action index :math:`j` of configuration C (``Discrete(A_max)``): position
  ``j`` of ``system.automaton.actions[C]``, the MDP's action order, so ``j`` means the same as
  the ``act`` of every :mod:`wncs_lp.policies` policy. Configuration C has ``n_actions[C]``
  feasible actions; :meth:`WncsEnv.action_masks` (and ``info["action_mask"]``) marks them;
* **reward** :math:`-c(s_t) = -\sum_k q_k(\tau_k)`, minus the cost of the state the action is
  taken in, so the long-run average reward of a policy is minus its gain :math:`g`;
* **transition** one uniform draw from the environment's ``np_random`` picks the outcome o of
  (C, j) with its probability; then :math:`C \leftarrow` ``nxt[C, j, o]`` and
  :math:`\tau_k \leftarrow \min(\tau_k + 1, \delta_k \text{ if } \delta_k > 0, \hat\tau_k)`.

The task is continuing: ``terminated`` is always False; ``truncated`` becomes True after
``max_steps`` steps when that is given. ``reset(seed=...)`` seeds the draws (Gymnasium's rule);
the start is every :math:`\tau_k` at its cap in the initial configuration (the simulator's), or
``options={"tau": [...]}``.

**An action outside the mask** (``j >= n_actions[C]``) is, by default (``invalid_action="first"``),
taken as the configuration's action 0, with ``info["invalid_action"] = True``. An infeasible
action then duplicates a feasible one, so the environment's optimal average reward is exactly
:math:`-g^*` (the padding rule of :func:`wncs_lp.io.to_mdptoolbox`). With
``invalid_action="raise"`` it is an :class:`EnvError` instead.

Reference values for reinforcement-learning baselines: :meth:`WncsEnv.optimum` (the certified
optimal gain :math:`g^*` and its bracket, by :func:`wncs_lp.solve`) and, for scenarios beyond an
exact solve, :meth:`WncsEnv.lower_bound` (a certified :math:`g_{lb} \le g^*`,
:func:`wncs_lp.bounds.lower_bound`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .errors import WncsError
from .io.toolkits import require_package
from .models.system import System
from .scenario import Scenario, load_scenario

gym = require_package("gymnasium", "gymnasium", "wncs_lp.env (the Gymnasium environment)")
spaces = gym.spaces

__all__ = ["EnvError", "WncsEnv", "INVALID_ACTION_RULES", "ENV_ID"]

#: The id under which importing this module registers :class:`WncsEnv` with Gymnasium:
#: ``gymnasium.make(ENV_ID, scenario="paper_p12", overrides=["tau_cap=10"], max_episode_steps=...)``.
ENV_ID = "wncs_lp/Wncs-v0"

#: What :class:`WncsEnv` does with an action outside the mask.
INVALID_ACTION_RULES = ("first", "raise")


class EnvError(WncsError):
    """Bad input to the environment: its scenario, an action, a reset option."""


def _system_of(scenario: Scenario | System | str | Path, overrides: Any) -> System:
    if isinstance(scenario, System):
        if overrides:
            raise EnvError("overrides apply to a scenario or a scenario file, not to a System")
        return scenario
    if isinstance(scenario, (str, Path)):
        from .formulations import scenario_names, scenario_path

        path = Path(scenario)
        if not path.exists() and isinstance(scenario, str) and f"{scenario.removesuffix('.toml')}.toml" in scenario_names():
            path = scenario_path(scenario)  # a shipped scenario's name, as wncs_lp.solve takes it
        scenario = load_scenario(path, overrides)
    elif overrides:
        raise EnvError("overrides apply to a scenario file or name; apply them to a Scenario with "
                       "wncs_lp.load_scenario(path, overrides)")
    if not isinstance(scenario, Scenario):
        raise EnvError(f"expected a Scenario, a System, a scenario file or a shipped scenario's name, "
                       f"got {type(scenario).__name__}")
    return System.from_scenario(scenario)


class WncsEnv(gym.Env):
    """A wncs_lp scenario as a ``gymnasium.Env`` (module docstring).

    Parameters
    ----------
    scenario : Scenario, System, path or str
        A scenario, its system, its TOML file or a shipped scenario's name (``"paper_p12"``).
    overrides : mapping or iterable of ``"key=value"``, optional
        Applied to a file or name as :func:`wncs_lp.load_scenario` does (e.g. ``["tau_cap=10"]``).
    max_steps : int, optional
        Truncate episodes after this many steps (default: never; the task is continuing).
    invalid_action : {"first", "raise"}
        An action outside the mask is the configuration's action 0 (default) or an error.
    render_mode : {None, "ansi"}

    Attributes
    ----------
    system : System
    observation_space : gymnasium.spaces.Dict
        ``tau``: ``MultiDiscrete(caps, start=1)``; ``config``: ``Discrete(|C|)``.
    action_space : gymnasium.spaces.Discrete
        ``Discrete(A_max)``, A_max the most actions of any configuration.
    """

    metadata = {"render_modes": ["ansi"]}

    def __init__(self, scenario: Scenario | System | str | Path, overrides: Any = None, *,
                 max_steps: int | None = None, invalid_action: str = "first", render_mode: str | None = None):
        if invalid_action not in INVALID_ACTION_RULES:
            raise EnvError(f"invalid_action must be one of {', '.join(INVALID_ACTION_RULES)}, got {invalid_action!r}")
        if max_steps is not None and (not isinstance(max_steps, (int, np.integer)) or max_steps < 1):
            raise EnvError(f"max_steps must be a positive integer or None, got {max_steps!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvError(f"render_mode must be None or 'ansi', got {render_mode!r}")
        self.system = _system_of(scenario, overrides)
        self.max_steps = None if max_steps is None else int(max_steps)
        self.invalid_action = invalid_action
        self.render_mode = render_mode
        sysm = self.system
        self._tables = sysm.pairs  # one row per feasible (configuration, action) pair
        self.observation_space = spaces.Dict({
            "tau": spaces.MultiDiscrete(sysm.caps, start=np.ones(sysm.n_processes, dtype=np.int64)),
            "config": spaces.Discrete(sysm.n_configs),
        })
        self.action_space = spaces.Discrete(sysm.max_actions)
        self._tau = sysm.caps.copy()
        self._config = sysm.initial_config
        self._steps = 0
        self._optima: dict = {}

    # ------------------------------------------------------------------ the Gymnasium API
    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        """Start in the initial configuration with every tau_k at its cap, or at ``options["tau"]``."""
        super().reset(seed=seed)
        self._tau = self._initial_tau(options)
        self._config = self.system.initial_config
        self._steps = 0
        return self._observation(), {"action_mask": self.action_masks(), "cost": self.cost()}

    def step(self, action: Any) -> tuple[dict, float, bool, bool, dict]:
        """One slot: reward ``-c(s_t)``, then the transition of (s_t, action)."""
        j, invalid = self._local_action(action)
        cost = self.cost()
        t = self._tables
        p = int(t.first[self._config]) + j
        o = int(np.count_nonzero(self.np_random.random() >= t.cum[p]))
        self._config = int(t.nxt[p, o])
        self._tau = self.system.next_tau(self._tau, t.deltas[t.delta[p, o]])
        self._steps += 1
        truncated = self.max_steps is not None and self._steps >= self.max_steps
        info = {"action_mask": self.action_masks(), "cost": cost, "invalid_action": invalid}
        return self._observation(), -cost, False, truncated, info

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        return f"tau={self._tau.tolist()} config {self._config}: {self.describe_config(self._config)}"

    # ------------------------------------------------------------------ masks and words
    def action_masks(self) -> np.ndarray:
        """(A_max,) bool: the feasible actions of the current configuration (the name
        sb3-contrib's ``MaskablePPO`` asks for)."""
        return self.system.action_valid[self._config].copy()

    def cost(self) -> float:
        """c(s) = sum_k q_k(tau_k) of the current state."""
        return float(sum(q[t - 1] for q, t in zip(self.system.q, self._tau.tolist())))

    def describe_config(self, config: int) -> str:
        """The configuration ``config`` (an observation's ``"config"``) in words."""
        return self.system.model.describe(self.system.automaton.configs[int(config)])

    def policy_action(self, policy: Any, observation: dict, rng: np.random.Generator | None = None) -> int:
        """The action a :mod:`wncs_lp.policies` policy of this scenario takes at ``observation``
        (its ``act`` on one state; ``rng`` for a randomised policy's own draws)."""
        if getattr(policy, "system", None) is not self.system:
            raise EnvError("the policy was built for another System; build it with env.system")
        tau = np.asarray(observation["tau"], dtype=np.int64)[None, :]
        config = np.array([int(observation["config"])], dtype=np.int64)
        return int(policy.act(tau, config, rng)[0])

    # ------------------------------------------------------------------ reference values
    def optimum(self, method: str = "auto", **solve_kwargs: Any) -> Any:
        """The certified average-cost optimum of the environment's problem (:func:`wncs_lp.solve`;
        each answer is kept): ``.gain`` is g*, ``[.gain_lower, .gain_upper]`` its certified
        bracket, ``.status`` ``"optimal"`` when the certificate closed. The best long-run average
        reward any agent can reach is ``-g*``.

        The environment has no constraints, so a scenario's ``[[constraint]]`` tables are
        ignored unless ``constrained=True`` is passed (then the constrained optimum, a bound no
        unconstrained agent is held to)."""
        solve_kwargs.setdefault("constrained", False)
        key = (method, repr(sorted(solve_kwargs.items())))
        if key not in self._optima:
            from . import solve

            self._optima[key] = solve(self.system.scenario, method, **solve_kwargs)
        return self._optima[key]

    def lower_bound(self, relaxation: str | int = "auto", **options: Any) -> Any:
        """A certified lower bound on g* (:func:`wncs_lp.bounds.lower_bound`, a ``BoundResult``
        whose ``.lower_bound`` holds), for scenarios too large to solve exactly."""
        from .bounds import lower_bound

        return lower_bound(self.system, relaxation, **options)

    # ------------------------------------------------------------------ helpers
    def _observation(self) -> dict:
        return {"tau": self._tau.copy(), "config": np.int64(self._config)}

    def _initial_tau(self, options: dict | None) -> np.ndarray:
        caps = self.system.caps
        if not options or options.get("tau") is None:
            return caps.copy()
        tau = np.asarray(options["tau"])
        if tau.shape != caps.shape or not np.issubdtype(tau.dtype, np.integer) or np.any(tau < 1) or np.any(tau > caps):
            raise EnvError(f"reset option 'tau' must be {caps.size} integers with 1 <= tau_k <= cap "
                           f"{caps.tolist()}, got {options['tau']!r}")
        return tau.astype(np.int64)

    def _local_action(self, action: Any) -> tuple[int, bool]:
        """(the local action taken, whether ``action`` was outside the mask)."""
        a = action[()] if isinstance(action, np.ndarray) and action.shape == () else action  # a 0-d array
        if isinstance(a, (bool, np.bool_)) or not isinstance(a, (int, np.integer)):
            raise EnvError(f"an action is an integer in 0..{self.system.max_actions - 1}, got {action!r}")
        j = int(a)
        if not 0 <= j < self.system.max_actions:
            raise EnvError(f"action {j} is outside the action space 0..{self.system.max_actions - 1}")
        if j < self.system.n_actions[self._config]:
            return j, False
        if self.invalid_action == "raise":
            raise EnvError(f"action {j} is not feasible in configuration {self._config} "
                           f"({self.describe_config(self._config)}), which has actions "
                           f"0..{self.system.n_actions[self._config] - 1}; see env.action_masks()")
        return 0, True


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=WncsEnv)
