"""The Section II model (``model.md`` section 2): sensors, links with delays, servers.

A server's configuration is the tuple ``(up, job, d, down)``:

* ``up``   -- the uplink pipeline, ``max(U - 1, 0)`` places; ``up[i]`` holds the process whose
  update was sent ``i + 1`` slots ago (0 = empty). It starts service ``U - 1 - i`` slots from now.
* ``job``, ``d`` -- the job in service and its remaining slots (``(0, 0)`` = idle).
* ``down`` -- the downlink pipeline, ``D`` places; ``down[i]`` holds the process whose command
  completed ``i + 1`` slots ago (0 = empty); ``down[D - 1]`` is delivered this slot.

A joint configuration is the tuple of the servers' configurations. One slot of one server, for
an action (the process sent to it, or 0), follows the order of ``docs/model.md`` exactly:
uplink loss -> start at once if U = 0 -> service -> downlink -> start from the uplink if U >= 1
-> downlink loss. A delivered command of process k sets delta_k = U + T_k + D (its age).
"""
from __future__ import annotations

import itertools
import math
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario, ServerSpec, scenario_from_dict
from .automaton import AutomatonBounds, ConfigAutomaton, explore_configs
from .base import Model

__all__ = [
    "WncsModel",
    "build_wncs",
    "wncs_automaton",
    "server_accepts",
    "server_step",
    "feasible_actions",
    "describe_wncs_config",
    "idle_config",
]

ServerState = tuple  # (up: tuple[int,...], job: int, d: int, down: tuple[int,...])


def idle_server(server: ServerSpec) -> ServerState:
    return ((0,) * max(server.uplink_delay - 1, 0), 0, 0, (0,) * server.downlink_delay)


def idle_config(scenario: Scenario) -> tuple:
    """The joint configuration with every server idle and every pipeline empty."""
    return tuple(idle_server(s) for s in scenario.servers)


def server_accepts(server: ServerSpec, state: ServerState) -> bool:
    """Whether an update sent now would find the server idle when it starts service.

    busy = max(d, max over uplink updates starting in j slots of j + T_k); accept iff
    busy <= U (for U = 0 that is d = 0, there being no uplink places).
    """
    up, _, d, _ = state
    U = server.uplink_delay
    busy = d
    for i, k in enumerate(up):
        if k:
            busy = max(busy, (U - 1 - i) + server.processing_time[k - 1])
    return busy <= U


def server_step(server: ServerSpec, state: ServerState, a: int) -> list[tuple[ServerState, int, float]]:
    """One slot of one server: ``[(next_state, delivered_process (0 = none), prob), ...]``."""
    up, job, d, down = state
    U, D, T = server.uplink_delay, server.downlink_delay, server.processing_time
    pu, pd = server.p_up, server.p_down
    sends = [(a, pu), (0, 1.0 - pu)] if a else [(0, 1.0)]
    out: list[tuple[ServerState, int, float]] = []
    for arrived, p1 in sends:
        j, dd = job, d
        if U == 0 and arrived:  # 2. start at once
            if dd != 0:
                raise ModelError(f"internal error: server {server.name} busy (d={dd}) when a job starts")
            j, dd = arrived, T[arrived - 1]
        completed = 0
        if dd > 0:  # 3. service
            dd -= 1
            if dd == 0:
                completed, j = j, 0
        if D == 0:  # 4. downlink
            delivered, new_down = completed, ()
        else:
            delivered, new_down = down[-1], (completed,) + down[:-1]
        new_up = up
        if U >= 1:  # 5. the update leaving the uplink starts service next slot
            if U == 1:
                leaving = arrived
            else:
                leaving, new_up = up[-1], (arrived,) + up[:-1]
            if leaving:
                if dd != 0:
                    raise ModelError(f"internal error: server {server.name} busy (d={dd}) when a job starts")
                j, dd = leaving, T[leaving - 1]
        nxt = (new_up, j, dd, new_down)
        if delivered:  # 6. downlink loss
            out.append((nxt, delivered, p1 * pd))
            out.append((nxt, 0, p1 * (1.0 - pd)))
        else:
            out.append((nxt, 0, p1))
    return out


