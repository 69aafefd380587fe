r"""Certified iteration: the one loop of every value-iteration solver of the toolkit.

A solver supplies an :class:`IterationScheme` -- how to sweep between two certificates, how to
compute the certificate of the current iterate h, how to move on to the next iterate -- and
:func:`certified_iteration` runs it (the shape of mdpax's ``Solver.solve`` with its
``_iteration_step``)::

    repeat until the budget (max_iter sweeps) is spent:
        sweeps between two certificates            scheme.improve   (none for Jacobi)
        bracket lo <= g* <= hi on h                scheme.certify   (Jacobi: also writes h')
        non-finite values                       -> SolverError (costs or values overflow)
        closing rule, round-off band included   -> "optimal"
        width inside the round-off band, stalled -> "inaccurate:precision"
        Jacobi bracket settled, far from closed -> "inaccurate:start_dependent"
        extrapolation moved h                   -> certify again before sweeping
        width not halved in stall_checks checks -> the Jacobi scheme takes over
        next iterate                               scheme.advance   (not after the last sweep)
    Ctrl-C: re-raise, or certify the current h once more and stop "interrupted"

The bracket ``lo = min_s (T h - h)(s) <= g* <= max_s (T h - h)(s) = hi`` holds for any h
(:mod:`wncs_lp.solvers.certify`), so the sweeps between two certificates need no convergence
theory to be trusted, and the returned h is always the one the last certificate was computed on.

The closing rule
----------------
:func:`~wncs_lp.solvers.certify.width_closed` -- ``hi - lo <= tol |g|``, or ``<= atol``, or
below ``1e-13 max|c|`` -- applied to the bracket **widened by the round-off bound** delta of its
computation on each side (:meth:`IterationScheme.roundoff`): each computed ``d(s)`` is within
delta of the exact one, so the exact bracket lies in ``[lo - delta, hi + delta]``, and the
certificate closes only when that interval does. The bracket reported is the computed one. The
floor ``1e-13 max|c|`` serves a gain at the round-off level of the costs (g* = 0, where no
relative width can be met); for a larger gain a width under the floor but over ``tol |g|`` is
a tolerance below the attainable precision, as below.

When the computed width meets the tolerance but the band ``2 delta`` alone does not, the
tolerance is below the attainable precision: the run stops with status
``"inaccurate:precision"`` and the bracket widened by delta. When the band fits but the width
plus the band does not yet, the iteration goes on (the width still falls). Without this, a run
whose computed width had just crossed the tolerance was sent to the precision stop although
the precision was far from reached (processes 1, 2 at cap 30, p = 0.9, RVI at tol 1e-10:
width 9.7e-11, band 4e-12).

A width inside the round-off band that has not halved for :data:`PRECISION_STALL_SWEEPS` sweeps
ends the run ``"inaccurate:precision"`` too (a tolerance no number of sweeps can meet).

A gain that depends on the start state
--------------------------------------
When the MDP has several closed classes with different optimal gains (multichain, not weakly
communicating), no h closes the bracket: lo <= min_s g*(s) and hi >= max_s g*(s). The Jacobi
iteration with the aperiodicity transform converges whenever the optimal gain is constant, so
when its bracket ends have not moved (by more than :data:`SETTLED_RTOL` of the width) over
``stall_checks`` certificates, far above the round-off band, the run stops with status
``"inaccurate:start_dependent"``: the bracket holds g*(s) for every start s, and ``stats["stop"]``
says so.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..errors import SolverError
from ..progress import Progress, convergence_eta
from ..status import INACCURATE, INTERRUPTED, MAX_ITER, OPTIMAL, PRECISION, START_DEPENDENT, Status, of
from .certify import width_closed

__all__ = ["IterationOptions", "IterationScheme", "IterationOutcome", "certified_iteration", "check_options",
           "options_from", "cert_line", "is_int", "is_real", "gamma", "max_abs", "VI_TOL", "PRECISION_STALL_SWEEPS",
           "SETTLED_RTOL", "ROUNDOFF_FLOOR", "ON_INTERRUPT"]

#: Default relative certificate width of value iteration.
VI_TOL = 1e-9

#: Sweeps without the certificate width halving, at a width inside the round-off band, after
#: which an iteration stops with status ``"inaccurate:precision"``.
PRECISION_STALL_SWEEPS = 50

#: The round-off floor of :func:`~wncs_lp.solvers.certify.width_closed`, relative to max|c|.
ROUNDOFF_FLOOR = 1e-13

#: Relative movement (of the width) under which the Jacobi bracket's ends count as settled.
SETTLED_RTOL = 1e-9

#: ``on_interrupt`` values.
ON_INTERRUPT = ("raise", "return")


@dataclass(frozen=True)
class IterationOptions:
    """What a certified iteration is asked for; checked once, when made.

    Attributes
    ----------
    tol : float
        Relative certificate width ``(hi - lo) / |g|`` to reach, finite and > 0.
    atol : float
        Absolute width accepted as well (useful when g* = 0), finite and >= 0.
    max_iter : int
        Budget of sweeps (improvement and certificate sweeps; evaluation sweeps not counted), >= 1.
    check_every : int
        Improvement sweeps between two certificates, >= 1.
    stall_checks : int
        Certificates without the width halving before the Jacobi scheme takes over (and, in the
        Jacobi scheme, with settled ends before the gain is called start-dependent), >= 1.
    on_interrupt : {"raise", "return"}
        On Ctrl-C: re-raise, or certify the current iterate and return it ``"interrupted"``.
    """

    tol: float = VI_TOL
    atol: float = 0.0
    max_iter: int = 100_000
    check_every: int = 5
    stall_checks: int = 40
    on_interrupt: str = "raise"

    def __post_init__(self) -> None:
        check_options(self)


def is_int(x: Any) -> bool:
    """An integer (Python or numpy), not a bool."""
    return isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))


def is_real(x: Any) -> bool:
    """A real number (Python or numpy), not a bool."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def check_options(opts: Any) -> None:
    """Raise one :class:`SolverError` naming the first field of ``opts`` out of its range."""
    if not (is_real(opts.tol) and math.isfinite(opts.tol) and opts.tol > 0):
        raise SolverError(f"tol must be a finite number > 0 (a relative certificate width), got {opts.tol!r}")
    if not (is_real(opts.atol) and math.isfinite(opts.atol) and opts.atol >= 0):
        raise SolverError(f"atol must be a finite number >= 0, got {opts.atol!r}")
    for name in ("max_iter", "check_every", "stall_checks"):
        v = getattr(opts, name)
        if not (is_int(v) and v >= 1):
            raise SolverError(f"{name} must be an integer >= 1, got {v!r}")
    if opts.on_interrupt not in ON_INTERRUPT:
        raise SolverError(f"on_interrupt must be 'return' or 'raise', got {opts.on_interrupt!r}")


