"""The shared engine of both model builders: a finite *configuration automaton* times AoI.

Both models of ``model.md`` have states s = (tau, C): the AoI vector tau in the box
1..tau_hat and a configuration C (server pipelines, jobs, arrivals...) whose dynamics do not
depend on tau. Given (C, a), each random outcome leads to a configuration C' and a *delivery
vector* delta (delta_k = the age a delivered command of process k carries, 0 if none), and

    tau'_k = min(tau_k + 1, delta_k if delta_k > 0 else inf, tau_hat_k).

So a builder only describes the small automaton over C (in Python, one configuration at a time,
with caching); this module does the large part vectorised over tau:

1. the reachable state set, as one boolean mask over the tau box per configuration, grown to a
   fixed point from the initial configurations (the image of a mask under the product map
   above is computed axis by axis with ``np.logical_or.reduceat``, the map being monotone);
2. the MDP in state-action-pair form, one vectorised block per (C, a, outcome).
"""
from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable, Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import ModelError
from ..mdp import MDP

__all__ = ["Outcome", "ConfigAutomaton", "FlatAutomaton", "StateSpace", "explore_configs", "build_aoi_mdp"]

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


@dataclass(frozen=True, eq=False)
class StateSpace:
    """The decoded view of an AoI-product state space.

    Attributes
    ----------
    tau : (n, N) int array
        The AoI of every process in every state (values 1..tau_hat_k).
    config : (n,) int array
        The configuration id of every state.
    configs : list
        The configuration objects (model-specific tuples), by id.
    caps : tuple[int, ...]
    describe_config : callable
        config object -> readable string.
    """

    tau: np.ndarray
    config: np.ndarray
    configs: list
    caps: tuple[int, ...]
    describe_config: Callable[[Any], str] = repr
    _lookup: np.ndarray | None = None  # (n_configs, box) -> state id or -1

    @property
    def n_states(self) -> int:
        return int(self.config.size)

    def label(self, s: int) -> str:
        t = ",".join(str(int(x)) for x in self.tau[s])
        return f"tau=({t}) | {self.describe_config(self.configs[int(self.config[s])])}"

    def find(self, tau: Sequence[int], config: Hashable | int) -> int:
        """The state id of (tau, config), or -1 when that state is not reachable."""
        c = config if isinstance(config, (int, np.integer)) else self.config_id(config)
        if c < 0:
            return -1
        tau = np.asarray(tau, dtype=np.int64)
        if tau.shape != (len(self.caps),) or np.any(tau < 1) or np.any(tau > np.asarray(self.caps)):
            return -1
        flat = int(np.ravel_multi_index(tuple(tau - 1), self.caps))
        return int(self._lookup[c, flat])

    def config_id(self, config: Hashable) -> int:
        try:
            return self.configs.index(config)
        except ValueError:
            return -1

    def lookup_grid(self, config: Hashable | int) -> np.ndarray:
        """State ids of one configuration over the whole tau box (shape = caps; -1 = unreachable)."""
        c = config if isinstance(config, (int, np.integer)) else self.config_id(config)
        if c < 0:
            raise ModelError(f"configuration {config!r} is not reachable")
        return self._lookup[c].reshape(self.caps)


def _axis_maps(cap: int, deltas: set[int]) -> dict[int, np.ndarray]:
    """For each delivery age d (0 = none): the index map i -> min(i + 1, d - 1, cap - 1)."""
    i = np.arange(cap)
    out = {}
    for d in deltas:
        m = np.minimum(i + 1, cap - 1)
        if d > 0:
            m = np.minimum(m, d - 1)
        out[d] = m
    return out


def _image(mask: np.ndarray, maps: Sequence[np.ndarray]) -> np.ndarray:
    """Image of a boolean N-d mask under the product of monotone per-axis index maps."""
    out = mask
    for axis, fmap in enumerate(maps):
        starts = np.flatnonzero(np.r_[True, fmap[1:] != fmap[:-1]])
        red = np.logical_or.reduceat(out, starts, axis=axis)
        new = np.zeros_like(out)
        idx = [slice(None)] * out.ndim
        idx[axis] = fmap[starts]
        new[tuple(idx)] = red
        out = new
    return out


