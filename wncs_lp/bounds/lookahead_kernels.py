"""numba kernel of the two-step lookahead policy (:mod:`wncs_lp.bounds.lookahead`), imported only
when numba is available.

Pairs p = (configuration c, local action j) are rows ``first[c] + j``, j < ``count[c]``; outcome o of
pair p leads to configuration ``nxt[p, o]`` with probability ``prob[p, o]`` and delivery vector
``deltas[delta[p, o]]``.

The base policy's value of pair (c, j) at AoI vector tau (its expectation of h after the pair) is a
sum over blocks b (a process, or a group of processes) of one flat array's entries,

    value(c, j, tau) = sum_b W[off[b] + first[c] * width[b] + t_b * count[c] + j],
    t_b = sum_i (tau_{k_i} - 1) * stride[i]  over the block's members k_i = members[mptr[b]:mptr[b + 1]]:

each configuration's entries are stored AoI-major, so the values of all its actions at one AoI
vector are contiguous (the inner minimum reads one short run per block instead of one cache line
per action). ``lookahead`` runs the loop over states on numba's threads, ``lookahead_serial`` on one.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..solvers.threads import twins


@njit(inline="always")
def _block_index(mptr, members, stride, t, tb):
    for b in range(tb.size):
        i = 0
        for j in range(mptr[b], mptr[b + 1]):
            i += t[members[j]] * stride[j]
        tb[b] = i


@njit(inline="always")
def _values(c, first, count, W, off, width, tb, v):
    """v[:count[c]] = the base policy's value of every action of c at the AoI vector of ``tb``."""
    n = count[c]
    for j in range(n):
        v[j] = 0.0
    for b in range(tb.size):
        i = off[b] + first[c] * width[b] + tb[b] * n
        for j in range(n):
            v[j] += W[i + j]


@njit(inline="always")
def _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
            k_cand, out, t0, t1, tb, gv, v2, cand):
    N = caps.size
    c = cfg[r]
    n = count[c]
    for k in range(N):
        t0[k] = tau[r, k] - 1
    m = n if k_cand <= 0 or k_cand > n else k_cand
    if m < n:  # the k_cand actions of least greedy value (ties: the first), in action order
        _block_index(mptr, members, stride, t0, tb)
        _values(c, first, count, W, off, width, tb, gv)
        for i in range(m):
            best, arg = np.inf, -1
            for a in range(n):
                if gv[a] < best:
                    best, arg = gv[a], a
            cand[i] = arg
            gv[arg] = np.inf
        cand[:m].sort()
    else:
        for i in range(n):
            cand[i] = i
    best, arg = np.inf, cand[0]
    for i in range(m):
        a = cand[i]
        p = first[c] + a
        val = 0.0
        for o in range(nxt.shape[1]):
            pr = prob[p, o]
            if pr == 0.0:
                continue
            c2 = nxt[p, o]
            d = delta[p, o]
            cost = 0.0
            for k in range(N):
                t = min(tau[r, k] + 1, caps[k])
                dk = deltas[d, k]
                if dk > 0 and dk < t:
                    t = dk
                t1[k] = t - 1
                cost += q[k, t - 1]
            _block_index(mptr, members, stride, t1, tb)
            _values(c2, first, count, W, off, width, tb, v2)
            inner = np.inf
            for a2 in range(count[c2]):
                if v2[a2] < inner:
                    inner = v2[a2]
            val += pr * (cost + inner)
        if val < best:
            best, arg = val, a
    out[r] = arg


def _lookahead_body(tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
                    k_cand, amax, out):
    n = cfg.size
    N = caps.size
    chunk = 4096
    for blk in prange((n + chunk - 1) // chunk):
        t0 = np.empty(N, dtype=np.int64)
        t1 = np.empty(N, dtype=np.int64)
        tb = np.empty(off.size, dtype=np.int64)
        gv = np.empty(amax)
        v2 = np.empty(amax)
        cand = np.empty(amax, dtype=np.int64)
        for r in range(blk * chunk, min(n, (blk + 1) * chunk)):
            _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members,
                    stride, k_cand, out, t0, t1, tb, gv, v2, cand)


#: The kernel on numba's threads and on one (``prange`` then ``range``).
lookahead, lookahead_serial = twins(_lookahead_body, "lookahead")
