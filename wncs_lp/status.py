"""The status vocabulary of every solve: a closed set of codes, a reason, and a message in words.

A result's ``status`` is a :class:`Status`: a **code**, one of the closed set :class:`Code`
(like cvxpy's ``OPTIMAL`` / ``OPTIMAL_INACCURATE`` and scipy's ``OptimizeResult.status``), and a
**reason**, None or one short word saying why the result is not optimal. Branch on
``result.status_code`` / ``result.status_reason``; show ``result.message`` to a person (like
scipy's ``OptimizeResult.message``).

================  ===============================================================================
code              meaning
================  ===============================================================================
``OPTIMAL``       the certificate closed: ``gain_lower <= g* <= gain_upper`` within the tolerance
``INACCURATE``    the method finished, but something is short of the tolerance (the reason says
                  what); the bracket still holds
``MAX_ITER``      an iteration (or time) budget ran out first; the bracket of the last iterate
                  still holds
``INTERRUPTED``   stopped by Ctrl-C; the bracket of the last iterate still holds
``INFEASIBLE``    (constrained problems) no stationary policy meets the bounds
``FAILED``        no usable answer (anything else, e.g. ``"error: ..."`` rows of a study)
================  ===============================================================================

The reasons (:data:`REASONS`, each with its sentence): ``certificate`` (the bracket is wider
than the tolerance), ``precision`` (tolerance below attainable precision: value iteration
stopped at the round-off floor), ``start_dependent`` (the optimal gain depends on the start
state), ``polish_max_iter`` and ``polish_<code or reason>`` (the polish of an LP's policy),
``cross_check`` (``auto``'s two methods disagree), ``infeasible_policy``, ``multichain``,
``objective_not_evaluated`` (constrained and convex programs), or **a backend's own status
word**, verbatim: an LP backend maps its native statuses into the codes by a table of its own
(:data:`wncs_lp.solvers.lp.CLARABEL_STATUS`, :data:`wncs_lp.solvers.highs.HIGHS_STATUS`,
:data:`wncs_lp.solvers.lp.CVXPY_STATUS`; as cvxpy's per-solver ``STATUS_MAP``) through
:func:`from_backend`, which keeps the native word as the reason (``max_iter:MaxIterations``,
``max_iter:kTimeLimit``, ``inaccurate:AlmostSolved``); a native status missing from the table is
``FAILED`` with its word kept. The native word is also in the result's ``stats["solver_status"]``.

**The text.** A :class:`Status` is a ``str``: ``"optimal"``, ``"max_iter"``, ``"inaccurate"``
or ``"<code>:<reason>"`` (``"inaccurate:precision"``). That is what JSON, CSV, Markdown and the
command line show, so the files written before and after the vocabulary had a type read the
same, and ``status == "optimal"`` keeps working. The text is the *output* form only: nothing
outside this module takes a status string apart. A status read back from a file (a cache, a CSV
row, a saved solution) or given as a string (``dataclasses.replace(sol, status="max_iter")``) is
turned into a :class:`Status` by :func:`parse` -- the one parser -- when the result is made
(:func:`as_status`); text that names no code (``"error: ..."``) parses to ``FAILED`` with the
text kept.

The certificate is what to trust in every case: the interval ``[gain_lower, gain_upper]``
contains the optimal gain whatever the status says.
"""
from __future__ import annotations

import re
from enum import Enum
from typing import Any, Iterable, Mapping

__all__ = ["Code", "Status", "OPTIMAL", "INACCURATE", "MAX_ITER", "INTERRUPTED", "INFEASIBLE", "FAILED",
           "STATUS_CODES", "REASONS", "CERTIFICATE", "PRECISION", "START_DEPENDENT", "UNVERIFIED", "POLISH_MAX_ITER", "CROSS_CHECK",
           "INFEASIBLE_POLICY", "MULTICHAIN", "OBJECTIVE_NOT_EVALUATED", "of", "error", "parse", "as_status",
           "from_backend", "status_from", "polish_reason", "status_code", "status_reason", "status_message"]


class Code(str, Enum):
    """The closed set of status codes (a ``str``: ``Code.OPTIMAL == "optimal"``)."""

    OPTIMAL = "optimal"
    INACCURATE = "inaccurate"
    MAX_ITER = "max_iter"
    INTERRUPTED = "interrupted"
    INFEASIBLE = "infeasible"
    FAILED = "failed"

    def __str__(self) -> str:
        return self.value

    def __format__(self, spec: str) -> str:
        return format(self.value, spec)


OPTIMAL = Code.OPTIMAL
INACCURATE = Code.INACCURATE
MAX_ITER = Code.MAX_ITER
INTERRUPTED = Code.INTERRUPTED
INFEASIBLE = Code.INFEASIBLE
FAILED = Code.FAILED
#: Every code, best first.
STATUS_CODES = tuple(Code)

