"""Dynamic-programming solvers: exact policy evaluation, relative value iteration, policy iteration.

All three work on the state-action-pair form of :class:`~wncs_lp.mdp.MDP` and return (or
use) the certificate of :mod:`wncs_lp.solvers.certify`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..chain import class_stationary, policy_matrices, recurrent_classes
from ..errors import PolicyError, SolverError
from ..mdp import MDP
from ..policy_forms import policy_array
from ..progress import Progress, as_progress
from ..status import INACCURATE, MAX_ITER, OPTIMAL, Status, of
from .certify import bracket, certificate_closed, greedy_first, q_values
from .iteration import (PRECISION_STALL_SWEEPS, VI_TOL, IterationOptions, IterationOutcome, IterationScheme,
                        cert_line, certified_iteration, gamma, is_int, max_abs)
from .result import Certificate, Certified, Solution, certificate_rows, certificate_summary, describe_array

__all__ = [
    "MultichainPolicyError",
    "initial_bias",
    "PolicyEvaluation",
    "evaluate_policy",
    "stationary_of",
    "relative_value_iteration",
    "value_iteration",
    "policy_iteration",
    "greedy_policy",
    "roundoff_bound",
    "RoundoffBound",
    "VI_TOL",
    "PRECISION_STALL_SWEEPS",
]

#: Relative residual above which an exact evaluation is rejected.
EVAL_RESIDUAL_TOL = 1e-6

#: :func:`evaluate_policy` with ``method="auto"`` solves by BiCGSTAB from this many states on.
#: A sparse LU of I - P_pi fills in badly on these chains (p12 at cap 30, 110k states: 13M
#: nonzeros in L + U, 7.6 s; the best of SuperLU's orderings), where BiCGSTAB needed ~130
#: mat-vecs (0.09 s) to a relative residual of 1e-13.
EVAL_ITERATIVE_MIN_STATES = 50_000

#: BiCGSTAB's stopping tolerance (its own recursive residual) in the iterative evaluation; the
#: *true* residual ||b - M z|| / ||b|| is then required to be <= 10x this, i.e. 1e-12, else the
#: sparse LU answers.
EVAL_ITERATIVE_RTOL = 1e-13

#: ``evaluate_policy`` methods
EVAL_METHODS = ("auto", "direct", "iterative")


class MultichainPolicyError(PolicyError):
    """The evaluated policy induces more than one recurrent class (a :class:`PolicyError`)."""


@dataclass(frozen=True, eq=False, repr=False)
class PolicyEvaluation(Certified):
    """Exact average-cost evaluation of a unichain stationary policy.

    Its :attr:`certificate` is ``[gain - residual, gain + residual]``: with ``r = c_pi + P_pi h - h
    - g`` the Poisson residual, ``g_pi = pi . c_pi = g + pi . r``, so ``|g - g_pi| <= max|r| <=
    residual``. Its status is always ``optimal`` (an evaluation that misses its residual
    tolerance raises instead).

    Attributes
    ----------
    gain : float
        g = pi . c_pi, the long-run average cost (the same from every start state).
    bias : (n,) array
        The solution h of g + h = c_pi + P_pi h, normalised so that h[0] = 0.
    stationary : (n,) array or None
        The stationary distribution pi = pi P_pi, sum(pi) = 1 (zero on transient states); None
        when not asked for (``evaluate_policy(..., stationary=False)``).
    residual : float
        max(||g + h - c_pi - P_pi h||_inf, ||pi P_pi - pi||_inf + |sum pi - 1|), absolute (the
        first term alone without the stationary distribution).
    solver : str
        ``"splu"`` (sparse LU + one refinement step), ``"bicgstab"``, or
        ``"bicgstab->splu"`` when the iterative solve missed its tolerance and LU took over.
    """

    gain: float
    bias: np.ndarray
    stationary: np.ndarray | None
    residual: float
    solver: str = "splu"

    method = "evaluate"

    def __post_init__(self) -> None:  # nothing to normalise: the status and certificate are derived
        pass

    @property
    def certificate(self) -> Certificate:
        """``[gain - residual, gain + residual]`` (the class docstring)."""
        r = abs(float(self.residual))
        return Certificate(self.gain - r, self.gain + r)

    @property
    def status(self) -> Status:
        return of(OPTIMAL)

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars: :func:`~wncs_lp.solvers.result.certificate_summary`, residual, solver."""
        return {**certificate_summary(self), "residual": float(self.residual), "solver": self.solver}

    def _display_head(self) -> str:
        return f"PolicyEvaluation of {np.asarray(self.bias).size:,} states ({self.solver})"

    def _display_rows(self) -> list[tuple[str, str]]:
        return certificate_rows(self) + [
            ("residual", f"{self.residual:.3g}"),
            ("bias", describe_array(self.bias, "floats") + ", h[0] = 0"),
            ("stationary", describe_array(self.stationary, "probabilities") + f", "
                           f"{int(np.count_nonzero(self.stationary)):,} recurrent states"),
        ]

    def _frame_records(self):
        n = np.asarray(self.bias).size
        return ["state", "bias", "stationary"], {"state": np.arange(n), "bias": np.asarray(self.bias, float),
                                                 "stationary": np.asarray(self.stationary, float)}


