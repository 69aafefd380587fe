"""The configuration automaton: the small, tau-independent part of every model.

Both models of the toolkit have states s = (tau, C): the AoI vector tau in the box 1..tau_hat
and a configuration C (server pipelines, jobs, arrivals...) whose dynamics do not depend on tau.
Given (C, a), each random outcome leads to a configuration C' and a *delivery vector* delta
(delta_k = the age a delivered command of process k carries, 0 if none), and

    tau'_k = min(tau_k + 1, delta_k if delta_k > 0 else inf, tau_hat_k).

A model describes the automaton over C one configuration at a time (:func:`explore_configs`);
:mod:`wncs_lp.models.assemble` does the large part, vectorised over tau.
"""
from __future__ import annotations

import math
from collections import deque
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Callable, Hashable, Iterable, Iterator, Sequence

import numpy as np

from ..errors import ModelError, SizeLimitError

__all__ = ["Outcome", "SharedOutcomes", "ConfigAutomaton", "FlatAutomaton", "LazyAutomaton", "AutomatonBounds",
           "explore_configs",
           "ExplorationLimitError", "exploration_limit", "approx_count", "MAX_CONFIGS", "MAX_EDGES", "MAX_WORK"]

#: The most configurations :func:`explore_configs` explores (about 45 s and 1 GB of Python
#: objects at the measured 4,400 configurations a second and 4 KB a configuration). The
#: automaton grows exponentially in the delays (an uplink pipeline of U - 1 places holds any
#: pattern of sent / lost updates); past this the MDP would not fit either, since each
#: configuration carries at least one state. ``exploration_limit(None)`` lifts the budget
#: (``force``).
MAX_CONFIGS = 200_000
#: The most edges (positive-probability outcomes of a configuration's actions) explored: about
#: 100 bytes each in Python lists, so 10 million is about 1 GB (the measured 4 KB a configuration
#: is mostly its ~40 edges).
MAX_EDGES = 10_000_000
#: The most work units spent exploring, one unit about 1.6 microseconds (measured, under load):
#: 100 plus its places (scalars of the nested tuple: a delay of U slots is U - 1 uplink places)
#: for each configuration interned, 20 plus N per outcome for each action's outcome list merged
#: (its delivery vectors have N entries). The paper's processes 1-3 with an uplink delay of 10
#: (118,765 configurations, 427,800 states) take 20 million; the budget stops a delay of 10,000
#: slots after ~4,000 configurations and 21 processes after ~230,000 outcome lists.
MAX_WORK = 40_000_000

_LIMIT: ContextVar[int | None] = ContextVar("wncs_lp_exploration_limit", default=-1)
_EDGE_LIMIT: ContextVar[int | None] = ContextVar("wncs_lp_exploration_edge_limit", default=None)


@dataclass(frozen=True)
class AutomatonBounds:
    """What a model knows of its automaton from the scenario alone, before exploring it.

    Attributes
    ----------
    configs : int or None
        An upper bound on the reachable configurations (None: unknown).
    initial : int
        The number of initial configurations (each carries the whole AoI box as states).
    edges_initial : int
        A lower bound on the edges (actions x outcomes) leaving one initial configuration.
    """

    configs: int | None = None
    initial: int = 1
    edges_initial: int = 1


@contextmanager
def exploration_limit(max_configs: int | None, max_edges: int | None = None) -> Iterator[None]:
    """Within the block, :func:`explore_configs` stops past ``max_configs`` configurations
    (``None``: no budget at all; outside any block: :data:`MAX_CONFIGS`, :data:`MAX_EDGES`
    and :data:`MAX_WORK`) and, when given, past ``max_edges`` edges instead of :data:`MAX_EDGES`."""
    token = _LIMIT.set(max_configs)
    token_e = _EDGE_LIMIT.set(max_edges)
    try:
        yield
    finally:
        _EDGE_LIMIT.reset(token_e)
        _LIMIT.reset(token)


class ExplorationLimitError(SizeLimitError):
    """The configuration automaton is larger than the exploration budget.

    Attributes
    ----------
    explored : int
        Configurations found when the exploration stopped.
    edges : int
        Edges found by then.
    places : int
        Places (scalars) of one configuration.
    """

    def __init__(self, message: str, explored: int, edges: int, places: int):
        self.explored, self.edges, self.places = explored, edges, places
        super().__init__(message)


def _places(config: Hashable) -> int:
    """Scalars in a (nested) configuration tuple."""
    n, stack = 0, [config]
    while stack:
        item = stack.pop()
        if isinstance(item, tuple):
            stack.extend(item)
        else:
            n += 1
    return n


