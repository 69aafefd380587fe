"""A generic finite average-cost MDP in state-action-pair form.

Following QuantEcon's ``DiscreteDP``, an MDP with state-dependent action sets is stored with
no padding: one row per feasible state-action pair ``l = 0..L-1``,

* ``s_indices[l]``  the state of pair l (pairs are sorted by state),
* ``a_indices[l]``  the action of pair l, an index into ``action_table``,
* ``cost[l]``       the one-slot cost c(s, a),
* ``P[l, :]``       the next-state distribution P(. | s, a), a CSR row.

``pair_ptr`` gives the pairs of state s as ``pair_ptr[s]:pair_ptr[s+1]`` (CSR-like), which is what
makes the Bellman minimum a vectorised ``np.minimum.reduceat``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.sparse as sp

from .errors import ModelError

__all__ = ["MDP", "MAX_COST"]

#: Tolerance on row sums of P.
ROW_SUM_TOL = 1e-9
#: The largest one-slot cost magnitude an MDP takes. The solvers add up, square and difference
#: costs (value iteration sums them over sweeps, an interior-point LP takes norms of squares over
#: every pair); with |c| <= 1e100 all of that stays finite in float64 (1e100^2 * 1e9 pairs is
#: far below 1.8e308), so a cost that would overflow is refused where it enters.
MAX_COST = 1e100


@dataclass(frozen=True, eq=False)
class MDP:
    """A finite MDP in state-action-pair form. Construct with :meth:`from_arrays`.

    Attributes
    ----------
    n_states : int
    s_indices : (L,) int64 array, nondecreasing
    a_indices : (L,) int64 array
    cost : (L,) float array
    P : (L, n_states) scipy.sparse.csr_matrix
    pair_ptr : (n_states + 1,) int64 array
    action_table : (n_actions, ...) array or None
        The decoded label of each action index (for the WNCS model, row = (a_1..a_M)).
    states : object or None
        A decoded view of the states (e.g. :class:`wncs_lp.models.statespace.StateSpace`).
    name : str
    meta : dict
        Free-form provenance (scenario, build time...).
    """

    n_states: int
    s_indices: np.ndarray
    a_indices: np.ndarray
    cost: np.ndarray
    P: sp.csr_matrix
    pair_ptr: np.ndarray
    action_table: np.ndarray | None = None
    states: Any = None
    name: str = "mdp"
    meta: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(
        cls,
        s_indices: Sequence[int] | np.ndarray,
        a_indices: Sequence[int] | np.ndarray,
        cost: Sequence[float] | np.ndarray,
        P: Any,
        n_states: int | None = None,
        *,
        action_table: np.ndarray | None = None,
        states: Any = None,
        name: str = "mdp",
        meta: dict | None = None,
        check: bool = True,
    ) -> "MDP":
        """Build and validate an MDP from per-pair arrays.

        Parameters
        ----------
        s_indices, a_indices : (L,) integer arrays
            State and action of each pair. Pairs need not be sorted; they are stably sorted by
            state. A state may not list the same action twice.
        cost : (L,) array
            c(s, a), finite.
        P : (L, n) array-like or sparse matrix
            Row l is P(. | s_l, a_l): nonnegative, summing to 1.
        n_states : int, optional
            Number of states (default: ``P.shape[1]``).
        check : bool
            Validate (default). Builders that construct valid matrices by design may skip it.

        Raises
        ------
        ModelError
            On any inconsistency; the message names the offending state or pair.
        """
        s = np.asarray(s_indices)
        a = np.asarray(a_indices)
        c = _numeric(cost, "cost")
        if s.ndim != 1 or a.shape != s.shape or c.shape != s.shape:
            raise ModelError(
                f"s_indices, a_indices and cost must be 1-D of one length; got shapes {s.shape}, {a.shape}, {c.shape}"
            )
        if not (np.issubdtype(s.dtype, np.integer) and np.issubdtype(a.dtype, np.integer)) and s.size:
            raise ModelError(f"s_indices and a_indices must be integers; got {s.dtype} and {a.dtype}")
        s = s.astype(np.int64)
        a = a.astype(np.int64)
        Pm = _transition_matrix(P)
        if Pm.shape[0] != s.size:
            raise ModelError(f"P must have one row per pair: {s.size} pairs but P has {Pm.shape[0]} rows")
        n = int(Pm.shape[1] if n_states is None else n_states)
        if Pm.shape[1] != n:
            raise ModelError(f"P must have n_states = {n} columns, found {Pm.shape[1]}")
        if check:
            _check_pairs(s, a, c, n)
        order = None
        if s.size and np.any(np.diff(s) < 0):
            order = np.argsort(s, kind="stable")
            s, a, c, Pm = s[order], a[order], c[order], Pm[order]
        Pm.sum_duplicates()
        Pm.sort_indices()
        ptr = np.searchsorted(s, np.arange(n + 1)).astype(np.int64)
        mdp = cls(n, s, a, c, Pm, ptr, action_table, states, name, dict(meta or {}))
        if check:
            mdp.validate()
        for arr in (s, a, c, ptr):
            arr.setflags(write=False)
        return mdp

    @classmethod
    def from_dense(cls, P: np.ndarray, cost: np.ndarray, feasible: np.ndarray | None = None, **kw) -> "MDP":
        """Build from dense arrays ``P[s, a, s']`` and ``cost[s, a]`` (QuantEcon's (R, Q) layout).

        ``feasible[s, a]`` (bool, default all True) marks the allowed pairs.
        """
        P = _numeric(P, "P")
        cost = _numeric(cost, "cost")
        if P.ndim != 3 or P.shape[0] != P.shape[2] or cost.shape != P.shape[:2]:
            raise ModelError(f"expected P of shape (n, m, n) and cost of shape (n, m); got {P.shape} and {cost.shape}")
        mask = np.ones(cost.shape, bool) if feasible is None else np.asarray(feasible, bool)
        s_idx, a_idx = np.nonzero(mask)
        return cls.from_arrays(s_idx, a_idx, cost[s_idx, a_idx], P[s_idx, a_idx, :], P.shape[0], **kw)

    # ------------------------------------------------------------------ properties
    @property
    def n_pairs(self) -> int:
        return int(self.s_indices.size)

    @property
    def n_actions(self) -> np.ndarray:
        """Number of feasible actions of each state."""
        return np.diff(self.pair_ptr)

    def state_cost(self) -> np.ndarray:
        """c(s) when the cost does not depend on the action (the first pair's cost otherwise)."""
        return self.cost[self.pair_ptr[:-1]]

    def pairs_of(self, s: int) -> range:
        return range(int(self.pair_ptr[s]), int(self.pair_ptr[s + 1]))

    def action_label(self, pair: int) -> Any:
        """The decoded action of a pair (its row of ``action_table`` or the raw index)."""
        a = int(self.a_indices[pair])
        if self.action_table is None:
            return a
        row = self.action_table[a]
        return tuple(int(x) for x in np.atleast_1d(row))

    def state_label(self, s: int) -> str:
        if self.states is not None and hasattr(self.states, "label"):
            return str(self.states.label(s))
        return str(s)

    # ------------------------------------------------------------------ checks
    def validate(self) -> None:
        """Check the invariants; raise :class:`ModelError` naming the first bad state or pair."""
        n, P = self.n_states, self.P
        _check_pairs(self.s_indices, self.a_indices, self.cost, n)
        if P.shape != (self.n_pairs, n) or P.indptr.size != self.n_pairs + 1 or P.indptr[-1] != P.indices.size:
            raise ModelError(f"P must be a CSR matrix of shape ({self.n_pairs}, {n}) with a consistent row pointer; "
                             f"found shape {P.shape}, {P.indptr.size} row pointers and {P.indices.size} entries")
        if P.nnz and (P.indices.min() < 0 or P.indices.max() >= n):
            bad = int(np.flatnonzero((P.indices < 0) | (P.indices >= n))[0])
            row = int(np.searchsorted(P.indptr, bad, side="right") - 1)
            raise ModelError(f"P has a column index {int(P.indices[bad])} out of range 0..{n - 1} in pair {row}")
        if P.nnz and (not np.all(np.isfinite(P.data)) or P.data.min() < 0):
            bad = np.flatnonzero(~np.isfinite(P.data) | (P.data < 0))[0]
            row = int(np.searchsorted(P.indptr, bad, side="right") - 1)
            raise ModelError(
                f"P has a negative or non-finite entry in pair {row} (state {self.state_label(self.s_indices[row])})"
            )
        sums = np.asarray(P.sum(axis=1)).ravel()
        off = np.abs(sums - 1.0) > ROW_SUM_TOL
        if off.any():
            l = int(np.flatnonzero(off)[0])
            raise ModelError(
                f"transition probabilities of pair {l} (state {self.state_label(self.s_indices[l])}, "
                f"action {self.action_label(l)}) sum to {sums[l]:.12g}, expected 1"
            )

    def __repr__(self) -> str:
        return f"MDP(name={self.name!r}, states={self.n_states}, pairs={self.n_pairs}, nnz={self.P.nnz})"


def _check_pairs(s: np.ndarray, a: np.ndarray, c: np.ndarray, n: int) -> None:
    if n < 1:
        raise ModelError(f"an MDP needs at least one state, got n_states = {n}")
    if s.size and (s.min() < 0 or s.max() >= n):
        bad = int(s[(s < 0) | (s >= n)][0])
        raise ModelError(f"state index {bad} out of range: expected 0..{n - 1}")
    if a.size and a.min() < 0:
        raise ModelError(f"action index {int(a.min())} is negative; expected indices >= 0")
    bad = ~(np.abs(c) <= MAX_COST)  # catches nan too
    if bad.any():
        l = int(np.flatnonzero(bad)[0])
        raise ModelError(f"cost of pair {l} (state {int(s[l])}) is {c[l]:.6g}, expected a finite number of magnitude "
                         f"at most {MAX_COST:g} (beyond it the solvers' sums and squares overflow)")
    counts = np.bincount(s, minlength=n)
    if (counts == 0).any():
        raise ModelError(f"state {int(np.flatnonzero(counts == 0)[0])} has no feasible action")
    key = s * (int(a.max()) + 1 if a.size else 1) + a
    if np.unique(key).size != key.size:
        uniq, cnt = np.unique(key, return_counts=True)
        k = int(uniq[cnt > 1][0])
        base = int(a.max()) + 1
        raise ModelError(f"state {k // base} lists action {k % base} more than once")


def _numeric(x: Any, name: str) -> np.ndarray:
    """``x`` as a float array; one ModelError for strings, objects or anything not numeric."""
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError) as exc:  # ragged nests
        raise ModelError(f"{name} must be an array of numbers: {exc}") from None
    if raw.dtype.kind not in "biuf":
        example = f" (e.g. {str(raw.flat[0])[:20]!r})" if raw.size else ""
        raise ModelError(f"{name} must be an array of numbers, found dtype {raw.dtype}{example}")
    return raw.astype(float)


def _transition_matrix(P: Any) -> sp.csr_matrix:
    """P as a float CSR matrix; one ModelError when it is not numeric."""
    if not sp.issparse(P):
        P = _numeric(P, "P")
        if P.ndim != 2:
            raise ModelError(f"P must be 2-D (one row per pair), found shape {P.shape}")
    elif P.dtype.kind not in "biuf":
        raise ModelError(f"P must hold numbers, found dtype {P.dtype}")
    return sp.csr_matrix(P, dtype=float)