def evaluate_policy(mdp: MDP, policy: Any = None, *, sigma: Any = None, method: str = "auto",
                    h0: np.ndarray | None = None, maxiter: int | None = None,
                    stationary: bool = True) -> PolicyEvaluation:
    """Exact gain, bias and stationary distribution of a unichain stationary policy.

    With ``r`` the smallest state of the (unique) recurrent class, solves

    .. math::

        g + h(s) - \\sum_{s'} P_\\pi(s, s') h(s') = c_\\pi(s) \\quad (s = 0..n-1),
        \\qquad h(r) = 0,

    i.e. ``M z = c_pi`` with ``M = I - P_pi`` whose column r is replaced by ones
    (``z[r] = g``, ``z[s] = h(s)`` otherwise). For a unichain P_pi this M is nonsingular; it is
    solved by a sparse LU (:func:`scipy.sparse.linalg.splu`) with one step of iterative
    refinement. The bias is returned as ``h - h[0]``. The stationary distribution is that of the
    recurrent class, by :func:`wncs_lp.chain.class_stationary` (the toolkit's one stationary
    solver).

    Large chains are solved iteratively instead: BiCGSTAB on ``M z = c_pi``, accepted when the
    true relative residual is at most 1e-12 (10 x :data:`EVAL_ITERATIVE_RTOL`), which avoids the
    LU's fill-in; if the solve misses that, the sparse LU is used after all (``solver`` says
    which). The iterative answer is less exact than the LU's but not by much: on p12 at cap 30
    its gain agreed with the LU's to 8e-13 relative, with an absolute Poisson residual of 1e-8
    against the LU's 2e-10.

    Parameters
    ----------
    mdp : MDP
    policy : array, Policy or Solution
        Deterministic (n,) pair indices or randomised (L,) pair probabilities, see
        :func:`policy_matrices`; or a :class:`~wncs_lp.policies.Policy` or a solution of ``mdp``.
    sigma : (n,) int array, optional
        The policy as an action per state instead (a row of ``mdp.action_table``, as
        :attr:`Solution.sigma`; :mod:`wncs_lp.policy_forms`).
    method : {"auto", "direct", "iterative"}
        ``"auto"``: iterative from :data:`EVAL_ITERATIVE_MIN_STATES` states on, else direct.
    h0 : (n,) array, optional
        Starting bias of the iterative solve (e.g. the previous policy-iteration iterate).
    maxiter : int, optional
        BiCGSTAB iteration cap per call (default ``max(1000, 2 sqrt(n))``); a solve whose true
        residual misses after a converged call is restarted from its answer, up to 4 calls.
    stationary : bool
        Compute the stationary distribution (default). Without it the evaluation is the Poisson
        solve alone: policy iteration needs the stationary law of its last policy only, and the
        stationary solve costs as much as the Poisson solve on chains whose LU fills in.

    Returns
    -------
    PolicyEvaluation

    Raises
    ------
    PolicyError
        If the policy is malformed, if the induced chain has more than one recurrent class
        (the message gives their number and a state of two of them), or if the residual of
        the solves exceeds 1e-6 relative to the size of c_pi and h.
    SolverError
        An unknown ``method``, or an ``h0`` that is not a finite (n,) array (checked on every
        path, although only the iterative solve uses it).
    """
    if method not in EVAL_METHODS:
        raise SolverError(f"unknown evaluation method {method!r}; expected one of {', '.join(EVAL_METHODS)}")
    if sigma is not None or not isinstance(policy, np.ndarray):  # the array of policy iteration goes straight on
        policy = policy_array(mdp, policy, sigma)
    P_pi, c_pi = policy_matrices(mdp, policy)
    n = mdp.n_states
    classes = recurrent_classes(P_pi)
    if len(classes) != 1:
        raise _multichain_error(mdp, classes)
    r = int(classes[0][0])
    M = _poisson_matrix(P_pi, r)
    z0 = None if h0 is None else initial_bias(h0, n, r)  # checked whichever path runs
    z, solver = _solve_poisson(M, P_pi, c_pi, r, z0, method, maxiter)
    g = float(z[r])
    h = z.copy()
    h[r] = 0.0
    pi = _class_law(P_pi, classes[0]) if stationary else None
    residual = _check_poisson(P_pi, c_pi, g, h, pi)
    return PolicyEvaluation(gain=g, bias=h - h[0], stationary=pi, residual=residual, solver=solver)


def _class_law(P_pi: sp.csr_matrix, cl: np.ndarray) -> np.ndarray:
    """The stationary distribution of a unichain P_pi whose recurrent class is ``cl`` (zero off it)."""
    pi = np.zeros(P_pi.shape[0])
    pi[cl] = class_stationary(P_pi, cl)[0]
    return pi


def stationary_of(mdp: MDP, policy: np.ndarray) -> np.ndarray:
    """The stationary distribution of a unichain deterministic policy (``policy``: a pair per state).

    Raises
    ------
    MultichainPolicyError
        The policy's chain has several recurrent classes.
    """
    P_pi, _ = policy_matrices(mdp, policy)
    classes = recurrent_classes(P_pi)
    if len(classes) != 1:
        raise _multichain_error(mdp, classes)
    return _class_law(P_pi, classes[0])


def _multichain_error(mdp: MDP, classes: list) -> MultichainPolicyError:
    a, b = classes[0], classes[1]
    return MultichainPolicyError(
        f"the policy induces a multichain Markov chain with {len(classes)} recurrent classes "
        f"(e.g. state {mdp.state_label(int(a[0]))} in a class of {a.size} state(s) and "
        f"state {mdp.state_label(int(b[0]))} in another of {b.size}); the average cost "
        "depends on the start state and a single gain/bias is undefined"
    )


