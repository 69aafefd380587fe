"""Dynamic-programming solvers: exact policy evaluation, relative value iteration, policy iteration.

All three work on the state-action-pair form of :class:`~wncs_lp.mdp.MDP` and return (or
use) the certificate of :mod:`wncs_lp.solvers.certify`.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from ..errors import PolicyError, SolverError
from ..mdp import MDP
from .certify import bracket, certificate_closed, greedy_first, q_values
from .result import Solution

__all__ = [
    "PolicyEvaluation",
    "policy_matrices",
    "recurrent_classes",
    "evaluate_policy",
    "relative_value_iteration",
    "policy_iteration",
]

#: Relative residual above which an exact evaluation is rejected.
EVAL_RESIDUAL_TOL = 1e-6
#: Tolerance on the per-state sums of a randomised policy.
PROB_SUM_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class PolicyEvaluation:
    """Exact average-cost evaluation of a unichain stationary policy.

    Attributes
    ----------
    gain : float
        g = pi . c_pi, the long-run average cost (the same from every start state).
    bias : (n,) array
        The solution h of g + h = c_pi + P_pi h, normalised so that h[0] = 0.
    stationary : (n,) array
        The stationary distribution pi = pi P_pi, sum(pi) = 1 (zero on transient states).
    residual : float
        max(||g + h - c_pi - P_pi h||_inf, ||pi P_pi - pi||_inf + |sum pi - 1|), absolute.
    """

    gain: float
    bias: np.ndarray
    stationary: np.ndarray
    residual: float


# ---------------------------------------------------------------------------- policies
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


def evaluate_policy(mdp: MDP, policy: np.ndarray) -> PolicyEvaluation:
    """Exact gain, bias and stationary distribution of a unichain stationary policy.

    With ``r`` the smallest state of the (unique) recurrent class, solves

    .. math::

        g + h(s) - \\sum_{s'} P_\\pi(s, s') h(s') = c_\\pi(s) \\quad (s = 0..n-1),
        \\qquad h(r) = 0,

    i.e. ``M z = c_pi`` with ``M = I - P_pi`` whose column r is replaced by ones
    (``z[r] = g``, ``z[s] = h(s)`` otherwise). For a unichain P_pi this M is nonsingular,
    and its transpose is ``(I - P_pi)^T`` with row r replaced by ones, so the same sparse LU
    (:func:`scipy.sparse.linalg.splu`) also gives the stationary distribution from
    ``M^T pi = e_r`` (pi (I - P_pi) = 0, sum pi = 1). One step of iterative refinement is
    applied to both solves. The bias is returned as ``h - h[0]``.

    Parameters
    ----------
    mdp : MDP
    policy : array
        Deterministic (n,) pair indices or randomised (L,) pair probabilities, see
        :func:`policy_matrices`.

    Returns
    -------
    PolicyEvaluation

    Raises
    ------
    PolicyError
        If the policy is malformed, if the induced chain has more than one recurrent class
        (the message gives their number and a state of two of them), or if the residual of
        the solves exceeds 1e-6 relative to the size of c_pi and h.
    """
    P_pi, c_pi = policy_matrices(mdp, policy)
    n = mdp.n_states
    classes = recurrent_classes(P_pi)
    if len(classes) != 1:
        a, b = classes[0], classes[1]
        raise PolicyError(
            f"the policy induces a multichain Markov chain with {len(classes)} recurrent classes "
            f"(e.g. state {mdp.state_label(int(a[0]))} in a class of {a.size} state(s) and "
            f"state {mdp.state_label(int(b[0]))} in another of {b.size}); the average cost "
            "depends on the start state and a single gain/bias is undefined"
        )
    r = int(classes[0][0])
    M = (sp.identity(n, format="csc") - P_pi).tocsc()
    M.data[M.indptr[r]:M.indptr[r + 1]] = 0.0
    M.eliminate_zeros()
    M = (M + sp.csc_matrix((np.ones(n), (np.arange(n), np.full(n, r))), shape=(n, n))).tocsc()
    try:
        lu = spla.splu(M)
    except RuntimeError as exc:  # exactly singular: should not happen for a unichain policy
        raise PolicyError(f"policy evaluation system is singular ({exc})") from exc

    def refine(rhs: np.ndarray, trans: str) -> np.ndarray:
        z = lu.solve(rhs, trans=trans)
        Mz = (M.T @ z) if trans == "T" else (M @ z)
        return z + lu.solve(rhs - Mz, trans=trans)

    z = refine(c_pi, "N")
    g = float(z[r])
    h = z.copy()
    h[r] = 0.0
    er = np.zeros(n)
    er[r] = 1.0
    pi = refine(er, "T")
    # round-off may leave -1e-17 on transient states
    pi = np.where(pi < 0, np.maximum(pi, 0.0), pi)
    pi = pi / pi.sum()

    res_bias = float(np.max(np.abs(g + h - c_pi - P_pi @ h)))
    res_pi = float(np.max(np.abs(P_pi.T @ pi - pi)) + abs(pi.sum() - 1.0))
    residual = max(res_bias, res_pi)
    scale = max(float(np.max(np.abs(c_pi))), float(np.max(np.abs(h))), 1e-300)
    if res_bias > EVAL_RESIDUAL_TOL * scale or res_pi > EVAL_RESIDUAL_TOL:
        raise PolicyError(
            f"policy evaluation is inaccurate: bias residual {res_bias:.3g} (scale {scale:.3g}), "
            f"stationary residual {res_pi:.3g}"
        )
    h = h - h[0]
    return PolicyEvaluation(gain=g, bias=h, stationary=pi, residual=residual)


# ---------------------------------------------------------------------------- RVI
def relative_value_iteration(
    mdp: MDP,
    *,
    tol: float = 1e-10,
    atol: float = 0.0,
    max_iter: int = 100_000,
    aperiodicity: float = 0.5,
    h0: np.ndarray | None = None,
    ref_state: int = 0,
    progress: bool = False,
) -> Solution:
    """Relative value iteration with the aperiodicity transform and a span certificate.

    The transform replaces P by :math:`\\tilde P = \\tau P + (1-\\tau) I` (``tau =
    aperiodicity``, 0 < tau <= 1): every transformed chain is aperiodic, the gain is
    unchanged and the biases are related by :math:`h = \\tau \\tilde h`. Written directly
    in the scale of the original bias ``h = tau * h~``, one sweep is

    .. math::

        d_k = T h_k - h_k, \\qquad h_{k+1} = h_k + \\tau d_k - \\tau d_k(\\text{ref}),

    which is exactly RVI on the transformed MDP. Each sweep costs one CSR mat-vec and one
    ``np.minimum.reduceat``. Because :math:`\\tilde T \\tilde h - \\tilde h = T h - h`,
    the certificate lo = min d_k <= g* <= hi = max d_k of the *original* operator comes for
    free every sweep; iteration stops when

    ``hi - lo <= tol * |(lo + hi) / 2|``  or  ``hi - lo <= atol``.

    Parameters
    ----------
    mdp : MDP
    tol : float
        Relative certificate width (hi - lo) / |g| to reach.
    atol : float
        Absolute width accepted as well (useful when g* = 0); default 0.
    max_iter : int
        Number of sweeps before giving up with status ``"max_iter"``.
    aperiodicity : float
        tau in (0, 1]; tau = 1 is plain RVI (which may oscillate on periodic chains).
    h0 : (n,) array, optional
        Warm start, in the scale of the original bias (e.g. a previous ``Solution.bias``).
    ref_state : int
        The state whose value is subtracted each sweep.
    progress : bool
        Print the certificate to stderr every 1000 sweeps.

    Returns
    -------
    Solution
        ``method="rvi"``; ``gain = (lo + hi)/2``; ``bias`` = the last h_k (on which the
        certificate was computed) with h[0] = 0; ``policy`` = greedy pairs of that h
        (ties to the first pair); status ``"optimal"`` or ``"max_iter"``. ``stats`` holds
        ``tau``, ``span`` (hi - lo), ``rel_gap``, ``converged``.
    """
    t0 = time.perf_counter()
    n = mdp.n_states
    tau = float(aperiodicity)
    if not (0.0 < tau <= 1.0):
        raise SolverError(f"aperiodicity must be in (0, 1], got {aperiodicity}")
    if not (0 <= ref_state < n):
        raise SolverError(f"ref_state must be in 0..{n - 1}, got {ref_state}")
    if max_iter < 1:
        raise SolverError(f"max_iter must be >= 1, got {max_iter}")
    if h0 is None:
        h = np.zeros(n)
    else:
        h = np.array(h0, dtype=float)
        if h.shape != (n,) or not np.all(np.isfinite(h)):
            raise SolverError(f"h0 must be a finite array of shape ({n},)")
        h -= h[ref_state]
    starts = mdp.pair_ptr[:-1]
    cost, P = mdp.cost, mdp.P
    converged = False
    lo = hi = np.nan
    q = Th = None
    it = 0
    for it in range(1, max_iter + 1):
        q = cost + P @ h
        Th = np.minimum.reduceat(q, starts)
        d = Th - h
        lo, hi = float(d.min()), float(d.max())
        width = hi - lo
        if width <= tol * abs(0.5 * (lo + hi)) or width <= atol:
            converged = True
            break
        if progress and it % 1000 == 0:
            print(f"[rvi] it={it} lo={lo:.12g} hi={hi:.12g} rel={width / max(abs(0.5 * (lo + hi)), 1e-300):.3g}",
                  file=sys.stderr)
        h = h + tau * d
        h -= h[ref_state]
    policy = greedy_first(mdp, q, Th)
    gain = 0.5 * (lo + hi)
    bias = h - h[0]
    rel = (hi - lo) / max(abs(gain), 1e-300)
    return Solution(
        method="rvi",
        status="optimal" if converged else "max_iter",
        gain=gain,
        gain_lower=lo,
        gain_upper=hi,
        bias=bias,
        policy=policy,
        occupation=None,
        iterations=it,
        seconds=time.perf_counter() - t0,
        stats={"tau": tau, "span": hi - lo, "rel_gap": rel, "converged": converged, "tol": tol},
    )


# ---------------------------------------------------------------------------- PI
def _improve(mdp: MDP, q: np.ndarray, current: np.ndarray, rtol: float) -> np.ndarray:
    """Greedy improvement that keeps the current pair when it is (nearly) a minimiser.

    The current pair of state s is kept when ``q[cur] <= min_s q + rtol * max|q|``; the
    tolerance is relative to the largest pair value because that sets the round-off of the
    evaluated bias. Otherwise the first exact minimiser is taken.
    """
    qmin = np.minimum.reduceat(q, mdp.pair_ptr[:-1])
    thresh = rtol * max(float(np.max(np.abs(q))), 1e-300)
    keep = q[current] <= qmin + thresh
    return np.where(keep, current, greedy_first(mdp, q, qmin))


def policy_iteration(
    mdp: MDP,
    *,
    policy0: np.ndarray | None = None,
    max_iter: int = 100,
    rtol: float = 1e-12,
    cert_rtol: float = 1e-6,
) -> Solution:
    """Howard's policy iteration for unichain average-cost MDPs.

    Each iteration evaluates d_k exactly (:func:`evaluate_policy`: g_k, h_k) and improves

    .. math:: d_{k+1}(s) \\in \\arg\\min_{l:\\, s_l = s} \\big[c_l + (P h_k)_l\\big],

    keeping d_k(s) whenever it is a minimiser up to ``rtol * max|Q|`` (prevents cycling
    between tied actions through round-off). Stops when the policy is stable; the
    certificate is :func:`~wncs_lp.solvers.certify.bracket` on the final bias.

    Parameters
    ----------
    mdp : MDP
    policy0 : (n,) int array, optional
        Initial pair indices; default the cheapest pair of each state (greedy for h = 0).
    max_iter : int
        Maximum number of evaluations.
    rtol : float
        Relative tie tolerance for keeping the current action.
    cert_rtol : float
        Status is ``"optimal"`` only if the policy is stable and (hi - lo)/|g| <= cert_rtol.

    Returns
    -------
    Solution
        ``method="pi"``; ``gain`` = exact gain of the final policy; ``occupation`` = the
        stationary pair frequencies of the final (deterministic) policy.

    Raises
    ------
    PolicyError
        If an iterate induces a multichain chain (PI here assumes a unichain MDP).
    """
    t0 = time.perf_counter()
    n = mdp.n_states
    if policy0 is None:
        d = greedy_first(mdp, mdp.cost)
    else:
        d = np.asarray(policy0)
        if not np.issubdtype(d.dtype, np.integer):
            raise PolicyError(f"policy0 must be an integer array of pair indices, got dtype {d.dtype}")
        d = d.astype(np.int64)
    stable = False
    ev = None
    it = 0
    changes = []
    for it in range(1, max_iter + 1):
        ev = evaluate_policy(mdp, d)
        q = q_values(mdp, ev.bias)
        d_new = _improve(mdp, q, d, rtol)
        nchg = int(np.count_nonzero(d_new != d))
        changes.append(nchg)
        if nchg == 0:
            stable = True
            break
        d = d_new
    assert ev is not None
    lo, hi = bracket(mdp, ev.bias)
    rel = (hi - lo) / max(abs(ev.gain), 1e-300)
    if not stable:
        status = "max_iter"
    elif certificate_closed(mdp, lo, hi, ev.gain, cert_rtol):
        status = "optimal"
    else:
        status = "inaccurate"
    occ = np.zeros(mdp.n_pairs)
    occ[d] = ev.stationary
    return Solution(
        method="pi",
        status=status,
        gain=ev.gain,
        gain_lower=lo,
        gain_upper=hi,
        bias=ev.bias,
        policy=d.copy(),
        occupation=occ,
        iterations=it,
        seconds=time.perf_counter() - t0,
        stats={"stable": stable, "changes": changes, "rel_gap": rel, "eval_residual": ev.residual},
    )
