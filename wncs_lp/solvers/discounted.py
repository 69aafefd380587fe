r"""The discounted criterion beside the average cost: certified solves for a discount factor beta.

For a discount factor :math:`0 \le \beta < 1` the value of a stationary policy d from state s is
:math:`v_d(s) = E_s \sum_{t \ge 0} \beta^t c(s_t, d(s_t))`, the unique solution of
:math:`v_d = c_d + \beta P_d v_d`, and the optimal value is the fixed point of

.. math::

    (T_\beta v)(s) = \min_{l:\, s_l = s} \Big( c_l + \beta \sum_{s'} P(s' \mid l)\, v(s') \Big).

**Certificate.** For any v, with :math:`\delta = T_\beta v - v`, MacQueen's bounds

.. math::

    T_\beta v + \tfrac{\beta}{1-\beta} \min_s \delta(s) \;\le\; v^* \;\le\;
    T_\beta v + \tfrac{\beta}{1-\beta} \max_s \delta(s)

hold state by state (Puterman, *Markov Decision Processes*, Thm. 6.6.3). Every method below ends
the same way, whatever produced its policy d: ``value`` is the exact :math:`v_d` (one sparse
solve of :math:`(I - \beta P_d) v = c_d`), ``lower`` the bound above on :math:`v_d`, so
:math:`\text{lower} \le v^* \le v_d = \text{value}`, and the solution is ``"optimal"`` only when
``gap = max_s (value - lower)`` is within the tolerance (relative to the size of the value).

**Methods.** ``"pi"``: Howard's policy iteration (exact, a few iterations); ``"vi"``: value
iteration stopped by the bounds; ``"lp"``: the discounted occupation-measure LP on HiGHS,

.. math::

    \min_{x \ge 0} \sum_l c_l x_l \quad \text{s.t.} \quad
    \sum_{l:\, s_l = s} x_l - \beta \sum_l P(s \mid l)\, x_l = \mu(s) \quad \forall s,

with :math:`\mu` uniform (every state then has :math:`x > 0` on some pair, which is its action).

**Towards the average cost.** For a fixed policy with gain g and bias h normalised by its
stationary law (:math:`\pi h = 0`), the Laurent expansion
:math:`v_\beta = g / (1-\beta) + h + O(1-\beta)` holds (Puterman Thm. 8.2.3, for a unichain
policy, periodic or not): :math:`(1-\beta) v_\beta \to g` and :math:`v_\beta - g/(1-\beta) \to h` as
:math:`\beta \to 1`, and the discounted optimal policies are average-cost optimal for beta close
enough to 1 (Blackwell). :func:`laurent_terms` computes the two sides for a policy.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import SolverError
from ..mdp import MDP
from .. import methods, moved
from ..methods import DISCOUNTED, DISCOUNTED_CRITERION, Entry
from ..policy_forms import policy_array
from .certify import greedy_first
from .result import describe_array, result_repr

__all__ = ["DiscountedSolution", "run_discounted", "check_discount", "discounted_value", "laurent_terms",
           "DISCOUNTED_METHODS",
           "DISCOUNTED_ENTRIES"]

#: The methods :func:`run_discounted` takes (the rows of :data:`wncs_lp.methods.DISCOUNTED`).
DISCOUNTED_METHODS = tuple(DISCOUNTED)


@dataclass(frozen=True, repr=False)
class DiscountedSolution:
    """A certified solution of the discounted problem (module docstring).

    Attributes
    ----------
    beta : float
        The discount factor.
    method : str
        ``"pi"``, ``"vi"`` or ``"lp"``.
    status : str
        ``"optimal"`` when ``gap`` is within the tolerance, else ``"inaccurate"`` (or
        ``"max_iter"`` when value iteration ran out of sweeps).
    value : (n,) array
        The exact discounted value :math:`v_d` of the returned policy (an upper bound on v*).
    lower : (n,) array
        A certified lower bound on the optimal value v*.
    gap : float
        ``max(value - lower)``: how far the policy can be from optimal, in any state.
    policy : (n,) int array
        The chosen pair of each state.
    iterations : int
    seconds : float
    pair_actions : (L,) int array
        The MDP's ``a_indices``, for :attr:`sigma`.
    """

    beta: float
    method: str
    status: str
    value: np.ndarray
    lower: np.ndarray
    gap: float
    policy: np.ndarray
    iterations: int = 0
    seconds: float = 0.0
    pair_actions: np.ndarray | None = field(default=None, repr=False)

    @property
    def sigma(self) -> np.ndarray | None:
        """The action index of each state (a row of ``mdp.action_table``), QuantEcon's ``sigma``."""
        return None if self.pair_actions is None else np.asarray(self.pair_actions)[self.policy]

    @property
    def ok(self) -> bool:
        """The certificate closed (``status == "optimal"``), as every solution of the toolkit says it."""
        return self.status == "optimal"

    def __repr__(self) -> str:
        rows = [("status", self.status), ("beta", f"{self.beta:g}"), ("gap", f"{self.gap:.3g}"),
                ("value", describe_array(self.value, "floats") + " (exact, of the policy)"),
                ("lower", describe_array(self.lower, "floats") + " (certified bound on v*)"),
                ("policy", describe_array(self.policy, "pair indices") + ", one per state"),
                ("iterations", str(self.iterations)), ("seconds", f"{self.seconds:.3g}")]
        return result_repr(f"DiscountedSolution of {self.policy.size:,} states by {self.method}", rows)


