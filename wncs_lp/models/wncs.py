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
-> downlink loss. A delivered command of process k sets delta_k = U + T_k + D (its age). The
uplink of process k to server m succeeds with pu_{m,k} (``ServerSpec.p_up[k - 1]``), its
downlink with pd_{m,k}.

**Random arrivals** (``docs/model.md``, "Random arrivals"). When some process has
``arrival_probability < 1`` a configuration is an :class:`ArrivalConfig` ``(servers, ages,
alpha)``: ``servers`` the tuple above, ``ages`` the same shape per server ``(up_ages, job_age,
down_ages)`` holding the age at send of each job (0 where empty), lumped at
a_{m,k} = max(0, tau_hat_k - (U_m + T_{m,k} + D_m)), and ``alpha`` the age of the update at each
sensor, lumped at a_k = max_m a_{m,k} (0 for a process sampling at will). A delivered command of
process k sent with age a through server m sets delta_k = a + U_m + T_{m,k} + D_m. Everything
that reads only the servers (acceptance, actions, claims, the busy table) reads ``servers``.
"""
from __future__ import annotations

import itertools
import math
from functools import lru_cache
from typing import Any, NamedTuple, Sequence

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario, ServerSpec, scenario_from_dict
from .automaton import AutomatonBounds, ConfigAutomaton, LazyAutomaton, explore_configs
from .base import Model

__all__ = [
    "WncsModel",
    "ArrivalConfig",
    "aged_server_step",
    "useful_ages",
    "initial_arrival_config",
    "build_wncs",
    "wncs_automaton",
    "server_accepts",
    "server_step",
    "feasible_actions",
    "describe_wncs_config",
    "idle_config",
]

ServerState = tuple  # (up: tuple[int,...], job: int, d: int, down: tuple[int,...])


class ArrivalConfig(NamedTuple):
    """A configuration of a scenario with random arrivals (module docstring).

    Attributes
    ----------
    servers : tuple
        Per server ``(up, job, d, down)``, as without arrivals.
    ages : tuple
        Per server ``(up_ages, job_age, down_ages)``: the age at send of the job in each place
        (lumped at a_{m,k}; 0 where the place is empty).
    alpha : tuple of int
        Per process, the age of the update at its sensor (lumped at a_k; 0 at will).
    """

    servers: tuple
    ages: tuple
    alpha: tuple


def _servers(config: Any) -> tuple:
    """The servers' part of a configuration (the whole of it without arrivals)."""
    return config.servers if isinstance(config, ArrivalConfig) else config


def useful_ages(scenario: Scenario) -> tuple[tuple[int, ...], tuple[tuple[int, ...], ...]]:
    """``(a_k per process, a_{m,k} per server and process)``: the lumping ages of ``docs/model.md``.

    a_{m,k} = max(0, tau_hat_k - (U_m + T_{m,k} + D_m)): an update sent to server m with at least
    this age cannot bring tau_k below its cap; a_k = max_m a_{m,k}, the sensor's. A process
    sampling at will has a_k = 0 and a_{m,k} = 0 (its updates are always fresh).
    """
    per_server = tuple(tuple(max(0, pr.tau_cap - s.loop[k]) if pr.has_arrivals else 0
                             for k, pr in enumerate(scenario.processes)) for s in scenario.servers)
    sensor = tuple(max(col) for col in zip(*per_server))
    return sensor, per_server


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
    return [(nxt, k, p) for nxt, _, k, _, p in aged_server_step(server, state, None, a, 0)]


