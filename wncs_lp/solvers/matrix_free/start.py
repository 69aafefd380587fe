"""Starting values of a matrix-free iteration (:func:`start_vector`): zeros, a given vector, a
solution's bias, or a separable value function sum_k h_k(tau_k, column_k(c)) such as the bounds'
tables (:class:`wncs_lp.bounds.result.ValueTables`, :class:`~wncs_lp.bounds.result.GroupTables`),
written straight into the one value vector of the solve (no copy of it is ever held)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import SolverError
from ..threads import run_twins
from .layout import BoxLayout
from .sweeper import load_kernels

__all__ = ["start_vector", "separable_values", "clamped_values"]


def _is_tables(x: Any) -> bool:
    return hasattr(x, "h") and hasattr(x, "column") and not isinstance(x, np.ndarray)


def separable_values(layout: BoxLayout, tables: Any, out: np.ndarray | None = None) -> np.ndarray:
    """sum over the tables' parts of h_part(tau_part, column_part(c)) at every layout state.

    ``tables`` has ``h`` and ``column`` (per process: ``h[k][col, tau - 1]``) and, for a
    grouped table, ``groups`` (``h[i][col, tau_{G[0]} - 1, ...]``): duck-typed, so that this room
    needs nothing from the bounds'. Written into ``out`` (a float64 vector of the layout's size)
    when given, configuration by configuration (one box of temporaries at a time).
    """
    N, n = layout.n_processes, layout.n_states
    groups = getattr(tables, "groups", None)
    groups = tuple(tuple(int(k) for k in g) for g in groups) if groups is not None else tuple((k,) for k in range(N))
    hs, cols = tuple(tables.h), tuple(tables.column)
    if len(hs) != len(groups) or len(cols) != len(groups) or sorted(k for g in groups for k in g) != list(range(N)):
        raise SolverError(f"start tables: expected one table per process (or per group of a partition of the "
                          f"{N} processes), got {len(hs)}")
    for i, (g, hg, col) in enumerate(zip(groups, hs, cols)):
        hg, col = np.asarray(hg), np.asarray(col)
        need = tuple(int(layout.caps[k]) for k in g)
        if hg.ndim != 1 + len(g) or any(a < b for a, b in zip(hg.shape[1:], need)) or col.shape != (layout.n_configs,) \
                or col.min(initial=0) < 0 or col.max(initial=0) >= hg.shape[0]:
            raise SolverError(f"start tables: part {i} (processes {[k + 1 for k in g]}) has shape {hg.shape} and "
                              f"{col.shape[0]} column entries; expected (columns, {', '.join(map(str, need))}) "
                              f"and one column in range per configuration ({layout.n_configs})")
        if not np.all(np.isfinite(hg)):
            raise SolverError(f"start tables: part {i} holds a non-finite value")
    h = np.empty(n) if out is None else out
    if h.shape != (n,) or h.dtype != np.float64:
        raise SolverError(f"start vector: expected a float64 vector of {n:,} values")
    for c in range(layout.n_configs):
        lo, dims = layout.lo[c], layout.dims[c]
        box = np.zeros(tuple(int(d) for d in dims))
        for g, hg, col in zip(groups, hs, cols):
            sub = np.asarray(hg)[int(col[c])]
            sub = sub[tuple(slice(int(lo[k]), int(lo[k] + dims[k])) for k in g)]
            shape = [1] * N
            for k in g:
                shape[k] = int(dims[k])
            box += sub.reshape(shape)
        h[layout.off[c]:layout.off[c + 1]] = box.ravel()
    return h


def start_vector(h0: Any, layout: BoxLayout) -> np.ndarray:
    """The first iterate of a solve over ``layout``, normalised to h[0] = 0: zeros for None; a
    separable value function (an object with ``h`` and ``column``, or one holding such ``tables``,
    e.g. a :class:`~wncs_lp.bounds.result.BoundResult`); a solution's or an evaluation's ``bias``; or
    any array of one finite value per layout state."""
    n = layout.n_states
    if h0 is None:
        return np.zeros(n)
    tables = getattr(h0, "tables", None)
    if _is_tables(tables):
        h0 = tables
    if _is_tables(h0):
        h = separable_values(layout, h0)
    else:
        h0 = getattr(h0, "bias", h0)
        try:
            h = np.array(h0, dtype=float)
        except (TypeError, ValueError):
            h = None
        if h is None or h.shape != (n,):
            raise SolverError(f"h0 must be a finite array of shape ({n},), a solution of the same layout, or "
                              "separable value tables (h, column)")
    if not (np.isfinite(h.max(initial=0.0)) and np.isfinite(h.min(initial=0.0))):
        raise SolverError("h0 holds a non-finite value")
    h -= h[0]
    return h


def clamped_values(small: BoxLayout, h_small: np.ndarray, big: BoxLayout, out: np.ndarray,
                   threads: int = 1) -> np.ndarray:
    """Into ``out`` (one value per state of ``big``): ``h_small`` read at the same configuration
    with each AoI clamped into ``small``'s box of that configuration,
    out(c, tau) = h_small(c, min(max(tau, lo_small(c)), hi_small(c))).

    The two layouts must be of the same configurations (the same automaton at other caps);
    a start for a solve at larger caps from a solution at smaller ones (the values past the old
    caps are those at them). One numba pass over ``out`` on ``threads`` threads: it runs inside the
    timed solve, where a one-core gather left the other core idle.
    """
    if small.n_configs != big.n_configs or small.n_processes != big.n_processes:
        raise SolverError(f"clamped start: the layouts differ in configurations ({small.n_configs} against "
                          f"{big.n_configs}) or processes")
    if h_small.shape != (small.n_states,) or out.shape != (big.n_states,):
        raise SolverError("clamped start: a vector does not match its layout")
    K = load_kernels()
    i64 = lambda a: np.ascontiguousarray(a, dtype=np.int64)  # noqa: E731
    run_twins(K.clamped, K.clamped_serial, int(threads), int(big.n_processes), i64(small.off), i64(small.lo),
              i64(small.dims), i64(small.strides), i64(big.off), i64(big.lo), i64(big.dims),
              np.ascontiguousarray(h_small, dtype=float), out)
    return out