def _flat_maps(caps: tuple[int, ...], deltas: np.ndarray) -> np.ndarray:
    """(nD, box) int64: the flat tau-box index map of every delivery vector.

    Box index f = ravel(tau - 1) goes to ravel(min(tau + 1, delta_k if > 0, tau_hat) - 1).
    """
    N = len(caps)
    box = int(np.prod(caps))
    grid = np.unravel_index(np.arange(box, dtype=np.int64), caps)
    out = np.empty((deltas.shape[0], box), dtype=np.int64)
    for i, d in enumerate(deltas):
        cols = []
        for k in range(N):
            m = np.minimum(grid[k] + 1, caps[k] - 1)
            if d[k] > 0:
                m = np.minimum(m, d[k] - 1)
            cols.append(m)
        out[i] = np.ravel_multi_index(tuple(cols), caps)
    return out


def _reachable(flat: FlatAutomaton, initial: Sequence[int], nC: int, box: int, fmap: np.ndarray) -> np.ndarray:
    """(nC, box) bool masks of the reachable (config, tau) states: a vectorised BFS.

    The state graph is the product of the configuration edges (c -> c', delta) with the
    tau-box maps; each BFS layer expands every frontier state along every distinct edge of its
    configuration at once (np.repeat over the per-configuration edge lists), so the work is
    about (reachable states) x (distinct edges per configuration), with one Python iteration
    per layer.
    """
    act_ptr, out_ptr = flat.act_ptr, flat.out_ptr
    E = flat.n_edges
    src = np.repeat(np.arange(nC, dtype=np.int64), np.diff(out_ptr[act_ptr]))
    nD = max(int(flat.deltas.shape[0]), 1)
    key = (src * nC + flat.out_nxt) * nD + flat.out_delta
    if E:  # sorted and deduplicated: grouped by source configuration
        key = np.sort(key)
        key = key[np.r_[True, key[1:] != key[:-1]]]
    e_d = key % nD
    rest = key // nD
    e_nxt = rest % nC
    e_src = rest // nC
    e_ptr = np.searchsorted(e_src, np.arange(nC + 1)).astype(np.int64)
    deg_c = np.diff(e_ptr)
    fmap_flat = fmap.ravel()
    seen = np.zeros(nC * box, dtype=bool)
    # dedupe without sorting: the last writer of stamp[x] is the one representative of x
    stamp = np.empty(nC * box, dtype=np.int32 if nC * box < 2**31 else np.int64)
    init = np.asarray(sorted(set(int(i) for i in initial)), dtype=np.int64)
    frontier = (init[:, None] * box + np.arange(box, dtype=np.int64)[None, :]).ravel()
    seen[frontier] = True
    layers = 0
    while frontier.size:
        layers += 1
        c = frontier // box
        f = frontier - c * box
        deg = deg_c[c]
        tot = int(deg.sum())
        if tot == 0:
            break
        starts = np.cumsum(deg) - deg
        ei = np.repeat(e_ptr[c] - starts, deg) + np.arange(tot, dtype=np.int64)
        new = e_nxt[ei] * box + fmap_flat[e_d[ei] * box + np.repeat(f, deg)]
        del ei
        new = new[~seen[new]]
        if new.size == 0:
            break
        pos = np.arange(new.size, dtype=stamp.dtype)
        stamp[new] = pos
        new = new[stamp[new] == pos]
        seen[new] = True
        frontier = new
    _reachable.layers = layers  # diagnostics for the benchmark
    return seen.reshape(nC, box)


