"""The Section IV model (``docs/model.md``, "Section IV"): one server with processing preemption.

Every slot every sensor transmits on its own orthogonal channel; the update of process k reaches
the server with probability ``pu_k`` (the one server's ``p_up[k - 1]``, independently per
process). The scheduler then chooses which arrived update, if any, to start -- preempting the job
in service if needed. A process with random arrivals (``arrival_probability`` lambda_k < 1) pushes
each update in the slot it is generated, so its update arrives with probability lambda_k pu_k
(``docs/model.md``, "Arrivals in the Section IV model").

Configuration
-------------
A configuration is the named tuple :class:`PreemptionConfig` ``(b, job, stack, down)`` (a plain
tuple compares and hashes equal, so ``mdp.states.find(tau, (b, job, stack, down))`` works):

* ``b``     -- ``tuple[int, ...]`` of length N, ``b[k-1] = 1`` when process k's update arrived
  at the start of this slot (so ``a = k`` is allowed).
* ``job``   -- the job in service, ``(k, d, g)`` (process k 1-based, d >= 1 slots of work
  left, g its age = slots since its sample was taken), or ``None`` when the server is idle.
* ``stack`` -- ``tuple`` of preempted jobs ``(k, d, g)``, **bottom first: ``stack[-1]`` is the
  top**, the most recently preempted job, the next to resume. Invariant: the jobs in ``job`` and
  ``stack`` belong to pairwise distinct processes (so at most N - 1 stacked jobs), and
  ``job is None`` implies ``stack == ()``.
* ``down``  -- the downlink pipeline, a tuple of D places, each ``(k, g)`` or ``None``;
  ``down[i]`` holds the command completed ``i + 1`` slots ago and ``down[D - 1]`` is the one
  delivered in this slot. ``()`` when D = 0.

All ages are as of the start of the slot and saturate at the process's cap tau_hat_k (exact for
the AoI, since a delivery sets tau_k <- min(tau_k + 1, g, tau_hat_k)).

A verifier reads a state's configuration as ``mdp.states.configs[mdp.states.config[s]]``;
:func:`describe_preemption_config` renders one.

Actions
-------
Labels are 1-tuples ``(a,)``, listed in the order ``(0,), (1,), ..., (N,)`` (feasible ones only):
so ties between equally good actions break towards *keeping the current job* (``a = 0``), and a
reported preemption is strictly better than continuing.

* ``a = 0``: keep going; nothing new is started.
* ``a = k`` (only if ``b_k = 1``; with ``preemptive = false`` only if ``job is None``): start
  process k's fresh update as ``(k, T_k, min(U, tau_hat_k))``. A current job of another
  process is pushed on the stack; a current job of process k is cancelled (obsolete); in both
  cases a stacked job of process k is discarded. Restarting the same process (``a = k`` while
  serving k) is allowed.

One slot (the order of ``docs/model.md``, resolved as follows)
------------------------------------------------
1. The action is applied (push / cancel / discard as above).
2. Service: the job in service (if any, including one started at step 1) gets one slot,
   ``d <- d - 1``, ``g <- g + 1``. With ``d = 0`` it completes (so a job with T_k = 1
   started now completes in this same slot).
3. Aging: every stacked job (including one pushed at step 1: it waits during this slot) and
   every command that was in the downlink at the start of the slot ages by one. A command
   completing at step 2 enters the downlink at place 0 with the age it has after service; it
   does not age again in this slot.
4. Downlink: for D >= 1 the command at ``down[D - 1]`` (after aging) leaves and the pipeline
   shifts (the completed command, or an empty place, enters at place 0); for D = 0 the command
   completed at step 2 is the one leaving.
5. Resume: if the server is now free (its job completed at step 2, or it was idle) the top of
   the stack becomes the job in service *of the next slot* -- no idle slot in between, and
   it gets its first resumed service slot in the next slot. It keeps its remaining work d and
   its age (which grew while it waited).
6. Delivery: the leaving command of process k with age g reaches the actuator with
   probability pd_k and then sets tau_k(t+1) = min(tau_k(t) + 1, g) (the engine's delta_k = g);
   every other tau grows by one; then the cap applies.
7. Arrivals: the next ``b`` is drawn, ``b'_k = 1`` with probability lambda_k pu_k independently
   (lambda_k = 1 when the process samples at will).

Consequently an uninterrupted job of process k is delivered with age U + T_k + D, exactly the
Section II loop length (``ServerSpec.loop``), also for U = 0 and/or D = 0 (U = D = 0, T = 1:
an update arriving at the start of slot t sets tau to 1 at t + 1). A job that waited w slots on
the stack is delivered with age U + T_k + D + w (capped).

Initial configurations: every ``b`` in {0,1}^N with an idle server, an empty stack and an empty
downlink; the state space is what is reachable from those times the whole tau box (with
pu in {0, 1} some of those initial ``b`` are never reached again but remain states).

With this reading the reference row (processes 1, 2, remote server U = D = 1,
T_k = n_k, p = 0.9, tau_hat = 12; ``formulations/paper_preemption_p12.toml``) has 692
configurations, 23,268 states, 46,536 state-action pairs and optimal gain 1078.548921698
(``tests/models/test_preemption.py``). The paper's own recursion (its T_1/T_2/E_t equations) keeps one
preempted job and adds T_k to its "extra age"; with N = 2 this is the same model, since the stack
never holds more than N - 1 jobs and a waiting job ages exactly while the other is served.
"""
from __future__ import annotations

