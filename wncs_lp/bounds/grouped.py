r"""Relaxation 3: private servers shared by groups of processes (relaxation 1 on groups).

Relaxation 1 (:mod:`wncs_lp.bounds.private`) gives every process its own copy of the servers
and keeps only the long-run capacity. Here a **partition of the processes into groups** does the
same with each group in place of a process: the processes of a group G share one private copy
of every server (the group alone, idling allowed: :meth:`Model.group_scenario`, state
:math:`(\tau_G, C_G)`), and only the capacity of each server m is averaged across groups,

.. math:: \sum_G E_{x_G}[\text{claim}_{m,G}] = 1 \;(\text{or} \le 1), \qquad
          \text{claim}_{m,G} = \sum_{k \in G} \text{claim}_{m,k}.

**Why it is a lower bound** -- relaxation 1's argument with groups for processes: under any
stationary policy of the real system the AoI and own jobs of the processes of G evolve exactly
as in G's private system under the projected action (a real acceptance is a private one: G's
private servers hold a subset of the jobs), the real stationary law projects onto a stationary
law of every group's private MDP, and the groups' claims sum to the joint claims, which sum to 1
on every server in every state-action pair (no idling, N >= M) or to at most 1. So for every
multiplier lambda (free, or >= 0)

.. math:: g^* \ge \sum_G \underline g_G(\lambda) - \sum_m \lambda_m,

:math:`\underline g_G` the certified lower end of group G's priced chain (policy iteration's
Bellman bracket). The multipliers are searched as in relaxation 1 (Kelley's cutting planes).

**Never looser than relaxation 1**: a policy of G's private system projects onto a policy of
each member's with the same costs and claims, so :math:`g_G(\lambda) \ge \sum_{k \in G}
g_k(\lambda)` at every lambda. It is tighter where processes of one group compete for the same
server at the same moments, which relaxation 1 lets each of them ignore. Measured (2026-12-02): the
paper's four process types twice at cap 20, relaxation 1 8706.58, **pairs of identical processes
8953.00 (+2.83%)**, pairs (1a, 2a), (3a, 4a), ... 8715.86; relaxation 2 there stays at relaxation 1.
At processes 1-4, cap 20, pairs (1, 2), (3, 4) give 1441.25 against relaxation 1's 1370.30 and
relaxation 2's 1547.63.

**Choosing the groups** (``groups="pairs"``): pairs, chosen by their **interaction** at relaxation
1's multipliers lambda*: :math:`w_{kl} = g_{\{k,l\}}(\lambda^*) - g_k(\lambda^*) - g_l(\lambda^*)
\ge 0`, the bound's increase at lambda* if k and l share their servers; then the partition into
pairs (one process alone when N is odd) of largest total interaction, exactly (a dynamic programme
over subsets) up to :data:`EXACT_MATCHING_MAX` processes, greedily beyond. Every candidate pair
chain is solved once (identical pairs share one chain), so the choice costs N(N-1)/2 priced
pair solves at most. A pair's private system has tau_hat_k tau_hat_l |C_{kl}| states (13k-42k
for the paper's processes at cap 20); larger groups grow as tau_hat^|G| and are left to the
caller (``groups=[(0, 1, 2), ...]``).
"""
from __future__ import annotations

import itertools
import time
from typing import Any, Sequence

import numpy as np

from ..errors import SolverError, WncsError
from ..models import Model, model_for
from ..models.system import System
from ..progress import as_progress
from ..scenario import Scenario
from ..status import MAX_ITER, OPTIMAL
from .inputs import bound_system, check_private_chains
from .private import PrivateChain, build_private_chain, chain_key, private_bound, private_lower_bound_at, search_multipliers
from .result import BoundResult, GroupTables

__all__ = ["grouped_bound", "choose_pairs", "group_table", "PrivateChains", "RELAXATION", "EXACT_MATCHING_MAX"]

#: Name of this relaxation in :class:`BoundResult`.
RELAXATION = "grouped-private-servers"
#: ``groups="pairs"`` finds the best pairing exactly (a dynamic programme over 2^N subsets) up to
#: this many processes, greedily (largest interaction first) beyond.
EXACT_MATCHING_MAX = 16


