r"""The Markov chain a stationary policy induces on an MDP: the one place for its analysis.

Like QuantEcon's ``MarkovChain``, a :class:`PolicyChain` is validated once and computes what is
asked of it lazily, caching it: the induced transition matrix and cost, the recurrent classes
(closed strongly connected components: an exact graph criterion), the recurrent-state mask, the
stationary law. Every module that needs "recurrent" or "stationary" gets it from here, under one
rule: a state is *recurrent* when it lies in a closed communicating class of ``P_pi`` (exactly
the states of positive stationary probability).

The stationary law of one closed class R solves :math:`\pi_R (I - P_{RR}) = 0`,
:math:`\sum \pi_R = 1` (:func:`class_stationary`), written as one bordered linear system (row 0
of :math:`(I - P_{RR})^T` replaced by ones): for classes of :data:`ITERATIVE_MIN_STATES` states or
more by BiCGSTAB, restarted until the true residual passes (an LU of a large class fills in
badly), then if need be by power iteration on the lazy chain :math:`(P + I)/2`; below that size --
or when both miss -- by a sparse LU of the bordered system, minimum-degree ordering on
:math:`A^T + A` and one step of iterative refinement; the residual
:math:`\|\pi_R P_{RR} - \pi_R\|_\infty` is checked against
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
    "STATIONARY_METHODS",
    "ITERATIVE_MIN_STATES",
    "bicgstab",
]

#: Residual above which a stationary distribution is rejected.
STATIONARY_TOL = 1e-9
#: Classes at least this large are solved iteratively first (BiCGSTAB, then the power iteration):
#: the LU's fill-in grows fast (measured in ``benchmarks/evaluation.py``).
ITERATIVE_MIN_STATES = 1_000
#: BiCGSTAB's own tolerance in the iterative stationary solve, and its restarts.
ITERATIVE_RTOL = 1e-13
ITERATIVE_RESTARTS = 3
#: The methods of :func:`class_stationary`.
STATIONARY_METHODS = ("auto", "lu", "iterative")
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


def _bordered(Pc: sp.csr_matrix) -> tuple[sp.csr_matrix, np.ndarray]:
    """``(A, e_0)`` with A = (I - P)^T whose row 0 is replaced by ones: A pi = e_0 says
    pi (I - P) = 0 off state 0 and sum pi = 1, which for a closed class is its stationary law."""
    m = Pc.shape[0]
    AT = (sp.identity(m, format="csr") - Pc).T.tocsr()
    A = sp.vstack([sp.csr_matrix(np.ones((1, m))), AT[1:]], format="csr")
    rhs = np.zeros(m)
    rhs[0] = 1.0
    return A, rhs


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    # a plain numpy sum, not BLAS: OpenBLAS's threads spin when the machine is loaded (measured under
    # load 21 on 2 cores: 11 ms per dot of 31,000 entries, BiCGSTAB 6.6 s against 0.15 s with one
    # BLAS thread), and the products here are too short to gain from threads
    return float(np.add.reduce(a * b))


def bicgstab(A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray, rtol: float, maxiter: int) -> tuple[np.ndarray, int]:
    """BiCGSTAB (van der Vorst 1992) for A x = b from x0, until ||b - A x|| <= rtol ||b|| on its
    recursive residual; returns ``(x, info)``, info 0 when it converged, 1 out of iterations, -1 on a
    breakdown. The sparse products are scipy's; the vector products plain numpy (:func:`_dot`)."""
    x = np.array(x0, dtype=float)
    r = b - A @ x
    r0 = r.copy()
    bnorm = np.sqrt(_dot(b, b)) or 1.0
    rho = alpha = omega = 1.0
    v = np.zeros_like(x)
    p = np.zeros_like(x)
    for _ in range(maxiter):
        if np.sqrt(_dot(r, r)) <= rtol * bnorm:
            return x, 0
        rho_new = _dot(r0, r)
        if rho_new == 0.0 or omega == 0.0:
            return x, -1
        beta = (rho_new / rho) * (alpha / omega)
        rho = rho_new
        p = r + beta * (p - omega * v)
        v = A @ p
        den = _dot(r0, v)
        if den == 0.0:
            return x, -1
        alpha = rho / den
        s = r - alpha * v
        if np.sqrt(_dot(s, s)) <= rtol * bnorm:
            return x + alpha * p, 0
        t = A @ s
        tt = _dot(t, t)
        omega = _dot(t, s) / tt if tt > 0 else 0.0
        x = x + alpha * p + omega * s
        r = s - omega * t
    return x, 1


