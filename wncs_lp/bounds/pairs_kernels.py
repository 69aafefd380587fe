"""numba kernels of relaxation 4 (:mod:`wncs_lp.bounds.pairs`), imported only when numba is available.

A group's chain lives on (C, t1, t2): the joint configuration and the AoI indices t = tau - 1 of
its two members, flat as ``T = t1 * c2 + t2`` (a group of one process is a pair whose second
member has cap c2 = 1 and never moves: ``s2`` all 0). Under outcome o the indices move to
``min(t + 1, s[o])``, s the member's column of :attr:`JointData.sat`, so for a fixed first index
the successors of the second are a shifted contiguous slice and one repeated value (as in
:mod:`~wncs_lp.bounds.joint_kernels`). Pairs p = (C, a) are configuration-major; the outcomes of
pair p are ``out_ptr[p]:out_ptr[p+1]``.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..solvers.threads import twins


@njit(inline="always")
def pair_expect(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc):
    """acc[T] += sum_o P(o|p) h[C'_o, T'_o(T)]."""
    for o in range(out_ptr[p], out_ptr[p + 1]):
        pr = out_prob[o]
        cn = out_nxt[o]
        m1 = s1[o]
        m2 = s2[o]
        for t1 in range(c1):
            n1 = t1 + 1 if t1 < m1 else m1
            base = n1 * c2
            row = t1 * c2
            for t2 in range(m2):
                acc[row + t2] += pr * h[cn, base + t2 + 1]
            v = pr * h[cn, base + m2]
            for t2 in range(m2, c2):
                acc[row + t2] += v


@njit(inline="always")
def _expect_upper(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc):
    """:func:`pair_expect` only where t2 >= t1 (a pair's fixed configuration; the rest mirrored). A copy
    rather than a flag of :func:`pair_expect`, so that the plain chains' innermost loops stay as they were."""
    for o in range(out_ptr[p], out_ptr[p + 1]):
        pr = out_prob[o]
        cn = out_nxt[o]
        m1 = s1[o]
        m2 = s2[o]
        for t1 in range(c1):
            n1 = t1 + 1 if t1 < m1 else m1
            base = n1 * c2
            row = t1 * c2
            for t2 in range(t1, m2):
                acc[row + t2] += pr * h[cn, base + t2 + 1]
            v = pr * h[cn, base + m2]
            for t2 in range(max(t1, m2), c2):
                acc[row + t2] += v


@njit(inline="always")
def _bellman_config(c, h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol, acc, best,
                    upper=False):
    """Row c of T h and its policy (``upper``: right only where t2 >= t1, the rest mirrored after)."""
    n_t = c1 * c2
    for t in range(n_t):
        best[t] = np.inf
    for p in range(act_ptr[c], act_ptr[c + 1]):
        for t in range(n_t):
            acc[t] = price[p]
        if upper:
            _expect_upper(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc)
        else:
            pair_expect(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc)
        for t in range(n_t):
            if acc[t] < best[t]:
                best[t] = acc[t]
                pol[c, t] = p
    for t in range(n_t):
        th[c, t] = best[t] + q[t]


@njit(cache=True)
def bellman_ser(h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol):
    """th = T h of the group's priced chain (pair cost q(T) + price[p]); pol = the first minimising pair."""
    acc = np.empty(c1 * c2)
    best = np.empty(c1 * c2)
    for c in range(act_ptr.size - 1):
        _bellman_config(c, h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol, acc, best)


@njit(cache=True, parallel=True)
def bellman_par(h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol):
    """:func:`bellman_ser` with the configurations split over numba's threads."""
    n_c = act_ptr.size - 1
    for c in prange(n_c):
        acc = np.empty(c1 * c2)
        best = np.empty(c1 * c2)
        _bellman_config(c, h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol, acc, best)


@njit(cache=True)
def residuals(h, q, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, u):
    """u[p] = max_T [h(C_p, T) - q(T) - sum_o P(o|p) h(C'_o, T'_o)]: the certificate's per-pair maximum."""
    n_t = c1 * c2
    acc = np.empty(n_t)
    for c in range(act_ptr.size - 1):
        for p in range(act_ptr[c], act_ptr[c + 1]):
            for t in range(n_t):
                acc[t] = 0.0
            pair_expect(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc)
            m = -np.inf
            for t in range(n_t):
                r = h[c, t] - q[t] - acc[t]
                if r > m:
                    m = r
            u[p] = m


@njit(cache=True, nogil=True)  # nogil: the groups' cuts run side by side on Python threads
def push(y, pol, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, y_out):
    """y_out = y P_pi for the deterministic policy ``pol[c, T]`` (a pair of configuration c)."""
    n_c, n_t = y.shape
    for c in range(n_c):
        for t in range(n_t):
            y_out[c, t] = 0.0
    for c in range(n_c):
        for t in range(n_t):
            w = y[c, t]
            if w == 0.0:
                continue
            t1 = t // c2
            _scatter(w, pol[c, t], t1, t - t1 * c2, c2, out_ptr, out_nxt, out_prob, s1, s2, y_out)


@njit(inline="always")
def _scatter(w, p, t1, t2, c2, out_ptr, out_nxt, out_prob, s1, s2, y_out):
    """Mass w at ages (t1, t2) pushed along the outcomes of pair p (:func:`push`, :func:`push_sym`)."""
    for o in range(out_ptr[p], out_ptr[p + 1]):
        m1 = s1[o]
        m2 = s2[o]
        n1 = t1 + 1 if t1 < m1 else m1
        n2 = t2 + 1 if t2 < m2 else m2
        y_out[out_nxt[o], n1 * c2 + n2] += w * out_prob[o]


# ---------------------------------------------------------------------------- a pair lumped by its own swap
# A same-type pair's chain is symmetric under sigma: (t1, t2, C) -> (t2, t1, swap[C]), pairs p ->
# pswap[p] (pairs.PairSwap). ``kind[c]``: 0 configuration c computed (its image swap[c] > c is
# not), 1 swap[c] == c, 2 the image of a smaller one (not computed); ``todo`` the configurations
# of kind 0 or 1; a fixed configuration's expectations only where t2 >= t1; each computed row then
# written onto the rest of its orbit (exactly sigma-invariant tables, and a policy equivariant off
# the diagonal).
def _bellman_sym_body(h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, kind, swap, pswap, todo,
                      th, pol):
    """:func:`bellman_ser` on the configurations ``todo`` (kind 0 or 1), each then mirrored onto
    the rest of its orbit (:func:`_mirror_config`): one parallel region a sweep."""
    for j in prange(todo.size):
        c = todo[j]
        acc = np.empty(c1 * c2)
        best = np.empty(c1 * c2)
        _bellman_config(c, h, q, price, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, th, pol, acc, best,
                        kind[c] == 1)
        _mirror_config(c, th, pol, c1, c2, kind, swap, pswap)


@njit(inline="always")
def _mirror_config(c, th, pol, c1, c2, kind, swap, pswap):
    """The states of configuration c's orbits not computed, from c's row: its image row swap[c]
    (kind 0) or its own states below the diagonal (kind 1): th[sigma s] = th[s], pol[sigma s] =
    pswap[pol[s]]. Rows written by one iteration only (sigma is an involution)."""
    d = swap[c]
    if kind[c] == 0:
        for t1 in range(c1):
            for t2 in range(c2):
                th[d, t2 * c2 + t1] = th[c, t1 * c2 + t2]
                pol[d, t2 * c2 + t1] = pswap[pol[c, t1 * c2 + t2]]
    else:
        for t1 in range(c1):
            for t2 in range(t1):
                th[c, t1 * c2 + t2] = th[c, t2 * c2 + t1]
                pol[c, t1 * c2 + t2] = pswap[pol[c, t2 * c2 + t1]]


bellman_sym_par, bellman_sym_ser = twins(_bellman_sym_body, "bellman_sym")


@njit(cache=True, nogil=True)
def push_sym(y, pol, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, kind, swap, y_out):
    """y_out = y P_pi for a sigma-invariant law y and policy: pushed from one state of each orbit
    (a fixed state with half its mass), then y_out(s) = z(s) + z(sigma s)."""
    n_c, n_t = y.shape
    for c in range(n_c):
        for t in range(n_t):
            y_out[c, t] = 0.0
    for c in range(n_c):
        if kind[c] == 2:
            continue
        for t1 in range(c1):
            for t2 in range(t1 if kind[c] == 1 else 0, c2):  # a fixed configuration: t2 >= t1
                w = y[c, t1 * c2 + t2]
                if kind[c] == 1 and t2 == t1:
                    w *= 0.5
                if w == 0.0:
                    continue
                _scatter(w, pol[c, t1 * c2 + t2], t1, t2, c2, out_ptr, out_nxt, out_prob, s1, s2, y_out)
    for c in range(n_c):  # z + sigma z, each orbit once
        if kind[c] == 2:
            continue
        d = swap[c]
        for t1 in range(c1):
            if kind[c] == 1:
                y_out[c, t1 * c2 + t1] *= 2.0
            for t2 in range(t1 + 1 if kind[c] == 1 else 0, c2):
                v = y_out[c, t1 * c2 + t2] + y_out[d, t2 * c2 + t1]
                y_out[c, t1 * c2 + t2] = v
                y_out[d, t2 * c2 + t1] = v


# ---------------------------------------------------------------------------- the relative value iteration's step
@njit(cache=True, nogil=True)
def bracket(th, h):
    """(min, max) of th - h (joint_chains.damped_rvi's bracket, without a temporary)."""
    lo = np.inf
    hi = -np.inf
    n_c, n_t = h.shape
    for c in range(n_c):
        for t in range(n_t):
            d = th[c, t] - h[c, t]
            lo = min(lo, d)
            hi = max(hi, d)
    return lo, hi


@njit(cache=True, nogil=True)
def relax_update(h, th, relax):
    """h <- h + relax (th - h), then minus its new h[0, 0]: the numbers of numpy's
    ``h += relax * (th - h); h -= h[0, 0]`` (the same operations, each rounded alike)."""
    n_c, n_t = h.shape
    h00 = h[0, 0] + relax * (th[0, 0] - h[0, 0])
    for c in range(n_c):
        for t in range(n_t):
            h[c, t] = (h[c, t] + relax * (th[c, t] - h[c, t])) - h00


@njit(cache=True, nogil=True)
def lazy_mix(y, yn, lazy, z):
    """z = |yn - y| and y <- lazy y + (1 - lazy) yn in one pass (joint_chains.lazy_power's step,
    the numbers numpy's expressions give)."""
    n_c, n_t = y.shape
    for c in range(n_c):
        for t in range(n_t):
            z[c, t] = abs(yn[c, t] - y[c, t])
            y[c, t] = lazy * y[c, t] + (1.0 - lazy) * yn[c, t]