class PrivateChains:
    """The private chains of groups, built once per distinct group system (identical groups share one)."""

    def __init__(self, model: Model):
        self.model = model
        self.by_key: dict[str, PrivateChain] = {}
        self.policies: dict[int, np.ndarray] = {}  # id(chain) -> its last computed policy

    def of(self, group: tuple) -> PrivateChain:
        sc = self.model.group_scenario(group)
        key = chain_key(sc)
        if key not in self.by_key:
            self.by_key[key] = build_private_chain(group, sc)
        return self.by_key[key]


def _priced_gain(chains: PrivateChains, chain: PrivateChain, lam: np.ndarray, tol: float) -> float:
    """The certified lower end of the chain's optimal gain at the multipliers lam (its policy kept
    to start the multiplier search)."""
    lb, solves = private_lower_bound_at([chain], np.ones(1), lam, tol)
    chains.policies[id(chain)] = solves[0].policy
    return lb + float(np.sum(lam))


def choose_pairs(system: System, lam: np.ndarray, single_gains: Sequence[float], *, solve_tol: float = 1e-10,
                 chains: PrivateChains | None = None, progress: Any = False,
                 expired: Any = None) -> tuple[tuple[tuple[int, ...], ...], dict]:
    """Pairs of processes of largest total interaction at the multipliers ``lam``.

    Parameters
    ----------
    system : System
    lam : (M,) array
        Relaxation 1's multipliers.
    single_gains : (N,) array
        Each process's certified gain at ``lam`` (relaxation 1's ``process_gains``).
    solve_tol : float
        Relative certificate width of each priced pair solve.
    chains : optional
        The cache of group chains to build into (the caller's, so the chosen pairs are not built twice).
    progress : bool or Progress
    expired : callable, optional
        ``expired()`` True (a time limit passed): no more pair chains are solved; a pair whose two
        kinds of process were measured together before still gets that weight, the others count as
        not interacting.

    Returns
    -------
    (groups, weights)
        The partition (pairs, and processes alone), and ``{(k, l): w_kl}`` of the pairs measured.
    """
    n = system.n_processes
    chains = chains if chains is not None else PrivateChains(system.model)
    prog = as_progress(progress)
    # a pair's gain does not depend on the order of its processes: one solve per multiset of processes
    kind = [chain_key(chains.model.private_scenario(k)) for k in range(n)]
    weights, seen = {}, {}
    for k, l in itertools.combinations(range(n), 2):
        key = tuple(sorted((kind[k], kind[l])))
        if key not in seen:
            if expired is not None and expired():
                continue  # no new pair chains; the pairs of kinds already measured still get their weight
            ch = chains.of((k, l))
            seen[key] = _priced_gain(chains, ch, lam, solve_tol)
            prog.tick(f"[grouped] pair ({k + 1}, {l + 1}): {ch.mdp.n_states:,} states, gain {seen[key]:.8g}")
        weights[(k, l)] = max(seen[key] - single_gains[k] - single_gains[l], 0.0)
    full = {p: weights.get(p, 0.0) for p in itertools.combinations(range(n), 2)}
    pairs = _best_matching(n, full) if n <= EXACT_MATCHING_MAX else _greedy_matching(n, full)
    singles = sorted(set(range(n)) - {k for p in pairs for k in p})
    return tuple(sorted([tuple(p) for p in pairs] + [(k,) for k in singles])), weights


def _best_matching(n: int, w: dict) -> list[tuple[int, int]]:
    """The pairing of largest total weight (unmatched processes allowed): a dynamic programme
    over the set of processes already decided, the lowest open process matched or left alone."""
    full = (1 << n) - 1
    value = [0.0] * (1 << n)
    choice = [-1] * (1 << n)
    for done in range(full - 1, -1, -1):
        open_ = ~done & full
        k = (open_ & -open_).bit_length() - 1
        rest = done | (1 << k)
        v, c = value[rest], -1  # k alone
        for l in range(k + 1, n):
            if not rest >> l & 1 and w[(k, l)] + value[rest | (1 << l)] > v:
                v, c = w[(k, l)] + value[rest | (1 << l)], l
        value[done], choice[done] = v, c
    pairs, done = [], 0
    while done != full:
        open_ = ~done & full
        k = (open_ & -open_).bit_length() - 1
        l = choice[done]
        done |= 1 << k
        if l >= 0:
            pairs.append((k, l))
            done |= 1 << l
    return pairs


