r"""A proximal bundle method for the Lagrangian of relaxation 2 (a Dantzig-Wolfe master).

The Lagrangian of relaxation 2 in its zero-sum form is

.. math::

    L(\mu) = \sum_k f_k(\mu_k), \qquad \sum_k \mu_k(p) = 0 \text{ for every pair } p,

f_k(mu_k) the optimal gain of process k's chain priced by mu_k (concave, piecewise linear).
Every policy pi of process k's chain with stationary law y and (C, a) marginal x gives the cut
f_k(mu_k) <= a + <x, mu_k>, a = <y, q_k>, for *every* mu_k: the model
m(mu) = sum_k min_i (a_i + <x_i, mu_k>) over the cuts of each process lies above L.

A proximal step maximises m(mu) - ||mu - centre||^2 / (2t) over the zero-sum prices. Its dual
is a small quadratic programme over convex weights alpha of each process's cuts (Clarabel):

.. math::

    \min_\alpha \sum_i \alpha_i (a_i + \langle x_i, \mathrm{centre}_{k_i}\rangle)
    + \tfrac t2 \| \Pi Z(\alpha) \|^2, \qquad Z_k = \sum_{i \in k} \alpha_i x_i,

Pi removing the mean over processes (the projection on zero-sum prices), and the step is
mu = centre + t Pi Z(alpha). A step is *serious* (the centre moves) when L rose by at least a
tenth of what the model predicted; t doubles after a step that earned half its prediction and
halves after a null step.

Stopping test (:meth:`PriceBundle.converged`): the master's mixtures of each process's cuts are
occupation measures of process k's chain; when their (C, a) marginals Z_k agree (total variation
of Z_k - mean Z below ``tol``) and the aggregate linearisation error at the centre is below
``tol |L|``, the mixture is (nearly) a feasible point of the relaxation costing (nearly) L(centre):
the relaxation is solved to ``tol``. It is a stopping rule, not a certificate; the bound itself is
certified separately.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["PriceBundle"]


class PriceBundle:
    """Proximal bundle over zero-sum prices mu (N, |C x A|) with per-process cuts.

    Parameters
    ----------
    centre : (N, P) array
        The starting prices (projected on the zero-sum subspace).
    value : float
        L(centre).
    t : float
        The starting prox parameter.
    max_cuts : int
        Cuts kept per process (the inactive oldest ones go first).
    """

    def __init__(self, centre: np.ndarray, value: float, t: float, max_cuts: int = 60):
        self.n = centre.shape[0]
        self.centre = centre - centre.mean(axis=0)
        self.value = float(value)
        self.t = float(t)
        self.max_cuts = int(max_cuts)
        self.k: list[int] = []
        self.a: list[float] = []
        self.x: list[np.ndarray] = []
        self.age: list[int] = []
        self.predicted = np.inf
        self.disagreement = np.inf
        self.linearisation_error = np.inf
        self.serious_steps = 0
        self.null_steps = 0

    @property
    def size(self) -> int:
        return len(self.a)

    def add_cut(self, k: int, a: float, x: np.ndarray) -> None:
        """The cut f_k(mu_k) <= a + <x, mu_k>."""
        self.k.append(int(k))
        self.a.append(float(a))
        self.x.append(np.asarray(x, dtype=float))
        self.age.append(0)
        self._prune(k)

    def _prune(self, k: int) -> None:
        mine = [i for i, kk in enumerate(self.k) if kk == k]
        if len(mine) <= self.max_cuts:
            return
        drop = max(mine, key=lambda i: (self.age[i], -i))
        for lst in (self.k, self.a, self.x, self.age):
            del lst[drop]

    def model(self, mu: np.ndarray) -> float:
        """m(mu) = sum_k min over process k's cuts."""
        best = np.full(self.n, np.inf)
        for k, a, x in zip(self.k, self.a, self.x):
            best[k] = min(best[k], a + float(x @ mu[k]))
        return float(best.sum())

    def candidate(self) -> np.ndarray:
        """The proximal point of the model from the centre (prices summing to zero over processes)."""
        X = np.array(self.x)
        ks = np.array(self.k)
        same = (ks[:, None] == ks[None, :]).astype(float)
        G = (X @ X.T) * (same - 1.0 / self.n)
        lin = np.array(self.a) + np.einsum("ip,ip->i", X, self.centre[ks])
        alpha = _simplex_qp(self.t * G, lin, ks, self.n)
        for i, al in enumerate(alpha):
            self.age[i] = 0 if al > 1e-9 else self.age[i] + 1
        Z = np.zeros_like(self.centre)
        np.add.at(Z, ks, alpha[:, None] * X)
        PZ = Z - Z.mean(axis=0)
        mu = self.centre + self.t * PZ
        self.predicted = self.model(mu) - self.value
        self.disagreement = float(np.abs(PZ).sum()) / self.n
        self.linearisation_error = float(alpha @ lin) - self.value
        return mu

    def converged(self, tol: float) -> bool:
        """The stopping test of the module docstring, after :meth:`candidate`."""
        return self.disagreement <= tol and self.linearisation_error <= tol * max(abs(self.value), 1.0)

    def report(self, mu: np.ndarray, value: float) -> bool:
        """L(mu) = value at the last candidate: move the centre or not, adapt t. True when serious."""
        gain = float(value) - self.value
        pred = max(self.predicted, 1e-300)
        if gain >= 0.1 * pred:
            if gain >= 0.5 * pred:
                self.t *= 2.0
            self.centre = mu - mu.mean(axis=0)
            self.value = float(value)
            self.serious_steps += 1
            return True
        self.t *= 0.5
        self.null_steps += 1
        return False


def _simplex_qp(Q: np.ndarray, lin: np.ndarray, blocks: np.ndarray, n_blocks: int) -> np.ndarray:
    """argmin 1/2 a^T Q a + lin^T a over a >= 0 with sum_{i in block k} a_i = 1 (Clarabel)."""
    import clarabel

    m = lin.size
    scale = max(float(np.abs(Q).max()), float(np.abs(lin).max()), 1e-300)
    P = sp.csc_matrix(np.triu(Q / scale + 1e-12 * np.eye(m)))
    A_eq = sp.csr_matrix((np.ones(m), (blocks, np.arange(m))), shape=(n_blocks, m))
    A = sp.vstack([A_eq, -sp.identity(m)]).tocsc()
    b = np.r_[np.ones(n_blocks), np.zeros(m)]
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    solver = clarabel.DefaultSolver(P, lin / scale, A, b, [clarabel.ZeroConeT(n_blocks), clarabel.NonnegativeConeT(m)],
                                    settings)
    alpha = np.maximum(np.nan_to_num(np.asarray(solver.solve().x, dtype=float)), 0.0)
    sums = np.bincount(blocks, weights=alpha, minlength=n_blocks)
    empty = sums[blocks] <= 0  # a block the solver left at zero: spread it evenly
    alpha[empty] = 1.0
    sums = np.bincount(blocks, weights=alpha, minlength=n_blocks)
    return alpha / sums[blocks]