def aged_server_step(server: ServerSpec, state: ServerState, ages: tuple | None, a: int,
                     sent_age: int) -> list[tuple[ServerState, tuple | None, int, int, float]]:
    """One slot of one server, the jobs carrying their age at send.

    ``ages`` is ``(up_ages, job_age, down_ages)`` (None: not tracked, all 0) and ``sent_age`` the
    (lumped) age of the update sent now. Returns ``[(next_state, next_ages, delivered_process
    (0 = none), its age at send, prob), ...]``, in the order of the uplink outcome (success first)
    then the downlink's.
    """
    up, job, d, down = state
    ua, ja, da = ages if ages is not None else ((0,) * len(up), 0, (0,) * len(down))
    U, D, T = server.uplink_delay, server.downlink_delay, server.processing_time
    pu = server.p_up[a - 1] if a else 1.0
    sends = [(a, pu), (0, 1.0 - pu)] if a else [(0, 1.0)]
    out: list[tuple[ServerState, tuple | None, int, int, float]] = []
    for arrived, p1 in sends:
        new_age = sent_age if arrived else 0
        j, dd, jage = job, d, ja
        if U == 0 and arrived:  # 2. start at once
            if dd != 0:
                raise ModelError(f"internal error: server {server.name} busy (d={dd}) when a job starts")
            j, dd, jage = arrived, T[arrived - 1], new_age
        completed, cage = 0, 0
        if dd > 0:  # 3. service
            dd -= 1
            if dd == 0:
                completed, cage, j, jage = j, jage, 0, 0
        if D == 0:  # 4. downlink
            delivered, dage, new_down, new_da = completed, cage, (), ()
        else:
            delivered, dage = down[-1], da[-1]
            new_down, new_da = (completed,) + down[:-1], (cage,) + da[:-1]
        new_up, new_ua = up, ua
        if U >= 1:  # 5. the update leaving the uplink starts service next slot
            if U == 1:
                leaving, lage = arrived, new_age
            else:
                leaving, lage = up[-1], ua[-1]
                new_up, new_ua = (arrived,) + up[:-1], (new_age,) + ua[:-1]
            if leaving:
                if dd != 0:
                    raise ModelError(f"internal error: server {server.name} busy (d={dd}) when a job starts")
                j, dd, jage = leaving, T[leaving - 1], lage
        nxt = (new_up, j, dd, new_down)
        nxt_ages = (new_ua, jage, new_da) if ages is not None else None
        if delivered:  # 6. downlink loss
            pd = server.p_down[delivered - 1]
            out.append((nxt, nxt_ages, delivered, dage, p1 * pd))
            out.append((nxt, nxt_ages, 0, 0, p1 * (1.0 - pd)))
        else:
            out.append((nxt, nxt_ages, 0, 0, p1))
    return out


def feasible_actions(scenario: Scenario, config: tuple) -> list[tuple[int, ...]]:
    """The feasible actions (a_1..a_M) of a joint configuration, in the MDP's action order.

    Non-accepting servers get 0. An accepting server gets a process 1..N, or 0 when
    ``allow_idle`` or when more servers accept than there are processes. With ``distinct``, no
    process goes to two servers. Order: lexicographic, each server's options listed 1..N then 0,
    so ties between equally good actions break towards sending rather than idling.
    """
    N = scenario.n_processes
    accepts = [server_accepts(s, st) for s, st in zip(scenario.servers, _servers(config))]
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
    """Explore the joint server configurations reachable from the all-idle one (with random
    arrivals: the :class:`ArrivalConfig` reachable from all-idle servers and fresh updates)."""
    return explore_configs(wncs_initial(scenario), wncs_step(scenario))


def wncs_initial(scenario: Scenario) -> list:
    """The initial configuration: every server idle (with arrivals, and fresh updates)."""
    return [initial_arrival_config(scenario) if scenario.has_arrivals else idle_config(scenario)]


def wncs_step(scenario: Scenario):
    """The automaton's step: ``step(config)`` yields ``(action, [(next_config, delta, prob), ...])``
    for every feasible action (a generator: explore_configs' edge budget can stop a huge action set)."""
    if scenario.model.kind != "wncs":
        raise ModelError(f"{scenario.source}: build_wncs needs kind = \"wncs\", found {scenario.model.kind!r}")
    if scenario.has_arrivals:
        return _arrival_step(scenario)
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

    return step


def _generations(scenario: Scenario, sensor_cap: tuple[int, ...]):
    """alpha -> [(alpha', prob), ...]: each process with arrivals draws its next update (alpha' = 0
    with lambda_k, else min(alpha + 1, a_k)); a process sampling at will keeps alpha = 0."""
    lam = [pr.arrival_probability for pr in scenario.processes]

    @lru_cache(maxsize=None)
    def draws(alpha: tuple) -> list:
        per = [[(0, lam[k]), (min(x + 1, sensor_cap[k]), 1.0 - lam[k])] if lam[k] < 1.0 else [(0, 1.0)]
               for k, x in enumerate(alpha)]
        out = []
        for combo in itertools.product(*per):
            prob = 1.0
            for _, pr in combo:
                prob *= pr
            out.append((tuple(x for x, _ in combo), prob))
        return out

    return draws