def options_from(cls: type, options: Any, given: dict[str, Any], what: str) -> Any:
    """An options dataclass ``cls`` from ``options`` (an instance or None) and keyword fields.

    A keyword that is not a field of ``cls`` is one :class:`SolverError` naming the fields.
    """
    names = [f.name for f in fields(cls)]
    bad = [k for k in given if k not in names]
    if bad:
        raise SolverError(f"{what} takes no option {bad[0]!r}; its options are {', '.join(names)}")
    if options is None:
        return cls(**given)
    if not isinstance(options, cls):
        raise SolverError(f"options must be a {cls.__name__}, got {type(options).__name__}")
    if not given:
        return options
    import dataclasses

    return dataclasses.replace(options, **given)


class IterationScheme:
    """The sweeps of one solver, as :func:`certified_iteration` drives them.

    A subclass holds the iterate ``h`` and implements :meth:`certify`, :meth:`roundoff` and
    whichever of the other steps its iteration has.

    Attributes
    ----------
    name : str
        The scheme now running (``"mpi"``, ``"gs"``, ``"jacobi"``, ``"warm"``): progress lines,
        ``stats["final_scheme"]``.
    h : (n,) array
        The current iterate.
    """

    name = "jacobi"
    h: np.ndarray

    @property
    def in_place(self) -> bool:
        """Whether :meth:`improve` has sweeps to make between two certificates."""
        return False

    @property
    def aperiodic_jacobi(self) -> bool:
        """Whether the scheme is Jacobi with the aperiodicity transform (tau < 1): its bracket
        closes whenever the optimal gain does not depend on the start state."""
        return False

    @property
    def warming(self) -> bool:
        """Whether the scheme is in a warm-start phase (:meth:`leave_warm` ends it)."""
        return False

    def improve(self, sweeps: int, shift: float) -> int:
        """Make ``sweeps`` improvement sweeps of h; returns the evaluation sweeps made besides."""
        return 0

    def certify(self, shift: float) -> tuple[float, float]:
        """The bracket (min, max) of ``T h - h`` on the current h (a Jacobi scheme also writes
        its next iterate aside, for :meth:`advance`)."""
        raise NotImplementedError

    def h_range(self) -> tuple[float, float]:
        """(min, max) of h (NaN if an entry is): two streaming numpy passes, no temporary; a
        scheme with a faster reduction (one parallel pass) overrides it."""
        h = self.h
        return (float(np.min(h)), float(np.max(h))) if h.size else (0.0, 0.0)

    def advance(self) -> None:
        """Take the next iterate written by the last :meth:`certify`, if it wrote one."""

    def roundoff(self) -> float:
        """delta: a bound on the floating-point error of each computed (T h - h)(s) on the current h."""
        raise NotImplementedError

    def next_shift(self, lo: float, hi: float) -> float:
        """The shift (the gain's estimate) of the sweeps until the next certificate, from the
        certificate (lo, hi) just computed: its midpoint, unless the scheme knows better (a
        shift does not touch the certificate, which holds for any h; it sets how far the
        in-place sweeps drift from the bias)."""
        return 0.5 * (lo + hi)

    def after_check(self, width: float, progress: Progress) -> bool:
        """Called with each certificate's width outside warm-up; True when it moved h (then h is
        certified again before any sweep)."""
        return False

    def fall_back(self) -> str | None:
        """The width stalled: switch to the Jacobi scheme. Returns None when already Jacobi, else a
        note for ``stats["fallback"]`` ("" when it switched, why not when it could not)."""
        return None

    def leave_warm(self, width: float, mid: float, used: int, max_iter: int) -> bool:
        """After a warm-up certificate: whether to leave the warm-up now."""
        return True

    def interrupt(self) -> None:
        """Ctrl-C arrived: forget anything pending so that :meth:`certify` certifies h as it is."""

    def settle(self) -> None:
        """The run is over: make h the iterate of the last certificate."""

    #: Who iterates, in the overflow message.
    label = "value iteration"

    def cost_note(self) -> str:
        """The size of the costs and what to do about them, for the overflow message."""
        return "the costs are too large for float64 arithmetic: rescale them"

    def overflow(self, lo: float, hi: float, used: int) -> SolverError:
        """The error for values that left float64's range (the run never goes on with them)."""
        return SolverError(f"{self.label}: the values overflow (after {used:,} sweep(s) the certificate is "
                           f"[{lo:.6g}, {hi:.6g}], and it, its midpoint or the bias is not finite); {self.cost_note()}")


