r"""A constrained average-cost problem: the MDP's cost to minimise, linear bounds on other averages.

Every bound is on a long-run average :math:`\bar d_j = \sum_l d_j(l)\, x_l` of the occupation
measure x. Internally each bound is one row of the *max form*

.. math:: D x \le b,

a ``max`` bound as :math:`d_j^T x \le \text{max}_j` and a ``min`` bound as
:math:`-d_j^T x \le -\text{min}_j`, so every multiplier is :math:`\lambda \ge 0` and the
Lagrangian cost of the rows is :math:`c + \lambda^T D` (spec: a ``min`` bound enters as the
``max`` bound :math:`-d_j \le -b_j`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import SolverError
from ..mdp import MDP

__all__ = ["LinearConstraint", "Rows", "constraints_for", "max_form", "with_cost"]


@dataclass(frozen=True, eq=False)
class LinearConstraint:
    r"""A bound ``min <= sum_l values[l] x_l <= max`` on one long-run average.

    Attributes
    ----------
    values : (L,) float array
        :math:`d(l)` per state-action pair of the MDP.
    max, min : float or None
        The bounds (at least one).
    label : str
        A readable name (``"send_rate[remote] <= 0.2"``).
    quantity : str
        The quantity's name (``"send_rate"``, ...; ``"custom"`` for a user vector).
    """

    values: np.ndarray
    max: float | None = None
    min: float | None = None
    label: str = "constraint"
    quantity: str = "custom"

    def __post_init__(self):
        v = np.asarray(self.values, dtype=float)
        if v.ndim != 1:
            raise SolverError(f"constraint {self.label!r}: values must be a 1-D array over the pairs, got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise SolverError(f"constraint {self.label!r}: values must be finite")
        for side in ("max", "min"):
            b = getattr(self, side)
            if b is not None and not (isinstance(b, (int, float, np.integer, np.floating)) and math.isfinite(float(b))):
                raise SolverError(f"constraint {self.label!r}: {side} must be a finite number, got {b!r}")
        if self.max is None and self.min is None:
            raise SolverError(f"constraint {self.label!r}: give a max and/or a min bound")
        if self.max is not None and self.min is not None and float(self.min) > float(self.max):
            raise SolverError(f"constraint {self.label!r}: min = {self.min:g} > max = {self.max:g}")
        v = v.copy()
        v.setflags(write=False)
        object.__setattr__(self, "values", v)

    def with_bounds(self, *, max: Any = "keep", min: Any = "keep") -> "LinearConstraint":
        """The same constraint with new bounds (``None`` removes one); the label is rebuilt."""
        hi = self.max if max == "keep" else max
        lo = self.min if min == "keep" else min
        return replace(self, max=hi, min=lo, label=_relabel(self.label, lo, hi))


def _relabel(label: str, lo: float | None, hi: float | None) -> str:
    """Replace the bounds of a label made by :func:`constraints_for` (``a <= what <= b``)."""
    what = label
    if " <= " in what:
        parts = what.split(" <= ")
        what = parts[1] if len(parts) == 3 else (parts[0] if _is_number(parts[1]) else parts[1])
    return f"{'' if lo is None else f'{lo:g} <= '}{what}{'' if hi is None else f' <= {hi:g}'}"


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def constraints_for(mdp: MDP, specs: Iterable[Any]) -> tuple[LinearConstraint, ...]:
    """The linear constraints of a list of scenario ``[[constraint]]`` tables on a built MDP.

    Parameters
    ----------
    mdp : MDP
        Built from the scenario (:func:`wncs_lp.build`).
    specs : iterable of ConstraintSpec or LinearConstraint
        Scenario constraints (``scenario.constraints``) are turned into per-pair vectors by
        :func:`wncs_lp.models.quantities.pair_values`; LinearConstraints pass through (their
        length is checked against the MDP).
    """
    from ..models.quantities import pair_values

    out = []
    for spec in specs:
        if isinstance(spec, LinearConstraint):
            if spec.values.shape != (mdp.n_pairs,):
                raise SolverError(f"constraint {spec.label!r} has {spec.values.size} values; the MDP has {mdp.n_pairs} pairs")
            out.append(spec)
            continue
        out.append(LinearConstraint(pair_values(mdp, spec), spec.max, spec.min, spec.label or spec.quantity, spec.quantity))
    return tuple(out)


@dataclass(frozen=True, eq=False)
class Rows:
    """The max form ``D x <= b`` of a list of constraints.

    Attributes
    ----------
    D : (K, L) float array
        One row per bound: ``+d_j`` for a ``max``, ``-d_j`` for a ``min``.
    b : (K,) float array
    owner : (K,) int array
        The constraint each row comes from.
    side : tuple of str
        ``"max"`` or ``"min"`` per row.
    """

    D: np.ndarray
    b: np.ndarray
    owner: np.ndarray
    side: tuple[str, ...]

    @property
    def n_rows(self) -> int:
        return int(self.b.size)


def max_form(constraints: Sequence[LinearConstraint], n_pairs: int) -> Rows:
    """Stack the bounds of ``constraints`` as rows ``D x <= b`` (see :class:`Rows`)."""
    D, b, owner, side = [], [], [], []
    for j, c in enumerate(constraints):
        if c.values.shape != (n_pairs,):
            raise SolverError(f"constraint {c.label!r} has {c.values.size} values; the MDP has {n_pairs} pairs")
        if c.max is not None:
            D.append(c.values)
            b.append(float(c.max))
            owner.append(j)
            side.append("max")
        if c.min is not None:
            D.append(-c.values)
            b.append(-float(c.min))
            owner.append(j)
            side.append("min")
    Dm = np.array(D, dtype=float).reshape(len(D), n_pairs)
    return Rows(Dm, np.array(b, dtype=float), np.array(owner, dtype=np.int64), tuple(side))


def with_cost(mdp: MDP, cost: np.ndarray) -> MDP:
    """The same MDP (states, actions, transitions) with another per-pair cost vector."""
    cost = np.asarray(cost, dtype=float)
    if cost.shape != (mdp.n_pairs,):
        raise SolverError(f"a cost vector needs {mdp.n_pairs} entries, got shape {cost.shape}")
    cost = cost.copy()
    cost.setflags(write=False)
    return replace(mdp, cost=cost)