def feasible_actions(scenario: Scenario, config: tuple) -> list[tuple[int, ...]]:
    """The feasible actions (a_1..a_M) of a joint configuration, in the MDP's action order.

    Non-accepting servers get 0. An accepting server gets a process 1..N, or 0 when
    ``allow_idle`` or when more servers accept than there are processes. With ``distinct``, no
    process goes to two servers. Order: lexicographic, each server's options listed 1..N then 0,
    so ties between equally good actions break towards sending rather than idling.
    """
    N = scenario.n_processes
    accepts = [server_accepts(s, st) for s, st in zip(scenario.servers, config)]
    n_acc = sum(accepts)
    idle_ok = scenario.model.allow_idle or n_acc > N
    choices = []
    for acc in accepts:
        if acc:
            choices.append(list(range(1, N + 1)) + ([0] if idle_ok else []))
        else:
            choices.append([0])
    out = []
    for a in itertools.product(*choices):
        if scenario.model.distinct:
            sent = [k for k in a if k]
            if len(sent) != len(set(sent)):
                continue
        out.append(a)
    return out


def wncs_automaton(scenario: Scenario) -> ConfigAutomaton:
    """Explore the joint server configurations reachable from the all-idle one."""
    if scenario.model.kind != "wncs":
        raise ModelError(f"{scenario.source}: build_wncs needs kind = \"wncs\", found {scenario.model.kind!r}")
    servers = scenario.servers
    N = scenario.n_processes
    steps = [lru_cache(maxsize=None)(lambda st, a, s=s: server_step(s, st, a)) for s in servers]

    def step(config: tuple):  # a generator: explore_configs' edge budget can stop a huge action set
        for action in feasible_actions(scenario, config):
            per_server = [steps[m](config[m], action[m]) for m in range(len(servers))]
            outs = []
            for combo in itertools.product(*per_server):
                prob = 1.0
                delta = [0] * N
                for m, (_, delivered, pr) in enumerate(combo):
                    prob *= pr
                    if delivered:
                        age = servers[m].loop[delivered - 1]
                        k = delivered - 1
                        delta[k] = age if delta[k] == 0 else min(delta[k], age)
                outs.append((tuple(c[0] for c in combo), tuple(delta), prob))
            yield action, outs

    return explore_configs([idle_config(scenario)], step)


def describe_wncs_config(servers: tuple[ServerSpec, ...], config: tuple) -> str:
    parts = []
    for s, (up, job, d, down) in zip(servers, config):
        if not job and not any(up) and not any(down):
            parts.append(f"{s.name}: idle")
            continue
        bits = []
        if any(up):
            bits.append("up[" + ",".join(str(k) for k in up) + "]")
        bits.append(f"job {job} d={d}" if job else "no job")
        if any(down):
            bits.append("down[" + ",".join(str(k) for k in down) + "]")
        parts.append(f"{s.name}: " + " ".join(bits))
    return "; ".join(parts)


def build_wncs(scenario: Scenario) -> MDP:
    """Build the Section II MDP of a ``kind = "wncs"`` scenario.

    Returns an :class:`~wncs_lp.mdp.MDP` whose ``states`` is a
    :class:`~wncs_lp.models.statespace.StateSpace` (tau per process, joint server configuration)
    and whose ``action_table`` rows are the actions (a_1..a_M), 0 = nothing sent.
    """
    return WncsModel(scenario).build()


def _is_idle_config(cfg: Any) -> bool:
    try:
        return all(job == 0 and d == 0 and not any(up) and not any(down) for (up, job, d, down) in cfg)
    except (TypeError, ValueError):
        return False


def _checked_group(group: Sequence[int], n: int) -> tuple:
    """``group`` as a tuple of distinct increasing process indices in 0..n-1."""
    out = tuple(int(k) for k in group)
    if not out or list(out) != sorted(set(out)) or out[0] < 0 or out[-1] >= n:
        raise ModelError(f"a group of processes must be distinct increasing indices in 0..{n - 1}, got {list(group)}")
    return out