@dataclass
class IterationOutcome:
    """What :func:`certified_iteration` ends with.

    Attributes
    ----------
    lo, hi : float
        The last certificate, as computed (not widened).
    status : Status
        ``"optimal"``, ``"max_iter"``, ``"interrupted"``, ``"inaccurate:precision"`` or
        ``"inaccurate:start_dependent"`` (:mod:`wncs_lp.status`).
    delta : float
        The round-off bound of the last certificate when it was needed (closing rule, precision
        stop), else 0.
    stop : str or None
        Why a run stopped short of the tolerance (precision, start-dependent gain), in words.
    used, evals, checks : int
        Sweeps (improvement + certificate), evaluation sweeps, certificates.
    fallback : str or None
        Why the Jacobi scheme took over, or None.
    history : list of (sweeps, eval sweeps, seconds, lo, hi)
        One entry per certificate.
    """

    lo: float = math.nan
    hi: float = math.nan
    status: Status = field(default_factory=lambda: of(MAX_ITER))
    delta: float = 0.0
    stop: str | None = None
    used: int = 0
    evals: int = 0
    checks: int = 0
    fallback: str | None = None
    history: list[tuple] = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return self.status.code is OPTIMAL

    @property
    def at_floor(self) -> bool:
        return self.status.reason == PRECISION


def gamma(k: int) -> float:
    """Higham's gamma_k = k u / (1 - k u), u = 2^-53 the unit round-off."""
    ku = k * (np.finfo(float).eps / 2)
    return ku / (1.0 - ku)


def max_abs(h: np.ndarray) -> float:
    """max |h| in two streaming passes (no length-n temporary)."""
    return max(float(np.max(h)), -float(np.min(h))) if h.size else 0.0


def _widths(history: list[tuple]) -> list[tuple[float, float]]:
    """``(seconds, relative certificate width)`` of each check of the history (for the ETA)."""
    return [(t, (hi - lo) / max(abs(0.5 * (lo + hi)), 1e-300)) for _, _, t, lo, hi in history]


