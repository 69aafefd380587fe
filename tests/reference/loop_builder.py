"""The original per-(configuration, action, outcome) loop builder: an independent reference.

:func:`wncs_lp.models.assemble.build_aoi_mdp` must return the identical MDP
(``tests/models/test_assemble.py``); ``benchmarks/`` times both in one run.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable, Sequence

import numpy as np
import scipy.sparse as sp

from wncs_lp.errors import ModelError
from wncs_lp.mdp import MDP
from wncs_lp.models.automaton import ConfigAutomaton
from wncs_lp.models.statespace import StateSpace

__all__ = ["build_aoi_mdp_loop"]


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



def build_aoi_mdp_loop(
    auto: ConfigAutomaton,
    caps: Sequence[int],
    q_tables: Sequence[np.ndarray],
    *,
    describe_config: Callable[[Any], str] = repr,
    name: str = "mdp",
    meta: dict | None = None,
) -> MDP:
    """The original per-(config, action, outcome) loop builder, kept as the reference.

    :func:`build_aoi_mdp` must return the identical MDP (``tests/models/test_assemble.py``);
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