# ----------------------------------------------------------------------------- reasons
CERTIFICATE = "certificate"
PRECISION = "precision"
START_DEPENDENT = "start_dependent"
#: A saved certificate that nothing binds to the policy saved with it (a file without its digest).
UNVERIFIED = "unverified"
POLISH_MAX_ITER = "polish_max_iter"
CROSS_CHECK = "cross_check"
INFEASIBLE_POLICY = "infeasible_policy"
MULTICHAIN = "multichain"
OBJECTIVE_NOT_EVALUATED = "objective_not_evaluated"

#: The reasons the toolkit gives, with what each means for the result. A backend's own status
#: word is a reason too (not listed: its message names it).
REASONS: dict[str, str] = {
    CERTIFICATE: "the solver finished, but the certificate gain_lower <= g* <= gain_upper is wider than "
                 "the tolerance asked for (cert_rtol); the bracket still holds",
    POLISH_MAX_ITER: "policy iteration, polishing the LP's policy, was not stable within its iteration cap "
                     "(polish_max_iter); the bracket still holds",
    "polish_inaccurate": "the polished policy's certificate is wider than the tolerance; the bracket still holds",
    "polish_precision": "value iteration inside the polish stopped at its round-off floor; the bracket still holds",
    "polish_start_dependent": "value iteration inside the polish found a gain that depends on the start state; "
                              "the bracket still holds",
    "polish_interrupted": "the polish of the LP's policy was interrupted; the bracket still holds",
    CROSS_CHECK: "method 'auto' ran both the LP and value iteration and their gains disagree beyond their "
                 "certificates (stats['cross_check_rel_diff'])",
    INFEASIBLE_POLICY: "the returned policy does not meet every bound within the feasibility tolerance",
    MULTICHAIN: "the returned policy's chain has several recurrent classes: its averages depend on the start",
    OBJECTIVE_NOT_EVALUATED: "the objective could not be evaluated exactly at the returned policy (its auxiliary "
                             "variables did not re-solve); the solver's value stands",
    UNVERIFIED: "a saved solution without the digest that binds its certificate to its policy (saved before "
                "it was written, or edited): its numbers are shown, never trusted as a certificate",
    PRECISION: "tolerance below attainable precision: value iteration reached the round-off floor of its "
               "sweeps (stats['stop'] says the width reached and the floor) and stopped; the bracket, widened "
               "by the round-off bound, still holds",
    START_DEPENDENT: "value iteration's certificate stopped shrinking: the optimal gain depends on the start "
                     "state (the MDP has several closed classes with different gains; stats['stop']), so no "
                     "single gain can be certified; the bracket gain_lower <= g*(s) <= gain_upper holds for "
                     "every start state s",
}

_CODE_MESSAGES = {
    OPTIMAL: "the certificate closed: gain_lower <= g* <= gain_upper within the tolerance asked for",
    INACCURATE: "the method finished, but its certificate is wider than the tolerance asked for; "
                "the bracket gain_lower <= g* <= gain_upper still holds",
    MAX_ITER: "the iteration budget (max_iter) ran out before the certificate closed; "
              "the bracket gain_lower <= g* <= gain_upper of the last iterate still holds",
    INTERRUPTED: "interrupted before the certificate closed; the bracket of the last iterate still holds",
    INFEASIBLE: "no stationary policy meets the bounds",
}

#: A reason is one line of text, no space at either end: usually one word (``precision``), or a
#: backend's native status as it names it (``MaxIterations``, ``kTimeLimit``).
_REASON = re.compile(r"\S(?:[^\n]*\S)?\Z")


class Status(str):
    """A status: its :attr:`code` and :attr:`reason`, and its text (the ``str`` it is).

    Make one with :func:`of` (or :func:`from_backend`, :func:`error`, :func:`parse`); the text is
    ``code`` or ``code:reason``.

    Attributes
    ----------
    code : Code
    reason : str or None
    """

    code: Code
    reason: str | None

    def __new__(cls, code: Code | str, reason: str | None = None, *, text: str | None = None) -> "Status":
        try:
            code = Code(code)
        except ValueError:
            raise ValueError(f"unknown status code {code!r}; expected one of "
                             f"{', '.join(c.value for c in Code)}") from None
        if reason is not None and (not isinstance(reason, str) or not _REASON.match(reason)):
            raise ValueError(f"a status reason is one line of text with no space at either end, got {reason!r}")
        if reason is not None and code is OPTIMAL:
            raise ValueError(f"an optimal status has no reason, got {reason!r}")
        self = super().__new__(cls, text if text is not None else code.value if reason is None
                               else f"{code.value}:{reason}")
        object.__setattr__(self, "code", code)
        object.__setattr__(self, "reason", reason)
        return self

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a Status is immutable")

    def __reduce__(self):
        return (parse, (str(self),))

    @property
    def ok(self) -> bool:
        """``code is OPTIMAL``."""
        return self.code is OPTIMAL

    @property
    def message(self) -> str:
        """What the status means for the result, in words."""
        return _message(self)


