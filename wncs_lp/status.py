"""The status vocabulary of every solve: a closed set of codes and a message in words.

A result's ``status`` string is kept as the solvers have always written it (``"optimal"``,
``"max_iter"``, ``"inaccurate"`` or ``"inaccurate:<reason>"``, ...), so code that compares it
with ``"optimal"`` or looks for the ``"inaccurate:"`` prefix keeps working. What to branch on
is its **code**, one of the constants below (``Solution.status_code``; like cvxpy's
``OPTIMAL`` / ``OPTIMAL_INACCURATE`` and scipy's ``OptimizeResult.status``), and what to show a
person is its **message** (``Solution.message``; like scipy's ``OptimizeResult.message``):

================  ===============================================================================
code              meaning
================  ===============================================================================
``OPTIMAL``       the certificate closed: ``gain_lower <= g* <= gain_upper`` within the tolerance
``INACCURATE``    the method finished, but something is short of the tolerance (the reason after
                  the colon: ``certificate``, ``polish_max_iter``, ``cross_check``,
                  ``precision`` (tolerance below attainable precision: value iteration stopped at
                  the round-off floor), ``start_dependent`` (the optimal gain depends on the start
                  state: several closed classes), the LP solver's own status...); the bracket still holds
``MAX_ITER``      the iteration budget ran out first; the bracket of the last iterate still holds
``INTERRUPTED``   stopped by Ctrl-C; the bracket of the last iterate still holds
``INFEASIBLE``    (constrained problems) no stationary policy meets the bounds
``FAILED``        no usable answer (anything else, e.g. ``"error: ..."`` rows of a sweep)
================  ===============================================================================

The certificate is what to trust in every case: the interval ``[gain_lower, gain_upper]``
contains the optimal gain whatever the status says.
"""
from __future__ import annotations

__all__ = ["OPTIMAL", "INACCURATE", "MAX_ITER", "INTERRUPTED", "INFEASIBLE", "FAILED", "STATUS_CODES",
           "status_code", "status_reason", "status_message"]

OPTIMAL = "optimal"
INACCURATE = "inaccurate"
MAX_ITER = "max_iter"
INTERRUPTED = "interrupted"
INFEASIBLE = "infeasible"
FAILED = "failed"
#: Every code, best first.
STATUS_CODES = (OPTIMAL, INACCURATE, MAX_ITER, INTERRUPTED, INFEASIBLE, FAILED)

_CODE_MESSAGES = {
    OPTIMAL: "the certificate closed: gain_lower <= g* <= gain_upper within the tolerance asked for",
    INACCURATE: "the method finished, but its certificate is wider than the tolerance asked for; "
                "the bracket gain_lower <= g* <= gain_upper still holds",
    MAX_ITER: "the iteration budget (max_iter) ran out before the certificate closed; "
              "the bracket gain_lower <= g* <= gain_upper of the last iterate still holds",
    INTERRUPTED: "interrupted before the certificate closed; the bracket of the last iterate still holds",
    INFEASIBLE: "no stationary policy meets the bounds",
}

_REASON_MESSAGES = {
    "certificate": "the solver finished, but the certificate gain_lower <= g* <= gain_upper is wider than "
                   "the tolerance asked for (cert_rtol); the bracket still holds",
    "polish_max_iter": "policy iteration, polishing the LP's policy, was not stable within its iteration cap "
                       "(polish_max_iter); the bracket still holds",
    "polish_inaccurate": "the polished policy's certificate is wider than the tolerance; the bracket still holds",
    "polish_max_iter_vi": "value iteration inside the polish ran out of iterations; the bracket still holds",
    "cross_check": "method 'auto' ran both the LP and value iteration and their gains disagree beyond their "
                   "certificates (stats['cross_check_rel_diff'])",
    "infeasible_policy": "the returned policy does not meet every bound within the feasibility tolerance",
    "multichain": "the returned policy's chain has several recurrent classes: its averages depend on the start",
    "precision": "tolerance below attainable precision: value iteration reached the round-off floor of its "
                 "sweeps (stats['stop'] says the width reached and the floor) and stopped; the bracket, widened "
                 "by the round-off bound, still holds",
    "start_dependent": "value iteration's certificate stopped shrinking: the optimal gain depends on the start "
                       "state (the MDP has several closed classes with different gains; stats['stop']), so no "
                       "single gain can be certified; the bracket gain_lower <= g*(s) <= gain_upper holds for "
                       "every start state s",
}


def status_code(status: str) -> str:
    """The code of a status string: the part before ``":"`` when it is one of
    :data:`STATUS_CODES`, else :data:`FAILED`."""
    code = str(status).split(":", 1)[0].strip()
    return code if code in STATUS_CODES else FAILED


def status_reason(status: str) -> str | None:
    """The reason after the colon (``"inaccurate:certificate"`` -> ``"certificate"``), or None."""
    head, sep, tail = str(status).partition(":")
    return tail.strip() or None if sep else None


def status_message(status: str) -> str:
    """A sentence saying what a status means for the result."""
    code, reason = status_code(status), status_reason(status)
    if code == FAILED:
        return f"the solve failed: {status}"
    if reason is None:
        return _CODE_MESSAGES[code]
    if reason in _REASON_MESSAGES:
        return _REASON_MESSAGES[reason]
    if reason.startswith("polish_"):
        return f"the polish of the LP's policy ended with status {reason[7:]!r}; the bracket still holds"
    return (f"the solver ended with status {reason!r} instead of success; the bracket "
            "gain_lower <= g* <= gain_upper still holds")
