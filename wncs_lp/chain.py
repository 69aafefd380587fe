r"""The Markov chain a stationary policy induces on an MDP: the one place for its analysis.

Like QuantEcon's ``MarkovChain``, a :class:`PolicyChain` is validated once and computes what is
asked of it lazily, caching it: the induced transition matrix and cost, the recurrent classes
(closed strongly connected components: an exact graph criterion), the recurrent-state mask, the
stationary law. Every module that needs "recurrent" or "stationary" gets it from here, under one
rule: a state is *recurrent* when it lies in a closed communicating class of ``P_pi`` (exactly
the states of positive stationary probability).

The stationary law of one closed class R solves :math:`\pi_R (I - P_{RR}) = 0`,
:math:`\sum \pi_R = 1` (:func:`class_stationary`): by power iteration on the lazy chain
:math:`(P + I)/2` for classes of :data:`POWER_MIN_STATES` states or more (an LU of a large class
fills in badly), else -- or when the power iteration misses :data:`POWER_TOL` -- by a sparse LU
with one row replaced by ones, minimum-degree ordering on :math:`A^T + A` and one step of
iterative refinement; the residual :math:`\|\pi_R P_{RR} - \pi_R\|_\infty` is checked against
:data:`STATIONARY_TOL`. The law of a multichain policy is a mixture of its classes' laws with
weights the caller chooses (:func:`stationary_law`): equal, or the absorption probabilities from
a start state.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from .errors import PolicyError
from .mdp import MDP

__all__ = [
    "PolicyChain",
    "policy_matrices",
    "recurrent_classes",
    "class_stationary",
    "stationary_law",
    "STATIONARY_TOL",
]

#: Residual above which a stationary distribution is rejected.
STATIONARY_TOL = 1e-9
#: Classes at least this large are first tried by power iteration (LU fill-in grows fast).
POWER_MIN_STATES = 20_000
#: Power iteration: stop when ||pi P - pi||_1 is below this, give up after POWER_MAX_ITER sweeps.
POWER_TOL = 1e-14
POWER_MAX_ITER = 20_000
#: Tolerance on the per-state sums of a randomised policy.
PROB_SUM_TOL = 1e-9


def policy_matrices(mdp: MDP, policy: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """The chain ``(P_pi, c_pi)`` induced by a deterministic or randomised policy.

    Parameters
    ----------
    mdp : MDP
    policy : array
        * integer dtype, shape (n,): ``policy[s]`` is the chosen pair index of state s
          (``mdp.s_indices[policy[s]] == s`` is required);
        * floating dtype, shape (L,): ``policy[l]`` is the probability of pair l in its
          state; nonnegative, summing to 1 (within 1e-9) over the pairs of each state.

    Returns
    -------
    P_pi : (n, n) CSR matrix
        ``P_pi[s, :] = sum_l policy[l] P[l, :]`` over the pairs of s.
    c_pi : (n,) array
        ``c_pi[s] = sum_l policy[l] c_l``.

    Raises
    ------
    PolicyError
        Wrong shape or dtype, a pair of the wrong state, negative probabilities, bad sums.
    """
    pol = np.asarray(policy)
    n, L = mdp.n_states, mdp.n_pairs
    if np.issubdtype(pol.dtype, np.integer) and not np.issubdtype(pol.dtype, np.bool_):
        if pol.shape != (n,):
            raise PolicyError(f"a deterministic policy must have shape ({n},) (one pair index per state), got {pol.shape}")
        pol = pol.astype(np.int64)
        bad = (pol < 0) | (pol >= L)
        if bad.any():
            s = int(np.flatnonzero(bad)[0])
            raise PolicyError(f"policy[{s}] = {int(pol[s])} is not a pair index in 0..{L - 1}")
        wrong = mdp.s_indices[pol] != np.arange(n)
        if wrong.any():
            s = int(np.flatnonzero(wrong)[0])
            raise PolicyError(
                f"policy[{s}] = pair {int(pol[s])}, which belongs to state {int(mdp.s_indices[pol[s]])}, not state {s}"
            )
        return mdp.P[pol].tocsr(), np.asarray(mdp.cost[pol], dtype=float)
    if np.issubdtype(pol.dtype, np.floating):
        if pol.shape != (L,):
            raise PolicyError(f"a randomised policy must have shape ({L},) (one probability per pair), got {pol.shape}")
        if not np.all(np.isfinite(pol)) or pol.min() < 0:
            l = int(np.flatnonzero(~np.isfinite(pol) | (pol < 0))[0])
            raise PolicyError(f"randomised policy has probability {pol[l]} on pair {l}; expected >= 0")
        sums = np.add.reduceat(pol, mdp.pair_ptr[:-1])
        off = np.abs(sums - 1.0) > PROB_SUM_TOL
        if off.any():
            s = int(np.flatnonzero(off)[0])
            raise PolicyError(f"randomised policy probabilities of state {s} sum to {sums[s]:.12g}, expected 1")
        D = sp.csr_matrix((pol, (mdp.s_indices, np.arange(L))), shape=(n, L))
        return (D @ mdp.P).tocsr(), np.asarray(D @ mdp.cost, dtype=float)
    raise PolicyError(
        f"policy must be an integer array of pair indices (shape ({n},)) or a float array of pair "
        f"probabilities (shape ({L},)); got dtype {pol.dtype}"
    )


def recurrent_classes(P_pi: sp.spmatrix) -> list[np.ndarray]:
    """The closed communicating (recurrent) classes of a finite chain.

    The states are the vertices of the directed graph with an edge i -> j whenever
    ``P_pi[i, j] > 0``. Its strongly connected components are the communicating classes,
    and a class is recurrent iff it is closed (no edge leaves it).

    Returns
    -------
    list of sorted int arrays, one per recurrent class, ordered by their smallest state.
    """
    G = sp.csr_matrix(P_pi)
    G.eliminate_zeros()
    G.data = (G.data > 0).astype(np.int8)
    G.eliminate_zeros()
    n = G.shape[0]
    ncomp, labels = connected_components(G, directed=True, connection="strong")
    coo = G.tocoo()
    leaving = labels[coo.row] != labels[coo.col]
    closed = np.ones(ncomp, bool)
    closed[labels[coo.row[leaving]]] = False
    classes = [np.flatnonzero(labels == k) for k in np.flatnonzero(closed)]
    classes.sort(key=lambda c: int(c[0]) if c.size else n)
    return classes


def _power_stationary(Pc: sp.spmatrix) -> np.ndarray | None:
    """Stationary distribution by power iteration on the lazy chain (P + I) / 2, or None.

    The lazy chain has the same stationary distribution and is aperiodic, so the iteration
    x <- (x + x P) / 2 converges geometrically from the uniform distribution.
    """
    m = Pc.shape[0]
    PT = Pc.T.tocsr()
    x = np.full(m, 1.0 / m)
    for it in range(1, POWER_MAX_ITER + 1):
        y = PT @ x
        if it % 25 == 0:
            if np.abs(y - x).sum() < POWER_TOL:
                return x / x.sum()
        x = 0.5 * (x + y)
    return None


def class_stationary(P: sp.spmatrix, cl: np.ndarray) -> tuple[np.ndarray, float]:
    """Stationary distribution of the closed class ``cl`` of P; returns ``(pi_cl, residual)``.

    Raises
    ------
    PolicyError
        The residual exceeds :data:`STATIONARY_TOL` (``cl`` is then not a closed class).
    """
    m = cl.size
    if m == 1:
        return np.ones(1), 0.0
    Pc = sp.csr_matrix(P)[cl][:, cl].tocsr()
    if m >= POWER_MIN_STATES:
        pi = _power_stationary(Pc)
        if pi is not None:
            residual = float(np.max(np.abs(Pc.T @ pi - pi)))
            if residual <= STATIONARY_TOL:
                return pi, residual
    A = (sp.identity(m, format="csr") - Pc).T.tocsr().tolil()
    A[0, :] = np.ones(m)
    A = A.tocsc()
    rhs = np.zeros(m)
    rhs[0] = 1.0
    try:
        lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A")
    except RuntimeError as exc:  # pragma: no cover - a closed communicating class is nonsingular
        raise PolicyError(f"stationary distribution: singular system ({exc})") from None
    pi = lu.solve(rhs)
    pi = pi + lu.solve(rhs - A @ pi)
    pi = np.maximum(pi, 0.0)
    pi /= pi.sum()
    residual = float(np.max(np.abs(Pc.T @ pi - pi)))
    if residual > STATIONARY_TOL:
        raise PolicyError(f"stationary distribution is inaccurate (residual {residual:.3g})")
    return pi, residual


def stationary_law(P: sp.spmatrix, classes: list[np.ndarray] | None = None,
                   weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """The mixture ``sum_i weights[i] pi_i`` of the classes' stationary laws (zero off them).

    Parameters
    ----------
    P : (n, n) sparse matrix
        A Markov chain.
    classes : list of int arrays, optional
        Closed classes (default: :func:`recurrent_classes` of P).
    weights : array, optional
        One weight per class (default equal weights, summing to 1); a class of weight 0 is not
        solved.

    Returns
    -------
    pi : (n,) array
    residual : float
        The largest residual of the classes solved.
    """
    if classes is None:
        classes = recurrent_classes(P)
    w = np.full(len(classes), 1.0 / max(len(classes), 1)) if weights is None else np.asarray(weights, float)
    pi = np.zeros(P.shape[0])
    residual = 0.0
    for wi, cl in zip(w, classes):
        if wi > 0:
            pi_c, res = class_stationary(P, cl)
            pi[cl] += wi * pi_c
            residual = max(residual, res)
    return pi, residual


class PolicyChain:
    """The Markov chain ``(P_pi, c_pi)`` a stationary policy induces on an MDP.

    Validated once on construction (:func:`policy_matrices`); the recurrent classes, the
    recurrent mask and the stationary law are computed on first use and cached.

    Parameters
    ----------
    mdp : MDP
    policy : array
        Deterministic (n,) pair indices or randomised (L,) pair probabilities.

    Attributes
    ----------
    P : (n, n) CSR matrix
    cost : (n,) array
    """

    def __init__(self, mdp: MDP, policy: np.ndarray):
        self.mdp = mdp
        self.policy = np.asarray(policy)
        self.P, self.cost = policy_matrices(mdp, self.policy)

    def __repr__(self) -> str:
        return f"PolicyChain({self.mdp.name!r}, n={self.P.shape[0]})"

    @property
    def n_states(self) -> int:
        return int(self.P.shape[0])

    @cached_property
    def recurrent_classes(self) -> list[np.ndarray]:
        """The closed communicating classes, ordered by their smallest state."""
        return recurrent_classes(self.P)

    @property
    def n_classes(self) -> int:
        return len(self.recurrent_classes)

    @property
    def is_unichain(self) -> bool:
        return self.n_classes == 1

    @cached_property
    def recurrent(self) -> np.ndarray:
        """(n,) bool: the state lies in a closed communicating class."""
        mask = np.zeros(self.n_states, bool)
        for cl in self.recurrent_classes:
            mask[cl] = True
        return mask

    @cached_property
    def _law(self) -> tuple[np.ndarray, float]:
        return stationary_law(self.P, self.recurrent_classes)

    @property
    def stationary(self) -> np.ndarray:
        """The stationary law; for a multichain policy the equal-weight mixture of its classes'."""
        return self._law[0]

    @property
    def residual(self) -> float:
        """Largest ``||pi_R P_RR - pi_R||_inf`` over the classes."""
        return self._law[1]
