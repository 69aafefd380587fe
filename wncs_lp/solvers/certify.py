"""Bellman operator in state-action-pair form and the average-cost certificate.

For an :class:`~wncs_lp.mdp.MDP` with pairs ``l = 0..L-1`` (state ``s_l``, cost ``c_l``,
next-state row ``P[l, :]``) and a function ``h`` on the states,

.. math::

    Q_h(l) = c_l + \\sum_{s'} P(s' \\mid l)\\, h(s'),  \\qquad
    (T h)(s) = \\min_{l:\\, s_l = s} Q_h(l).

For *any* ``h`` the span bounds

.. math::

    \\mathrm{lo} = \\min_s (T h - h)(s) \\;\\le\\; g^* \\;\\le\\; \\max_s (T h - h)(s) = \\mathrm{hi}

hold (Puterman, *Markov Decision Processes*, Thm. 8.5.5 / Odoni's bounds): every stationary
policy d satisfies c_d + P_d h >= T h >= h + lo, so its average cost is >= lo, and the greedy
policy of h satisfies c_d + P_d h = T h <= h + hi, so its average cost (from every start
state) is <= hi.  The bracket is therefore a certificate that can be checked independently
of the method that produced ``h``.
"""
from __future__ import annotations

import numpy as np

from ..mdp import MDP

__all__ = ["q_values", "bellman_step", "bracket", "greedy_first", "certificate_closed", "width_closed"]


def q_values(mdp: MDP, h: np.ndarray) -> np.ndarray:
    """Pair values :math:`Q_h(l) = c_l + (P h)_l`.

    Parameters
    ----------
    mdp : MDP
    h : (n,) array
        A function on the states.

    Returns
    -------
    (L,) float array
        One CSR mat-vec plus the cost vector.
    """
    h = np.asarray(h, dtype=float)
    if h.shape != (mdp.n_states,):
        raise ValueError(f"h must have shape ({mdp.n_states},), got {h.shape}")
    return mdp.cost + mdp.P @ h


def greedy_first(mdp: MDP, q: np.ndarray, qmin: np.ndarray | None = None) -> np.ndarray:
    """Index of the first (lowest pair index) exact minimiser of ``q`` within each state.

    Parameters
    ----------
    mdp : MDP
    q : (L,) array
        Pair values.
    qmin : (n,) array, optional
        ``np.minimum.reduceat(q, pair_ptr[:-1])`` if already computed.

    Returns
    -------
    (n,) int64 array of pair indices ``l`` with ``s_l = s`` and ``q[l] == min`` exactly.

    Notes
    -----
    The comparison ``q[l] == qmin[s_l]`` is exact (no tolerance): ``qmin`` is one of the
    ``q`` values itself, so at least one pair of every state matches, and among ties the
    smallest pair index wins (a ``np.minimum.reduceat`` over the candidate indices).
    """
    starts = mdp.pair_ptr[:-1]
    if qmin is None:
        qmin = np.minimum.reduceat(q, starts)
    L = q.shape[0]
    cand = np.where(q == qmin[mdp.s_indices], np.arange(L, dtype=np.int64), np.int64(L))
    return np.minimum.reduceat(cand, starts)


def bellman_step(mdp: MDP, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One application of the average-cost Bellman operator.

    .. math:: (T h)(s) = \\min_{l:\\, s_l = s} \\big[c_l + (P h)_l\\big]

    Parameters
    ----------
    mdp : MDP
    h : (n,) array

    Returns
    -------
    Th : (n,) float array
        ``np.minimum.reduceat(q, pair_ptr[:-1])`` with ``q = c + P h``.
    greedy : (n,) int64 array
        The minimising pair of each state; ties go to the first (lowest index) pair.
    """
    q = q_values(mdp, h)
    Th = np.minimum.reduceat(q, mdp.pair_ptr[:-1])
    return Th, greedy_first(mdp, q, Th)


def bracket(mdp: MDP, h: np.ndarray) -> tuple[float, float]:
    """The certificate ``(lo, hi)`` with ``lo <= g* <= hi``.

    .. math::

        \\mathrm{lo} = \\min_s (T h - h)(s), \\qquad \\mathrm{hi} = \\max_s (T h - h)(s).

    Parameters
    ----------
    mdp : MDP
    h : (n,) array
        Any function on the states (a bias estimate); the bounds are valid for every h and
        tight (lo = hi = g*) when h solves the optimality equation g* + h = T h.

    Returns
    -------
    lo, hi : float
    """
    h = np.asarray(h, dtype=float)
    Th, _ = bellman_step(mdp, h)
    d = Th - h
    return float(d.min()), float(d.max())


def width_closed(lo: float, hi: float, gain: float, rtol: float, *, atol: float = 0.0,
                 cost_scale: float = 0.0) -> bool:
    """The one rule for a tight bracket: ``hi - lo <= rtol * |gain|``, or ``<= atol``, or below
    the round-off level ``1e-13 * cost_scale`` (``cost_scale`` ~ max|c|), so that MDPs with
    g* = 0 can be certified. A non-finite width is never closed."""
    width = hi - lo
    if not np.isfinite(width):
        return False
    return width <= rtol * abs(gain) or width <= atol or width <= 1e-13 * cost_scale


def certificate_closed(mdp: MDP, lo: float, hi: float, gain: float, rtol: float) -> bool:
    """Whether the bracket is tight: :func:`width_closed` with the MDP's max|c| as the scale of
    its round-off floor ``hi - lo <= 1e-13 * max|c|``."""
    scale = float(np.max(np.abs(mdp.cost))) if mdp.n_pairs else 0.0
    return width_closed(lo, hi, gain, rtol, cost_scale=scale)
