"""Eliminate forced states: the semi-Markov reduction used by the LP.

Most states of these models have a single feasible action (a busy server leaves no choice).
Such a *forced* state f has one pair, and in the occupation-measure LP its frequency is fixed
by its predecessors; in the optimality equation its bias is fixed by its successors. Removing
the forced states that lie on acyclic forced paths leaves a semi-Markov decision problem over
the *decision* states D: from a decision pair l the chain runs through forced states until it
next hits D, which takes T_l slots on average (its *sojourn*, not an AoI), costs C_l on average and
lands in D with distribution Q[l, :]:

    Q = P_DD + P_DF Z,   Z = (I - P_FF)^{-1} P_FD,
    T = 1 + P_DF (I - P_FF)^{-1} 1,   C = c_D + P_DF (I - P_FF)^{-1} c_F.

The average-cost LP of that problem is the original one with the forced variables and
balance rows substituted out (Gaussian elimination done once, up front):

    min C^T x  s.t.  (E_D - Q^T) x = 0,  T^T x = 1,  x >= 0,

with the same optimal value g*; the forced frequencies are X_F = (I - P_FF^T)^{-1} P_DF^T x
and the forced biases h_F = (I - P_FF)^{-1} (c_F - g 1 + P_FD h_D) (:meth:`Reduction.lift_x`,
:meth:`Reduction.lift_h`).

Which states are eliminated: forced states in singleton strongly connected components of the
forced subgraph (self-loops allowed, with probability < 1). Forced states on forced cycles
stay decision states (then ``I - P_FF`` restricted to the eliminated set is, after ordering by
*level* -- the longest forced path to D -- block triangular with 1 x 1 blocks, and every
solve above is a sweep over the levels with a sparse product per level; no factorisation).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..mdp import MDP

__all__ = ["Reduction", "reduce_forced"]


@dataclass(frozen=True, eq=False)
class Reduction:
    """The decision-state semi-Markov problem of an MDP (see the module docstring).

    Attributes
    ----------
    mdp : the original MDP
    D : (nD,) sorted decision states (every state that is not eliminated)
    F : (nF,) eliminated forced states, ordered by level (level 0 first)
    level_ptr : (K+1,) the states of level k are ``F[level_ptr[k]:level_ptr[k+1]]``
    dpairs : (LD,) the pairs of the decision states (sorted; state-major as in the MDP)
    Q : (LD, nD) CSR -- where the chain next enters D after pair l
    sojourn : (LD,) expected slots until then (>= 1); ``tau`` is an alias kept for existing callers
    C : (LD,) expected cost until then
    seconds : float
    """

    mdp: MDP
    D: np.ndarray
    F: np.ndarray
    level_ptr: np.ndarray
    dpairs: np.ndarray
    Q: sp.csr_matrix
    sojourn: np.ndarray
    C: np.ndarray
    seconds: float
    # internals (F-order indexing)
    _A_FF: sp.csr_matrix  # (nF, nF) forced -> forced transitions without self-loops
    _A_FD: sp.csr_matrix  # (nF, nD)
    _inv_self: np.ndarray  # 1 / (1 - P(f, f))
    _P_DF: sp.csr_matrix  # (LD, nF)
    _cF: np.ndarray

    @property
    def tau(self) -> np.ndarray:
        """Alias of :attr:`sojourn`."""
        return self.sojourn

    @property
    def n_decision(self) -> int:
        return int(self.D.size)

    @property
    def n_eliminated(self) -> int:
        return int(self.F.size)

    def _levels(self):
        lp = self.level_ptr
        return [(int(lp[k]), int(lp[k + 1])) for k in range(lp.size - 1)]

    def lift_x(self, xD: np.ndarray) -> np.ndarray:
        """Full pair frequencies from the decision-pair frequencies (forced pairs filled in)."""
        mdp = self.mdp
        nF = self.F.size
        inflow = np.asarray(self._P_DF.T @ xD).ravel() if nF else np.zeros(0)
        XF = np.zeros(nF)
        AT = self._A_FF.T.tocsr()  # AT[f', f] = P(f -> f'); predecessors of f' sit at higher levels
        for s, e in reversed(self._levels()):
            if e < nF:
                inflow[s:e] += AT[s:e, e:] @ XF[e:]
            XF[s:e] = inflow[s:e] * self._inv_self[s:e]
        x = np.zeros(mdp.n_pairs)
        x[self.dpairs] = xD
        x[mdp.pair_ptr[self.F]] = XF
        return x

    def lift_h(self, hD: np.ndarray, g: float) -> np.ndarray:
        """Full bias from the decision-state bias: h_F = (I - P_FF)^{-1} (c_F - g + P_FD h_D)."""
        nF = self.F.size
        rhs = self._cF - g + (self._A_FD @ hD if nF else 0.0)
        hF = np.zeros(nF)
        A = self._A_FF
        for s, e in self._levels():
            v = rhs[s:e]
            if s > 0:
                v = v + A[s:e, :s] @ hF[:s]
            hF[s:e] = v * self._inv_self[s:e]
        h = np.zeros(self.mdp.n_states)
        h[self.D] = hD
        h[self.F] = hF
        return h


def reduce_forced(mdp: MDP) -> Reduction:
    """Eliminate the forced states on acyclic forced paths (see the module docstring)."""
    t0 = time.perf_counter()
    n = mdp.n_states
    P = mdp.P.tocsr()
    forced = mdp.n_actions == 1
    first = mdp.pair_ptr[:-1]
    # forced subgraph: f -> f' (both forced, f' != f)
    Ps = P[first]  # (n, n): the single row of each forced state (rows of decision states ignored)
    fidx = np.flatnonzero(forced)
    G = Ps[fidx][:, fidx].tocoo()
    off = G.row != G.col
    Gf = sp.csr_matrix((np.ones(int(off.sum())), (G.row[off], G.col[off])), shape=(fidx.size, fidx.size))
    ncomp, lab = connected_components(Gf, directed=True, connection="strong")
    size = np.bincount(lab, minlength=ncomp)
    self_p = np.asarray(Ps[fidx, fidx]).ravel() if fidx.size else np.zeros(0)
    elim_f = (size[lab] == 1) & (self_p < 1.0 - 1e-12)
    F0 = fidx[elim_f]
    is_F = np.zeros(n, bool)
    is_F[F0] = True
    D = np.flatnonzero(~is_F)
    # levels: longest path (within F) to a decision state; Kahn peeling on out-degrees
    A = Ps[F0][:, F0].tocsr()
    A.setdiag(0.0)
    A.eliminate_zeros()
    nF = F0.size
    outdeg = np.diff(A.indptr).astype(np.int64)
    AT = A.T.tocsr()
    level = np.full(nF, -1, np.int64)
    ready = np.flatnonzero(outdeg == 0)
    k = 0
    while ready.size:
        level[ready] = k
        # predecessors of the ready states lose one unresolved successor each
        preds = AT[ready]
        dec = np.bincount(preds.indices, minlength=nF)
        outdeg -= dec
        ready = np.flatnonzero((outdeg == 0) & (level < 0) & (dec > 0))
        k += 1
    assert (level >= 0).all(), "forced subgraph restricted to singleton SCCs must be acyclic"
    order = np.argsort(level, kind="stable")
    F = F0[order]
    level_ptr = np.searchsorted(level[order], np.arange(k + 1)).astype(np.int64)
    # matrices in F order
    rowsF = P[first[F]]  # (nF, n)
    dpos = np.full(n, -1, np.int64)
    dpos[D] = np.arange(D.size)
    fpos = np.full(n, -1, np.int64)
    fpos[F] = np.arange(nF)
    colsF = fpos >= 0
    colsD = dpos >= 0
    rowsF_coo = rowsF.tocoo()
    c, r, v = rowsF_coo.col, rowsF_coo.row, rowsF_coo.data
    mF = colsF[c]
    selfm = mF & (fpos[c] == r)
    inv_self = 1.0 / (1.0 - np.bincount(r[selfm], weights=v[selfm], minlength=nF))
    keepF = mF & ~selfm
    A_FF = sp.csr_matrix((v[keepF], (r[keepF], fpos[c[keepF]])), shape=(nF, nF))
    A_FD = sp.csr_matrix((v[colsD[c]], (r[colsD[c]], dpos[c[colsD[c]]])), shape=(nF, D.size))
    cF = mdp.cost[first[F]].astype(float)
    # Z_ext = (I - P_FF)^{-1} [P_FD, 1, c_F], level by level (all successors sit at lower levels)
    blocks = []
    w1 = np.zeros(nF)
    wc = np.zeros(nF)
    Zcur = sp.csr_matrix((0, D.size))
    for kk in range(k):
        s, e = int(level_ptr[kk]), int(level_ptr[kk + 1])
        inv = sp.diags(inv_self[s:e])
        if s > 0:
            Ab = A_FF[s:e, :s]
            Zb = inv @ (A_FD[s:e] + Ab @ Zcur)
            w1[s:e] = inv_self[s:e] * (1.0 + Ab @ w1[:s])
            wc[s:e] = inv_self[s:e] * (cF[s:e] + Ab @ wc[:s])
        else:
            Zb = inv @ A_FD[s:e]
            w1[s:e] = inv_self[s:e]
            wc[s:e] = inv_self[s:e] * cF[s:e]
        blocks.append(sp.csr_matrix(Zb))
        Zcur = sp.vstack(blocks, format="csr")
    Z = Zcur if nF else sp.csr_matrix((0, D.size))
    dpairs = np.flatnonzero(~is_F[mdp.s_indices])
    Pd = P[dpairs]
    Pd_coo = Pd.tocoo()
    cD = colsD[Pd_coo.col]
    P_DD = sp.csr_matrix((Pd_coo.data[cD], (Pd_coo.row[cD], dpos[Pd_coo.col[cD]])), shape=(dpairs.size, D.size))
    cf = ~cD
    P_DF = sp.csr_matrix((Pd_coo.data[cf], (Pd_coo.row[cf], fpos[Pd_coo.col[cf]])), shape=(dpairs.size, nF))
    Q = (P_DD + P_DF @ Z).tocsr()
    Q.sum_duplicates()
    Q.sort_indices()
    sojourn = 1.0 + P_DF @ w1
    C = mdp.cost[dpairs] + P_DF @ wc
    return Reduction(mdp, D, F, level_ptr, dpairs, Q, np.asarray(sojourn, float), np.asarray(C, float),
                     time.perf_counter() - t0, A_FF, A_FD, inv_self, P_DF, cF)