def approx_count(n: int) -> str:
    """A count for a message: ``1,234,567``, or ``9.22e18`` past 10^15 (any Python int, however large)."""
    n = int(n)
    if n < 10**15:
        return f"{n:,}"
    e = math.log10(n)
    return f"{10 ** (e - math.floor(e)):.2f}e{math.floor(e)}"


class _Budget:
    """The exploration budget of one :func:`explore_configs` call (off under ``exploration_limit(None)``)."""

    def __init__(self, initial: Sequence[Hashable]):
        limit = _LIMIT.get()
        self.on = limit is not None
        self.max_configs = MAX_CONFIGS if limit in (-1, None) else int(limit)
        edges = _EDGE_LIMIT.get()
        self.max_edges = (MAX_EDGES if edges is None else int(edges)) if self.on else float("inf")
        self.places = max((_places(c) for c in initial[:1000]), default=1)
        self.work = 0

    def config(self, n_configs: int, n_edges: int) -> None:
        """Before interning configuration number ``n_configs + 1``."""
        if self.on:
            self.work += 100 + self.places
            if n_configs >= self.max_configs or self.work > MAX_WORK:
                raise self.error(n_configs, n_edges)

    def merged(self, n_configs: int, n_edges: int, scalars: int) -> None:
        """After merging an outcome list of ``scalars`` delivery entries."""
        if self.on:
            self.work += 20 + scalars
            if self.work > MAX_WORK:
                raise self.error(n_configs, n_edges)

    def error(self, n_configs: int, n_edges: int) -> ExplorationLimitError:
        return ExplorationLimitError(
            f"the configuration automaton is larger than the exploration budget: it stopped at {n_configs:,} "
            f"configurations of {self.places:,} places each and {n_edges:,} edges (actions x outcomes), "
            f"{self.work:,} work units spent (wncs_lp.models.automaton: at most {self.max_configs:,} configurations, "
            f"{MAX_EDGES:,} edges, {MAX_WORK:,} units, about a minute)", n_configs, n_edges, self.places)


#: (next configuration, delivery ages per process (0 = none), probability)
Outcome = tuple[Hashable, tuple[int, ...], float]


class SharedOutcomes(list):
    """An outcome list that a model's ``step`` returns for many configurations, keeping it alive
    itself (the preemption model's slot after the action depends on few things):
    :func:`explore_configs` merges it once and remembers the merge by the list's identity. A
    plain list is merged where it is met and not kept, so a step that builds a new list for every
    action (the Section II model, with random arrivals hundreds of outcomes each) holds no raw
    outcome after its merge."""


@dataclass(frozen=True, eq=False)
class FlatAutomaton:
    """The automaton's edges as flat arrays (what the vectorised builder consumes).

    Global action ``a`` numbers the (configuration, action) pairs configuration-major, and the
    outcomes of a configuration are contiguous (its actions in order, each action's merged
    outcomes in order):

    * ``act_ptr`` (nC + 1,): the actions of configuration c are ``act_ptr[c]:act_ptr[c+1]``;
    * ``out_ptr`` (nA + 1,): the outcomes of global action a are ``out_ptr[a]:out_ptr[a+1]``;
    * ``out_nxt``, ``out_delta``, ``out_prob`` (E,): next configuration id, delivery-vector
      id (a row of ``deltas``) and probability of each outcome;
    * ``deltas`` (nD, N): the distinct delivery vectors.
    """

    act_ptr: np.ndarray
    out_ptr: np.ndarray
    out_nxt: np.ndarray
    out_delta: np.ndarray
    out_prob: np.ndarray
    deltas: np.ndarray

    @property
    def n_edges(self) -> int:
        return int(self.out_nxt.size)

    @classmethod
    def from_outcomes(cls, outcomes: list, n_processes: int | None = None) -> "FlatAutomaton":
        """Flatten ``ConfigAutomaton.outcomes`` (for automata built without :func:`explore_configs`)."""
        did: dict[tuple[int, ...], int] = {}
        n_act, n_out, nxt, dl, pr = [], [], [], [], []
        for per_c in outcomes:
            n_act.append(len(per_c))
            for outs in per_c:
                n_out.append(len(outs))
                for nx, d, p in outs:
                    nxt.append(nx)
                    dl.append(did.setdefault(tuple(int(x) for x in d), len(did)))
                    pr.append(p)
        return cls._make(n_act, n_out, nxt, dl, pr, did, n_processes)

    @classmethod
    def _make(cls, n_act, n_out, nxt, dl, pr, did, n_processes) -> "FlatAutomaton":
        N = n_processes if n_processes is not None else (len(next(iter(did))) if did else 0)
        deltas = np.zeros((len(did), N), dtype=np.int64)
        for d, i in did.items():
            deltas[i] = d
        return cls(
            act_ptr=np.r_[0, np.cumsum(np.asarray(n_act, np.int64))].astype(np.int64),
            out_ptr=np.r_[0, np.cumsum(np.asarray(n_out, np.int64))].astype(np.int64),
            out_nxt=np.asarray(nxt, dtype=np.int64),
            out_delta=np.asarray(dl, dtype=np.int64),
            out_prob=np.asarray(pr, dtype=float),
            deltas=deltas,
        )