import itertools
from typing import Any, NamedTuple, Optional, Sequence

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario
from .automaton import AutomatonBounds, ConfigAutomaton, LazyAutomaton, SharedOutcomes, explore_configs
from .base import Model

__all__ = [
    "PreemptionModel",
    "PreemptionConfig",
    "build_preemption",
    "preemption_automaton",
    "preemption_step",
    "feasible_preemption_actions",
    "initial_preemption_configs",
    "describe_preemption_config",
]

Job = tuple  # (k, d, g)
Command = tuple  # (k, g)


class PreemptionConfig(NamedTuple):
    """``(b, job, stack, down)``; see the module docstring. ``stack[-1]`` is the top."""

    b: tuple
    job: Optional[tuple]
    stack: tuple
    down: tuple


def _check_scenario(scenario: Scenario) -> None:
    if scenario.model.kind != "preemption":
        raise ModelError(
            f"{scenario.source}: build_preemption needs kind = \"preemption\", found {scenario.model.kind!r}"
        )
    if scenario.n_servers != 1:
        raise ModelError(f"{scenario.source}: a preemption scenario has exactly one server, found {scenario.n_servers}")


def initial_preemption_configs(scenario: Scenario) -> list[PreemptionConfig]:
    """Every arrival vector b, with an idle server, an empty stack and an empty downlink."""
    N = scenario.n_processes
    D = scenario.servers[0].downlink_delay
    return [PreemptionConfig(tuple(b), None, (), (None,) * D) for b in itertools.product((0, 1), repeat=N)]


def feasible_preemption_actions(scenario: Scenario, config: tuple) -> list[tuple[int]]:
    """The feasible labels ``(a,)`` of a configuration: ``(0,)`` first, then each arrived k."""
    b, job = config[0], config[1]
    if not scenario.model.preemptive and job is not None:
        return [(0,)]
    return [(0,)] + [(k,) for k in range(1, len(b) + 1) if b[k - 1]]


def arrival_probabilities(scenario: Scenario) -> tuple[float, ...]:
    """Per process, the probability that its update reaches the server in a slot: lambda_k pu_k."""
    server = scenario.servers[0]
    return tuple(pr.arrival_probability * server.p_up[k] if pr.has_arrivals else server.p_up[k]
                 for k, pr in enumerate(scenario.processes))


def _arrival_distribution(probs: Sequence[float]) -> list[tuple[tuple[int, ...], float]]:
    out = []
    for b in itertools.product((0, 1), repeat=len(probs)):
        prob = 1.0
        for x, pu in zip(b, probs):
            prob *= pu if x else 1.0 - pu
        if prob > 0.0:
            out.append((tuple(b), prob))
    return out


