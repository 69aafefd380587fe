"""numba kernel of the two-step lookahead policy (:mod:`wncs_lp.bounds.lookahead`), imported only
when numba is available.

Pairs p = (configuration c, local action j) are rows ``first[c] + j``, j < ``count[c]``; outcome o of
pair p leads to configuration ``nxt[p, o]`` with probability ``prob[p, o]`` and delivery vector
``deltas[delta[p, o]]``.

The base policy's value of pair (c, j) at AoI vector tau (its expectation of h after the pair) is a
sum over blocks b (a process, or a group of processes) of one flat array's entries, with
t_b = sum_i (tau_{k_i} - 1) * stride[i] over the block's members k_i = members[mptr[b]:mptr[b + 1]]:

* joint tables (``idle`` empty): value(c, j, tau) = sum_b W[off[b] + first[c] * width[b] + t_b * count[c] + j],
  each configuration's entries stored AoI-major, so the values of all its actions at one AoI vector
  are contiguous (the inner minimum reads one short run per block instead of one cache line per
  action);
* tables over the members' private pairs (:mod:`~wncs_lp.bounds.projected`): value(c, j, tau) =
  sum_b W(b, idle[b, c]) + sum_m [touch[p, m] >= 0] (W(touch, tpair[p, m]) - W(touch, idle[touch, c])),
  W(b, row) = W[off[b] + row * width[b] + t_b], p = first[c] + j: each member's "send nothing" and
  a correction for each member the pair sends (at most M). ``lookahead`` runs the loop over states on numba's threads, ``lookahead_serial`` on one.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..policies.rollout import TIE
from ..solvers.threads import twins


@njit(inline="always")
def _block_index(mptr, members, stride, t, tb):
    for b in range(tb.size):
        i = 0
        for j in range(mptr[b], mptr[b + 1]):
            i += t[members[j]] * stride[j]
        tb[b] = i


@njit(inline="always")
def _values(c, first, count, W, off, width, idle, touch, tpair, tb, v):
    """v[:count[c]] = the base policy's value of every action of c at the AoI vector of ``tb``."""
    n = count[c]
    if idle.shape[0] == 0:  # joint tables, AoI-major within each configuration
        for j in range(n):
            v[j] = 0.0
        for b in range(tb.size):
            i = off[b] + first[c] * width[b] + tb[b] * n
            for j in range(n):
                v[j] += W[i + j]
        return
    base = 0.0  # tables over private pairs: every member's "send nothing", corrected where a pair sends
    for b in range(tb.size):
        base += W[off[b] + idle[b, c] * width[b] + tb[b]]
    for j in range(n):
        p = first[c] + j
        x = base
        for m in range(touch.shape[1]):
            b = touch[p, m]
            if b >= 0:
                x += W[off[b] + tpair[p, m] * width[b] + tb[b]] - W[off[b] + idle[b, c] * width[b] + tb[b]]
        v[j] = x


@njit(cache=True)
def _top(c, n, k_cand, first, count, W, off, width, idle, touch, tpair, mptr, members, stride, t, tb, gv, cand):
    """cand[:m] = the k_cand actions of c of least greedy value at AoI indices t (ties: the first), in
    action order; every action when k_cand <= 0 or >= n. Returns m."""
    m = n if k_cand <= 0 or k_cand > n else k_cand
    if m < n:
        _block_index(mptr, members, stride, t, tb)
        _values(c, first, count, W, off, width, idle, touch, tpair, tb, gv)
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
    return m


@njit(inline="always")
def _step(p, o, t, deltas, delta, caps, q, t1):
    """t1 = the AoI indices after outcome o of pair p from AoI indices t; returns the cost there."""
    d = delta[p, o]
    cost = 0.0
    for k in range(caps.size):
        x = min(t[k] + 1, caps[k] - 1)
        dk = deltas[d, k]
        if dk > 0 and dk - 1 < x:
            x = dk - 1
        t1[k] = x
        cost += q[k, x]
    return cost


@njit(cache=True)
def _q2(c, a, t, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride, idle, touch,
        tpair, t1, tb, v2):
    """sum_o P(o | c, a) [cost(t'_o) + min_a' value(c'_o, a', t'_o)]: the two-step value of action a."""
    p = first[c] + a
    val = 0.0
    for o in range(nxt.shape[1]):
        pr = prob[p, o]
        if pr == 0.0:
            continue
        c2 = nxt[p, o]
        cost = _step(p, o, t, deltas, delta, caps, q, t1)
        _block_index(mptr, members, stride, t1, tb)
        _values(c2, first, count, W, off, width, idle, touch, tpair, tb, v2)
        inner = np.inf
        for a2 in range(count[c2]):
            if v2[a2] < inner:
                inner = v2[a2]
        val += pr * (cost + inner)
    return val


@njit(cache=True)
def _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
            idle, touch, tpair, k_cand, depth, k_mid, out, t0, t1, t2, tb, gv, v2, cand, cand2):
    c = cfg[r]
    for k in range(caps.size):
        t0[k] = tau[r, k] - 1
    m = _top(c, count[c], k_cand, first, count, W, off, width, idle, touch, tpair, mptr, members, stride, t0, tb, gv,
             cand)
    best, arg = np.inf, cand[0]
    for i in range(m):
        a = cand[i]
        if depth == 2:
            val = _q2(c, a, t0, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members,
                      stride, idle, touch, tpair, t1, tb, v2)
        else:  # depth 3: sum_o P(o) [cost(t'_o) + min over the k_mid best a' of the two-step value there]
            p = first[c] + a
            val = 0.0
            for o in range(nxt.shape[1]):
                pr = prob[p, o]
                if pr == 0.0:
                    continue
                c2 = nxt[p, o]
                cost = _step(p, o, t0, deltas, delta, caps, q, t2)
                m2 = _top(c2, count[c2], k_mid, first, count, W, off, width, idle, touch, tpair, mptr, members,
                          stride, t2, tb, gv, cand2)
                inner = np.inf
                for i2 in range(m2):
                    v = _q2(c2, cand2[i2], t2, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr,
                            members, stride, idle, touch, tpair, t1, tb, v2)
                    if v < inner:
                        inner = v
                val += pr * (cost + inner)
        if val < best:
            best, arg = val, a
    out[r] = arg