def _assemble_P(
    flat: FlatAutomaton,
    cfg_of_state: np.ndarray,
    flat_of_state: np.ndarray,
    lookup_flat: np.ndarray,
    fmap: np.ndarray,
    box: int,
    row_len: np.ndarray,
    chunk: int = 1 << 22,
) -> sp.csr_matrix:
    """The transition matrix in CSR, written directly in row order (no COO sort).

    The outcomes of a configuration are one contiguous run ``pstart[c] : pstart[c] + K_c`` of
    the flat arrays (its actions in order, each action's outcomes in order), and the rows of a
    state are its actions in order: so the entries of state s are exactly that run, with the
    columns ``lookup[nxt, fmap[delta, f(s)]]``. Entry t of state s takes outcome
    ``pstart[c_s] + (t - estart[s])`` -- two ``np.repeat`` and a few gathers per chunk of
    states. Duplicate columns (two outcomes landing on one state) are summed by scipy's
    compiled ``sum_duplicates``, which also sorts the indices of each row.
    """
    n = int(cfg_of_state.size)
    pstart = flat.out_ptr[flat.act_ptr[:-1]]
    K = flat.out_ptr[flat.act_ptr[1:]] - pstart
    Ks = K[cfg_of_state]
    estart = np.r_[0, np.cumsum(Ks)].astype(np.int64)
    T = int(estart[-1])
    idx_dtype = np.int32 if max(T, n, lookup_flat.size) < np.iinfo(np.int32).max else np.int64
    indices = np.empty(T, dtype=idx_dtype)
    data = np.empty(T, dtype=float)
    fmap_flat = fmap.ravel()
    nxt_base = flat.out_nxt * box
    d_base = flat.out_delta * box
    s0 = 0
    while s0 < n:
        # a chunk of whole states holding about `chunk` entries
        s1 = int(np.searchsorted(estart, estart[s0] + chunk, side="right")) - 1
        s1 = min(max(s1, s0 + 1), n)
        ks = Ks[s0:s1]
        t0, t1 = int(estart[s0]), int(estart[s1])
        pp = np.repeat(pstart[cfg_of_state[s0:s1]] - estart[s0:s1], ks) + np.arange(t0, t1, dtype=np.int64)
        col = lookup_flat[nxt_base[pp] + fmap_flat[d_base[pp] + np.repeat(flat_of_state[s0:s1], ks)]]
        if col.size and col.min() < 0:  # the fixed point guarantees closure; this is a bug guard
            raise ModelError("internal error: a transition leaves the reachable state set")
        indices[t0:t1] = col
        data[t0:t1] = flat.out_prob[pp]
        s0 = s1
    indptr = np.r_[0, np.cumsum(row_len)].astype(idx_dtype)
    P = sp.csr_matrix((data, indices, indptr), shape=(row_len.size, n))
    P.has_sorted_indices = False
    P.sum_duplicates()
    return P