def preemption_step(scenario: Scenario, config: tuple, a: int) -> list[tuple[PreemptionConfig, tuple[int, ...], float]]:
    """One slot from ``config`` under action ``a``: ``[(next_config, delta, prob), ...]``.

    ``delta[k-1]`` is the age of the delivered command of process k (0 = none). Outcomes are not
    merged (the engine does that); probabilities-0 outcomes are omitted.
    """
    server = scenario.servers[0]
    caps = scenario.tau_caps
    N = scenario.n_processes
    U, D, T = server.uplink_delay, server.downlink_delay, server.processing_time
    b, job, stack, down = config
    if len(b) != N or len(down) != D:
        raise ModelError(f"configuration {config!r} does not fit the scenario (N = {N}, D = {D})")
    # 1. action
    if a:
        if not b[a - 1]:
            raise ModelError(f"action {a} infeasible in {describe_preemption_config(config)}: no update of process {a} arrived")
        if job is not None and not scenario.model.preemptive:
            raise ModelError(f"action {a} infeasible in {describe_preemption_config(config)}: non-preemptive server is busy")
        stack = tuple(j for j in stack if j[0] != a)
        if job is not None and job[0] != a:
            stack = stack + (job,)
        job = (a, T[a - 1], min(U, caps[a - 1]))
    # 2. service
    completed: Command | None = None
    if job is not None:
        k, d, g = job
        d, g = d - 1, min(g + 1, caps[k - 1])
        if d == 0:
            completed, job = (k, g), None
        else:
            job = (k, d, g)
    # 3. aging of waiting jobs and of the downlink contents present at the start of the slot
    stack = tuple((k, d, min(g + 1, caps[k - 1])) for k, d, g in stack)
    # 4. downlink
    if D == 0:
        leaving, new_down = completed, ()
    else:
        aged = tuple(None if c is None else (c[0], min(c[1] + 1, caps[c[0] - 1])) for c in down)
        leaving, new_down = aged[-1], (completed,) + aged[:-1]
    # 5. resume
    if job is None and stack:
        job, stack = stack[-1], stack[:-1]
    # 6. delivery, 7. arrivals
    if leaving is not None:
        pd = server.p_down[leaving[0] - 1]
        delta_ok = tuple(leaving[1] if k == leaving[0] else 0 for k in range(1, N + 1))
        links = [(delta_ok, pd), ((0,) * N, 1.0 - pd)]
    else:
        links = [((0,) * N, 1.0)]
    out = []
    for nb, pb in _arrival_distribution(arrival_probabilities(scenario)):
        nxt = PreemptionConfig(nb, job, stack, new_down)
        for delta, pl in links:
            if pl > 0.0:
                out.append((nxt, delta, pb * pl))
    return out


def preemption_automaton(scenario: Scenario) -> ConfigAutomaton:
    """Explore the configurations reachable from :func:`initial_preemption_configs`.

    The slot dynamics after the action depend only on (job, stack, down) after the action is
    applied, so those are cached across configurations that share them.
    """
    return explore_configs(initial_preemption_configs(scenario), preemption_step_function(scenario))


def preemption_step_function(scenario: Scenario):
    """The automaton's step: ``step(config)`` lists ``(action, [(next_config, delta, prob), ...])``."""
    _check_scenario(scenario)
    cache: dict[tuple, list] = {}

    def step(config):
        result = []
        for label in feasible_preemption_actions(scenario, config):
            a = label[0]
            # the post-action core (b only gates feasibility): normalise b to all-ones for the key
            key = (a, config[1], config[2], config[3])
            outs = cache.get(key)
            if outs is None:
                full_b = (1,) * scenario.n_processes
                outs = cache[key] = SharedOutcomes(preemption_step(scenario, (full_b,) + tuple(config[1:]), a))
            result.append((label, outs))
        return result

    return step


def _fmt_job(j: tuple) -> str:
    return f"{j[0]}(d={j[1]},g={j[2]})"


def describe_preemption_config(config: tuple) -> str:
    """A readable label, e.g. ``b=10 | serving 2(d=1,g=2) | stack [top 1(d=3,g=4)] | down [-]``."""
    b, job, stack, down = config
    parts = ["b=" + "".join(str(x) for x in b)]
    parts.append("serving " + _fmt_job(job) if job is not None else "idle")
    if stack:
        parts.append("stack [top " + ", ".join(_fmt_job(j) for j in reversed(stack)) + "]")
    if down:
        parts.append("down [" + ",".join("-" if c is None else f"{c[0]}(g={c[1]})" for c in down) + "]")
    return " | ".join(parts)


def build_preemption(scenario: Scenario) -> MDP:
    """Build the Section IV MDP of a ``kind = "preemption"`` scenario.

    Returns an :class:`~wncs_lp.mdp.MDP` whose ``states`` is a
    :class:`~wncs_lp.models.statespace.StateSpace` (tau per process, :class:`PreemptionConfig`)
    and whose ``action_table`` rows are ``(a,)``: 0 = keep going, k = start process k's update.
    """
    return PreemptionModel(scenario).build()