def _greedy_matching(n: int, w: dict) -> list[tuple[int, int]]:
    used, pairs = set(), []
    for (k, l), wkl in sorted(w.items(), key=lambda kv: -kv[1]):
        if wkl <= 0:
            break  # no interaction: alone costs nothing and keeps the chains small
        if k not in used and l not in used:
            pairs.append((k, l))
            used |= {k, l}
    return pairs


def _checked_partition(groups: Sequence[Sequence[int]], n: int) -> tuple[tuple[int, ...], ...]:
    out = tuple(tuple(sorted(int(k) for k in g)) for g in groups)
    flat = sorted(k for g in out for k in g)
    if flat != list(range(n)) or any(len(g) == 0 for g in out):
        raise WncsError(f"groups must partition the processes 0..{n - 1} (0-based), each once; got {list(groups)}")
    return out


def group_table(chain: PrivateChain, bias: np.ndarray) -> np.ndarray:
    """(|C_G|, tau_hat_1, ..., tau_hat_g) table of a bias over the group's private states; the
    entries of unreachable (tau_G, C_G) take their configuration's largest value (the joint
    system never reads them from a reachable state)."""
    st = chain.mdp.states
    tau = np.asarray(st.tau)
    caps = tuple(int(c) for c in chain.scenario.tau_caps)
    out = np.full((chain.n_configs,) + caps, np.nan)
    out[(np.asarray(st.config),) + tuple(tau[:, i] - 1 for i in range(len(caps)))] = bias
    flat = out.reshape(chain.n_configs, -1)
    for row in flat:
        missing = np.isnan(row)
        if missing.any():
            row[missing] = 0.0 if missing.all() else np.nanmax(row)
    return out


