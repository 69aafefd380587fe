"""Checks of the arguments of the public functions: type, range, finite values.

Each check returns the value as the function uses it (a Python ``int`` or ``float``) or raises
one :class:`~wncs_lp.errors.ArgumentError` that names the argument and says what was expected
and what was given, before any work (``simulate(slots=2.5)``: "slots: expected a whole number
>= 1, got 2.5 (float)"). The command line's parser applies the same checks to its options
(:mod:`wncs_lp.cli.common`), so an option and the argument it becomes accept the same values.

Booleans are not numbers here (``slots=True`` is refused), numpy's integer and float scalars
are; a float is not a whole number even when integral (``reps=20.0`` is refused: a count is
an ``int``).
"""
from __future__ import annotations

import math
import numbers
from typing import Any, Callable, Iterable, Mapping

from .errors import ArgumentError

__all__ = ["whole", "real", "seed", "keywords", "choice", "shown"]


def shown(value: Any) -> str:
    """A value as a message shows it: its repr, at most 60 characters, and its type."""
    text = repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def _range_words(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    """``">= 1"``, ``"> 0 and < 1"``: a range in words (whole numbers with thousands separators)."""
    def bound(op: str, x: float) -> str:
        return f"{op} {x:g}" if isinstance(x, float) else f"{op} {x:,}"

    parts = []
    if lo is not None:
        parts.append(bound(">" if lo_open else ">=", lo))
    if hi is not None:
        parts.append(bound("<" if hi_open else "<=", hi))
    return " and ".join(parts)


def _in_range(x: float, lo, hi, lo_open: bool, hi_open: bool) -> bool:
    if lo is not None and (x <= lo if lo_open else x < lo):
        return False
    if hi is not None and (x >= hi if hi_open else x > hi):
        return False
    return True


def whole(value: Any, name: str, *, lo: int | None = None, hi: int | None = None, why: str = "") -> int:
    """``value`` as an ``int`` in ``[lo, hi]``; ``why`` is added to the message of a value out of range."""
    words = _range_words(lo, hi, False, False)
    expected = f"expected a whole number{' ' + words if words else ''}"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ArgumentError(name, f"{expected}, got {shown(value)}")
    v = int(value)
    if not _in_range(v, lo, hi, False, False):
        raise ArgumentError(name, f"{expected}, got {v:,}" + (f" ({why})" if why else ""))
    return v


def real(value: Any, name: str, *, lo: float | None = None, hi: float | None = None, lo_open: bool = False,
         hi_open: bool = False) -> float:
    """``value`` as a finite ``float`` in the range (``lo_open`` / ``hi_open``: the end excluded)."""
    ok = not isinstance(value, bool) and isinstance(value, numbers.Real)
    v = float(value) if ok else math.nan
    words = _range_words(None if lo is None else float(lo), None if hi is None else float(hi), lo_open, hi_open)
    if not ok or not math.isfinite(v) or not _in_range(v, lo, hi, lo_open, hi_open):
        raise ArgumentError(name, f"expected a finite number{' ' + words if words else ''}, got {shown(value)}")
    return v


def seed(value: Any, name: str = "seed") -> int | None:
    """A random seed: None (fresh entropy) or a whole number >= 0 (``numpy.random.SeedSequence``)."""
    if value is None:
        return None
    return whole(value, name, lo=0)


def choice(value: Any, name: str, allowed: Iterable[str]) -> str:
    """One of the names ``allowed``."""
    allowed = tuple(allowed)
    if not isinstance(value, str) or value not in allowed:
        raise ArgumentError(name, f"expected one of {', '.join(allowed)}, got {shown(value)}")
    return value


def keywords(given: Mapping[str, Any], allowed: Iterable[str] | Callable[..., Any], where: str) -> None:
    """Refuse a keyword ``where`` (a function's name) does not take: ``allowed`` is the names, or
    a function whose keyword parameters are read (a ``**kwargs`` of its own takes any)."""
    if callable(allowed):
        import inspect

        params = inspect.signature(allowed).parameters.values()
        if any(p.kind is p.VAR_KEYWORD for p in params):
            return
        names = [p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)]
    else:
        names = list(allowed)
    unknown = [k for k in given if k not in names]
    if unknown:
        raise ArgumentError(unknown[0], f"{where} takes no keyword {unknown[0]!r}; it takes "
                                        f"{', '.join(names) or 'none'}")