class PreemptionModel(Model):
    """The Section IV model: one server, every sensor on its own channel, preemptive scheduling.

    A configuration is a :class:`PreemptionConfig` ``(b, job, stack, down)``; an action label is
    ``(a,)``: 0 = keep going, k = start process k's arrived update.
    """

    kind = "preemption"
    checks = ("monotonicity", "threshold", "consistency")
    threshold_form = "intervals"
    threshold_configs = "all"
    has_static_policy = False
    private_servers_refusal = ("its one server is shared through preemption and a stack of preempted jobs, so a "
                               "process's job progress depends on the other processes' (a process alone with its "
                               "own server is no relaxation of it); the bounds need the Section II model")

    def __init__(self, scenario: Scenario):
        _check_scenario(scenario)
        super().__init__(scenario)

    def explore(self) -> ConfigAutomaton:
        return preemption_automaton(self.scenario)

    def lazy_automaton(self) -> LazyAutomaton:
        return LazyAutomaton(initial_preemption_configs(self.scenario), preemption_step_function(self.scenario))

    def automaton_bounds(self) -> AutomatonBounds:
        """b is one of 2^N arrival vectors; the job in service is none or (k, d <= T_k, g <= tau_hat_k)
        (J = sum_k T_k tau_hat_k choices), the stack at most N - 1 such jobs, each of the D downlink
        places none or (k, g <= tau_hat_k): at most 2^N (1 + J)^N (1 + sum_k tau_hat_k)^D
        configurations. The 2^N initial ones each draw every arrival vector next when every arrival
        probability lambda_k pu_k is in (0, 1)."""
        sc = self.scenario
        N, srv = sc.n_processes, sc.servers[0]
        jobs = sum(t * cap for t, cap in zip(srv.processing_time, sc.tau_caps))
        configs = 2 ** N * (1 + jobs) ** N * (1 + sum(sc.tau_caps)) ** srv.downlink_delay
        edges = 2 ** sum(0.0 < p < 1.0 for p in arrival_probabilities(sc))
        return AutomatonBounds(configs=configs, initial=2 ** N, edges_initial=edges)

    def initial_config(self) -> PreemptionConfig:
        return initial_preemption_configs(self.scenario)[0]

    def meta(self) -> dict[str, Any]:
        return {"kind": self.kind, "preemptive": self.scenario.model.preemptive,
                "source": self.scenario.source, "fingerprint": self.scenario.fingerprint()}

    def accepts(self, config: tuple) -> tuple[bool, ...]:
        """The one server accepts a new job when it is idle or preemption is allowed."""
        return (config[1] is None or self.scenario.model.preemptive,)

    def busy(self, config: tuple, labels: np.ndarray) -> np.ndarray:
        """The server is busy when a job is in service at the start of the slot, or the action
        starts one (it is served in this slot)."""
        if config[1] is not None:
            return np.ones(labels.shape, dtype=float)
        return (labels > 0).astype(float)

    def greedy_label(self, config: tuple, order: Sequence[int]) -> tuple[int, ...]:
        """A greedy work-conserving rule of our own: when the server is idle, start the arrived
        update of largest cost (first in ``order``); when it is busy, keep going."""
        b, job = config[0], config[1]
        if job is None:
            for k in order:
                if b[k]:
                    return (k + 1,)
        return (0,)

    def describe(self, config: tuple) -> str:
        return describe_preemption_config(config)

    @classmethod
    def is_idle(cls, config: Any) -> bool:
        if not hasattr(config, "_fields"):
            return False
        return config[1] is None and not config[2] and all(x is None for x in config[3])

    @classmethod
    def job_in_service(cls, config: Any) -> tuple[int, int] | None:
        job = config[1]
        return None if job is None else (int(job[0]), int(job[1]))

    @classmethod
    def arrived(cls, config: Any) -> tuple[int, ...]:
        return tuple(int(x) for x in config[0])

    @classmethod
    def action_name(cls, label: tuple[int, ...], config: Any, names: dict) -> str:
        procs = names["processes"]
        a = label[0]
        job = None if config is None else config[1]
        if a == 0:
            if config is None:
                return "keep going (no new job)"
            return "stay idle" if job is None else f"keep going (serve {procs[job[0] - 1]})"
        if job is None:
            return f"start {procs[a - 1]}" if config is not None else f"start {procs[a - 1]} (preempting if busy)"
        if job[0] == a:
            return f"restart {procs[a - 1]} (cancel)"
        return f"{procs[a - 1]} preempts {procs[job[0] - 1]}"

    @classmethod
    def short_action(cls, label: tuple[int, ...], names: dict) -> str:
        procs = names["processes"]
        return "keep" if label[0] == 0 else f"start {procs[label[0] - 1]}"

    def serving_config(self, k: int, arrived: Sequence[int]) -> PreemptionConfig:
        """Process k's job one slot into service on an otherwise empty server (job
        ``(k, T_k - 1, U + 1)``, empty stack and downlink), with the arrivals ``arrived``."""
        srv = self.scenario.servers[0]
        job = (k, srv.processing_time[k - 1] - 1, srv.uplink_delay + 1)
        return PreemptionConfig(tuple(int(x) for x in arrived), job, (), (None,) * srv.downlink_delay)