class WncsModel(Model):
    """The Section II model: N processes, M servers with uplink/downlink pipelines.

    A configuration is a tuple of per-server ``(up, job, d, down)`` (module docstring); an
    action label is ``(a_1..a_M)``, ``a_m`` the process sent to server m (0 = nothing).
    """

    kind = "wncs"
    checks = ("monotonicity", "threshold")
    threshold_form = "rays"
    threshold_configs = "idle"
    has_static_policy = True

    def explore(self) -> ConfigAutomaton:
        return wncs_automaton(self.scenario)

    def automaton_bounds(self) -> AutomatonBounds:
        """A server's configuration holds U - 1 uplink places and D downlink places (each empty or
        one of N processes) and a job with its remaining slots (idle, or process k with 1..T_k
        left): at most (N + 1)^(U - 1 + D) (1 + sum_k T_k) configurations, and the joint one the
        product over servers. In the idle configuration every server accepts, so it has at least
        N!/(N - M)! actions (distinct processes) or N^M."""
        sc = self.scenario
        N, M = sc.n_processes, sc.n_servers
        configs = 1
        for s in sc.servers:
            configs *= (N + 1) ** (max(s.uplink_delay - 1, 0) + s.downlink_delay) * (1 + sum(s.processing_time))
        if sc.model.distinct:
            actions = math.perm(N, min(N, M))
        else:
            actions = N ** M
        return AutomatonBounds(configs=configs, initial=1, edges_initial=max(actions, 1))

    def initial_config(self) -> tuple:
        return idle_config(self.scenario)

    def accepts(self, config: tuple) -> tuple[bool, ...]:
        return tuple(server_accepts(s, st) for s, st in zip(self.scenario.servers, config))

    def busy(self, config: tuple, labels: np.ndarray) -> np.ndarray:
        """A server is busy when a job is in service at the start of the slot (d > 0), or when
        U_m = 0 and an update is sent to it and survives the uplink (it is served in this same
        slot), which has probability ``pu_m``."""
        out = np.zeros(labels.shape, dtype=float)
        for m, (srv, st) in enumerate(zip(self.scenario.servers, config)):
            base = 1.0 if st[2] > 0 else 0.0
            out[:, m] = base
            if srv.uplink_delay == 0 and base == 0.0:
                out[:, m] = np.where(labels[:, m] > 0, srv.p_up, 0.0)
        return out

    def greedy_label(self, config: tuple, order: Sequence[int]) -> tuple[int, ...]:
        """The paper's greedy baseline: walking down the ranking while accepting servers remain,
        each process takes, among the accepting servers not yet taken this slot, the one with the
        smallest loop U_m + T_{m,k} + D_m (ties: lower server index)."""
        sc = self.scenario
        acc = self.accepts(config)
        free = [m for m in range(sc.n_servers) if acc[m]]
        label = [0] * sc.n_servers
        for k in order:
            if not free:
                break
            m = min(free, key=lambda m: (sc.servers[m].loop[k], m))
            label[m] = k + 1
            free.remove(m)
        return tuple(label)

    def cheaper_routes(self) -> list[str]:
        return ["the separable suboptimal policy with Monte Carlo simulation (needs no enumeration)"]

    # ------------------------------------------------------------------ private servers
    def private_scenario(self, k: int) -> Scenario:
        """Process ``k`` alone with its own copy of every server (same delays, its processing
        times, same links), ``allow_idle = true``, ``distinct`` as in the scenario."""
        return self._alone((k,), f"{self.scenario.processes[k].name} alone on private servers")

    def group_scenario(self, group: Sequence[int]) -> Scenario:
        """The processes of ``group`` alone with their own copy of every server (same delays,
        their processing times, same links), ``allow_idle = true``, ``distinct`` as in the scenario."""
        group = _checked_group(group, self.scenario.n_processes)
        names = ", ".join(self.scenario.processes[k].name for k in group)
        return self._alone(group, f"{names} on private servers")

    def _alone(self, group: tuple, what: str) -> Scenario:
        sc = self.scenario
        raw = {
            "model": {"kind": self.kind, "allow_idle": True, "distinct": sc.model.distinct},
            "channel": {} if sc.p != sc.p else {"success_probability": sc.p},
            "process": [{"name": pr.name, "A": pr.A.tolist(), "R": pr.R.tolist(), "weight": pr.weight,
                         "tau_cap": pr.tau_cap} for pr in (sc.processes[k] for k in group)],
            "server": [{"name": s.name, "uplink_delay": s.uplink_delay, "downlink_delay": s.downlink_delay,
                        "processing_time": [s.processing_time[k] for k in group], "p_up": s.p_up, "p_down": s.p_down}
                       for s in sc.servers],
        }
        return scenario_from_dict(raw, source=f"{sc.source} [{what}]")

    def project_group(self, config: tuple, group: Sequence[int]) -> tuple:
        """Every entry of a process outside ``group`` emptied, process ``group[i]`` renamed i + 1."""
        rename = {k + 1: i + 1 for i, k in enumerate(group)}

        def mine(x: int) -> int:
            return rename.get(x, 0)

        return tuple((tuple(mine(x) for x in up), mine(job), d if mine(job) else 0, tuple(mine(x) for x in down))
                     for (up, job, d, down) in config)

    def project_labels(self, labels: np.ndarray, k: int) -> np.ndarray:
        """a^k_m = 1 where a_m = k + 1 (process k sent to server m), else 0."""
        return (np.asarray(labels) == k + 1).astype(np.int64)

    def claims(self, config: tuple, labels: np.ndarray) -> np.ndarray:
        """Who takes slot t + U_m of server m's timeline: process k claims it when

        * its job in service still runs then: d >= U_m + 1;
        * its update in uplink place i (sent i + 1 slots ago, service from slot t + U_m - 1 - i)
          still runs then: T_{m,k} >= i + 2 (only for U_m >= 2);
        * it is sent to server m now (a_m = k + 1): its service would start at slot t + U_m.

        A server accepts exactly when no job already there holds slot t + U_m
        (:func:`server_accepts`: busy <= U_m), and jobs never overlap, so in every state-action
        pair the claims of all processes on server m sum to 1, or to 0 when an accepting server
        is left unused.
        """
        labels = np.asarray(labels)
        N = self.scenario.n_processes
        out = np.zeros(labels.shape + (N,), dtype=np.int64)
        for m, (srv, (up, job, d, _)) in enumerate(zip(self.scenario.servers, config)):
            U = srv.uplink_delay
            if job and d >= U + 1:
                out[:, m, job - 1] += 1
            for i, kk in enumerate(up):
                if kk and srv.processing_time[kk - 1] >= i + 2:
                    out[:, m, kk - 1] += 1
            for kk in range(1, N + 1):
                out[:, m, kk - 1] += labels[:, m] == kk
        return out

    def describe(self, config: tuple) -> str:
        return describe_wncs_config(self.scenario.servers, config)

    @classmethod
    def is_idle(cls, config: Any) -> bool:
        return _is_idle_config(config)

    @classmethod
    def complete_partial(cls, text: str, descriptions: Sequence[str], idle_description: str | None) -> str | None:
        """Servers not named in ``"edge: job 3 d=3"`` are idle."""
        if idle_description is None:
            return None
        server_names = [p.split(":")[0].strip().lower() for p in idle_description.split(";")]
        given = {}
        for part in text.split(";"):
            if ":" in part:
                nm, rest = part.split(":", 1)
                given[nm.strip().lower()] = rest
        if given and set(given) <= set(server_names):
            return "; ".join(f"{nm}: {given.get(nm, 'idle')}" for nm in server_names)
        return None

    @classmethod
    def action_name(cls, label: tuple[int, ...], config: Any, names: dict) -> str:
        procs = names["processes"]
        servers = names["servers"] or [f"server {m}" for m in range(1, len(label) + 1)]
        parts = [f"{procs[k - 1]} to {servers[m]}" for m, k in enumerate(label) if k]
        return "(" + ", ".join(parts) + ")" if parts else "(send nothing)"

    @classmethod
    def short_action(cls, label: tuple[int, ...], names: dict) -> str:
        procs = names["processes"]
        return "(" + ",".join(procs[k - 1] if k else "-" for k in label) + ")"

    @classmethod
    def default_servers(cls, configs: Sequence[Any]) -> list[str] | None:
        if not configs:
            return None
        return [f"server {m}" for m in range(1, len(configs[0]) + 1)]