def check_discount(beta: Any) -> float:
    """``beta`` as a float if it is a discount factor in [0, 1), else one :class:`SolverError` saying so."""
    try:
        b = float(beta)
    except (TypeError, ValueError):
        raise SolverError(f"the discount factor beta must be a number in [0, 1); got {beta!r}") from None
    if not 0.0 <= b < 1.0:
        raise SolverError(f"the discount factor beta must be in [0, 1); got {beta!r}")
    return b


def discounted_value(mdp: MDP, policy: Any = None, beta: float = 0.95, *, sigma: Any = None) -> np.ndarray:
    r"""The exact discounted value :math:`v = (I - \beta P_d)^{-1} c_d` of a stationary policy.

    Parameters
    ----------
    mdp : MDP
    policy : Policy, solution or array
        Any form of :func:`wncs_lp.policy_forms.policy_array` (pair indices, pair probabilities).
    beta : float
        In [0, 1).
    sigma : (n,) int array, optional
        The policy as an action per state instead.

    Returns
    -------
    (n,) float array
    """
    b = check_discount(beta)
    arr = policy_array(mdp, policy, sigma)
    if np.issubdtype(arr.dtype, np.integer):
        P_d, c_d = mdp.P[arr], np.asarray(mdp.cost)[arr]
    else:  # pair probabilities: P_d = B P with B the (n, L) matrix of the probabilities
        B = sp.csr_matrix((arr, (mdp.s_indices, np.arange(mdp.n_pairs))), shape=(mdp.n_states, mdp.n_pairs))
        P_d, c_d = B @ mdp.P, B @ np.asarray(mdp.cost)
    A = (sp.identity(mdp.n_states, format="csc") - b * sp.csc_matrix(P_d)).tocsc()
    return np.asarray(spla.spsolve(A, c_d), dtype=float).reshape(-1)


