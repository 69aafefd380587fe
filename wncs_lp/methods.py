"""The solver vocabulary: one set of method names and one default for every entry point.

Every command that solves (``solve``, ``evaluate``, ``simulate``, ``sweep``, ``verify``, ``map``,
``capstudy``) and every library function that takes a ``method`` (:func:`wncs_lp.solve`,
:meth:`wncs_lp.policies.OptimalPolicy.from_scenario`, :func:`wncs_lp.policies.make_policy`,
:func:`wncs_lp.policies.policy_for`, :func:`wncs_lp.sweep.run_sweep`,
:func:`wncs_lp.capstudy.cap_study`) accepts the names of :data:`METHODS` and defaults to
:data:`DEFAULT_METHOD`, ``"auto"``:

=============  ==========================================================================
``auto``       the LP on small models (at most 6,000 pairs), certified value iteration
               above; both run and are compared when both are cheap (at most 30,000
               pairs). ``stats["auto_choice"]`` says whose answer it is.
``lp``         the occupation-measure LP on Clarabel (direct), its policy polished and
               exactly evaluated.
``lp-highs``   the same LP on HiGHS (simplex or interior point + crossover, by the LP's
               shape). The library's ``solve_lp`` (and ``auto``'s LP) picks Clarabel or
               HiGHS by a measured rule; ``stats["lp_choice"]`` says why.
``lp-cvxpy``   the same LP built with cvxpy.
``vi``         certified value iteration (Gauss-Seidel modified policy iteration on the
               numba kernel, Jacobi relative value iteration without numba).
``rvi``        relative value iteration with the aperiodicity transform.
``pi``         Howard policy iteration with exact (sparse) evaluation.
=============  ==========================================================================

Every method returns the same certificate ``gain_lower <= g* <= gain_upper`` and takes the same
keywords ``tol`` (the accuracy asked for: the relative certificate width; for ``lp``/``lp-cvxpy``
the solver's tolerance, the certificate being checked at ``cert_rtol``) and ``progress`` (show
the work on stderr); all but ``auto`` take ``max_iter``, and ``auto``, ``vi``, ``rvi`` and ``pi``
a warm start ``h0`` (a bias). :func:`wncs_lp.solve` answers a keyword a method does not take with
one :class:`~wncs_lp.errors.SolverError` naming those it does.

A scenario with ``[[constraint]]`` tables is solved by :data:`CONSTRAINED_METHODS` instead
(:func:`wncs_lp.constrained.solve_constrained`).

This module imports nothing heavy, so the command line can build its parser from it.
"""
from __future__ import annotations

__all__ = ["METHODS", "DEFAULT_METHOD", "CONSTRAINED_METHODS", "LP_METHODS", "METHOD_HELP", "check_method"]

#: The methods of an unconstrained solve, in the order the help lists them
#: (the same names as :data:`wncs_lp.solvers.METHODS`).
METHODS = ("auto", "lp", "lp-highs", "lp-cvxpy", "vi", "rvi", "pi")
#: The default of every command and library function that solves.
DEFAULT_METHOD = "auto"
#: The methods of a constrained solve (a scenario with ``[[constraint]]`` tables).
CONSTRAINED_METHODS = ("auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian")
#: The methods that solve an interior-point LP (their memory need is the size guard's LP estimate).
LP_METHODS = ("lp", "lp-highs", "lp-cvxpy")

#: One help text for ``--method``, shared by every command.
METHOD_HELP = ("solver: auto (default: the LP on small models, certified value iteration above, "
               "cross-checked when both are cheap; it says which it chose), lp (occupation-measure LP on "
               "Clarabel), lp-highs (the same LP on HiGHS), lp-cvxpy (the same LP through cvxpy), vi "
               "(certified value iteration), rvi (relative value iteration), pi (policy iteration)")


def check_method(method: str, allowed: tuple[str, ...] = METHODS, what: str = "method") -> str:
    """``method`` if it is one of ``allowed``, else a :class:`~wncs_lp.errors.SolverError` listing them."""
    if method not in allowed:
        from .errors import SolverError

        raise SolverError(f"unknown {what} {method!r}; expected one of {', '.join(allowed)}")
    return method