def _poisson_matrix(P_pi: sp.csr_matrix, r: int) -> sp.csc_matrix:
    """M = I - P_pi with column r replaced by ones (z[r] is then the gain g)."""
    n = P_pi.shape[0]
    M = (sp.identity(n, format="csc") - P_pi).tocsc()
    M.data[M.indptr[r]:M.indptr[r + 1]] = 0.0
    M.eliminate_zeros()
    return (M + sp.csc_matrix((np.ones(n), (np.arange(n), np.full(n, r))), shape=(n, n))).tocsc()


def _solve_poisson(M: sp.csc_matrix, P_pi: sp.csr_matrix, c_pi: np.ndarray, r: int, z0: np.ndarray | None,
                   method: str, maxiter: int | None) -> tuple[np.ndarray, str]:
    """z with M z = c_pi: BiCGSTAB on large chains (or when asked), else (or when it misses) a
    sparse LU with one refinement step; and which solver answered."""
    n = M.shape[0]
    if method == "iterative" or (method == "auto" and n >= EVAL_ITERATIVE_MIN_STATES):
        if z0 is not None:
            z0[r] = float(np.median(c_pi + P_pi @ z0 - z0))  # a gain estimate for the unknown g
        its = int(maxiter) if maxiter is not None else max(1000, int(2 * np.sqrt(n)))
        z = _bicgstab(M.tocsr(), c_pi, z0, its)
        if z is not None:
            return z, "bicgstab"
        solver = "bicgstab->splu"
    else:
        solver = "splu"
    import scipy.sparse.linalg as spla  # imported where used: 0.3-0.5 s that value iteration never needs

    try:
        lu = spla.splu(M)
    except RuntimeError as exc:  # exactly singular: should not happen for a unichain policy
        raise PolicyError(f"policy evaluation system is singular ({exc})") from exc
    z = lu.solve(c_pi)
    return z + lu.solve(c_pi - M @ z), solver


def _check_poisson(P_pi: sp.csr_matrix, c_pi: np.ndarray, g: float, h: np.ndarray, pi: np.ndarray | None) -> float:
    """The residual of g + h = c_pi + P_pi h and of pi P_pi = pi, sum pi = 1 (when pi is given);
    PolicyError if too large."""
    res_bias = float(np.max(np.abs(g + h - c_pi - P_pi @ h)))
    res_pi = 0.0 if pi is None else float(np.max(np.abs(P_pi.T @ pi - pi)) + abs(pi.sum() - 1.0))
    scale = max(float(np.max(np.abs(c_pi))), float(np.max(np.abs(h))), 1e-300)
    if not (res_bias <= EVAL_RESIDUAL_TOL * scale and res_pi <= EVAL_RESIDUAL_TOL):  # NaN fails too
        raise PolicyError(
            f"policy evaluation is inaccurate: bias residual {res_bias:.3g} (scale {scale:.3g}), "
            f"stationary residual {res_pi:.3g}"
        )
    return max(res_bias, res_pi)


def _bicgstab(A: sp.csr_matrix, b: np.ndarray, x0: np.ndarray | None, maxiter: int,
              restarts: int = 3) -> np.ndarray | None:
    """BiCGSTAB to a *true* residual ||b - A x|| <= 10 EVAL_ITERATIVE_RTOL ||b||; None if missed.

    BiCGSTAB stops on its recursively updated residual, which can drift from the true one
    (measured: 1e-13 reported, 1e-12 true), so the true residual is checked and the solve
    restarted from its own answer, at most ``restarts`` times.
    """
    import scipy.sparse.linalg as spla

    target = 10 * EVAL_ITERATIVE_RTOL * max(float(np.linalg.norm(b)), 1e-300)
    x = x0
    for _ in range(restarts + 1):
        x, info = spla.bicgstab(A, b, x0=x, rtol=EVAL_ITERATIVE_RTOL, atol=0.0, maxiter=maxiter)
        if not np.all(np.isfinite(x)):
            return None
        if float(np.linalg.norm(b - A @ x)) <= target:
            return x
        if info != 0:  # out of iterations (or a breakdown): not converging, let the LU take over
            return None
    return None


# ---------------------------------------------------------------------------- value iteration
def initial_bias(h0: np.ndarray | None, n: int, ref: int) -> np.ndarray:
    """A warm-start bias (zeros by default), checked and normalised so that h[ref] = 0."""
    if h0 is None:
        return np.zeros(n)
    try:
        h = np.array(h0, dtype=float)
    except (TypeError, ValueError):
        h = None
    if h is None or h.shape != (n,) or not np.all(np.isfinite(h)):
        raise SolverError(f"h0 must be a finite array of shape ({n},)")
    return h - h[ref]


