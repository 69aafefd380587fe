r"""The pieces of relaxation 2 that live on one process's chain (tau_k, C), and its certificate.

Relaxation 2 (see :mod:`wncs_lp.bounds.joint`) gives each process k its own chain over
(tau_k, C), the joint server configuration C, driven by the joint pairs p = (C, a). Three things
are computed here, all from a :class:`~wncs_lp.models.system.System`'s automaton and cost tables,
never from the tau box:

* :func:`certify_tables` -- **the certificate**. For any tables h_k(tau, C),

  .. math::

      u_k(p) = \max_\tau \Big[h_k(\tau, C_p) - q_k(\tau) - \sum_o P(o|p)\, h_k(\tau'_k(o), C'(o))\Big],
      \qquad g(h) = -\max_p \sum_k u_k(p)

  is a lower bound on g*: (g(h), h) is feasible in the approximate LP of relaxation 2, whose
  every feasible point is a Bellman sub-solution of the joint MDP. It is computed constraint by
  constraint (N * tau_hat * |C x A| evaluations), and the floating-point error of the
  evaluation is bounded and subtracted.
* :func:`solve_chain` -- process k's **priced chain**: the average-cost MDP on (tau_k, C) with
  pair cost q_k(tau) + mu_k(p), solved by relative value iteration to a Bellman bracket
  lower <= g_k(mu_k) <= upper.
* :func:`stationary` and :func:`column` -- the stationary law of a (randomised) policy of the
  priced chain and its (C, a) marginal: a cutting plane g_k(mu'_k) <= a + <x, mu'_k> of the
  Lagrangian of relaxation 2, valid for every price mu'_k.

The hot loops run in numba (:mod:`wncs_lp.bounds.joint_kernels`) when it imports, else in numpy
/ scipy (the same arithmetic up to summation order).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .. import moved
from ..errors import SolverError
from ..models.system import System
from ..solvers.threads import run_twins

__all__ = ["JointData", "TableCertificate", "ChainSolution", "Kernels", "certify_tables", "certificate_of",
           "solve_chain", "damped_rvi", "policy_weights", "stationary", "lazy_power", "column", "kernels_available"]

_UNIT = np.finfo(float).eps / 2  # unit round-off u = 2^-53


def _gamma(n: int) -> float:
    """Higham's gamma_n = n u / (1 - n u): the relative error bound of an n-term sum of products."""
    return n * _UNIT / (1.0 - n * _UNIT)