def grouped_bound(scenario_or_system: Scenario | System, groups: str | Sequence[Sequence[int]] = "pairs", *,
                  tol: float = 1e-6, max_iter: int = 80, solve_tol: float = 1e-10, time_limit: float | None = None,
                  cpu_limit: float | None = None, relaxation_1: BoundResult | None = None,
                  progress: Any = False) -> BoundResult:
    """The grouped private-servers lower bound on g* (relaxation 3), certified.

    Parameters
    ----------
    scenario_or_system : Scenario or System
        A Section II scenario.
    groups : "pairs" or sequence of sequences of int
        ``"pairs"`` (default): pairs of largest interaction at relaxation 1's multipliers
        (:func:`choose_pairs`); or an explicit partition of the processes (0-based), e.g.
        ``[(0, 4), (1, 5), (2, 6), (3, 7)]``.
    tol, max_iter, solve_tol : as :func:`~wncs_lp.bounds.private.private_bound`.
    time_limit : float, optional
        Seconds at most (after relaxation 1): choosing the pairs stops measuring pairs, and the
        multiplier search stops, when it is reached; the bound is certified whatever stops it.
    cpu_limit : float, optional
        The same in seconds of this process's CPU time (after relaxation 1; whichever limit comes
        first): a limit a loaded machine does not bring forward, so the bound is the same there as on
        a quiet one (``lower_bound(x, "auto")`` uses it).
    relaxation_1 : BoundResult, optional
        Relaxation 1's result on this system, to start from (computed when not given).
    progress : bool or Progress

    Returns
    -------
    BoundResult
        ``relaxation="grouped-private-servers"``; ``tables`` a :class:`GroupTables` (each group's
        bias h_G(tau_G, C_G) at the multipliers); ``process_gains`` one entry per group (its
        certified gain, in the order of ``tables.groups``); ``stats["groups"]`` the partition
        (0-based) and, with ``"pairs"``, ``stats["pair_interaction"]``; ``stats["relaxation_1_bound"]``.
        The multiplier search starts at relaxation 1's multipliers, and the returned bound is never
        below relaxation 1's (the search keeps its best point; at relaxation 1's multipliers the
        groups' gains are at least their members').

    Raises
    ------
    ModelError
        A model kind without private servers (the preemption model).
    WncsError
        ``groups`` is not a partition of the processes.
    """
    t0 = time.perf_counter()
    prog = as_progress(progress)
    if isinstance(scenario_or_system, System):  # checked; cost tables of its own honoured
        scenario_or_system = bound_system(scenario_or_system)
    model = scenario_or_system.model if isinstance(scenario_or_system, System) else model_for(scenario_or_system)
    model.group_scenario((0,))  # refuses a kind without the relaxation before any work
    system = scenario_or_system if isinstance(scenario_or_system, System) else System.from_scenario(
        scenario_or_system, model)
    n = system.n_processes
    if not isinstance(groups, str):
        groups = _checked_partition(groups, n)
    elif groups != "pairs":
        raise WncsError(f"unknown groups {groups!r}; expected 'pairs' or a partition of the processes")
    r1 = relaxation_1 if relaxation_1 is not None else private_bound(system, tol=tol, solve_tol=solve_tol)
    deadline = time.perf_counter() + (float(time_limit) if time_limit is not None else np.inf)
    cpu_end = time.process_time() + (float(cpu_limit) if cpu_limit is not None else np.inf)

    def expired() -> bool:  # either limit, wall clock or CPU time
        return time.perf_counter() >= deadline or time.process_time() >= cpu_end

    lam1 = np.asarray(r1.multipliers, float)
    chains = PrivateChains(model)
    stats: dict[str, Any] = {"relaxation_1_bound": r1.lower_bound, "capacity": r1.stats["capacity"]}
    if groups == "pairs":
        prog.phase(f"grouped bound: the interaction of every pair of {n} processes at relaxation 1's multipliers")
        groups, weights = choose_pairs(system, lam1, r1.process_gains, solve_tol=solve_tol, chains=chains,
                                       progress=prog, expired=expired)
        stats["pair_interaction"] = {f"{k + 1},{l + 1}": round(float(v), 9) for (k, l), v in weights.items()}
    group_chains = [chains.of(g) for g in groups]
    columns = tuple(_columns(system, model, c, g) for c, g in zip(group_chains, groups))
    check_private_chains(system, groups, group_chains, columns, "relaxation 3")
    distinct = list({id(c): c for c in group_chains}.values())
    which = np.array([next(i for i, c in enumerate(distinct) if c is gc) for gc in group_chains])
    prog.phase(f"grouped bound: groups {[tuple(k + 1 for k in g) for g in groups]}, "
               f"{len(distinct)} distinct private chains of {[c.mdp.n_states for c in distinct]} states")
    search = search_multipliers(system, distinct, which, r1.stats["capacity"], tol, max_iter, solve_tol, prog,
                                lam0=lam1, expired=expired,
                                policies0=[chains.policies.get(id(c)) for c in distinct])
    solves = search["solves"]
    tables = GroupTables(groups=groups,
                         h=tuple(group_table(distinct[which[i]], solves[which[i]].bias) for i in range(len(groups))),
                         column=columns)
    stats.update(groups=[list(g) for g in groups], private_chains=len(distinct),
                 chain_states=[int(c.mdp.n_states) for c in distinct], cuts=search["cuts"],
                 priced_solves=search["solves_done"] + (len(chains.by_key) if "pair_interaction" in stats else 0),
                 priced_status=sorted({s.status for s in solves}), box=search["box"],
                 stopped_by_time=expired())
    return BoundResult(
        relaxation=RELAXATION, lower_bound=search["lb"], relaxation_upper=search["upper"],
        status=OPTIMAL if search["converged"] else MAX_ITER, certified_by=_certified_by(groups, r1.stats["capacity"]),
        multipliers=search["lambda"], process_gains=np.array([solves[which[i]].lower for i in range(len(groups))]),
        tables=tables, seconds=time.perf_counter() - t0, iterations=search["iterations"], stats=stats)


def _columns(system: System, model: Model, chain: PrivateChain, group: tuple) -> np.ndarray:
    """Group ``group``'s private configuration id of every joint configuration."""
    try:
        return np.array([chain.config_index[model.project_group(cfg, group)] for cfg in system.automaton.configs],
                        np.int64)
    except KeyError as exc:  # the projection argument says this cannot happen
        raise SolverError(f"internal error: the projection {exc} of a joint configuration on the group "
                          f"{tuple(k + 1 for k in group)} is not a configuration of its private system") from None


def _certified_by(groups: tuple, sense: str) -> str:
    names = ", ".join("(" + ", ".join(str(k + 1) for k in g) + ")" for g in groups)
    return (f"sum over the groups {names} of the lower end gain_lower of the Bellman bracket of each group's priced "
            "private chain (its processes sharing one copy of the servers, idling allowed; q + lambda . claim, solved "
            "by policy iteration), minus sum_m lambda_m; valid for every "
            + ("lambda (the claims sum to 1 in every state-action pair)" if sense == "equality"
               else "lambda >= 0 (the claims sum to at most 1)"))