def cert_line(name: str, sweeps: int, lo: float, hi: float, tol: float) -> str:
    """One progress line of an iteration: the sweeps and the certificate gap against its target."""
    rel = (hi - lo) / max(abs(0.5 * (lo + hi)), 1e-300)
    return f"[{name}] sweep {sweeps:,}: {lo:.10g} <= g* <= {hi:.10g}, gap {rel:.2e} (target {tol:.0e})"


class _Judge:
    """The stopping rules of one run: closing with the round-off band, the precision stall and
    the settled Jacobi bracket (module docstring)."""

    def __init__(self, opts: IterationOptions, scheme: IterationScheme, cost_scale: float):
        self.opts, self.scheme, self.scale = opts, scheme, cost_scale
        self.best, self.best_at = math.inf, 0  # the precision stall: sweeps since the width halved
        self.ends: list[tuple[float, float]] = []  # Jacobi (lo, hi) since it took over
        self.delta = 0.0
        self._delta_at = 0
        self.stop: str | None = None

    def _closed(self, lo: float, hi: float) -> bool:
        o, mid = self.opts, 0.5 * (lo + hi)
        # width_closed's floor (1e-13 max|c|) is there to certify a gain at the round-off level of
        # the costs (g* = 0, where no relative width can be met); above it, a width under the floor
        # but over tol |g| is a tolerance below the attainable precision (the precision stop)
        scale = self.scale if abs(mid) <= ROUNDOFF_FLOOR * self.scale else 0.0
        return width_closed(lo, hi, mid, o.tol, atol=o.atol, cost_scale=scale)

    def __call__(self, lo: float, hi: float, used: int) -> Status | None:
        """The status the certificate (lo, hi) after ``used`` sweeps ends the run with, or None."""
        width = hi - lo
        if self._closed(lo, hi):
            self.delta = d = self.scheme.roundoff()
            if self._closed(lo - d, hi + d):
                return of(OPTIMAL)
            mid = 0.5 * (lo + hi)
            if not self._closed(mid - d, mid + d):  # the band alone is wider than the tolerance
                return self._precision(lo, hi)
        if width < 0.5 * self.best:
            self.best, self.best_at = width, used
        elif used - self.best_at >= PRECISION_STALL_SWEEPS and self._in_band(width, used):
            return self._precision(lo, hi)
        return self._settled(lo, hi)

    def _in_band(self, width: float, used: int) -> bool:
        """width <= 2 delta on the current h. delta costs a pass or two over h (the scheme's max |h|),
        so a width far above the last delta computed (3x, within 1,000 sweeps) is let go
        without one."""
        if self.delta > 0 and width > 6.0 * self.delta and used - self._delta_at < 1_000:
            return False
        self.delta, self._delta_at = self.scheme.roundoff(), used
        return width <= 2.0 * self.delta

    def _precision(self, lo: float, hi: float) -> Status:
        mid = max(abs(0.5 * (lo + hi)), 1e-300)
        self.stop = (f"tolerance below attainable precision: reached {(hi - lo) / mid:.3g} "
                     f"(round-off floor 2 delta / |g| = {2 * self.delta / mid:.3g}; asked {self.opts.tol:.3g}); "
                     f"bracket widened by delta = {self.delta:.3g} to cover the round-off")
        return of(INACCURATE, PRECISION)

    def _settled(self, lo: float, hi: float) -> Status | None:
        if not self.scheme.aperiodic_jacobi:
            self.ends = []
            return None
        self.ends.append((lo, hi))
        k = self.opts.stall_checks
        if len(self.ends) < k:
            return None
        last = np.asarray(self.ends[-k:])
        self.ends = self.ends[-k:]
        width = hi - lo
        moved = max(float(np.ptp(last[:, 0])), float(np.ptp(last[:, 1])))
        if moved > SETTLED_RTOL * width:
            return None
        self.delta = self.scheme.roundoff()
        if width <= 2.0 * self.delta:
            return None
        self.stop = (f"the bracket stopped shrinking at [{lo:.10g}, {hi:.10g}] (its ends moved by at most "
                     f"{moved:.3g} over {k} Jacobi certificates): the optimal gain depends on the start state "
                     "(the MDP has several closed classes with different gains), so no single gain closes it; "
                     "every start state's optimal gain lies in the bracket")
        return of(INACCURATE, START_DEPENDENT)