@dataclass(frozen=True, eq=False)
class JointData:
    """The flat automaton of a :class:`System` as relaxation 2 reads it (no tau box).

    Attributes
    ----------
    caps : (N,) int array
        tau_hat_k.
    q : tuple of (tau_hat_k,) arrays
        q_k(tau) at index tau - 1.
    act_ptr : (|C| + 1,) int array
        The pairs of configuration c are ``act_ptr[c]:act_ptr[c+1]`` (configuration-major, in
        the automaton's action order: pair p is the global action index of the automaton).
    pair_c : (|C x A|,) int array
        The configuration of each pair.
    out_ptr, out_nxt, out_prob : outcome arrays
        The outcomes of pair p are ``out_ptr[p]:out_ptr[p+1]``, with next configuration and
        probability.
    out_delta : (E, N) int array
        Delivery age of each outcome per process (0: none).
    """

    caps: np.ndarray
    q: tuple
    act_ptr: np.ndarray
    pair_c: np.ndarray
    out_ptr: np.ndarray
    out_nxt: np.ndarray
    out_prob: np.ndarray
    out_delta: np.ndarray

    @classmethod
    def from_system(cls, system: System) -> "JointData":
        n = system.n_processes
        fl = system.automaton.flat(n)
        act_ptr = np.ascontiguousarray(fl.act_ptr, dtype=np.int64)
        pair_c = np.repeat(np.arange(act_ptr.size - 1), np.diff(act_ptr)).astype(np.int64)
        delta = np.ascontiguousarray(np.asarray(fl.deltas, dtype=np.int64)[fl.out_delta].reshape(-1, n))
        return cls(caps=np.asarray(system.caps, dtype=np.int64), q=tuple(np.asarray(t, float) for t in system.q),
                   act_ptr=act_ptr, pair_c=pair_c, out_ptr=np.ascontiguousarray(fl.out_ptr, dtype=np.int64),
                   out_nxt=np.ascontiguousarray(fl.out_nxt, dtype=np.int64),
                   out_prob=np.ascontiguousarray(fl.out_prob, dtype=float), out_delta=delta)

    # ------------------------------------------------------------------ sizes
    @property
    def n_processes(self) -> int:
        return int(self.caps.size)

    @property
    def n_configs(self) -> int:
        return int(self.act_ptr.size - 1)

    @property
    def n_pairs(self) -> int:
        return int(self.pair_c.size)

    @property
    def n_outcomes(self) -> int:
        return int(self.out_nxt.size)

    @cached_property
    def max_outcomes(self) -> int:
        """The most outcomes of one pair (the length of the sums in the certificate)."""
        return int(np.diff(self.out_ptr).max())

    @cached_property
    def prob_defect(self) -> float:
        """max_p |1 - sum_o P(o|p)|, summed exactly: the outcome tables are stochastic up to this."""
        return max(abs(1.0 - math.fsum(self.out_prob[a:b])) for a, b in zip(self.out_ptr[:-1], self.out_ptr[1:]))

    # ------------------------------------------------------------------ per process
    @cached_property
    def sat(self) -> np.ndarray:
        """(E, N) int array m: under outcome o, AoI index t of process k moves to min(t + 1, m)
        (m = tau_hat_k - 1, or the delivered age - 1 when that is smaller)."""
        cap = self.caps[None, :] - 1
        d = self.out_delta
        return np.ascontiguousarray(np.where((d > 0) & (d - 1 < cap), d - 1, cap))

    @cached_property
    def sat_columns(self) -> tuple:
        """The columns of :attr:`sat`, each contiguous."""
        return tuple(np.ascontiguousarray(self.sat[:, k]) for k in range(self.n_processes))

    def sat_of(self, k: int) -> np.ndarray:
        """Process k's column of :attr:`sat`, contiguous."""
        return self.sat_columns[k]

    def next_t(self, k: int) -> np.ndarray:
        """(E, tau_hat_k) int array: the successor AoI index of index t under each outcome."""
        cap = int(self.caps[k])
        return np.minimum(np.arange(1, cap + 1)[None, :], self.sat[:, k][:, None])

    def expect(self, k: int, h: np.ndarray) -> np.ndarray:
        """(|C x A|, tau_hat_k): sum_o P(o|p) h_k(tau'_k(o), C'(o)) for every pair and AoI."""
        vals = self.out_prob[:, None] * h[self.out_nxt[:, None], self.next_t(k)]
        return np.add.reduceat(vals, self.out_ptr[:-1], axis=0)


# ---------------------------------------------------------------------------- the certificate
@dataclass(frozen=True, eq=False)
class TableCertificate:
    r"""A lower bound on g* from separable tables, checked constraint by constraint.

    Attributes
    ----------
    lower_bound : float
        ``raw - roundoff``: a lower bound on g* for the exact arithmetic.
    raw : float
        g(h) = -max_p sum_k u_k(p) as computed in floating point.
    roundoff : float
        A bound on the floating-point error of ``raw`` (Higham's gamma bounds on the sums, plus
        the outcome tables' defect from stochastic times max|h|).
    u : (N, |C x A|) array
        u_k(p) = max_tau [h_k(tau, C_p) - q_k(tau) - E h_k(tau', C')].
    binding_pair : int
        A pair p where sum_k u_k(p) is largest (where the bound is decided).
    """

    lower_bound: float
    raw: float
    roundoff: float
    u: np.ndarray
    binding_pair: int


def certify_tables(data: JointData, tables) -> TableCertificate:
    r"""The certified lower bound g(h) of separable tables ``tables[k]`` of shape (|C|, tau_hat_k).

    Valid for *any* tables: with u_k(p) = max_tau [h_k(tau, C_p) - q_k(tau) - E h_k(tau', C')],
    the pair (g(h), h), g(h) = -max_p sum_k u_k(p), satisfies

    .. math:: g(h) + \sum_k h_k(\tau_k, C) \le c(\tau) + \sum_o P(o|C,a) \sum_k h_k(\tau'_k, C')

    for every (tau, C, a) of the box by construction, and telescoping it along any policy of the
    joint MDP gives g(h) <= g*. Each table is first shifted by a constant (which changes no
    constraint beyond the outcome tables' defect from stochastic, accounted for) to make its
    magnitudes, and so the round-off, small. Tables with a non-finite entry certify nothing
    (``lower_bound`` = -inf).

    Raises
    ------
    SolverError
        ``tables`` is not one (|C|, tau_hat_k) array per process.
    """
    tables = _checked_tables(data, tables)
    return certificate_of(data, tables, data.q,
                          lambda k, h: (h[data.pair_c] - data.q[k][None, :] - data.expect(k, h)).max(axis=1))


