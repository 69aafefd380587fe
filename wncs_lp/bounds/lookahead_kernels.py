"""numba kernel of the two-step lookahead policy (:mod:`wncs_lp.bounds.lookahead`), imported only
when numba is available.

The base policy's value of action a in configuration c at AoI vector tau is a sum over blocks b
(a process, or a group of processes) of one flat array's entries:
``W[woff[b] + row[c * A + a] * width[b] + sum_i (tau_{k_i} - 1) * stride[i]]`` over the block's
members k_i = ``members[mptr[b]:mptr[b + 1]]`` (strides in the same slots). ``_par`` runs the loop
over states with ``prange``.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(inline="always")
def _decide(r, tau, cfg, nact, nxt, delta, prob, caps, q, W, woff, width, row, mptr, members, stride, out, t1):
    N = caps.size
    A = nxt.shape[1]
    c = cfg[r]
    best, arg = np.inf, 0
    for a in range(nact[c]):
        val = 0.0
        for o in range(nxt.shape[2]):
            p = prob[c, a, o]
            if p == 0.0:
                continue
            c2 = nxt[c, a, o]
            cost = 0.0
            for k in range(N):
                t = min(tau[r, k] + 1, caps[k])
                d = delta[c, a, o, k]
                if d > 0 and d < t:
                    t = d
                t1[k] = t - 1
                cost += q[k, t - 1]
            inner = np.inf
            for a2 in range(nact[c2]):
                v = 0.0
                rw = row[c2 * A + a2]
                for b in range(woff.size):
                    i = woff[b] + rw * width[b]
                    for j in range(mptr[b], mptr[b + 1]):
                        i += t1[members[j]] * stride[j]
                    v += W[i]
                if v < inner:
                    inner = v
            val += p * (cost + inner)
        if val < best:
            best, arg = val, a
    out[r] = arg


@njit(cache=True)
def lookahead_ser(tau, cfg, nact, nxt, delta, prob, caps, q, W, woff, width, row, mptr, members, stride, out):
    t1 = np.empty(caps.size, dtype=np.int64)
    for r in range(cfg.size):
        _decide(r, tau, cfg, nact, nxt, delta, prob, caps, q, W, woff, width, row, mptr, members, stride, out, t1)


@njit(cache=True, parallel=True)
def lookahead_par(tau, cfg, nact, nxt, delta, prob, caps, q, W, woff, width, row, mptr, members, stride, out):
    n = cfg.size
    chunk = 4096
    for b in prange((n + chunk - 1) // chunk):
        t1 = np.empty(caps.size, dtype=np.int64)
        for r in range(b * chunk, min(n, (b + 1) * chunk)):
            _decide(r, tau, cfg, nact, nxt, delta, prob, caps, q, W, woff, width, row, mptr, members, stride, out,
                    t1)