@dataclass
class ConfigAutomaton:
    """The configuration part of a model, explored from its initial configurations.

    Attributes
    ----------
    configs : list
        Hashable configuration objects; index = configuration id.
    initial : list[int]
        Ids of the configurations whose whole tau box is a set of initial states.
    actions : list[list[tuple]]
        Per configuration, its feasible action labels in the MDP's action order.
    outcomes : list[list[list[tuple[int, tuple[int, ...], float]]]]
        ``outcomes[c][j]``: the merged positive-probability outcomes (next id, delta, prob) of
        action j in configuration c.
    flat_arrays : FlatAutomaton or None
        The same edges as flat arrays (filled by :func:`explore_configs`; see :meth:`flat`).
    """

    configs: list
    initial: list[int]
    actions: list[list[tuple]]
    outcomes: list[list[list[tuple[int, tuple[int, ...], float]]]]
    index: dict = field(default_factory=dict)
    flat_arrays: FlatAutomaton | None = None

    def flat(self, n_processes: int | None = None) -> FlatAutomaton:
        """The edges as a :class:`FlatAutomaton` (built from ``outcomes`` when not cached)."""
        if self.flat_arrays is None:
            self.flat_arrays = FlatAutomaton.from_outcomes(self.outcomes, n_processes)
        return self.flat_arrays


def explore_configs(
    initial: Sequence[Hashable],
    step: Callable[[Hashable], Iterable[tuple[tuple, list[Outcome]]]],
) -> ConfigAutomaton:
    """Breadth-first exploration of the configurations reachable from ``initial``.

    ``step(config)`` returns (or yields) ``[(action_label, [(next_config, delta, prob), ...]), ...]``.
    Outcomes of probability 0 are dropped and equal (next, delta) outcomes merged, so the
    automaton only has edges of positive probability.

    The merge of a :class:`SharedOutcomes` list is cached by the identity of the list object (a
    reference is kept, so the identity cannot be reused): a ``step`` that returns the same cached
    list for many configurations -- the preemption model does -- is merged once. Other lists are
    merged each time and dropped.

    Raises
    ------
    ExplorationLimitError
        The automaton exceeds the budget (:func:`exploration_limit`; by default
        :data:`MAX_CONFIGS`, :data:`MAX_EDGES`, :data:`MAX_WORK`): the exploration stops there.
    """
    configs: list = []
    index: dict = {}
    budget = _Budget(initial)
    f_nact: list[int] = []
    f_nout: list[int] = []
    f_nxt: list[int] = []
    f_did: list[int] = []
    f_prob: list[float] = []

    def intern(cfg: Hashable) -> int:
        i = index.get(cfg)
        if i is None:
            budget.config(len(configs), len(f_nxt))
            i = index[cfg] = len(configs)
            configs.append(cfg)
            queue.append(i)
        return i

    queue: deque[int] = deque()
    init_ids = [intern(c) for c in initial]
    actions: list[list[tuple]] = []
    outcomes: list[list[list[tuple[int, tuple[int, ...], float]]]] = []
    merge_cache: dict[int, tuple] = {}
    delta_id: dict[tuple[int, ...], int] = {}
    same_delta: dict[tuple[int, ...], tuple[int, ...]] = {}
    max_edges = budget.max_edges
    while queue:
        c = queue.popleft()
        acts, outs = [], []
        for label, outs_raw in step(configs[c]):  # a generator is consumed lazily: the budget stops it
            if len(f_nxt) > max_edges:
                raise budget.error(len(configs), len(f_nxt))
            shared = isinstance(outs_raw, SharedOutcomes)
            hit = merge_cache.get(id(outs_raw)) if shared else None
            if hit is None or hit[0] is not outs_raw:
                merged: dict[tuple[int, tuple[int, ...]], float] = {}
                for nxt, delta, prob in outs_raw:
                    if prob > 0.0:
                        d = tuple(int(x) for x in delta)
                        key = (intern(nxt), same_delta.setdefault(d, d))  # one tuple per distinct delta
                        merged[key] = merged.get(key, 0.0) + float(prob)
                if not merged:
                    raise ModelError(f"configuration {configs[c]!r}, action {label}: no outcome of positive probability")
                lst = [(n, d, p) for (n, d), p in merged.items()]
                budget.merged(len(configs), len(f_nxt), len(outs_raw) * len(lst[0][1]))
                hit = (
                    outs_raw,
                    lst,
                    [o[0] for o in lst],
                    [delta_id.setdefault(o[1], len(delta_id)) for o in lst],
                    [o[2] for o in lst],
                )
                if shared:
                    merge_cache[id(outs_raw)] = hit
            acts.append(tuple(label))
            outs.append(list(hit[1]))
            f_nout.append(len(hit[2]))
            f_nxt.extend(hit[2])
            f_did.extend(hit[3])
            f_prob.extend(hit[4])
        if not acts:
            raise ModelError(f"configuration {configs[c]!r} has no feasible action")
        # configurations are interned in BFS order, so c == len(actions) here
        actions.append(acts)
        outcomes.append(outs)
        f_nact.append(len(acts))
    n_proc = len(next(iter(delta_id))) if delta_id else 0
    flat = FlatAutomaton._make(f_nact, f_nout, f_nxt, f_did, f_prob, delta_id, n_proc)
    return ConfigAutomaton(configs, init_ids, actions, outcomes, index, flat)