def _lookahead_body(tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members, stride,
                    idle, touch, tpair, k_cand, depth, k_mid, amax, out):
    n = cfg.size
    N = caps.size
    chunk = 4096
    for blk in prange((n + chunk - 1) // chunk):
        t0 = np.empty(N, dtype=np.int64)
        t1 = np.empty(N, dtype=np.int64)
        t2 = np.empty(N, dtype=np.int64)
        tb = np.empty(off.size, dtype=np.int64)
        gv = np.empty(amax)
        v2 = np.empty(amax)
        cand = np.empty(amax, dtype=np.int64)
        cand2 = np.empty(amax, dtype=np.int64)
        for r in range(blk * chunk, min(n, (blk + 1) * chunk)):
            _decide(r, tau, cfg, first, count, nxt, delta, deltas, prob, caps, q, W, off, width, mptr, members,
                    stride, idle, touch, tpair, k_cand, depth, k_mid, out, t0, t1, t2, tb, gv, v2, cand, cand2)


#: The kernel on numba's threads and on one (``prange`` then ``range``).
lookahead, lookahead_serial = twins(_lookahead_body, "lookahead")


@njit(cache=True)
def _rollout_decide(r, tau, cfg, first, count, nxt, delta, deltas, cum, caps, q, W, off, width, mptr, members, stride,
                    idle, touch, tpair, hflat, hoff, hwidth, hcol, U, k_cand, greedy, out, t0, t1, t2, tb, g0, gv, v2, cand):
    """The rollout's action at state r (:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`): the
    greedy choice ``greedy[r]``, then the k_cand - 1 others of least greedy value, each scored by its greedy value
    plus the mean over the rows of U of the greedy policy's Bellman residuals
    cost(t') + min_a' value(c', a', t') - h(c', t') along the path the row's uniforms draw."""
    c = cfg[r]
    for k in range(caps.size):
        t0[k] = tau[r, k] - 1
    n = count[c]
    _block_index(mptr, members, stride, t0, tb)
    _values(c, first, count, W, off, width, idle, touch, tpair, tb, g0)
    m = n if k_cand <= 0 or k_cand > n else k_cand
    for j in range(n):
        gv[j] = g0[j]
    cand[0] = greedy[r]  # the greedy policy's own choice (its tie rule), then by least value
    gv[greedy[r]] = np.inf
    for i in range(1, m):
        best, arg = np.inf, -1
        for a in range(n):
            if gv[a] < best:
                best, arg = gv[a], a
        cand[i] = arg
        gv[arg] = np.inf
    S, H1 = U.shape
    if m == 1 or H1 == 0:
        out[r] = cand[0]
        return
    bestq, choice = np.inf, cand[0]
    for i in range(m):
        a = cand[i]
        tot = 0.0
        for s in range(S):
            for k in range(caps.size):
                t1[k] = t0[k]
            p = first[c] + a
            for st in range(H1):
                u = U[s, st]
                o = 0
                for j in range(cum.shape[1]):
                    if u >= cum[p, j]:
                        o += 1
                cost = _step(p, o, t1, deltas, delta, caps, q, t2)
                c2 = nxt[p, o]
                _block_index(mptr, members, stride, t2, tb)
                _values(c2, first, count, W, off, width, idle, touch, tpair, tb, v2)
                a2, v = 0, np.inf
                for j in range(count[c2]):
                    if v2[j] < v:
                        a2, v = j, v2[j]
                hv = 0.0
                for b in range(tb.size):
                    hv += hflat[hoff[b] + hcol[b, c2] * hwidth[b] + tb[b]]
                tot += cost + v - hv
                p = first[c2] + a2
                for k in range(caps.size):
                    t1[k] = t2[k]
        gv[i] = g0[a] + tot / S
        if gv[i] < bestq:
            bestq = gv[i]
    for i in range(m):  # the first candidate within TIE of the least score (sums in another order tie)
        if gv[i] <= bestq + TIE * abs(bestq):
            choice = cand[i]
            break
    out[r] = choice


def _rollout_body(tau, cfg, first, count, nxt, delta, deltas, cum, caps, q, W, off, width, mptr, members, stride,
                  idle, touch, tpair, hflat, hoff, hwidth, hcol, U, k_cand, greedy, amax, out):
    n = cfg.size
    N = caps.size
    chunk = 256
    for blk in prange((n + chunk - 1) // chunk):
        t0 = np.empty(N, dtype=np.int64)
        t1 = np.empty(N, dtype=np.int64)
        t2 = np.empty(N, dtype=np.int64)
        tb = np.empty(off.size, dtype=np.int64)
        g0 = np.empty(amax)
        gv = np.empty(amax)
        v2 = np.empty(amax)
        cand = np.empty(amax, dtype=np.int64)
        for r in range(blk * chunk, min(n, (blk + 1) * chunk)):
            _rollout_decide(r, tau, cfg, first, count, nxt, delta, deltas, cum, caps, q, W, off, width, mptr, members,
                            stride, idle, touch, tpair, hflat, hoff, hwidth, hcol, U, k_cand, greedy, out, t0, t1,
                            t2, tb, g0, gv, v2, cand)


#: The rollout kernel on numba's threads and on one.
rollout, rollout_serial = twins(_rollout_body, "rollout")
