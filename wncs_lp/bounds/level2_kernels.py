"""numba kernel of the level-2 relaxation's certificate (:mod:`wncs_lp.bounds.level2`), imported only
when numba is available.

A pair's table lives on (C, T), T = t1 * c2 + t2 the flat index of its two members' (lumped) AoI
indices; under outcome o index t of a member moves to ``min(t + 1, s[o])``, s the member's column
of :attr:`~wncs_lp.bounds.joint_chains.JointData.sat` clipped to its lumped range. A process alone
is a pair whose second member has c2 = 1 and never moves (``s2`` all 0). Pairs p = (C, a) are
configuration-major; the outcomes of pair p are ``out_ptr[p]:out_ptr[p+1]``.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .pairs_kernels import pair_expect  # the pair chains' expectation, the same loops


@njit(cache=True)
def residuals(h, lam1, lam2, c1, c2, act_ptr, out_ptr, out_nxt, out_prob, s1, s2, u):
    """u[p] = max_T [h(C_p, T) - sum_o P(o|p) h(C'_o, T'_o) - lam1[p, t1] - lam2[p, t2]].

    ``h`` (|C|, c1 * c2), ``lam1`` (|C x A|, c1), ``lam2`` (|C x A|, c2), ``u`` (|C x A|,) written.
    For a fixed first index the successors of the second are a shifted contiguous slice and one
    repeated value, so the inner loops are branch-free.
    """
    n_t = c1 * c2
    acc = np.empty(n_t)
    for c in range(act_ptr.size - 1):
        for p in range(act_ptr[c], act_ptr[c + 1]):
            for t in range(n_t):
                acc[t] = 0.0
            pair_expect(p, h, c1, c2, out_ptr, out_nxt, out_prob, s1, s2, acc)
            m = -np.inf
            for t1 in range(c1):
                a = lam1[p, t1]
                for t2 in range(c2):
                    t = t1 * c2 + t2
                    r = h[c, t] - acc[t] - a - lam2[p, t2]
                    if r > m:
                        m = r
            u[p] = m
