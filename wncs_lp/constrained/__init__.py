"""Constrained and convex scheduling over the occupation measure (``docs/constraints.md``).

Minimise the average cost while bounding other long-run averages (a server's send rate, one
process's AoI or MSE, ...). The optimum is a *randomised* stationary policy, certified by
``[L(lambda), exact cost of the returned policy]``.

* ``wncs_lp.solve(mdp, method, constraints=...)`` -- the entry point (its constrained step,
  :func:`~wncs_lp.constrained.registry.run_constrained`): ``method="lp"`` (Clarabel),
  ``"lp-highs"``, ``"lp-cvxpy"``, ``"lagrangian"`` (one constraint, beyond the LP's size) or
  ``"auto"``; ``solve_constrained``, its old name, is still found here for one release with a
  :class:`DeprecationWarning`;
* :class:`OccupationProgram` -- convex programs over the occupation measure (cvxpy + Clarabel):
  the variable, the balance constraints and the quantities as expressions;
* :func:`constraints_for` -- a scenario's ``[[constraint]]`` tables as :class:`LinearConstraint`;
* :class:`ConstrainedSolution` -- what every route returns.
"""
from __future__ import annotations

from .. import moved
from ..methods import CONSTRAINED_METHODS  # one vocabulary: wncs_lp.methods
from .convex import OccupationProgram
from .certify import CERT_RTOL, certify, evaluate_rows, lagrangian_bound, policy_from_occupation
from .lp import check_reachable, reachable_range, solve_constrained_lp
from .warm import solve_constrained_highs
from .problem import LinearConstraint, Rows, constraints_for, max_form, with_cost
from .registry import CONSTRAINED_ENTRIES
from .result import ConstrainedSolution, ConstraintReport

__all__ = [
    "solve_constrained_lp",
    "solve_constrained_highs",
    "OccupationProgram",
    "constraints_for",
    "LinearConstraint",
    "ConstrainedSolution",
    "ConstraintReport",
    "Rows",
    "max_form",
    "with_cost",
    "certify",
    "evaluate_rows",
    "lagrangian_bound",
    "policy_from_occupation",
    "reachable_range",
    "check_reachable",
    "CONSTRAINED_METHODS",
    "CONSTRAINED_ENTRIES",
]


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
