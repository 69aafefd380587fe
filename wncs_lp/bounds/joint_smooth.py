r"""Relaxation 2's prices raised by quasi-Newton steps on the entropy-smoothed lumped Lagrangian.

The lumped Lagrangian of :mod:`~wncs_lp.bounds.joint_ascent` restricted to the prices whose
G-orbit sums are all equal (the affine set its steps keep),

.. math::  L(\nu) = \sum_r w_r\, g_r(q_r - \nu_r / w_r) + s(\nu_0),

is concave and piecewise linear: supergradient steps crawl on it (their lengths must shrink to
zero). Smoothing it makes it differentiable. Replace every chain's minimum over pairs by the soft
minimum at temperature eta_r = eta / w_r,

.. math::

    (T^\eta h)(c, t) = q(t) - \eta_r \log \sum_{p \in c} \exp\bigl(-(\mathrm{price}(p)
    + E\, h(\mathrm{next})) / \eta_r\bigr),

whose average-cost fixed point g_r^eta is the optimal gain of the chain with an entropy bonus
(``joint_kernels.soft_bellman``). Then, with A_r the most pairs of one configuration of chain r,

.. math::  g_r - \eta_r \log A_r \;\le\; g_r^\eta \;\le\; g_r,

so the smoothed function L_eta lies within eta sum_r log A_r below L everywhere, and it is concave and
differentiable: its gradient in nu_r(O) is -x_r(O), the (C, a) marginal of the stationary law of
the softmin policy (whose weights the kernel returns). L-BFGS (scipy's ``fmin_l_bfgs_b``) maximises
it on the affine set (the gradient projected as in the supergradient method), warm-starting the
chains' biases and stationary laws from the last evaluation, for a decreasing sequence of
temperatures (each stage starting from the last one's prices). At the prices of each stage's end
the lumped chains are solved *unsmoothed* (:meth:`LumpedChains.lagrangian`): since g_r >= g_r^eta,
that value is at least the stage's smoothed maximum, itself at least max L - eta sum_r log A_r --
so a stage run to convergence is within that much of relaxation 2's optimum. The best unsmoothed
value's chains are returned; the caller certifies their tables (any prices give a valid bound).

The work is counted in evaluations (a count: the same result on every machine); ``cpu_limit``
is a guard that ends the search early (the best point so far is kept).
"""
from __future__ import annotations

import time

import numpy as np

from .joint_ascent import AscentRun, projector
from .joint_chains import Kernels, column, damped_rvi, lazy_power
from .joint_symmetry import LumpedChains

__all__ = ["smoothed_ascent", "SMOOTH_STAGES"]

#: The temperatures' stages: each a smoothing error bound eta sum_r log A_r relative to |L| at the
#: start, and the L-BFGS iterations of the stage.
SMOOTH_STAGES = ((1e-2, 200), (1e-3, 200), (1e-4, 200))


class _Stop(Exception):
    """Raised inside the objective to end L-BFGS (evaluations or CPU spent, ``stop()``)."""