def certificate_of(data: JointData, tables: list[np.ndarray], costs, residual_max) -> TableCertificate:
    """The certificate of tables split into parts over the joint configuration (one per process for
    relaxation 2, one per group for relaxation 4): for each (C, a) pair every part's largest
    residual u_i(p) = max over its ages of [h_i - q_i - E h_i], g(h) = -max_p sum_i u_i(p), less a
    bound on its round-off.

    Each table is first shifted by a constant (which changes no constraint beyond the outcome
    tables' defect from stochastic, accounted for) to make its magnitudes, and so the round-off,
    small; ``residual_max(i, h)`` returns the (|C x A|,) residuals of part i on the shifted table
    ``h``. Tables with a non-finite entry certify nothing (``lower_bound`` = -inf).
    """
    n = len(tables)
    if not all(np.isfinite(h).all() for h in tables):
        return TableCertificate(lower_bound=-np.inf, raw=-np.inf, roundoff=np.inf, u=np.full((n, data.n_pairs), np.inf),
                                binding_pair=-1)
    u = np.empty((n, data.n_pairs))
    err = 0.0
    m = data.max_outcomes
    for i, table in enumerate(tables):
        h = table - 0.5 * (table.max() + table.min())
        hk = float(np.abs(h).max())
        u[i] = residual_max(i, h)
        err += _gamma(m + 2) * (2.0 * hk + float(np.abs(costs[i]).max())) + data.prob_defect * hk
    total = u.sum(axis=0)
    p = int(np.argmax(total))
    err += _gamma(n) * float(np.abs(u).max(axis=1).sum())
    raw = -float(total[p])
    return TableCertificate(lower_bound=raw - err, raw=raw, roundoff=err, u=u, binding_pair=p)


def _checked_tables(data: JointData, tables) -> list[np.ndarray]:
    """The tables as float arrays, one (|C|, tau_hat_k) per process, or one clear error."""
    if len(tables) != data.n_processes:
        raise SolverError(f"relaxation 2's certificate needs {data.n_processes} value tables (one per process), "
                          f"got {len(tables)}")
    out = []
    for k, h in enumerate(tables):
        h = np.asarray(h, dtype=float)
        want = (data.n_configs, int(data.caps[k]))
        if h.shape != want:
            raise SolverError(f"value table of process {k + 1} has shape {h.shape}; expected {want} "
                              "(configurations x tau_hat)")
        out.append(h)
    return out


# ---------------------------------------------------------------------------- kernels
_NUMBA = None


def kernels_available() -> bool:
    """Whether the numba kernels import (and ``WNCS_LP_NO_NUMBA`` is not set)."""
    global _NUMBA
    if _NUMBA is None:
        _NUMBA = False
        if not os.environ.get("WNCS_LP_NO_NUMBA"):
            try:
                from . import joint_kernels as mod

                _NUMBA = mod
            except Exception:  # numba missing or broken: numpy / scipy do the work
                _NUMBA = False
    return _NUMBA is not False