class LazyAutomaton:
    """The configuration automaton explored on demand, for systems whose automaton is too large to
    enumerate (a dozen processes on three servers; thirty-two on two).

    Configurations are numbered as they are first seen -- the initial ones, then each outcome of a
    configuration being expanded -- and a configuration is *expanded* (its actions and their merged
    outcomes listed by the model's ``step``, as :func:`explore_configs` does) only when
    :meth:`expand` is asked for it, e.g. when a simulation first visits it. Nothing is kept per
    edge but four numbers in the caller's arrays (:meth:`wncs_lp.models.system.System.expand`).

    Attributes
    ----------
    configs : list
        The configurations seen so far; index = id.
    index : dict
        Configuration -> id.
    initial : list[int]
    actions : list[list[tuple]]
        Per configuration its feasible action labels (empty until it is expanded).
    deltas : dict
        Delivery vector -> its id (the row of the system's ``pairs.deltas``).
    """

    def __init__(self, initial: Sequence[Hashable], step: Callable[[Hashable], Iterable[tuple[tuple, list[Outcome]]]]):
        self.configs: list = []
        self.index: dict = {}
        self.actions: list[list[tuple]] = []
        self.deltas: dict[tuple[int, ...], int] = {}
        self._step = step
        self.initial = [self._intern(c) for c in initial]
        self.n_expanded = 0
        self.n_edges = 0

    def _intern(self, cfg: Hashable) -> int:
        i = self.index.get(cfg)
        if i is None:
            i = self.index[cfg] = len(self.configs)
            self.configs.append(cfg)
            self.actions.append([])
        return i

    def expand(self, config_ids: Iterable[int]) -> list[tuple[int, list[tuple], list[list[tuple[int, int, float]]]]]:
        """Expand the configurations ``config_ids`` not yet expanded: per configuration (its id, its
        action labels, per action its merged outcomes ``(next id, delivery-vector id, prob)``)."""
        out = []
        for c in config_ids:
            c = int(c)
            if self.actions[c]:
                continue
            labels, outs = [], []
            for label, outs_raw in self._step(self.configs[c]):
                merged: dict[tuple[int, tuple[int, ...]], float] = {}
                for nxt, delta, prob in outs_raw:
                    if prob > 0.0:
                        key = (self._intern(nxt), tuple(int(x) for x in delta))
                        merged[key] = merged.get(key, 0.0) + float(prob)
                if not merged:
                    raise ModelError(f"configuration {self.configs[c]!r}, action {label}: no outcome of positive probability")
                labels.append(tuple(label))
                outs.append([(n, self.deltas.setdefault(d, len(self.deltas)), p) for (n, d), p in merged.items()])
                self.n_edges += len(merged)
            if not labels:
                raise ModelError(f"configuration {self.configs[c]!r} has no feasible action")
            self.actions[c] = labels
            self.n_expanded += 1
            out.append((c, labels, outs))
        return out