def build_aoi_mdp(
    auto: ConfigAutomaton,
    caps: Sequence[int],
    q_tables: Sequence[np.ndarray],
    *,
    describe_config: Callable[[Any], str] = repr,
    name: str = "mdp",
    meta: dict | None = None,
) -> MDP:
    """Assemble the MDP over the reachable (tau, C) states of an explored automaton.

    Parameters
    ----------
    auto : ConfigAutomaton
    caps : tau_hat_k per process
    q_tables : q_k(1..tau_hat_k) per process; the state cost is sum_k q_k(tau_k).

    States are numbered configuration by configuration (in automaton order), and within a
    configuration in C order of the tau box; pairs are state-major in each configuration's
    action order.

    Vectorised over configurations (no Python loop over configurations, actions or outcomes):
    reachability is a layered BFS over (config, tau) (:func:`_reachable`), the numbering one
    ``np.nonzero`` of the masks, and P is written in CSR order by index arithmetic
    (:func:`_assemble_P`). The result is identical to :func:`_build_aoi_mdp_loop`.
    """
    t0 = time.perf_counter()
    caps = tuple(int(c) for c in caps)
    N = len(caps)
    box = int(np.prod(caps))
    nC = len(auto.configs)
    flat = auto.flat(N)
    deltas = flat.deltas if flat.deltas.shape[0] else np.zeros((1, N), np.int64)
    fmap = _flat_maps(caps, deltas)

    # 1. reachable masks
    masks = _reachable(flat, auto.initial, nC, box, fmap)
    t_reach = time.perf_counter() - t0

    # 2. numbering: states config-major, C order of the box within a configuration
    cfg_idx, flat_of_state = np.nonzero(masks)
    n = int(cfg_idx.size)
    lookup = np.full((nC, box), -1, dtype=np.int64)
    lookup[cfg_idx, flat_of_state] = np.arange(n, dtype=np.int64)
    cfg_of_state = cfg_idx.astype(np.int32)
    flat_of_state = flat_of_state.astype(np.int64)
    tau_idx = np.stack(np.unravel_index(flat_of_state, caps), axis=1) if n else np.zeros((0, N), np.int64)
    state_cost = np.zeros(n)
    for k in range(N):
        state_cost += np.asarray(q_tables[k], dtype=float)[tau_idx[:, k]]

    # 3. pairs and action table
    label_id: dict[tuple, int] = {}
    act_label = np.empty(int(flat.act_ptr[-1]), dtype=np.int64)
    g = 0
    for acts in auto.actions:
        for lab in acts:
            act_label[g] = label_id.setdefault(lab, len(label_id))
            g += 1
    n_act = np.diff(flat.act_ptr)
    na_state = n_act[cfg_of_state]
    pair_ptr = np.r_[0, np.cumsum(na_state)].astype(np.int64)
    L = int(pair_ptr[-1])
    s_idx = np.repeat(np.arange(n, dtype=np.int64), na_state)
    a_glob = np.repeat(flat.act_ptr[:-1][cfg_of_state] - pair_ptr[:-1], na_state) + np.arange(L, dtype=np.int64)
    a_idx = act_label[a_glob]
    row_len = np.diff(flat.out_ptr)[a_glob]
    del a_glob
    P = _assemble_P(flat, cfg_of_state, flat_of_state, lookup.ravel(), fmap, box, row_len)
    cost = np.repeat(state_cost, na_state)

    action_table = np.array(sorted(label_id, key=label_id.get), dtype=np.int64)
    tau = (tau_idx + 1).astype(np.int32)
    tau.setflags(write=False)
    space = StateSpace(tau, cfg_of_state, list(auto.configs), caps, describe_config, lookup)
    info = dict(meta or {})
    info.update(
        n_configs=nC,
        seconds_reachability=t_reach,
        seconds_build=time.perf_counter() - t0,
    )
    return MDP(n, s_idx, a_idx, cost, P, pair_ptr, action_table, space, name, info)