def _iterative_stationary(Pc: sp.csr_matrix) -> np.ndarray | None:
    """Stationary distribution by BiCGSTAB on the bordered system (:func:`_bordered`) from the
    uniform law, restarted from its own answer until the true residual ||pi P - pi||_inf is below
    :data:`STATIONARY_TOL` (at most :data:`ITERATIVE_RESTARTS` restarts); None if it misses.

    A Krylov solver needs far fewer products with P than the power iteration on a slowly mixing
    chain, and, unlike the LU, no fill-in."""
    A, rhs = _bordered(Pc)
    m = Pc.shape[0]
    PT = Pc.T.tocsr()
    x = np.full(m, 1.0 / m)
    for _ in range(ITERATIVE_RESTARTS + 1):
        x, info = bicgstab(A, rhs, x, ITERATIVE_RTOL, max(1000, 2 * int(np.sqrt(m))))
        if not np.all(np.isfinite(x)):
            return None
        pi = np.maximum(x, 0.0)
        pi /= pi.sum()
        if float(np.max(np.abs(PT @ pi - pi))) <= STATIONARY_TOL:
            return pi
        if info != 0:  # out of iterations or a breakdown
            return None
    return None


def class_stationary(P: sp.spmatrix, cl: np.ndarray, method: str = "auto") -> tuple[np.ndarray, float]:
    """Stationary distribution of the closed class ``cl`` of P; returns ``(pi_cl, residual)``.

    Parameters
    ----------
    method : {"auto", "lu", "iterative"}
        ``"lu"``: the sparse LU of the bordered system (one refinement step). ``"iterative"``:
        BiCGSTAB on it (:func:`_iterative_stationary`), then the power iteration, then the LU, each
        tried when the one before misses :data:`STATIONARY_TOL`. ``"auto"``: the LU below
        :data:`ITERATIVE_MIN_STATES` states, iterative from there on (the crossover measured in
        ``benchmarks/evaluation.py``).

    Raises
    ------
    PolicyError
        The residual exceeds :data:`STATIONARY_TOL` (``cl`` is then not a closed class), or an
        unknown method.
    """
    if method not in STATIONARY_METHODS:
        raise PolicyError(f"unknown stationary method {method!r}; expected one of {', '.join(STATIONARY_METHODS)}")
    m = cl.size
    if m == 1:
        return np.ones(1), 0.0
    Pc = sp.csr_matrix(P)[cl][:, cl].tocsr()
    if method == "iterative" or (method == "auto" and m >= ITERATIVE_MIN_STATES):
        for solver in (_iterative_stationary, _power_stationary):
            pi = solver(Pc)
            if pi is not None:
                residual = float(np.max(np.abs(Pc.T @ pi - pi)))
                if residual <= STATIONARY_TOL:
                    return pi, residual
    A, rhs = _bordered(Pc)
    A = A.tocsc()
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
                   weights: np.ndarray | None = None, method: str = "auto") -> tuple[np.ndarray, float]:
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
    method : {"auto", "lu", "iterative"}
        How each class is solved (:func:`class_stationary`).

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
            pi_c, res = class_stationary(P, cl, method)
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
    method : {"auto", "lu", "iterative"}
        How the stationary law is solved (:func:`class_stationary`).

    Attributes
    ----------
    P : (n, n) CSR matrix
    cost : (n,) array
    """

    def __init__(self, mdp: MDP, policy: np.ndarray, method: str = "auto"):
        if method not in STATIONARY_METHODS:
            raise PolicyError(f"unknown stationary method {method!r}; expected one of {', '.join(STATIONARY_METHODS)}")
        self.mdp = mdp
        self.method = method
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
        return stationary_law(self.P, self.recurrent_classes, method=self.method)

    @property
    def stationary(self) -> np.ndarray:
        """The stationary law; for a multichain policy the equal-weight mixture of its classes'."""
        return self._law[0]

    @property
    def residual(self) -> float:
        """Largest ``||pi_R P_RR - pi_R||_inf`` over the classes."""
        return self._law[1]