def _bellman(mdp: MDP, v: np.ndarray, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """``(Q, T v)``: the pair values and their minimum per state."""
    q = mdp.cost + beta * (mdp.P @ v)
    return q, np.minimum.reduceat(q, mdp.pair_ptr[:-1])


def _bounds(mdp: MDP, v: np.ndarray, beta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MacQueen's ``(lower, upper)`` on v* from one Bellman step on v, and the pair values."""
    q, tv = _bellman(mdp, v, beta)
    d = tv - v
    k = beta / (1.0 - beta) if beta > 0 else 0.0
    return tv + k * d.min(), tv + k * d.max(), q


def _policy_iteration(mdp: MDP, beta: float, max_iter: int) -> tuple[np.ndarray, int, str]:
    """Howard's policy iteration; a pair changes only on a strict improvement (no cycling on ties)."""
    q0 = np.asarray(mdp.cost, dtype=float)
    pol = greedy_first(mdp, q0)
    for it in range(1, max_iter + 1):
        v = discounted_value(mdp, pol, beta)
        q, tv = _bellman(mdp, v, beta)
        tol = 1e-12 * max(1.0, float(np.abs(v).max()))
        better = q[pol] > tv + tol
        if not better.any():
            return pol, it, "optimal"
        pol = np.where(better, greedy_first(mdp, q, tv), pol)
    return pol, max_iter, "max_iter"


def _value_iteration(mdp: MDP, beta: float, tol: float, max_iter: int) -> tuple[np.ndarray, int, str]:
    """Value iteration until MacQueen's bounds are within ``tol`` (relative); the greedy policy."""
    v = np.zeros(mdp.n_states)
    for it in range(1, max_iter + 1):
        lo, hi, q = _bounds(mdp, v, beta)
        if float((hi - lo).max()) <= tol * max(1.0, float(np.abs(hi).max())):
            return greedy_first(mdp, q), it, "optimal"
        v = 0.5 * (lo + hi)  # the midpoint of the bounds: the extrapolated value (closer than T v)
    return greedy_first(mdp, _bellman(mdp, v, beta)[0]), max_iter, "max_iter"


def _linear_program(mdp: MDP, beta: float) -> tuple[np.ndarray, int, str]:
    """The discounted occupation-measure LP on HiGHS; each state's pair of largest frequency."""
    from scipy.optimize import linprog

    n, L = mdp.n_states, mdp.n_pairs
    own = sp.csr_matrix((np.ones(L), (mdp.s_indices, np.arange(L))), shape=(n, L))
    A = (own - beta * mdp.P.T).tocsr()
    res = linprog(np.asarray(mdp.cost, dtype=float), A_eq=A, b_eq=np.full(n, 1.0 / n), bounds=(0, None),
                  method="highs")
    if res.status != 0 or res.x is None:
        raise SolverError(f"HiGHS did not solve the discounted LP (beta = {beta:g}): {res.message}")
    x = np.asarray(res.x)
    best = np.maximum.reduceat(x, mdp.pair_ptr[:-1])
    cand = np.where(x == best[mdp.s_indices], np.arange(L, dtype=np.int64), np.int64(L))
    return np.minimum.reduceat(cand, mdp.pair_ptr[:-1]), int(getattr(res, "nit", 0)), "optimal"


def _run_policy_iteration(mdp: MDP, beta: float, tol: float, max_iter: int | None) -> tuple[np.ndarray, int, str]:
    return _policy_iteration(mdp, beta, max_iter or 1000)


def _run_value_iteration(mdp: MDP, beta: float, tol: float, max_iter: int | None) -> tuple[np.ndarray, int, str]:
    return _value_iteration(mdp, beta, tol / 10, max_iter or 1_000_000)


def _run_linear_program(mdp: MDP, beta: float, tol: float, max_iter: int | None) -> tuple[np.ndarray, int, str]:
    return _linear_program(mdp, beta)


#: The discounted methods' functions, one entry per row of :data:`wncs_lp.methods.DISCOUNTED`:
#: ``run(mdp, beta, tol, max_iter) -> (policy, iterations, status)``.
DISCOUNTED_ENTRIES: dict[str, Entry] = {
    "pi": Entry(DISCOUNTED["pi"], _run_policy_iteration),
    "vi": Entry(DISCOUNTED["vi"], _run_value_iteration),
    "lp": Entry(DISCOUNTED["lp"], _run_linear_program),
}


def run_discounted(mdp: MDP, beta: float, method: str = "pi", *, tol: float = 1e-9,
                   max_iter: int | None = None) -> DiscountedSolution:
    """The discounted step of :func:`wncs_lp.solve` (``discount=beta``) on an MDP: the discounted
    problem with discount factor ``beta``, certified (module docstring).

    Parameters
    ----------
    mdp : MDP
    beta : float
        The discount factor, in [0, 1).
    method : {"pi", "vi", "lp"}
        Policy iteration (default), value iteration, or the LP on HiGHS.
    tol : float
        The certificate closes when ``gap <= tol * max(1, max |value|)``.
    max_iter : int, optional
        Iterations of ``pi`` (default 1,000) or sweeps of ``vi`` (default 1,000,000).

    Returns
    -------
    DiscountedSolution
        ``status == "optimal"`` only when the certificate closed.

    Raises
    ------
    SolverError
        beta outside [0, 1), an unknown method, or an LP HiGHS could not solve.
    """
    b = check_discount(beta)
    found = DISCOUNTED_ENTRIES[methods.method(method, criterion=DISCOUNTED_CRITERION).name]
    t0 = time.perf_counter()
    pol, its, status = found.run(mdp, b, tol, max_iter)
    value = discounted_value(mdp, pol, b)
    lower, _, _ = _bounds(mdp, value, b)
    lower = np.minimum(lower, value)  # v_d >= v* >= lower: a rounding above v_d says nothing more
    gap = float((value - lower).max()) if value.size else 0.0
    closed = gap <= tol * max(1.0, float(np.abs(value).max()) if value.size else 1.0)
    return DiscountedSolution(beta=b, method=method, status="optimal" if closed else (
        "max_iter" if status == "max_iter" else "inaccurate"), value=value, lower=lower, gap=gap,
        policy=pol.astype(np.int64), iterations=its, seconds=time.perf_counter() - t0,
        pair_actions=np.asarray(mdp.a_indices))


def laurent_terms(mdp: MDP, policy: Any, beta: float, *, gain: float, bias: np.ndarray,
                  stationary: np.ndarray) -> dict[str, float]:
    r"""How far the discounted value of a policy is from its Laurent expansion at ``beta``.

    With :math:`v_\beta` the exact discounted value, g the gain, h the bias and :math:`\pi` the
    stationary law of the (unichain) policy, returns ``gain_error`` = :math:`\max_s
    |(1-\beta) v_\beta(s) - g|` and ``bias_error`` = :math:`\max_s |v_\beta(s) - g/(1-\beta) -
    (h(s) - \pi h)|`, both :math:`O(1-\beta)` (module docstring).
    """
    v = discounted_value(mdp, policy, beta)
    h = np.asarray(bias, dtype=float)
    h = h - float(np.asarray(stationary) @ h)
    return {"beta": float(beta), "gain_error": float(np.abs((1 - beta) * v - gain).max()),
            "bias_error": float(np.abs(v - gain / (1 - beta) - h).max())}


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
