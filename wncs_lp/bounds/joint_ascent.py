r"""Relaxation 2's prices raised by projected supergradient steps on the lumped chains.

The Lagrangian of relaxation 2 reduced by interchangeable processes
(:class:`~wncs_lp.bounds.joint_symmetry.LumpedChains`),

.. math::

    L(\nu) = \sum_r w_r\, g_r(q_r - \nu_r / w_r)
             + \min_Q \sum_r \sum_{O \subseteq Q} \frac{|O|}{|Q|} \nu_r(O),

is concave and piecewise linear; every nu gives a certified bound (the lumped chains' biases,
spread to every process and checked by :func:`~wncs_lp.bounds.joint_chains.certify_tables`), so
any ascent method is safe: only the bound's value depends on how far it climbs.

The steps stay on the affine set where every G-orbit Q has the same weighted sum
s_Q(nu) = sum_r sum_{O in Q} |O| / |Q| nu_r(O) (relaxation 1's prices start there, with s_Q = 0),
where the second term is that common value. There a supergradient of the first term is
-x_r(O), x_r the (C, a) marginal of the stationary law of the lumped chain's greedy policy (a
cut of :mod:`~wncs_lp.bounds.joint_bundle`'s kind: g_r(q - nu'/w) <= a + <x, -nu'/w> for every
nu'), and its projection on the set -- each Q's weighted sum of the step removed -- is an ascent
direction of the restricted function. The step length is Polyak's with a target level
best + eps |best| (eps halved after ``patience`` steps without a new best): the standard projected
subgradient method with an adaptive level,
which converges to the maximum over the set (the Lagrangian's maximum, the LP's optimum: moving
the sums s_Q to a common value never lowers the minimum).

Each step costs the lumped chains (warm-started from the last biases) and their stationary
laws (warm-started from the last ones): at the paper's four process types four times (cap 40)
four chains of 1,009-1,348 orbits of configurations, a small fraction of one whole chain. The
best prices met are kept; the bound is certified once, at the end, by the caller.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .joint_chains import ChainSolution, Kernels, column, policy_weights, stationary
from .joint_symmetry import LumpedChains

__all__ = ["AscentRun", "lumped_ascent", "projector"]


@dataclass(frozen=True, eq=False)
class AscentRun:
    """What :func:`lumped_ascent` found.

    Attributes
    ----------
    prices : list of arrays
        The best prices met (LP order, one array per class).
    value : float
        L at those prices (the chains' lower brackets: not a certificate).
    solutions : list of ChainSolution
        The lumped chains solved at those prices.
    history : list of float
        L at every step.
    cpu_seconds : float
    """

    prices: list
    value: float
    solutions: list
    history: list
    cpu_seconds: float


def projector(lumped: LumpedChains):
    """The projection removing each G-orbit's weighted sum from a step (LP order)."""
    q_lp, share_lp = [], []
    for order, q, sh in zip(lumped.order, lumped.q_orbit, lumped.share):
        qq, ss = np.empty_like(q), np.empty_like(sh)
        qq[order], ss[order] = q, sh
        q_lp.append(qq)
        share_lp.append(ss)
    norm = np.zeros(lumped.n_q)
    for q, sh in zip(q_lp, share_lp):
        np.add.at(norm, q, sh * sh)
    norm = np.where(norm > 0, norm, 1.0)

    def project(steps: list) -> list:
        dot = np.zeros(lumped.n_q)
        for q, sh, d in zip(q_lp, share_lp, steps):
            np.add.at(dot, q, sh * d)
        f = dot / norm
        return [d - f[q] * sh for q, sh, d in zip(q_lp, share_lp, steps)]

    return project


def lumped_ascent(lumped: LumpedChains, prices0: list, kern: Kernels, *, iterations: int = 300, eps: float = 0.05,
                  patience: int = 5, tol: float = 1e-7, cpu_limit: float | None = None, stop=None,
                  progress=None) -> AscentRun:
    """Projected supergradient ascent of the lumped Lagrangian from ``prices0`` (module docstring).

    Parameters
    ----------
    lumped : LumpedChains
    prices0 : list of arrays
        The start (LP order; e.g. :meth:`LumpedChains.prices_from` of relaxation 1's prices). It
        should have equal weighted sums on the G-orbits (relaxation 1's: all zero); the steps keep
        them.
    kern : Kernels
    iterations : int
        Steps at most (a count, so the result is the same on every machine).
    eps : float
        The Polyak target's first relative margin over the best value, halved after ``patience``
        steps in a row without a new best.
    tol : float
        The chains' relative bracket width.
    cpu_limit : float, optional
        Seconds of this process's CPU time after which no step is begun.
    stop : callable, optional
        ``stop()`` True ends the ascent (a deadline, Ctrl-C's flag).
    progress : Progress, optional
    """
    cpu0 = time.process_time()
    project = projector(lumped)
    prices = [np.array(p, dtype=float, copy=True) for p in prices0]
    best, best_prices, best_sols = -np.inf, prices, None
    h0, laws, history, since = None, [None] * len(prices), [], 0
    for it in range(max(int(iterations), 1)):
        value, sols = lumped.lagrangian(prices, kern, tol=tol, h0=h0)
        h0 = [s.h for s in sols]
        history.append(value)
        if value > best:
            best, best_prices, best_sols, since = value, [p.copy() for p in prices], sols, 0
        else:
            since += 1
            if since >= patience:
                eps, since = 0.5 * eps, 0
        if progress is not None and it % 25 == 0:
            progress.tick(f"relaxation 2, lumped ascent step {it}: L {value:.10g}, best {best:.10g}")
        if it + 1 >= iterations or (stop is not None and stop()) or (
                cpu_limit is not None and time.process_time() - cpu0 > cpu_limit):
            break
        grads = []
        for c, (ld, sol) in enumerate(zip(lumped.chains, sols)):
            w = policy_weights(ld, 0, sol.policy)
            laws[c], _, _ = stationary(ld, 0, w, kern, laws[c], tol=1e-9)  # cuts steer; they certify nothing
            _, x = column(ld, 0, laws[c], w)
            g = np.empty_like(x)
            g[lumped.order[c]] = -x
            grads.append(g)
        steps = project(grads)
        norm2 = sum(float(d @ d) for d in steps)
        if norm2 <= 0.0:  # every chain's marginal agrees: the point is optimal
            break
        margin = eps * max(abs(best), 1.0)
        length = (best + margin - value) / norm2
        prices = [p + length * d for p, d in zip(prices, steps)]
    return AscentRun(prices=best_prices, value=float(best), solutions=best_sols, history=history,
                     cpu_seconds=time.process_time() - cpu0)