def of(code: Code | str, reason: str | None = None) -> Status:
    """The status of a result: ``of(OPTIMAL)``, ``of(INACCURATE, PRECISION)``, ...: the one way solvers
    make one."""
    return Status(code, reason)


def error(message: str) -> Status:
    """A ``FAILED`` status whose text is ``"error: <message>"`` (a failed point of a study)."""
    return Status(FAILED, text=f"error: {message}")


def parse(text: str) -> Status:
    """The :class:`Status` of a status text (read back from a file, or given as a string): the part
    before ``":"`` when it names a code, the word after it as the reason; anything else (``"error:
    ..."``, an unknown code) is ``FAILED`` with the text kept."""
    if isinstance(text, Status):
        return text
    text = str(text)
    head, sep, tail = text.partition(":")
    head, tail = head.strip(), tail.strip()
    try:
        code = Code(head)
    except ValueError:
        return Status(FAILED, text=text)
    reason = tail or None if sep else None
    if reason is not None and (code is OPTIMAL or not _REASON.match(reason)):
        return Status(FAILED, text=text)
    return Status(code, reason, text=text)


def as_status(value: Any) -> Status:
    """A :class:`Status` from a status, a code or a status text (:func:`parse`)."""
    if isinstance(value, Status):
        return value
    if isinstance(value, Code):
        return Status(value)
    return parse(value)


def from_backend(table: Mapping[str, Code], native: Any) -> Status:
    """The status of a backend's own status word: its code in the backend's ``table``, the word
    itself as the reason (none for ``OPTIMAL``); a word missing from the table is ``FAILED``."""
    word = str(native)
    code = table.get(word, FAILED)
    if code is OPTIMAL:
        return Status(OPTIMAL)
    return Status(code, word.strip() or None)


def status_from(defects: Iterable[Status | str | None]) -> Status:
    """A result's status from its possible defects, in order of precedence: the first one that is
    not None (nor an optimal status) decides. A :class:`Status` stands as it is (a backend's
    ``max_iter:MaxIterations`` stays ``MAX_ITER``); a reason given as text makes ``INACCURATE``
    with that reason (``"certificate"`` -> ``inaccurate:certificate``). No defect: ``OPTIMAL``.

    ``status_from((backend_status, polish_issue, None if closed else CERTIFICATE))`` is how the LP
    and the constrained solvers say "optimal only when the backend succeeded and the certificate
    closed".
    """
    for d in defects:
        if isinstance(d, Code):
            d = Status(d)
        if d is None or (isinstance(d, Status) and d.ok):
            continue
        if isinstance(d, Status):
            return d
        return Status(INACCURATE, " ".join(str(d).split()) or None)
    return Status(OPTIMAL)


def polish_reason(polish: Status) -> str:
    """The reason an LP's answer gets when the polish of its policy ended with ``polish`` (not
    optimal): ``polish_<reason>`` or ``polish_<code>`` (``polish_max_iter``, ``polish_precision``)."""
    return f"polish_{polish.reason or polish.code.value}"


# ----------------------------------------------------------------------------- strings
def status_code(status: Any) -> Code:
    """The code of a status (or of a status text, :func:`parse`)."""
    return as_status(status).code


def status_reason(status: Any) -> str | None:
    """The reason of a status (``"inaccurate:certificate"`` -> ``"certificate"``), or None."""
    return as_status(status).reason


def status_message(status: Any) -> str:
    """A sentence saying what a status means for the result."""
    return _message(as_status(status))


def _message(st: Status) -> str:
    code, reason = st.code, st.reason
    if code is FAILED and reason is None:
        return f"the solve failed: {st}"
    if code in (FAILED, INFEASIBLE) and reason is not None and reason not in REASONS:
        return f"the solver ended with its own status {reason!r} ({code.value}): no usable answer"
    if reason is None:
        return _CODE_MESSAGES[code]
    if reason in REASONS:
        return REASONS[reason]
    if reason.startswith("polish_"):
        return f"the polish of the LP's policy ended with status {reason[7:]!r}; the bracket still holds"
    return (f"the solver ended with its own status {reason!r} ({code.value}) instead of success; the bracket "
            "gain_lower <= g* <= gain_upper still holds")