def _finite(lo: float, hi: float, scheme: IterationScheme) -> bool:
    """Whether the bracket, its width and midpoint, and every entry of the scheme's h are finite
    (h by its min and max, :meth:`IterationScheme.h_range`; either is NaN if an entry is)."""
    lo, hi = float(lo), float(hi)
    if not all(math.isfinite(x) for x in (lo, hi, hi - lo, lo + hi)):
        return False
    return all(math.isfinite(x) for x in scheme.h_range())


def certified_iteration(scheme: IterationScheme, opts: IterationOptions, *, cost_scale: float,
                        progress: Progress, label: str, t0: float | None = None) -> IterationOutcome:
    """Run ``scheme`` to a closed certificate, a stop, the budget or an interrupt (module docstring).

    Parameters
    ----------
    scheme : IterationScheme
    opts : IterationOptions
    cost_scale : float
        max|c| (the scale of the closing rule's round-off floor ``1e-13 max|c|``).
    progress : Progress
        A line per certificate (rate-limited), and the scheme's notes.
    label : str
        The progress lines' prefix (e.g. ``"vi"``, ``"matrix-free"``).
    t0 : float, optional
        ``time.perf_counter()`` at the start of the solve (the history's seconds).

    Raises
    ------
    SolverError
        The values became non-finite (the costs overflow float64 arithmetic).
    KeyboardInterrupt
        With ``opts.on_interrupt == "raise"``.
    """
    t0 = time.perf_counter() if t0 is None else t0
    out = IterationOutcome()
    judge = _Judge(opts, scheme, cost_scale)
    try:
        _loop(scheme, opts, judge, out, progress, label, t0)
    except KeyboardInterrupt:
        if opts.on_interrupt == "raise":
            raise
        scheme.interrupt()
        progress.phase(f"[{label}] interrupted: certifying the current iterate")
        out.lo, out.hi = scheme.certify(0.0)
        out.checks += 1
        if not _finite(out.lo, out.hi, scheme):
            raise scheme.overflow(out.lo, out.hi, out.used) from None
        verdict = judge(out.lo, out.hi, out.used)
        out.status = of(OPTIMAL) if verdict is not None and verdict.code is OPTIMAL else of(INTERRUPTED)
        judge.stop = None
    scheme.settle()
    out.delta, out.stop = judge.delta, judge.stop
    return out


def _loop(scheme: IterationScheme, opts: IterationOptions, judge: _Judge, out: IterationOutcome,
          progress: Progress, label: str, t0: float) -> None:
    """The iteration proper (module docstring); fills ``out``."""
    first = True  # the certificate comes first: a good warm start stops at once
    shift = 0.0
    best_w, best_at = math.inf, 0
    while out.used < opts.max_iter:
        if scheme.in_place and not first:
            todo = min(opts.check_every, max(opts.max_iter - out.used - 1, 0))
            out.evals += scheme.improve(todo, shift)
            out.used += todo
        first = False
        lo, hi = scheme.certify(shift)
        out.used += 1
        out.checks += 1
        out.lo, out.hi = lo, hi
        out.history.append((out.used, out.evals, time.perf_counter() - t0, lo, hi))
        if not _finite(lo, hi, scheme):
            raise scheme.overflow(lo, hi, out.used)
        if progress.enabled and progress.due():
            progress.tick(cert_line(f"{label}:{scheme.name}", out.used, lo, hi, opts.tol)
                          + convergence_eta(_widths(out.history), opts.tol))
        status = judge(lo, hi, out.used)
        if status is not None:
            out.status = status
            return
        width, mid = hi - lo, 0.5 * (lo + hi)
        if scheme.warming:
            shift = mid
            if out.used < opts.max_iter:
                scheme.advance()
            first = scheme.leave_warm(width, mid, out.used, opts.max_iter)
            continue
        if scheme.after_check(width, progress):
            first = True  # certify the moved h before sweeping on
            continue
        if width < 0.5 * best_w:
            best_w, best_at = width, out.checks
        elif out.checks - best_at >= opts.stall_checks:
            best_at = out.checks
            name = scheme.name
            note = scheme.fall_back()
            if note is not None:
                out.fallback = (f"{name} stalled at relative width {width / max(abs(mid), 1e-300):.3g} "
                                f"after {out.used} sweeps{note}")
                progress.phase(f"[{label}] {out.fallback}" + ("" if note else ": the Jacobi scheme takes over"))
        shift = scheme.next_shift(lo, hi)
        if out.used < opts.max_iter:  # the budget's last pass keeps its (certified) h
            scheme.advance()