class Kernels:
    """The loops of relaxation 2 with numba (``threads`` >= 2: a parallel driver) or numpy / scipy.

    Parameters
    ----------
    kernel : {"auto", "numba", "numpy"}
    threads : int
        numba threads for the parallel loops (1: serial; numba's OpenMP layer does not survive
        a fork, so parallel loops are an opt-in).
    """

    def __init__(self, kernel: str = "auto", threads: int = 1):
        if kernel not in ("auto", "numba", "numpy"):
            raise ValueError(f"unknown kernel {kernel!r}; expected 'auto', 'numba' or 'numpy'")
        if kernel == "numba" and not kernels_available():
            raise ValueError("kernel 'numba' requested but numba is not importable (pip install 'wncs_lp[fast]')")
        self.mod = _NUMBA if kernel != "numpy" and kernels_available() else None
        self.name = "numba" if self.mod is not None else "numpy"
        self.threads = 1
        if self.mod is not None:
            import numba

            self.threads = max(1, min(int(threads or 1), numba.config.NUMBA_NUM_THREADS))

    def parallel(self, serial, par, *args):
        """Run ``par`` under this many numba threads (``serial`` with one)."""
        return run_twins(par, serial, self.threads, *args)

    def bellman(self, data: JointData, k: int, h: np.ndarray, price: np.ndarray, th: np.ndarray, pol: np.ndarray):
        """th = T h of process k's priced chain (pair cost q_k + price); pol = a minimising pair."""
        cap = int(data.caps[k])
        if self.mod is not None:
            self.parallel(self.mod.bellman_ser, self.mod.bellman_par, h, data.q[k], price, cap, data.act_ptr,
                          data.out_ptr, data.out_nxt, data.out_prob, data.sat_of(k), th, pol)
            return
        val = price[:, None] + data.expect(k, h)
        starts = data.act_ptr[:-1]
        best = np.minimum.reduceat(val, starts, axis=0)
        th[:] = best + data.q[k][None, :]
        idx = np.where(val <= best[data.pair_c], np.arange(data.n_pairs)[:, None], data.n_pairs)
        pol[:] = np.minimum.reduceat(idx, starts, axis=0)

    def soft_bellman(self, data: JointData, k: int, h: np.ndarray, price: np.ndarray, eta: float, th: np.ndarray,
                     weights: np.ndarray):
        """th = T_eta h, the soft minimum over pairs at temperature ``eta`` of process k's priced chain
        (:mod:`~wncs_lp.bounds.joint_smooth`); weights[p, t] = the softmin policy's probabilities."""
        cap = int(data.caps[k])
        if self.mod is not None:
            self.mod.soft_bellman(h, data.q[k], price, cap, data.act_ptr, data.out_ptr, data.out_nxt, data.out_prob,
                                  data.sat_of(k), float(eta), th, weights)
            return
        val = price[:, None] + data.expect(k, h)
        starts = data.act_ptr[:-1]
        best = np.minimum.reduceat(val, starts, axis=0)
        e = np.exp((best[data.pair_c] - val) / eta)
        tot = np.add.reduceat(e, starts, axis=0)
        th[:] = data.q[k][None, :] + best - eta * np.log(tot)
        weights[:] = e / tot[data.pair_c]

    def push(self, data: JointData, k: int, y: np.ndarray, weights: np.ndarray, y_out: np.ndarray):
        """y_out = y P_pi for the randomised policy ``weights[p, t]``."""
        cap = int(data.caps[k])
        if self.mod is not None:
            self.mod.push(y, weights, cap, data.act_ptr, data.out_ptr, data.out_nxt, data.out_prob,
                          data.sat_of(k), y_out)
            return
        flow = y[data.pair_c] * weights  # (P, cap) mass leaving through each pair
        vals = np.repeat(flow, np.diff(data.out_ptr), axis=0) * data.out_prob[:, None]
        y_out[:] = 0.0
        np.add.at(y_out, (np.repeat(data.out_nxt, cap).reshape(-1, cap), data.next_t(k)), vals)


# ---------------------------------------------------------------------------- the priced chain
@dataclass(frozen=True, eq=False)
class ChainSolution:
    """Process k's priced chain solved by relative value iteration.

    Attributes
    ----------
    h : (|C|, tau_hat_k) array
        The last iterate (a bias when the bracket is closed), h[0, 0] = 0.
    lower, upper : float
        min and max of (T h - h): lower <= g_k(mu_k) <= upper (the optimal gain of the chain,
        from every state).
    policy : (|C|, tau_hat_k) int array
        A pair minimising the Bellman operator at each state (the greedy policy of ``h``).
    sweeps : int
    """

    h: np.ndarray
    lower: float
    upper: float
    policy: np.ndarray
    sweeps: int


def solve_chain(data: JointData, k: int, price: np.ndarray, h0: np.ndarray | None, kern: Kernels, *,
                tol: float, max_sweeps: int = 100_000, relax: float = 0.9, stop=None) -> ChainSolution:
    """Relative value iteration on process k's priced chain until upper - lower <= tol * max(|lower|, 1).

    ``h <- h + relax (T h - h) - shift``: the damping (relax < 1) makes the iteration converge
    on periodic chains too, and the bracket [min (T h - h), max (T h - h)] holds for any h.
    ``stop()`` (optional) is polled every 16 sweeps and ends the iteration early.
    """
    cap = int(data.caps[k])
    shape = (data.n_configs, cap)
    h = np.zeros(shape) if h0 is None else np.array(h0, dtype=float, copy=True)
    th = np.empty(shape)
    pol = np.empty(shape, dtype=np.int64)
    price = np.ascontiguousarray(price, dtype=float)
    lo, hi, sweeps = damped_rvi(lambda x: kern.bellman(data, k, x, price, th, pol), h, th, tol=tol,
                                max_sweeps=max_sweeps, relax=relax, stop=stop)
    return ChainSolution(h=h, lower=lo, upper=hi, policy=pol, sweeps=sweeps)


