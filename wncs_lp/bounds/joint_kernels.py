"""numba kernels of relaxation 2 (:mod:`wncs_lp.bounds.joint`), imported only when numba is available.

Every kernel works on the flat outcome arrays of :class:`~wncs_lp.bounds.joint_chains.JointData`
(pairs p = (C, a) configuration-major; the outcomes of pair p are ``out_ptr[p]:out_ptr[p+1]``)
and on process k's AoI index t = tau - 1 in 0..cap-1. Under outcome o the index moves to

    nt(t) = t + 1 for t < m,   nt(t) = m for t >= m,   m = sat[o, k] = min(cap - 1, d - 1 if d > 0),

so the successors of a row h[c', :] are a shifted contiguous slice and one repeated value: the
loops over t are innermost and contiguous. Kernels ending in ``_par`` run their outer loop
with ``prange`` (called under ``numba.set_num_threads``); the others are serial.

The LP kernels apply the occupation-measure LP of :mod:`wncs_lp.bounds.joint_lp` without storing
it: columns y_k(p, t) (process k's block, (P, cap_k) row-major at ``yoff[k]``) and x(p) (at
``xoff``); rows: balance (k, c, t) (block (|C|, cap_k) at ``boff[k]``), coupling (k, p) at
``coff + k P + p``, normalisation at ``coff + N P``. ``sgn = -1`` gives A, ``sgn = +1`` |A|
(the abs-sums of the scaling).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange


# ---------------------------------------------------------------------------- priced chains
@njit(inline="always")
def _pair_value(p, h, price, cap, out_ptr, out_nxt, out_prob, sat, acc):
    """acc[t] = price[p] + sum_o P(o|p) h(next(o), nt(t)): pair p's value at every AoI index."""
    for t in range(cap):
        acc[t] = price[p]
    for o in range(out_ptr[p], out_ptr[p + 1]):
        pr = out_prob[o]
        cn = out_nxt[o]
        m = sat[o]
        for t in range(m):
            acc[t] += pr * h[cn, t + 1]
        v = pr * h[cn, m]
        for t in range(m, cap):
            acc[t] += v


@njit(inline="always")
def _bellman_config(c, h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, th, pol, acc, best):
    for t in range(cap):
        best[t] = np.inf
    for p in range(act_ptr[c], act_ptr[c + 1]):
        _pair_value(p, h, price, cap, out_ptr, out_nxt, out_prob, sat, acc)
        for t in range(cap):
            if acc[t] < best[t]:
                best[t] = acc[t]
                pol[c, t] = p
    for t in range(cap):
        th[c, t] = best[t] + q[t]


@njit(cache=True)
def bellman_ser(h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, th, pol):
    """th = T h (process k's priced chain), pol = the first minimising pair."""
    acc = np.empty(cap)
    best = np.empty(cap)
    for c in range(act_ptr.size - 1):
        _bellman_config(c, h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, th, pol, acc, best)