def _arrival_step(scenario: Scenario):
    """The step of the automaton over :class:`ArrivalConfig`: the servers' slot with the jobs' ages,
    then the sensors' generations (independent of the action and the channels)."""
    servers = scenario.servers
    N = scenario.n_processes
    sensor_cap, job_cap = useful_ages(scenario)
    loops = [s.loop for s in servers]
    steps = [lru_cache(maxsize=None)(lambda st, ag, a, age, s=s: aged_server_step(s, st, ag, a, age)) for s in servers]
    draws = _generations(scenario, sensor_cap)

    def step(config: ArrivalConfig):
        srv, ages, alpha = config
        nexts = draws(alpha)
        for action in feasible_actions(scenario, srv):
            per_server = [steps[m](srv[m], ages[m], a, min(alpha[a - 1], job_cap[m][a - 1]) if a else 0)
                          for m, a in enumerate(action)]
            outs = []
            for combo in itertools.product(*per_server):
                prob = 1.0
                delta = [0] * N
                for m, (_, _, delivered, sent, pr) in enumerate(combo):
                    prob *= pr
                    if delivered:
                        k = delivered - 1
                        age = sent + loops[m][k]
                        delta[k] = age if delta[k] == 0 else min(delta[k], age)
                nsrv, nages, delta = tuple(c[0] for c in combo), tuple(c[1] for c in combo), tuple(delta)
                outs.extend((ArrivalConfig(nsrv, nages, nalpha), delta, prob * pa) for nalpha, pa in nexts)
            yield action, outs

    return step


def initial_arrival_config(scenario: Scenario) -> ArrivalConfig:
    """Every server idle with empty pipelines, every sensor holding a fresh update (alpha = 0)."""
    idle = idle_config(scenario)
    ages = tuple((tuple(0 for _ in up), 0, tuple(0 for _ in down)) for up, _, _, down in idle)
    return ArrivalConfig(idle, ages, (0,) * scenario.n_processes)


def describe_wncs_config(servers: tuple[ServerSpec, ...], config: tuple) -> str:
    """One line per configuration: ``"remote: job 1 d=2 down[2]; edge: idle"``; with random
    arrivals a job shows its age at send (``job 1@3 d=2``: process 1's update, sent 3 slots
    old) and the sensors' ages close the line (``; sensor ages: 0, 4``)."""
    aged = isinstance(config, ArrivalConfig)
    srv_cfg = _servers(config)
    all_ages = config.ages if aged else [None] * len(srv_cfg)

    def one(k: int, age: int) -> str:
        return f"{k}@{age}" if aged and k else str(k)

    parts = []
    for s, (up, job, d, down), ages in zip(servers, srv_cfg, all_ages):
        ua, ja, da = ages if ages is not None else ((0,) * len(up), 0, (0,) * len(down))
        if not job and not any(up) and not any(down):
            parts.append(f"{s.name}: idle")
            continue
        bits = []
        if any(up):
            bits.append("up[" + ",".join(one(k, a) for k, a in zip(up, ua)) + "]")
        bits.append(f"job {one(job, ja)} d={d}" if job else "no job")
        if any(down):
            bits.append("down[" + ",".join(one(k, a) for k, a in zip(down, da)) + "]")
        parts.append(f"{s.name}: " + " ".join(bits))
    if aged:
        parts.append("sensor ages: " + ", ".join(str(x) for x in config.alpha))
    return "; ".join(parts)


def build_wncs(scenario: Scenario) -> MDP:
    """Build the Section II MDP of a ``kind = "wncs"`` scenario.

    Returns an :class:`~wncs_lp.mdp.MDP` whose ``states`` is a
    :class:`~wncs_lp.models.statespace.StateSpace` (tau per process, joint server configuration)
    and whose ``action_table`` rows are the actions (a_1..a_M), 0 = nothing sent.
    """
    return WncsModel(scenario).build()