def damped_rvi(bellman, h: np.ndarray, th: np.ndarray, *, tol: float, max_sweeps: int, relax: float,
               stop=None, fused=None) -> tuple[float, float, int]:
    """The relative value iteration of the relaxations' priced chains, in place on ``h``:
    ``bellman(h)`` writes T h into ``th``; h <- h + relax (T h - h), recentred at h[0, 0], until
    max (T h - h) - min (T h - h) <= tol * max(|min|, 1), ``max_sweeps`` or ``stop()`` (polled
    every 16 sweeps). Returns (min, max, sweeps): the bracket of the chain's gain at the last h.

    ``fused``: a pair (bracket, update) of kernels doing the same arithmetic without temporaries,
    ``bracket(th, h) -> (min, max)`` of th - h and ``update(h, th, relax)`` (the same numbers)."""
    lo, hi = -np.inf, np.inf
    sweeps = 0
    while sweeps < max_sweeps:
        bellman(h)
        sweeps += 1
        if fused is None:
            d = th - h
            lo, hi = float(d.min()), float(d.max())
        else:
            lo, hi = fused[0](th, h)
        if hi - lo <= tol * max(abs(lo), 1.0) or (stop is not None and sweeps % 16 == 0 and stop()):
            break
        if fused is None:
            h += relax * d
            h -= h[0, 0]
        else:
            fused[1](h, th, relax)
    return lo, hi, sweeps


def policy_weights(data: JointData, k: int, policy: np.ndarray) -> np.ndarray:
    """(|C x A|, tau_hat_k) 0/1 weights of a deterministic policy given as pair per state."""
    cap = int(data.caps[k])
    w = np.zeros((data.n_pairs, cap))
    w[policy, np.arange(cap)[None, :]] = 1.0
    return w


def stationary(data: JointData, k: int, weights: np.ndarray, kern: Kernels, y0: np.ndarray | None = None, *,
               tol: float = 1e-11, max_sweeps: int = 20_000) -> tuple[np.ndarray, float, int]:
    """A stationary law of the policy ``weights`` on process k's chain, by power iteration of the
    lazy chain (P + I) / 2 from ``y0`` (default uniform): (y, ||y P - y||_1, sweeps).

    Any stationary law (a mixture of the recurrent classes' laws when the policy is multichain)
    gives a valid cut; ``y0`` decides which one, so a warm start keeps the cuts of successive
    iterations consistent.
    """
    cap = int(data.caps[k])
    shape = (data.n_configs, cap)
    y = np.full(shape, 1.0 / (shape[0] * cap)) if y0 is None else np.array(y0, dtype=float, copy=True)
    return lazy_power(lambda x, out: kern.push(data, k, x, weights, out), y, tol=tol, max_sweeps=max_sweeps)


def lazy_power(push, y: np.ndarray, *, tol: float, max_sweeps: int,
               lazy: float = 0.5, mix=None) -> tuple[np.ndarray, float, int]:
    """Power iteration of the lazy chain lazy I + (1 - lazy) P from ``y`` (normalised first), the
    stationary laws of the relaxations' priced chains: ``push(y, out)`` writes y P into ``out``;
    until ||y P - y||_1 <= tol or ``max_sweeps``. Returns (y, ||y P - y||_1, sweeps).

    The lazy chain has P's stationary laws and no period for any 0 < ``lazy`` < 1; an eigenvalue
    lambda of P becomes lazy + (1 - lazy) lambda, so near lambda = 1 (slow mixing, the common
    case) a smaller ``lazy`` converges faster (complex eigenvalues near the unit circle the other way).

    ``mix``: a kernel ``mix(y, yn, lazy, z)`` writing |yn - y| into z and lazy y + (1 - lazy) yn
    into y in one pass (the same numbers, fewer temporaries)."""
    if not 0.0 < lazy < 1.0:
        raise SolverError(f"lazy must be in (0, 1), got {lazy!r}")
    y = y / y.sum()
    yn = np.empty_like(y)
    z = None if mix is None else np.empty_like(y)
    res = np.inf
    sweeps = 0
    while sweeps < max_sweeps:
        push(y, yn)
        sweeps += 1
        if mix is None:
            res = float(np.abs(yn - y).sum())
            y = lazy * y + (1.0 - lazy) * yn
        else:
            mix(y, yn, lazy, z)
            res = float(z.sum())
        y /= y.sum()
        if res <= tol:
            break
    return y, res, sweeps


def column(data: JointData, k: int, y: np.ndarray, weights: np.ndarray) -> tuple[float, np.ndarray]:
    """The cut of a policy with stationary law ``y``: (a, x) with a = <y, q_k> and x(p) its (C, a)
    marginal, so that the policy's average priced cost is a + <x, mu_k> for every price mu_k."""
    x = (y[data.pair_c] * weights).sum(axis=1)
    return float((y * data.q[k][None, :]).sum()), x


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