def smoothed_ascent(lumped: LumpedChains, prices0: list, kern: Kernels, *, stages=SMOOTH_STAGES,
                    evaluations: int | None = None, tol: float = 1e-9, chain_tol: float = 2e-6, cpu_limit: float | None = None,
                    stop=None, progress=None) -> AscentRun:
    """L-BFGS on the entropy-smoothed lumped Lagrangian from ``prices0`` (module docstring).

    Parameters
    ----------
    lumped : LumpedChains
    prices0 : list of arrays
        The start (LP order), with equal weighted sums on the G-orbits (relaxation 1's prices
        through :meth:`LumpedChains.prices_from`: all zero); the steps keep them.
    kern : Kernels
    stages : sequence of (relative error, iterations)
        Each stage's temperature, as the bound eta sum_r log A_r on the smoothing's error relative
        to |L(prices0)|, and its L-BFGS iterations at most.
    evaluations : int, optional
        Smoothed evaluations at most over all stages (default: no limit beyond the stages').
    tol : float
        The smoothed chains' relative bracket width (their values enter the line searches).
    chain_tol : float
        The unsmoothed chains' relative bracket width (their tables are the ones certified).
    cpu_limit : float, optional
        Seconds of this process's CPU time after which no evaluation is begun.
    stop : callable, optional
    progress : Progress, optional

    Returns
    -------
    AscentRun
        The best unsmoothed value met (at the start or a stage's end), its prices and chains;
        ``history`` the unsmoothed values at the start and each stage's end.
    """
    from scipy.optimize import fmin_l_bfgs_b

    cpu0 = time.process_time()
    project = projector(lumped)
    n = len(prices0)
    base = [np.array(p, dtype=float, copy=True) for p in prices0]
    cuts = np.cumsum([0] + [p.size for p in base])

    def prices_of(z: np.ndarray) -> list:
        return [b + d for b, d in zip(base, project([z[cuts[i]:cuts[i + 1]] for i in range(n)]))]

    best_value, sols = lumped.lagrangian(base, kern, tol=chain_tol)
    best = (best_value, base, sols)
    history = [best_value]
    scale = max(abs(best_value), 1.0)
    n_act = [max(int(np.diff(ld.act_ptr).max()), 2) for ld in lumped.chains]
    spread = float(sum(np.log(a) for a in n_act))
    biases = [s.h.copy() for s in sols]
    laws = [None] * n
    count = [0]
    z = np.zeros(int(cuts[-1]))
    top = [-np.inf, z.copy()]  # the best smoothed point of the current stage

    def smoothed(z: np.ndarray, eta: float):
        if (evaluations is not None and count[0] >= evaluations) or (stop is not None and stop()) or (
                cpu_limit is not None and time.process_time() - cpu0 > cpu_limit):
            raise _Stop
        prices = prices_of(z)
        value, grads = 0.0, []
        for c, (ld, w) in enumerate(zip(lumped.chains, lumped.weights)):
            price = np.ascontiguousarray(-np.asarray(prices[c], dtype=float)[lumped.order[c]] / w)
            shape = biases[c].shape
            th, weights = np.empty(shape), np.empty((ld.n_pairs, shape[1]))
            lo, hi, _ = damped_rvi(lambda x: kern.soft_bellman(ld, 0, x, price, eta / w, th, weights), biases[c], th,
                                   tol=tol, max_sweeps=100_000, relax=0.9)
            kern.soft_bellman(ld, 0, biases[c], price, eta / w, th, weights)  # the weights of the last biases
            y0 = np.full(shape, 1.0 / th.size) if laws[c] is None else laws[c]
            laws[c], _, _ = lazy_power(lambda x, out: kern.push(ld, 0, x, weights, out), y0, tol=1e-10,
                                       max_sweeps=20_000)
            _, x = column(ld, 0, laws[c], weights)
            g = np.empty_like(x)
            g[lumped.order[c]] = -x
            grads.append(g)
            value += w * 0.5 * (lo + hi)
        count[0] += 1
        if value > top[0]:
            top[0], top[1] = value, z.copy()
        return -value, -np.concatenate(project(grads))

    for rel, iters in stages:
        eta = rel * scale / spread
        top[0] = -np.inf
        stopped = False
        try:
            z, _, _ = fmin_l_bfgs_b(smoothed, z, args=(eta,), m=20, maxiter=int(iters), pgtol=1e-12, factr=10.0)
        except _Stop:
            stopped = True
        z = top[1] if stopped or not np.isfinite(top[0]) else z
        prices = prices_of(z)
        value, sols = lumped.lagrangian(prices, kern, tol=chain_tol, h0=[s.h for s in best[2]])
        history.append(value)
        if value > best[0]:
            best = (value, prices, sols)
        if progress is not None:
            progress.tick(f"relaxation 2, smoothed ascent (eta {eta:.3g}): smoothed {top[0]:.10g}, L {value:.10g}, "
                          f"best {best[0]:.10g}, {count[0]} evaluations")
        if stopped:
            break
    return AscentRun(prices=[p.copy() for p in best[1]], value=float(best[0]), solutions=best[2], history=history,
                     cpu_seconds=time.process_time() - cpu0)
