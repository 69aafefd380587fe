"""The toolkit's exception classes.

Every error that bad input can trigger is a :class:`WncsError` (a ``ValueError``), so a
caller can catch one class and always get a message naming what was wrong.
"""
from __future__ import annotations

__all__ = ["printable", "WncsError", "ArgumentError", "ScenarioError", "ModelError", "SolverError", "PolicyError",
           "InfeasibleConstraintsError", "ExportError",
           "ScenarioWarning", "SizeLimitError"]


def printable(text: object) -> str:
    """``str(text)`` with its control characters escaped (``\\n``, ``\\x1b``): one line, and no
    escape sequence reaches a terminal (a name read from a file may hold any character)."""
    s = str(text)
    if s.isprintable():
        return s
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in s)


class WncsError(ValueError):
    """Base class of every error raised by wncs_lp on bad input or a failed computation."""


class ArgumentError(WncsError, TypeError):
    """An argument of a public function of the wrong type, out of its range or not finite.

    The message starts with the argument's name. Also a ``TypeError``, so code that catches
    Python's own error for a wrong type still catches it.

    Attributes
    ----------
    argument : str
        The name of the argument.
    detail : str
        The message without the name (what was expected, what was given).
    """

    def __init__(self, argument: str, message: str):
        self.argument = argument
        self.detail = message
        super().__init__(f"{argument}: {message}")


class ScenarioError(WncsError):
    """A scenario file, dictionary or override is invalid.

    The message names the source (file or ``<dict>``), the field and what was expected.
    """

    def __init__(self, source: str, field: str, expected: str, what: str = "field"):
        self.source = source
        self.field = field
        self.expected = expected
        # one line always: control characters in a field name (e.g. from --set) are escaped
        shown = printable(field)
        super().__init__(f"{source}: {what} '{shown}': {expected}")


class ScenarioWarning(UserWarning):
    """A valid scenario that describes a degenerate problem (a server that never delivers, a cap at
    or below every loop length): see :meth:`wncs_lp.scenario.Scenario.degenerate_warnings`."""


class ModelError(WncsError):
    """An MDP is malformed (bad shapes, rows not summing to one, a state without action...)."""


class SizeLimitError(WncsError):
    """A computation would exceed the memory limit or the exploration budget (the size guard,
    :mod:`wncs_lp.models.guard`); ``force`` runs it anyway.

    Attributes
    ----------
    estimate : SizeEstimate or None
        The guard's estimate (:class:`wncs_lp.models.guard.SizeEstimate`) when there is one.
    """

    def __init__(self, message: str, estimate=None):
        self.estimate = estimate
        super().__init__(message)


class SolverError(WncsError):
    """A solver failed or returned an answer that did not pass its accuracy checks."""


class ExportError(WncsError):
    """A file is not a readable ``wncs_lp`` export (:mod:`wncs_lp.io`), or a model cannot be written in
    another tool's format as asked (a reward model that is not an identifier, negative rewards)."""


class PolicyError(WncsError):
    """A policy is infeasible for the MDP, or its induced chain cannot be evaluated."""


class InfeasibleConstraintsError(SolverError):
    """No stationary policy meets the bounds of a constrained problem.

    Attributes
    ----------
    constraints : tuple of str
        The labels of the constraints at fault: those whose bound no policy can reach on its
        own, or all of them when each is reachable alone but not together.
    bounds : tuple of float
        The bound each of them asks for (the ``max`` or the ``min``).
    reachable : tuple of float
        For each of them the least (for a ``max`` bound) or largest (for a ``min`` bound)
        long-run average any stationary policy reaches for that quantity alone.
    sides : tuple of str
        ``"max"`` or ``"min"``: which bound of each constraint fails.
    jointly : bool
        True when every bound is reachable alone and only their combination is infeasible.
    """

    def __init__(self, message: str, constraints=(), bounds=(), reachable=(), sides=(), jointly=False):
        super().__init__(message)
        self.constraints = tuple(constraints)
        self.bounds = tuple(float(b) for b in bounds)
        self.reachable = tuple(float(r) for r in reachable)
        self.sides = tuple(sides)
        self.jointly = bool(jointly)