class RoundoffBound:
    r"""The round-off bound delta of a certificate computed on the stored matrix.

    Each d(s) = min_l (c_l + sum_k P_lk h(j_k)) - h(s) is computed with m_l <= m products and
    additions after the cost (m = the longest row of P), a comparison (exact) and one
    subtraction. The standard bound for a floating-point dot product (Higham, *Accuracy and
    Stability of Numerical Algorithms*, 2nd ed., eq. 3.5) with the unit round-off u = 2^-53 gives

    .. math::

        |fl(d(s)) - d(s)| \le \delta := \gamma_{m+2}\,(\max|c| + 2\max|h|),
        \qquad \gamma_k = \frac{k u}{1 - k u},

    because sum_k P_lk = 1 bounds the sum of the magnitudes of the terms by |c_l| + max|h|, and
    the subtraction adds u |d| <= u (max|c| + 2 max|h|). So the computed ``lo``, ``hi`` are
    each within delta of the exact ones: the exact certificate is contained in
    ``[lo - delta, hi + delta]``, and a computed width below ``2 delta`` says nothing more about
    the exact one. That is the attainable precision: ``2 delta / |g|``. (The width sweeps
    actually reach is smaller, a few ulps of max|h|, because round-off errors do not all add
    up; e.g. processes 1, 2 at cap 40: max|h| = 3.3e6, max|c| = 4.1e5, m = 8,
    2 delta / g = 1.7e-11, widths reached ~1e-12.) How the iteration uses it:
    :mod:`wncs_lp.solvers.iteration`.
    """

    def __init__(self, mdp: MDP):
        ptr = mdp.P.indptr  # the longest row, by blocks: a whole np.diff would be a length-L temporary
        self.m = max((int(np.diff(ptr[a:a + (1 << 20) + 1]).max()) for a in range(0, ptr.size - 1, 1 << 20)),
                     default=0)
        self.cmax = float(np.max(np.abs(mdp.cost))) if mdp.n_pairs else 0.0

    def __call__(self, h: np.ndarray) -> float:
        """delta for the bias ``h`` the certificate was computed on."""
        return gamma(self.m + 2) * (self.cmax + 2.0 * max_abs(h))


def roundoff_bound(mdp: MDP, h: np.ndarray) -> float:
    """delta: a bound on the floating-point error of each computed ``d(s) = (T h - h)(s)``, so of
    the computed certificate ends ``lo``, ``hi`` (see :class:`RoundoffBound`)."""
    return RoundoffBound(mdp)(np.asarray(h, dtype=float))


class _PairSweeps(IterationScheme):
    """The sweeps of value iteration on the stored matrix (:mod:`wncs_lp.solvers.kernels`).

    ``"mpi"`` / ``"gs"``: in-place improvement sweeps (and ``n_eval`` fixed-policy sweeps after
    each); the certificate pass is a Jacobi step relaxed by ``relax`` whose output becomes the next
    iterate. ``"jacobi"``: the Jacobi step with the aperiodicity transform ``tau`` (RVI: shift 0,
    h renormalised at ``ref``).
    """

    def __init__(self, mdp: MDP, K: Any, h: np.ndarray, scheme: str, *, relax: float = 0.8, n_eval: int = 0,
                 tau: float = 0.5, ref: int = 0, use_shift: bool = True):
        self.mdp, self.K, self.h, self.name = mdp, K, h, scheme
        self.h_next = np.empty_like(h)
        self.pol = mdp.pair_ptr[:-1].astype(np.int64)
        self.relax, self.n_eval, self.tau, self.ref, self.use_shift = relax, n_eval, tau, ref, use_shift
        self.bound = RoundoffBound(mdp)

    @property
    def in_place(self) -> bool:
        return self.name != "jacobi"

    @property
    def aperiodic_jacobi(self) -> bool:
        return self.name == "jacobi" and self.tau < 1.0

    def improve(self, sweeps: int, shift: float) -> int:
        K, h, pol = self.K, self.h, self.pol
        for _ in range(sweeps):
            K.gauss_seidel(h, self.relax, shift, pol)
            for _ in range(self.n_eval):
                K.evaluate(h, self.relax, shift, pol)
        return sweeps * self.n_eval

    def certify(self, shift: float) -> tuple[float, float]:
        tau = self.tau if self.name == "jacobi" else self.relax
        return self.K.jacobi(self.h, self.h_next, tau, shift if self.use_shift else 0.0)

    def advance(self) -> None:
        self.h_next -= self.h_next[self.ref]
        self.h, self.h_next = self.h_next, self.h

    def roundoff(self) -> float:
        return self.bound(self.h)

    def fall_back(self) -> str | None:
        if self.name == "jacobi":
            return None
        self.name = "jacobi"
        return ""

    def cost_note(self) -> str:
        return f"the costs (max |c| = {self.bound.cmax:.3g}) are too large for float64 arithmetic: rescale them"


def _kernel(mdp: MDP, kernel: str, threads: int | None, in_place: bool = False):
    from .kernels import get_kernel

    try:
        return get_kernel(mdp, kernel, threads, in_place=in_place)
    except ValueError as exc:
        raise SolverError(str(exc)) from exc


