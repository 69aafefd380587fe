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

from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Hashable, Sequence

import numpy as np

from ..errors import ModelError

__all__ = ["Outcome", "ConfigAutomaton", "FlatAutomaton", "explore_configs"]

#: (next configuration, delivery ages per process (0 = none), probability)
Outcome = tuple[Hashable, tuple[int, ...], float]


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
    step: Callable[[Hashable], list[tuple[tuple, list[Outcome]]]],
) -> ConfigAutomaton:
    """Breadth-first exploration of the configurations reachable from ``initial``.

    ``step(config)`` returns ``[(action_label, [(next_config, delta, prob), ...]), ...]``.
    Outcomes of probability 0 are dropped and equal (next, delta) outcomes merged, so the
    automaton only has edges of positive probability.

    The merge of an outcome list is cached by the identity of the list object (a reference
    is kept, so the identity cannot be reused): a ``step`` that returns the same cached list
    for many configurations -- the preemption model does -- is merged once.
    """
    configs: list = []
    index: dict = {}

    def intern(cfg: Hashable) -> int:
        i = index.get(cfg)
        if i is None:
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
    f_nact: list[int] = []
    f_nout: list[int] = []
    f_nxt: list[int] = []
    f_did: list[int] = []
    f_prob: list[float] = []
    while queue:
        c = queue.popleft()
        acts, outs = [], []
        for label, outs_raw in step(configs[c]):
            hit = merge_cache.get(id(outs_raw))
            if hit is None or hit[0] is not outs_raw:
                merged: dict[tuple[int, tuple[int, ...]], float] = {}
                for nxt, delta, prob in outs_raw:
                    if prob > 0.0:
                        key = (intern(nxt), tuple(int(x) for x in delta))
                        merged[key] = merged.get(key, 0.0) + float(prob)
                if not merged:
                    raise ModelError(f"configuration {configs[c]!r}, action {label}: no outcome of positive probability")
                lst = [(n, d, p) for (n, d), p in merged.items()]
                hit = (
                    outs_raw,
                    lst,
                    [o[0] for o in lst],
                    [delta_id.setdefault(o[1], len(delta_id)) for o in lst],
                    [o[2] for o in lst],
                )
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
