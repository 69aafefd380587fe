"""numba kernel of the two-step lookahead policy (:mod:`wncs_lp.bounds.lookahead`), imported only
when numba is available.

Pairs p = (configuration c, local action j) are rows ``first[c] + j``, j < ``count[c]``; outcome o of
pair p leads to configuration ``nxt[p, o]`` with probability ``prob[p, o]`` and delivery vector
``deltas[delta[p, o]]``.

The base policy's value of pair p at AoI vector tau (its expectation of h after the pair) is a sum
over blocks b (a process, or a group of processes) of entries of one flat array W:

    value(p, tau) = sum_b [base_row[b, c] >= 0] W(b, base_row[b, c], tau)
                  + sum_{j in corr_ptr[p]:corr_ptr[p+1]} (W(b_j, corr_row[j], tau) - [base_row[b_j, c] >= 0] W(b_j, base_row[b_j, c], tau)),

W(b, r, tau) = ``W[off[b] + r * width[b] + sum_i (tau_{k_i} - 1) * stride[i]]`` over the block's members
k_i = ``members[mptr[b]:mptr[b + 1]]``. Joint tables have no base and one correction per block and
pair; tables read through the private projections have a base (each member's "send nothing") and
at most M corrections a pair (the members the pair sends).

``_par`` runs the loop over states with ``prange``.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(inline="always")
def _block_index(mptr, members, stride, t1, tb):
    for b in range(tb.size):
        i = 0
        for j in range(mptr[b], mptr[b + 1]):
            i += t1[members[j]] * stride[j]
        tb[b] = i


@njit(inline="always")
def _base(c, W, off, width, base_row, tb):
    v = 0.0
    for b in range(tb.size):
        r = base_row[b, c]
        if r >= 0:
            v += W[off[b] + r * width[b] + tb[b]]
    return v


@njit(inline="always")
def _correction(p, c, W, off, width, base_row, corr_ptr, corr_block, corr_row, tb):
    v = 0.0
    for j in range(corr_ptr[p], corr_ptr[p + 1]):
        b = corr_block[j]
        v += W[off[b] + corr_row[j] * width[b] + tb[b]]
        r = base_row[b, c]
        if r >= 0:
            v -= W[off[b] + r * width[b] + tb[b]]
    return v


@njit(inline="always")
def _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
            base_row, corr_ptr, corr_block, corr_row, k_cand, out, t0, t1, tb, gv, cand):
    N = caps.size
    c = cfg[r]
    n = count[c]
    # the greedy value of every action here, and the k_cand best of them (ties: the first)
    for k in range(N):
        t0[k] = tau[r, k] - 1
    _block_index(mptr, members, stride, t0, tb)
    for a in range(n):
        gv[a] = _correction(first[c] + a, c, W, off, width, base_row, corr_ptr, corr_block, corr_row, tb)
    m = n if k_cand <= 0 or k_cand > n else k_cand
    if m < n:
        for i in range(m):
            best, arg = np.inf, -1
            for a in range(n):
                if gv[a] < best:
                    best, arg = gv[a], a
            cand[i] = arg
            gv[arg] = np.inf
        cand[:m].sort()  # ties of the two-step value go to the first action
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
            inner = np.inf
            for a2 in range(count[c2]):
                v = _correction(first[c2] + a2, c2, W, off, width, base_row, corr_ptr, corr_block, corr_row, tb)
                if v < inner:
                    inner = v
            val += pr * (cost + _base(c2, W, off, width, base_row, tb) + inner)
        if val < best:
            best, arg = val, a
    out[r] = arg


@njit(cache=True)
def lookahead_ser(tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
                  base_row, corr_ptr, corr_block, corr_row, k_cand, amax, out):
    N = caps.size
    t0 = np.empty(N, dtype=np.int64)
    t1 = np.empty(N, dtype=np.int64)
    tb = np.empty(off.size, dtype=np.int64)
    gv = np.empty(amax)
    cand = np.empty(amax, dtype=np.int64)
    for r in range(cfg.size):
        _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
                base_row, corr_ptr, corr_block, corr_row, k_cand, out, t0, t1, tb, gv, cand)


@njit(cache=True, parallel=True)
def lookahead_par(tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
                  base_row, corr_ptr, corr_block, corr_row, k_cand, amax, out):
    n = cfg.size
    N = caps.size
    chunk = 4096
    for blk in prange((n + chunk - 1) // chunk):
        t0 = np.empty(N, dtype=np.int64)
        t1 = np.empty(N, dtype=np.int64)
        tb = np.empty(off.size, dtype=np.int64)
        gv = np.empty(amax)
        cand = np.empty(amax, dtype=np.int64)
        for r in range(blk * chunk, min(n, (blk + 1) * chunk)):
            _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members,
                    stride, base_row, corr_ptr, corr_block, corr_row, k_cand, out, t0, t1, tb, gv, cand)
