"""Assembly of an AoI MDP from an explored configuration automaton, vectorised over tau.

1. the reachable state set, grown by a layered breadth-first search over (configuration, tau)
   (:func:`_reachable`);
2. the MDP in state-action-pair form, its transition matrix written in CSR order by index
   arithmetic (:func:`_assemble_P`).

The tests hold the original per-(configuration, action, outcome) loop builder as an independent
reference (``tests/reference/loop_builder.py``); both must give the identical MDP.
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Sequence

import numpy as np
import scipy.sparse as sp

from ..errors import ModelError, SizeLimitError
from ..mdp import MDP
from .automaton import ConfigAutomaton, FlatAutomaton, approx_count
from .statespace import StateSpace

__all__ = ["build_aoi_mdp"]


def _flat_maps(caps: tuple[int, ...], deltas: np.ndarray) -> np.ndarray:
    """(nD, box) int64: the flat tau-box index map of every delivery vector.

    Box index f = ravel(tau - 1) goes to ravel(min(tau + 1, delta_k if > 0, tau_hat) - 1).
    """
    N = len(caps)
    box = math.prod(caps)
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
    # cumulated straight into the index dtype: np.r_[0, np.cumsum(row_len)].astype(...) made three
    # length-L temporaries (~4 bytes per transition) at the build's peak, with data and indices full
    indptr = np.zeros(row_len.size + 1, dtype=idx_dtype)
    np.cumsum(row_len, dtype=idx_dtype, out=indptr[1:])
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
    model: Any = None,
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
    (:func:`_assemble_P`). The result is identical to the reference loop builder of the tests.
    """
    t0 = time.perf_counter()
    caps = tuple(int(c) for c in caps)
    N = len(caps)
    box = math.prod(caps)  # a Python integer: 40^16 does not wrap around
    if box * len(auto.configs) >= 2**62:
        raise SizeLimitError(f"the AoI box has {approx_count(box)} vectors per configuration, beyond what int64 indices "
                             "address (and any memory), even with force: bounds and simulation need no enumeration")
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
    flat_of_state = flat_of_state.astype(np.int64)  # a copy: frees np.nonzero's (2, n) block with cfg_idx
    del cfg_idx
    # the AoI vectors made as int32 (what StateSpace keeps) before P: an int64 (n, N) copy alive
    # across _assemble_P was ~3 bytes per transition of the build's peak (issue 18)
    tau = np.empty((n, N), dtype=np.int32)
    state_cost = np.zeros(n)
    for k in range(N):  # C order of the box: axis k of f is (f // prod(caps[k+1:])) % caps[k]
        tk = (flat_of_state // math.prod(caps[k + 1:])) % caps[k]
        state_cost += np.asarray(q_tables[k], dtype=float)[tk]  # summed in process order, as always
        tau[:, k] = tk + 1
        del tk

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
    row_len = np.diff(flat.out_ptr).astype(np.int32)[a_glob]  # outcomes per pair: small
    del a_glob
    P = _assemble_P(flat, cfg_of_state, flat_of_state, lookup.ravel(), fmap, box, row_len)
    cost = np.repeat(state_cost, na_state)

    action_table = np.array(sorted(label_id, key=label_id.get), dtype=np.int64)
    tau.setflags(write=False)
    space = StateSpace(tau, cfg_of_state, list(auto.configs), caps, describe_config, lookup, model)
    info = dict(meta or {})
    info.update(
        n_configs=nC,
        seconds_reachability=t_reach,
        seconds_build=time.perf_counter() - t0,
    )
    return MDP(n, s_idx, a_idx, cost, P, pair_ptr, action_table, space, name, info)