def relative_value_iteration(
    mdp: MDP,
    *,
    tol: float = 1e-10,
    atol: float = 0.0,
    max_iter: int = 100_000,
    aperiodicity: float = 0.5,
    h0: np.ndarray | None = None,
    ref_state: int = 0,
    progress: bool | Progress = False,
    kernel: str = "auto",
    threads: int | None = None,
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
    free every sweep. The loop, its closing rule (the round-off band included), the precision
    stop and the start-dependent stop are :mod:`wncs_lp.solvers.iteration`'s.

    Parameters
    ----------
    mdp : MDP
    tol : float
        Relative certificate width (hi - lo) / |g| to reach, finite and > 0.
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
    progress : bool or Progress
        Show the sweeps and the certificate on stderr (:mod:`wncs_lp.progress`: one line
        rewritten on a terminal).
    kernel : {"auto", "numba", "scipy"}
        The sweep kernel (:mod:`wncs_lp.solvers.kernels`): numba's fused single pass when
        importable and the MDP is large enough for numba to pay (``"auto"``), else scipy's
        mat-vec + ``reduceat``. Same iterates up to summation order.
    threads : int, optional
        numba threads of the sweep (default: the usable cores on large MDPs, see
        :func:`wncs_lp.solvers.kernels.get_kernel`; one in a fork of a process that used them).

    Returns
    -------
    Solution
        ``method="rvi"``; ``gain = (lo + hi)/2``; ``bias`` = the h the last certificate was
        computed on, with h[0] = 0; ``policy`` = greedy pairs of that h (ties to the first pair);
        status ``"optimal"``, ``"max_iter"``, ``"inaccurate:precision"`` (tolerance below
        attainable precision) or ``"inaccurate:start_dependent"`` (the optimal gain depends on the
        start state). ``stats`` holds ``tau``, ``span`` (hi - lo), ``rel_gap``, ``converged``,
        ``roundoff_delta`` (the round-off bound delta of the last certificate), ``span_computed``
        (the width before any widening) and ``stop`` (None, or why the run stopped short).
    """
    t0 = time.perf_counter()
    n = mdp.n_states
    tau = float(aperiodicity)
    if not (0.0 < tau <= 1.0):
        raise SolverError(f"aperiodicity must be in (0, 1], got {aperiodicity}")
    if not (0 <= ref_state < n):
        raise SolverError(f"ref_state must be in 0..{n - 1}, got {ref_state}")
    opts = IterationOptions(tol=tol, atol=atol, max_iter=max_iter)
    h = initial_bias(h0, n, ref_state)
    K = _kernel(mdp, kernel, threads)
    prog = as_progress(progress)
    sweeps = _PairSweeps(mdp, K, h, "jacobi", tau=tau, ref=ref_state, use_shift=False)
    out = certified_iteration(sweeps, opts, cost_scale=sweeps.bound.cmax, progress=prog, label="rvi", t0=t0)
    return _finish(mdp, "rvi", sweeps, out, t0, opts, prog,
                   {"tau": tau, "tol": tol, "kernel": K.name, "threads": K.threads})


def _finish(mdp: MDP, method: str, sweeps: _PairSweeps, out: IterationOutcome, t0: float,
            opts: IterationOptions, prog: Progress, stats: dict) -> Solution:
    """The Solution of a value-iteration run.

    At the precision stop the bracket is widened by the round-off bound delta on each side
    (:class:`RoundoffBound`), so that it holds for the exact arithmetic too; ``stats["stop"]``
    says why the run stopped short of the tolerance (precision, start-dependent gain).
    """
    lo, hi = out.lo, out.hi
    delta = sweeps.roundoff()
    extra = {"roundoff_delta": delta, "span_computed": hi - lo, "stop": out.stop}
    if out.stop is not None:
        prog.done(f"[{method}] sweep {out.used:,}: {out.stop}")
    else:
        prog.done(cert_line(f"{method}:{stats['final_scheme']}" if "final_scheme" in stats else method,
                            out.used, lo, hi, opts.tol))
    if out.at_floor:
        lo, hi = lo - delta, hi + delta
    return _iteration_solution(mdp, method, sweeps.h, lo, hi, out.converged, out.used, t0, {**stats, **extra},
                               out.status)


def _iteration_solution(mdp: MDP, method: str, h: np.ndarray, lo: float, hi: float, converged: bool,
                        iterations: int, t0: float, stats: dict, status: Status | None = None) -> Solution:
    """The Solution of a value-iteration run: the certificate [lo, hi] computed on ``h``, its
    midpoint as the gain, ``h - h[0]`` as the bias and h's greedy policy (first minimiser);
    ``stats`` gains ``span``, ``rel_gap`` and ``converged``. ``status`` overrides the default
    ``"optimal"`` / ``"max_iter"``."""
    policy = greedy_policy(mdp, h)
    gain = 0.5 * (lo + hi)
    return Solution(
        method=method,
        status=status or of(OPTIMAL if converged else MAX_ITER),
        gain=gain,
        gain_lower=lo,
        gain_upper=hi,
        bias=h - h[0],
        policy=policy,
        occupation=None,
        iterations=iterations,
        seconds=time.perf_counter() - t0,
        stats={**stats, "span": hi - lo, "rel_gap": (hi - lo) / max(abs(gain), 1e-300), "converged": converged},
        pair_actions=mdp.a_indices,
    )


#: Pairs per block of :func:`greedy_policy`.
GREEDY_BLOCK_PAIRS = 1 << 20



def greedy_policy(mdp: MDP, h: np.ndarray, block: int = GREEDY_BLOCK_PAIRS) -> np.ndarray:
    """The greedy pairs of ``h`` (first minimiser of ``c + P h`` per state), block by block.

    The same pairs as ``greedy_first(mdp, q_values(mdp, h))``, bit for bit: scipy's CSR mat-vec
    sums each row on its own, in stored order, so a block of rows gives the very same q. Whole
    they take ~5 length-L arrays (q, q's row minimum gathered per pair, candidate indices...),
    about 9 bytes per transition on these models, which was the peak of a stored-matrix value
    iteration once its sweep arrays were compact; by blocks of ``block`` pairs the temporaries
    are O(block).
    """
    h = np.asarray(h, dtype=float)
    n, ptr, P = mdp.n_states, mdp.pair_ptr, mdp.P
    out = np.empty(n, dtype=np.int64)
    s0 = 0
    while s0 < n:
        s1 = int(np.searchsorted(ptr, ptr[s0] + block, side="right")) - 1
        s1 = min(max(s1, s0 + 1), n)
        p0, p1 = int(ptr[s0]), int(ptr[s1])
        a, b = int(P.indptr[p0]), int(P.indptr[p1])
        rows = sp.csr_matrix((P.data[a:b], P.indices[a:b], P.indptr[p0:p1 + 1] - a), shape=(p1 - p0, P.shape[1]),
                             copy=False)
        q = mdp.cost[p0:p1] + rows @ h
        starts = ptr[s0:s1] - p0
        qmin = np.minimum.reduceat(q, starts)
        cand = np.where(q == np.repeat(qmin, np.diff(ptr[s0:s1 + 1])), np.arange(p0, p1, dtype=np.int64),
                        np.int64(mdp.n_pairs))
        out[s0:s1] = np.minimum.reduceat(cand, starts)
        s0 = s1
    return out


# ---------------------------------------------------------------------------- VI / MPI
#: value-iteration schemes
SCHEMES = ("auto", "mpi", "gs", "jacobi")


def value_iteration(
    mdp: MDP,
    *,
    tol: float = VI_TOL,
    atol: float = 0.0,
    max_iter: int = 100_000,
    scheme: str = "auto",
    relax: float = 0.8,
    eval_sweeps: int = 1,
    check_every: int = 5,
    h0: np.ndarray | None = None,
    kernel: str = "auto",
    threads: int | None = None,
    stall_checks: int = 40,
    progress: bool | Progress = False,
) -> Solution:
    """Certified average-cost value iteration: Gauss-Seidel / modified policy iteration sweeps.

    Schemes (all on the fused kernels of :mod:`wncs_lp.solvers.kernels`):

    * ``"mpi"`` -- modified policy iteration: a Gauss-Seidel improvement sweep (states in
      order, in place, relaxed by ``relax``: ``h(s) += relax ((T h)(s) - h(s) - shift)``,
      recording the minimising pair) followed by ``eval_sweeps`` in-place sweeps of that
      fixed policy (one pair per state instead of all of them);
    * ``"gs"``  -- the same without the evaluation sweeps;
    * ``"jacobi"`` -- relative value iteration with the aperiodicity transform
      (``tau = 0.5``), exactly :func:`relative_value_iteration`'s iteration;
    * ``"auto"`` -- ``"mpi"`` with the numba kernel, ``"jacobi"`` with the scipy one (no
      in-place sweep). MPI needs 2-3x fewer sweeps than Jacobi on the paper's instances, but
      not on the small preemption model (cap 12: 70 Jacobi sweeps vs ~550).

    Every ``check_every`` improvement sweeps, one Jacobi sweep computes the certificate
    ``lo = min (T h - h) <= g* <= max (T h - h) = hi`` on the current h (valid for any h, so the
    in-place sweeps need no convergence theory to be trusted). The loop -- closing rule with the
    round-off band (:class:`RoundoffBound`), precision stop, Jacobi fallback after
    ``stall_checks`` checks without the width halving, start-dependent stop -- is
    :func:`wncs_lp.solvers.iteration.certified_iteration`.

    Parameters
    ----------
    mdp : MDP
    tol, atol : float
        Relative (default 1e-9; finite, > 0) and absolute (>= 0) certificate widths.
    max_iter : int
        Budget of sweeps of any kind.
    scheme : {"auto", "mpi", "gs", "jacobi"}
    relax : float
        Relaxation of the in-place sweeps, in (0, 1]; 0.8 was the best of 0.5..1 on the
        paper's instances (1.0 can fail to converge on near-periodic chains).
    eval_sweeps : int
        Fixed-policy sweeps after each improvement sweep (``"mpi"``).
    check_every : int
        Improvement sweeps between two certificate (Jacobi) sweeps.
    h0 : (n,) array, optional
        Warm start (e.g. the bias of a neighbouring parameter value in a sweep).
    kernel : {"auto", "numba", "scipy"}
    threads : int, optional
        numba threads of the Jacobi sweeps (the in-place sweeps are sequential); default as
        :func:`wncs_lp.solvers.kernels.get_kernel`.
    stall_checks : int
    progress : bool or Progress
        Show the sweeps and the certificate gap on stderr as it shrinks (:mod:`wncs_lp.progress`).

    Returns
    -------
    Solution
        ``method="vi"``; ``gain = (lo + hi)/2``; ``bias`` = the h the last certificate was
        computed on (h[0] = 0); ``policy`` = its greedy pairs (first minimiser). ``stats``:
        ``scheme``, ``kernel``, ``threads``, ``sweeps`` (improvement + certificate sweeps),
        ``eval_sweeps``, ``checks``, ``relax``, ``rel_gap``, ``bytes_per_sweep``,
        ``fallback`` (None or why the Jacobi scheme took over), ``roundoff_delta``,
        ``span_computed`` and ``stop`` (as :func:`relative_value_iteration`). Status
        ``"optimal"``, ``"max_iter"``, ``"inaccurate:precision"`` or
        ``"inaccurate:start_dependent"``.
    """
    t0 = time.perf_counter()
    if scheme not in SCHEMES:
        raise SolverError(f"unknown value-iteration scheme {scheme!r}; expected auto, mpi, gs or jacobi")
    if not (0.0 < relax <= 1.0):
        raise SolverError(f"relax must be in (0, 1], got {relax}")
    if not (isinstance(eval_sweeps, (int, np.integer)) and eval_sweeps >= 0):
        raise SolverError(f"eval_sweeps must be an integer >= 0, got {eval_sweeps!r}")
    opts = IterationOptions(tol=tol, atol=atol, max_iter=max_iter, check_every=check_every,
                            stall_checks=stall_checks)
    K = _kernel(mdp, kernel, threads, in_place=scheme in ("mpi", "gs"))
    if scheme == "auto":
        scheme = "mpi" if K.supports_gauss_seidel else "jacobi"
    if scheme in ("mpi", "gs") and not K.supports_gauss_seidel:
        raise SolverError(f"scheme {scheme!r} needs in-place sweeps, which the {K.name} kernel does not have")
    h = initial_bias(h0, mdp.n_states, 0)
    prog = as_progress(progress)
    sweeps = _PairSweeps(mdp, K, h, scheme, relax=relax, n_eval=eval_sweeps if scheme == "mpi" else 0)
    out = certified_iteration(sweeps, opts, cost_scale=sweeps.bound.cmax, progress=prog, label="vi", t0=t0)
    from .kernels import prepare

    return _finish(mdp, "vi", sweeps, out, t0, opts, prog, {
        "scheme": scheme, "kernel": K.name, "threads": K.threads, "sweeps": out.used, "eval_sweeps": out.evals,
        "checks": out.checks, "relax": relax, "tol": tol, "bytes_per_sweep": prepare(mdp).bytes_per_sweep,
        "fallback": out.fallback, "final_scheme": sweeps.name})


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
    h0: np.ndarray | None = None,
    max_iter: int = 100,
    tol: float | None = None,
    rtol: float = 1e-12,
    cert_rtol: float | None = None,
    multichain: str = "fallback",
    kernel: str = "auto",
    progress: bool | Progress = False,
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
    h0 : (n,) array, optional
        Warm start as a bias (the keyword value iteration takes): policy iteration starts from
        its greedy policy. Give ``policy0`` or ``h0``, not both.
    max_iter : int
        Maximum number of evaluations.
    tol : float, optional
        The relative certificate width (hi - lo)/|g| required for status ``"optimal"`` (the
        keyword every method takes; default 1e-6). ``cert_rtol`` is its older name.
    rtol : float
        Relative tie tolerance for keeping the current action.
    cert_rtol : float, optional
        Same as ``tol`` (give one of them).
    multichain : {"fallback", "raise"}
        What to do when an iterate induces several recurrent classes (exact evaluation is
        then undefined; it happens at p = 1, e.g. the preemption paper instance). With
        ``"fallback"`` (default), :func:`value_iteration` is run, warm-started from the last
        exact bias, and policy iteration restarts from its greedy policy; if that policy is
        multichain as well, the value-iteration solution is returned (still certified by its
        bracket; ``occupation`` None). ``stats["fallback"]`` says what happened.
        ``"raise"`` re-raises the :class:`MultichainPolicyError`.
    kernel : str
        Sweep kernel of the fallback value iteration.
    progress : bool or Progress
        Show each improvement (gain of the evaluated policy, states changed) on stderr.

    Returns
    -------
    Solution
        ``method="pi"``; ``gain`` = exact gain of the final policy; ``occupation`` = the
        stationary pair frequencies of the final (deterministic) policy.

    Raises
    ------
    PolicyError
        A malformed ``policy0``; with ``multichain="raise"``, a multichain iterate.
    SolverError
        ``tol`` and ``cert_rtol`` both given and different, ``policy0`` and ``h0`` both given,
        or a bad ``h0``.
    """
    t0 = time.perf_counter()
    cert_rtol = _pi_tolerance(tol, cert_rtol)
    if not (is_int(max_iter) and max_iter >= 1):
        raise SolverError(f"max_iter must be an integer >= 1, got {max_iter!r}")
    if multichain not in ("fallback", "raise"):
        raise SolverError(f"multichain must be 'fallback' or 'raise', got {multichain!r}")
    prog = as_progress(progress)
    run = _HowardRun(mdp, _pi_start(mdp, policy0, h0), rtol, multichain, kernel, prog)
    run.iterate(max_iter)
    if run.ev is None or run.vi_stands:  # every iterate multichain: value iteration's certificate stands
        return _vi_as_pi(mdp, run.vi, t0, run.it, run.changes, run.fallback, cert_rtol)
    return _pi_solution(mdp, run, t0, cert_rtol, prog)


def _pi_tolerance(tol: float | None, cert_rtol: float | None) -> float:
    """The certificate's relative width asked for (``tol``, or its older name ``cert_rtol``)."""
    if tol is not None and cert_rtol is not None and tol != cert_rtol:
        raise SolverError(f"policy iteration: give tol or its older name cert_rtol, not both ({tol} and {cert_rtol})")
    out = float(tol if tol is not None else cert_rtol if cert_rtol is not None else 1e-6)
    if not out >= 0:
        raise SolverError(f"tol must be >= 0, got {out}")
    return out


def _pi_start(mdp: MDP, policy0: np.ndarray | None, h0: np.ndarray | None) -> np.ndarray:
    """The first policy: ``policy0``, the greedy policy of ``h0``, or the cheapest pair of each state."""
    if policy0 is not None and h0 is not None:
        raise SolverError("policy iteration starts from policy0 or from the greedy policy of h0, not both")
    if h0 is not None:
        return greedy_first(mdp, q_values(mdp, initial_bias(h0, mdp.n_states, 0)))
    if policy0 is None:
        return greedy_first(mdp, mdp.cost)
    d = np.asarray(policy0)
    if not np.issubdtype(d.dtype, np.integer):
        raise PolicyError(f"policy0 must be an integer array of pair indices, got dtype {d.dtype}")
    return d.astype(np.int64)


class _HowardRun:
    """The evaluate -> improve loop of policy iteration, with its multichain fallback."""

    def __init__(self, mdp: MDP, d: np.ndarray, rtol: float, multichain: str, kernel: str, prog: Progress):
        self.mdp, self.d, self.rtol, self.multichain, self.kernel, self.prog = mdp, d, rtol, multichain, kernel, prog
        self.ev: PolicyEvaluation | None = None
        self.ev_d: np.ndarray = d  # the policy self.ev evaluated
        self.vi: Solution | None = None
        self.vi_stands = False
        self.stable = False
        self.it = 0
        self.changes: list[int] = []
        self.fallback: str | None = None

    def iterate(self, max_iter: int) -> None:
        for self.it in range(1, max_iter + 1):
            try:
                # the stationary law of the last policy only (_pi_solution): the iterates need g and h
                ev = evaluate_policy(self.mdp, self.d, h0=None if self.ev is None else self.ev.bias,
                                     stationary=False)
            except MultichainPolicyError as exc:
                if self.multichain == "raise":
                    raise
                if not self._restart(exc):
                    return
                continue
            self.ev, self.ev_d = ev, self.d
            d_new = _improve(self.mdp, q_values(self.mdp, ev.bias), self.d, self.rtol)
            nchg = int(np.count_nonzero(d_new != self.d))
            self.changes.append(nchg)
            self.prog.tick(f"[pi] iteration {self.it}: gain of the evaluated policy {ev.gain:.10g}, {nchg:,} states "
                           "improve", force=True)
            if nchg == 0:
                self.stable = True
                return
            self.d = d_new

    def _restart(self, exc: MultichainPolicyError) -> bool:
        """A multichain iterate: value iteration, then policy iteration from its greedy policy. False
        when value iteration's policy was multichain already (its certificate then stands)."""
        if self.vi is not None:
            self.fallback = f"value iteration (its greedy policy is multichain too: {exc})"
            self.vi_stands = True
            return False
        self.prog.phase(f"[pi] iterate {self.it} is multichain: value iteration, then policy iteration from its policy")
        self.vi = value_iteration(self.mdp, h0=None if self.ev is None else self.ev.bias, kernel=self.kernel,
                                  progress=self.prog)
        self.fallback = (f"iterate {self.it} multichain; restarted from the value-iteration policy "
                         f"({self.vi.iterations} sweeps)")
        self.d = self.vi.policy.astype(np.int64)
        self.changes.append(-1)
        return True


def _pi_solution(mdp: MDP, run: _HowardRun, t0: float, cert_rtol: float, prog: Progress) -> Solution:
    """The Solution of a policy-iteration run: the exact gain of its last policy, the certificate
    on that policy's bias, its stationary pair frequencies."""
    ev = run.ev
    lo, hi = bracket(mdp, ev.bias)
    rel = (hi - lo) / max(abs(ev.gain), 1e-300)
    if not run.stable:
        status = of(MAX_ITER)
    elif certificate_closed(mdp, lo, hi, ev.gain, cert_rtol):
        status = of(OPTIMAL)
    else:
        status = of(INACCURATE)
    occ = np.zeros(mdp.n_pairs)
    occ[run.ev_d] = stationary_of(mdp, run.ev_d)  # of the evaluated policy (run.d is one step on at max_iter)
    prog.done(f"[pi] {run.it} evaluation(s): {lo:.10g} <= g* <= {hi:.10g}, gap {rel:.2e} ({status})")
    return Solution(
        method="pi", status=status, gain=ev.gain, gain_lower=lo, gain_upper=hi, bias=ev.bias, policy=run.d.copy(),
        occupation=occ, iterations=run.it, seconds=time.perf_counter() - t0,
        stats={"stable": run.stable, "changes": run.changes, "rel_gap": rel, "eval_residual": ev.residual,
               "fallback": run.fallback, "vi_sweeps": None if run.vi is None else run.vi.iterations,
               "tol": cert_rtol},
        pair_actions=mdp.a_indices,
    )


def _vi_as_pi(mdp: MDP, vi: Solution, t0: float, it: int, changes: list, fallback: str, cert_rtol: float) -> Solution:
    closed = vi.ok and certificate_closed(mdp, vi.gain_lower, vi.gain_upper, vi.gain, cert_rtol)
    return Solution(
        method="pi",
        status=of(OPTIMAL) if closed else (vi.status if not vi.ok else of(INACCURATE)),
        gain=vi.gain,
        gain_lower=vi.gain_lower,
        gain_upper=vi.gain_upper,
        bias=vi.bias,
        policy=vi.policy,
        occupation=None,
        iterations=it,
        seconds=time.perf_counter() - t0,
        stats={"stable": False, "changes": changes, "rel_gap": vi.gap, "eval_residual": None,
               "fallback": fallback, "vi_sweeps": vi.iterations, "multichain_policy": True,
               "stop": vi.stats.get("stop")},
        pair_actions=mdp.a_indices,
    )