def _build_aoi_mdp_loop(
    auto: ConfigAutomaton,
    caps: Sequence[int],
    q_tables: Sequence[np.ndarray],
    *,
    describe_config: Callable[[Any], str] = repr,
    name: str = "mdp",
    meta: dict | None = None,
) -> MDP:
    """The original per-(config, action, outcome) loop builder, kept as the reference.

    :func:`build_aoi_mdp` must return the identical MDP (``tests/test_perf_builder.py``);
    ``benchmarks/`` times both in one run. Not used on any hot path.

    Parameters
    ----------
    auto : ConfigAutomaton
    caps : tau_hat_k per process
    q_tables : q_k(1..tau_hat_k) per process; the state cost is sum_k q_k(tau_k).

    States are numbered configuration by configuration (in automaton order), and within a
    configuration in C order of the tau box; pairs are state-major in each configuration's
    action order.
    """
    t0 = time.perf_counter()
    caps = tuple(int(c) for c in caps)
    N = len(caps)
    box = int(np.prod(caps))
    nC = len(auto.configs)
    deltas_per_axis = [{0} for _ in range(N)]
    for outs_c in auto.outcomes:
        for outs in outs_c:
            for _, d, _ in outs:
                for k in range(N):
                    deltas_per_axis[k].add(d[k])
    maps = [_axis_maps(caps[k], deltas_per_axis[k]) for k in range(N)]

    # 1. reachable masks: worklist fixed point
    masks = np.zeros((nC, *caps), dtype=bool)
    work: deque[int] = deque()
    queued = np.zeros(nC, dtype=bool)
    for c in auto.initial:
        masks[c] = True
        if not queued[c]:
            work.append(c)
            queued[c] = True
    while work:
        c = work.popleft()
        queued[c] = False
        src = masks[c]
        cache: dict[tuple[int, ...], np.ndarray] = {}
        for outs in auto.outcomes[c]:
            for nxt, d, _ in outs:
                img = cache.get(d)
                if img is None:
                    img = cache[d] = _image(src, [maps[k][d[k]] for k in range(N)])
                if np.any(img & ~masks[nxt]):
                    masks[nxt] |= img
                    if not queued[nxt]:
                        work.append(nxt)
                        queued[nxt] = True
    t_reach = time.perf_counter() - t0

    # 2. numbering
    flat_masks = masks.reshape(nC, box)
    counts = flat_masks.sum(axis=1)
    offsets = np.r_[0, np.cumsum(counts)].astype(np.int64)
    n = int(offsets[-1])
    lookup = np.full((nC, box), -1, dtype=np.int64)
    cfg_of_state = np.empty(n, dtype=np.int32)
    flat_of_state = np.empty(n, dtype=np.int64)
    for c in range(nC):
        f = np.flatnonzero(flat_masks[c])
        lookup[c, f] = np.arange(offsets[c], offsets[c + 1])
        cfg_of_state[offsets[c] : offsets[c + 1]] = c
        flat_of_state[offsets[c] : offsets[c + 1]] = f
    tau_idx = np.stack(np.unravel_index(flat_of_state, caps), axis=1) if n else np.zeros((0, N), np.int64)
    state_cost = np.zeros(n)
    for k in range(N):
        state_cost += np.asarray(q_tables[k], dtype=float)[tau_idx[:, k]]

    # 3. action table
    label_id: dict[tuple, int] = {}
    for acts in auto.actions:
        for lab in acts:
            label_id.setdefault(lab, len(label_id))
    n_act = np.array([len(a) for a in auto.actions], dtype=np.int64)
    pairs_per_cfg = counts * n_act
    pair_off = np.r_[0, np.cumsum(pairs_per_cfg)].astype(np.int64)
    L = int(pair_off[-1])
    s_idx = np.repeat(np.arange(n, dtype=np.int64), np.repeat(n_act, counts))
    a_idx = np.empty(L, dtype=np.int64)
    rows, cols, vals = [], [], []
    for c in range(nC):
        nc = int(counts[c])
        if nc == 0:
            continue
        na = int(n_act[c])
        local = tau_idx[offsets[c] : offsets[c + 1]]
        base_rows = pair_off[c] + np.arange(nc, dtype=np.int64) * na
        ids = np.array([label_id[lab] for lab in auto.actions[c]], dtype=np.int64)
        a_idx[pair_off[c] : pair_off[c + 1]] = np.tile(ids, nc)
        nxt_cache: dict[tuple[int, ...], np.ndarray] = {}
        for j, outs in enumerate(auto.outcomes[c]):
            r = base_rows + j
            for nxt, d, prob in outs:
                flat = nxt_cache.get(d)
                if flat is None:
                    cols_k = [maps[k][d[k]][local[:, k]] for k in range(N)]
                    flat = nxt_cache[d] = np.ravel_multi_index(tuple(cols_k), caps)
                dest = lookup[nxt, flat]
                rows.append(r)
                cols.append(dest)
                vals.append(np.full(nc, prob))
    row = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    col = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    val = np.concatenate(vals) if vals else np.zeros(0)
    if col.size and col.min() < 0:  # the fixed point guarantees closure; this is a bug guard
        raise ModelError("internal error: a transition leaves the reachable state set")
    P = sp.csr_matrix((val, (row, col)), shape=(L, n))
    P.sum_duplicates()
    cost = np.repeat(state_cost, np.repeat(n_act, counts))

    action_table = np.array(sorted(label_id, key=label_id.get), dtype=np.int64)
    tau = (tau_idx + 1).astype(np.int32)
    tau.setflags(write=False)
    space = StateSpace(tau, cfg_of_state, list(auto.configs), caps, describe_config, lookup)
    info = dict(meta or {})
    info.update(
        n_configs=nC,
        seconds_reachability=t_reach,
        seconds_build=time.perf_counter() - t0,
    )
    mdp = MDP(n, s_idx, a_idx, cost, P, np.r_[0, np.cumsum(np.repeat(n_act, counts))].astype(np.int64),
              action_table, space, name, info)
    return mdp