def _is_idle_config(cfg: Any) -> bool:
    """Every server idle with empty pipelines (with random arrivals: and every sensor holding a
    fresh update, the initial configuration)."""
    if isinstance(cfg, ArrivalConfig):
        return _is_idle_config(cfg.servers) and not any(cfg.alpha)
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

    def lazy_automaton(self) -> LazyAutomaton:
        return LazyAutomaton(wncs_initial(self.scenario), wncs_step(self.scenario))

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
        if sc.has_arrivals:  # the sensors' ages, and an age at send in every place of every server
            sensor_cap, job_cap = useful_ages(sc)
            configs *= math.prod(a + 1 for a in sensor_cap)
            for s, caps in zip(sc.servers, job_cap):
                configs *= (1 + max(caps)) ** (max(s.uplink_delay - 1, 0) + 1 + s.downlink_delay)
        if sc.model.distinct:
            actions = math.perm(N, min(N, M))
        else:
            actions = N ** M
        return AutomatonBounds(configs=configs, initial=1, edges_initial=max(actions, 1))

    def initial_config(self) -> tuple:
        """Every server idle with empty pipelines (with random arrivals: and every sensor holding
        a fresh update)."""
        if self.scenario.has_arrivals:
            return initial_arrival_config(self.scenario)
        return idle_config(self.scenario)

    def accepts(self, config: tuple) -> tuple[bool, ...]:
        return tuple(server_accepts(s, st) for s, st in zip(self.scenario.servers, _servers(config)))

    def busy(self, config: tuple, labels: np.ndarray) -> np.ndarray:
        """A server is busy when a job is in service at the start of the slot (d > 0), or when
        U_m = 0 and an update is sent to it and survives the uplink (it is served in this same
        slot), which has probability ``pu_{m,k}`` of the process k sent."""
        out = np.zeros(labels.shape, dtype=float)
        for m, (srv, st) in enumerate(zip(self.scenario.servers, _servers(config))):
            base = 1.0 if st[2] > 0 else 0.0
            out[:, m] = base
            if srv.uplink_delay == 0 and base == 0.0:
                pu = np.asarray(srv.p_up, dtype=float)
                out[:, m] = np.where(labels[:, m] > 0, pu[np.clip(labels[:, m] - 1, 0, pu.size - 1)], 0.0)
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
        """The processes of ``group`` with everything that is theirs: A, R, weight, cap, cost family,
        arrivals, processing times and their own link probabilities to every server."""
        sc = self.scenario

        def process(pr) -> dict:
            out = {"name": pr.name, "A": pr.A.tolist(), "R": pr.R.tolist(), "weight": pr.weight,
                   "tau_cap": pr.tau_cap, "cost": pr.cost.to_raw()}
            if pr.has_arrivals:
                out["arrival_probability"] = pr.arrival_probability
            return out

        raw = {
            "model": {"kind": self.kind, "allow_idle": True, "distinct": sc.model.distinct},
            "channel": {} if sc.p != sc.p else {"success_probability": sc.p},
            "process": [process(sc.processes[k]) for k in group],
            "server": [{"name": s.name, "uplink_delay": s.uplink_delay, "downlink_delay": s.downlink_delay,
                        "processing_time": [s.processing_time[k] for k in group],
                        "p_up": [s.p_up[k] for k in group], "p_down": [s.p_down[k] for k in group]}
                       for s in sc.servers],
        }
        return scenario_from_dict(raw, source=f"{sc.source} [{what}]")

    def project_group(self, config: tuple, group: Sequence[int]) -> tuple:
        """Every entry of a process outside ``group`` emptied, process ``group[i]`` renamed i + 1;
        with random arrivals, the group's jobs keep their ages at send and its sensors their
        ages (a plain server tuple when no process of the group has random arrivals)."""
        rename = {k + 1: i + 1 for i, k in enumerate(group)}

        def mine(x: int) -> int:
            return rename.get(x, 0)

        srv = tuple((tuple(mine(x) for x in up), mine(job), d if mine(job) else 0, tuple(mine(x) for x in down))
                    for (up, job, d, down) in _servers(config))
        if not any(self.scenario.processes[k].has_arrivals for k in group):
            return srv
        ages = tuple((tuple(a if mine(x) else 0 for x, a in zip(up, ua)), ja if mine(job) else 0,
                      tuple(a if mine(x) else 0 for x, a in zip(down, da)))
                     for (up, job, _, down), (ua, ja, da) in zip(config.servers, config.ages))
        return ArrivalConfig(srv, ages, tuple(config.alpha[k] for k in group))

    def project_labels(self, labels: np.ndarray, k: int) -> np.ndarray:
        """a^k_m = 1 where a_m = k + 1 (process k sent to server m), else 0."""
        return (np.asarray(labels) == k + 1).astype(np.int64)

    def project_group_labels(self, labels: np.ndarray, group: Sequence[int]) -> np.ndarray:
        """a^G_m = i + 1 where a_m = group[i] + 1 (a process of the group sent to server m, renamed
        as in :meth:`project_group`), else 0."""
        group = _checked_group(group, self.scenario.n_processes)
        rename = np.zeros(self.scenario.n_processes + 1, dtype=np.int64)
        rename[[k + 1 for k in group]] = np.arange(1, len(group) + 1)
        return rename[np.asarray(labels, dtype=np.int64)]

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
        for m, (srv, (up, job, d, _)) in enumerate(zip(self.scenario.servers, _servers(config))):
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
        """Servers not named in ``"edge: job 3 d=3"`` are idle (and, with random arrivals, the
        sensors' ages not given are those of the idle configuration: fresh updates)."""
        if idle_description is None:
            return None
        defaults = {}
        for part in idle_description.split(";"):
            nm, _, rest = part.partition(":")
            defaults[nm.strip().lower()] = rest.strip()
        given = {}
        for part in text.split(";"):
            if ":" in part:
                nm, rest = part.split(":", 1)
                given[nm.strip().lower()] = rest.strip()
        if given and set(given) <= set(defaults):
            return "; ".join(f"{nm}: {given.get(nm, default)}" for nm, default in defaults.items())
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
