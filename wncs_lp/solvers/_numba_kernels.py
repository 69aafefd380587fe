"""numba kernels of :mod:`wncs_lp.solvers.kernels` (imported only when numba is available).

All three read P as (indptr, indices, codes, table): entry k of pair l is
``table[codes[k]]`` in column ``indices[k]``, for k in ``indptr[l]:indptr[l+1]``; the cost of
pair l of state s is ``cost[s]`` when ``cps`` (cost per state) else ``cost[l]``. Minimisers
are the first pair reaching the minimum (strict ``<``), as :func:`~wncs_lp.solvers.certify.greedy_first`.

``jacobi_sweep`` runs its state chunks on numba's threads (``prange``); ``jacobi_sweep_serial``
is the same body compiled for one thread (:func:`~wncs_lp.solvers.threads.twins`). Which one a solve calls, and how many
threads, :mod:`wncs_lp.solvers.threads` decides (GNU OpenMP does not survive a fork).

The loop bodies are written out in each kernel on purpose: factoring the pair value and the
Jacobi chunk into shared ``@njit`` helpers (inlined or not) was measured 5x slower for the
Gauss-Seidel and serial Jacobi sweeps on numba 0.68 (p123 cap 15: 6.2 -> 35 ms per sweep).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from .threads import twins


def _jacobi_body(indptr, indices, codes, table, cost, cps, pair_ptr, h, h_out, tau, shift, nchunk, los, his):
    n = pair_ptr.size - 1
    step = (n + nchunk - 1) // nchunk
    for c in prange(nchunk):
        lo = np.inf
        hi = -np.inf
        s0 = c * step
        s1 = min(n, s0 + step)
        for s in range(s0, s1):
            best = np.inf
            for l in range(pair_ptr[s], pair_ptr[s + 1]):
                acc = cost[s] if cps else cost[l]
                for k in range(indptr[l], indptr[l + 1]):
                    acc += table[codes[k]] * h[indices[k]]
                if acc < best:
                    best = acc
            d = best - h[s]
            if d < lo:
                lo = d
            if d > hi:
                hi = d
            h_out[s] = h[s] + tau * (d - shift)
        los[c] = lo
        his[c] = hi


#: One Jacobi sweep: d = T h - h, h_out = h + tau (d - shift), per chunk of states its min / max of d.
jacobi_sweep, jacobi_sweep_serial = twins(_jacobi_body, "jacobi_sweep", boundscheck=False)


@njit(cache=True, nogil=True, boundscheck=False)
def gs_sweep(indptr, indices, codes, table, cost, cps, pair_ptr, h, tau, shift, pol):
    n = pair_ptr.size - 1
    for s in range(n):
        best = np.inf
        arg = pair_ptr[s]
        for l in range(pair_ptr[s], pair_ptr[s + 1]):
            acc = cost[s] if cps else cost[l]
            for k in range(indptr[l], indptr[l + 1]):
                acc += table[codes[k]] * h[indices[k]]
            if acc < best:
                best = acc
                arg = l
        pol[s] = arg
        h[s] = h[s] + tau * (best - h[s] - shift)


@njit(cache=True, nogil=True, boundscheck=False)
def eval_sweep(indptr, indices, codes, table, cost, cps, pair_ptr, h, tau, shift, pol):
    n = pair_ptr.size - 1
    for s in range(n):
        l = pol[s]
        acc = cost[s] if cps else cost[l]
        for k in range(indptr[l], indptr[l + 1]):
            acc += table[codes[k]] * h[indices[k]]
        h[s] = h[s] + tau * (acc - h[s] - shift)