@njit(cache=True, parallel=True)
def bellman_par(h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, th, pol):
    n_c = act_ptr.size - 1
    nchunk = min(n_c, 64)
    for i in prange(nchunk):
        acc = np.empty(cap)
        best = np.empty(cap)
        for c in range(i * n_c // nchunk, (i + 1) * n_c // nchunk):
            _bellman_config(c, h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, th, pol, acc, best)


@njit(cache=True)
def push(y, weights, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, y_out):
    """y_out = y P_pi for the randomised policy ``weights[p, t]`` = pi(p | c_p, t)."""
    y_out[:] = 0.0
    f = np.empty(cap)
    for c in range(act_ptr.size - 1):
        for p in range(act_ptr[c], act_ptr[c + 1]):
            tot = 0.0
            for t in range(cap):
                f[t] = y[c, t] * weights[p, t]
                tot += f[t]
            if tot == 0.0:
                continue
            for o in range(out_ptr[p], out_ptr[p + 1]):
                pr = out_prob[o]
                cn = out_nxt[o]
                m = sat[o]
                for t in range(m):
                    y_out[cn, t + 1] += pr * f[t]
                s = 0.0
                for t in range(m, cap):
                    s += f[t]
                y_out[cn, m] += pr * s


@njit(cache=True)
def soft_bellman(h, q, price, cap, act_ptr, out_ptr, out_nxt, out_prob, sat, eta, th, weights):
    """The entropy-smoothed Bellman operator of process k's priced chain: th(c, t) = q(t) - eta log
    sum_p exp(-v_p(t) / eta), v_p = price[p] + E h(next); weights[p, t] = the softmin policy."""
    n_max = 0
    for c in range(act_ptr.size - 1):
        n_max = max(n_max, act_ptr[c + 1] - act_ptr[c])
    acc = np.empty((n_max, cap))
    best = np.empty(cap)
    tot = np.empty(cap)
    for c in range(act_ptr.size - 1):
        p0 = act_ptr[c]
        for t in range(cap):
            best[t] = np.inf
            tot[t] = 0.0
        for p in range(p0, act_ptr[c + 1]):
            a = acc[p - p0]
            _pair_value(p, h, price, cap, out_ptr, out_nxt, out_prob, sat, a)
            for t in range(cap):
                if a[t] < best[t]:
                    best[t] = a[t]
        for p in range(p0, act_ptr[c + 1]):
            a = acc[p - p0]
            for t in range(cap):
                e = np.exp((best[t] - a[t]) / eta)
                weights[p, t] = e
                tot[t] += e
        for p in range(p0, act_ptr[c + 1]):
            for t in range(cap):
                weights[p, t] /= tot[t]
        for t in range(cap):
            th[c, t] = q[t] + best[t] - eta * np.log(tot[t])


# ---------------------------------------------------------------------------- the LP operator
@njit(inline="always")
def _rmatvec_block(k, p, lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff,
                   n_pairs, acc):
    """out[y_k(p, .)] = dc * (A^T (dr * lam)) on process k's column block of pair p."""
    cap = caps[k]
    bb = boff[k]
    rc = bb + pair_c[p] * cap
    ci = coff + k * n_pairs + p
    vc = dr[ci] * lam[ci]
    for t in range(cap):
        acc[t] = dr[rc + t] * lam[rc + t] + vc
    for o in range(out_ptr[p], out_ptr[p + 1]):
        pr = sgn * out_prob[o]
        r0 = bb + out_nxt[o] * cap
        m = sat[o, k]
        for t in range(m):
            acc[t] += pr * dr[r0 + t + 1] * lam[r0 + t + 1]
        v = pr * dr[r0 + m] * lam[r0 + m]
        for t in range(m, cap):
            acc[t] += v
    j0 = yoff[k] + p * cap
    for t in range(cap):
        out[j0 + t] = dc[j0 + t] * acc[t]


@njit(inline="always")
def _rmatvec_pairs(lo, hi, lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff,
                   xoff, acc):
    n_k = caps.size
    n_pairs = pair_c.size
    for p in range(lo, hi):
        for k in range(n_k):
            _rmatvec_block(k, p, lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff,
                           boff, coff, n_pairs, acc)
        s = dr[coff + n_k * n_pairs] * lam[coff + n_k * n_pairs]
        for k in range(n_k):
            ci = coff + k * n_pairs + p
            s += sgn * dr[ci] * lam[ci]
        out[xoff + p] = dc[xoff + p] * s


@njit(cache=True)
def lp_rmatvec_ser(lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, xoff):
    """out = diag(dc) A^T diag(dr) lam (``sgn = +1``: |A| instead of A)."""
    acc = np.empty(caps.max())
    _rmatvec_pairs(0, pair_c.size, lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff,
                   coff, xoff, acc)


@njit(cache=True, parallel=True)
def lp_rmatvec_par(lam, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, xoff):
    n_pairs = pair_c.size
    nchunk = min(n_pairs, 64)
    for i in prange(nchunk):
        acc = np.empty(caps.max())
        _rmatvec_pairs(i * n_pairs // nchunk, (i + 1) * n_pairs // nchunk, lam, dr, dc, out, sgn, pair_c, out_ptr,
                       out_nxt, out_prob, sat, caps, yoff, boff, coff, xoff, acc)


@njit(inline="always")
def _matvec_process(k, z, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, f):
    """Process k's balance and coupling rows of A diag(dc) z (its y columns)."""
    cap = caps[k]
    bb = boff[k]
    n_pairs = pair_c.size
    for p in range(n_pairs):
        j0 = yoff[k] + p * cap
        tot = 0.0
        for t in range(cap):
            f[t] = dc[j0 + t] * z[j0 + t]
            tot += f[t]
        out[coff + k * n_pairs + p] += tot
        rc = bb + pair_c[p] * cap
        for t in range(cap):
            out[rc + t] += f[t]
        for o in range(out_ptr[p], out_ptr[p + 1]):
            pr = sgn * out_prob[o]
            r0 = bb + out_nxt[o] * cap
            m = sat[o, k]
            for t in range(m):
                out[r0 + t + 1] += pr * f[t]
            s = 0.0
            for t in range(m, cap):
                s += f[t]
            out[r0 + m] += pr * s


@njit(inline="always")
def _matvec_rest(z, dr, dc, out, sgn, pair_c, caps, coff, xoff):
    n_k = caps.size
    n_pairs = pair_c.size
    s = 0.0
    for p in range(n_pairs):
        v = dc[xoff + p] * z[xoff + p]
        s += v
        for k in range(n_k):
            out[coff + k * n_pairs + p] += sgn * v
    out[coff + n_k * n_pairs] += s
    for i in range(out.size):
        out[i] *= dr[i]


@njit(cache=True)
def lp_matvec_ser(z, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, xoff):
    """out = diag(dr) A diag(dc) z (``sgn = +1``: |A|)."""
    out[:] = 0.0
    f = np.empty(caps.max())
    for k in range(caps.size):
        _matvec_process(k, z, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, f)
    _matvec_rest(z, dr, dc, out, sgn, pair_c, caps, coff, xoff)


@njit(cache=True, parallel=True)
def lp_matvec_par(z, dr, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, xoff):
    """The same; processes write disjoint rows, one process per task."""
    out[:] = 0.0
    for k in prange(caps.size):
        f = np.empty(caps.max())
        _matvec_process(k, z, dc, out, sgn, pair_c, out_ptr, out_nxt, out_prob, sat, caps, yoff, boff, coff, f)
    _matvec_rest(z, dr, dc, out, sgn, pair_c, caps, coff, xoff)


# ---------------------------------------------------------------------------- PDHG vector passes
@njit(cache=True)
def primal_step(z, c, aty, tau, z_new, z_ext):
    """z_new = max(z - tau (c - A^T lam), 0); z_ext = 2 z_new - z (the extrapolated point)."""
    for j in range(z.size):
        v = z[j] - tau * (c[j] - aty[j])
        if v < 0.0:
            v = 0.0
        z_new[j] = v
        z_ext[j] = 2.0 * v - z[j]


@njit(cache=True)
def dual_step(lam, b, az, sigma, free, lam_new):
    """lam_new = lam + sigma (b - A z_ext) on the free rows (the dropped rows stay 0)."""
    for i in range(lam.size):
        lam_new[i] = (lam[i] + sigma * (b[i] - az[i])) * free[i]


@njit(cache=True)
def halpern_step(x, xt, anchor, a, rho):
    """x <- a ((1 + rho) xt - rho x) + (1 - a) anchor, in place; returns ||xt - x_old||^2."""
    r = 0.0
    for j in range(x.size):
        d = xt[j] - x[j]
        r += d * d
        x[j] = a * ((1.0 + rho) * xt[j] - rho * x[j]) + (1.0 - a) * anchor[j]
    return r
