"""The options of the matrix-free solver (:class:`MatrixFreeOptions`), checked once, when made."""
from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import SolverError
from ..iteration import VI_TOL, IterationOptions, is_int, is_real
from .layout import DOMAINS

__all__ = ["MatrixFreeOptions", "SCHEMES", "TILE_ORDERS"]

#: ``scheme`` values of :func:`~.iterate.matrix_free_value_iteration`.
SCHEMES = ("auto", "mpi", "gs", "jacobi")
#: ``tile_order`` values.
TILE_ORDERS = ("forward", "reverse")
#: ``candidates`` values: the candidate actions' bit set per configuration or per row.
CANDIDATES = ("config", "row")
#: ``wide_shift`` values: the in-place sweeps' shift while the certificate is wide.
WIDE_SHIFTS = ("mid", "lo", "best", "geo")


@dataclass(frozen=True)
class MatrixFreeOptions(IterationOptions):
    """How :func:`~.iterate.matrix_free_value_iteration` and :func:`~.iterate.matrix_free_evaluate`
    iterate. Every field can also be given to them as a keyword.

    Attributes
    ----------
    tol, atol, max_iter, check_every, stall_checks
        As :class:`~wncs_lp.solvers.iteration.IterationOptions` (relative width 1e-9, absolute
        0, 100,000 sweeps, a certificate every 5 improvement sweeps, the Jacobi fallback after 40
        certificates without the width halving).
    on_interrupt : {"return", "raise"}
        On Ctrl-C: certify the current h with one more pass and return it with status
        ``"interrupted"`` (default), or re-raise.
    scheme : {"auto", "mpi", "gs", "jacobi"}
        Value iteration only. ``"auto"`` = ``"mpi"``: relaxed Gauss-Seidel improvement sweeps,
        each followed by ``eval_sweeps`` sweeps of the policy it found; ``"gs"`` without them;
        ``"jacobi"`` is relative value iteration with the aperiodicity transform (tau = 0.5),
        which needs a second value vector.
    relax : float
        Relaxation of the in-place sweeps, in (0, 1].
    eval_sweeps : int
        Value iteration only: fixed-policy sweeps after each improvement sweep (``"mpi"``), >= 0
        (2: a fixed-policy sweep costs a fraction of an improvement sweep, and a second one saved
        a third of the improvement sweeps on processes 1-4).
    threads : int or None
        numba threads (:func:`wncs_lp.solvers.threads.resolve_threads`): by default the usable
        cores from 1,000,000 layout states on, else one; a count given is used as it is (capped
        at numba's maximum; one in a fork of a process that ran GNU OpenMP). With 2 or more the
        in-place sweeps are asynchronous between the threads (iterates depend on timing; the
        certificate does not).
    domain : {"auto", "hull", "reachable"}
        Over which states the certificate is taken (:mod:`wncs_lp.solvers.matrix_free`): the
        interval hull (valid always, closes when :func:`~.layout.drains_to_initial`), or the
        exact reachable set (a byte mask; ``"auto"`` uses it only when the hull's bracket might
        not close).
    tile_order : {"forward", "reverse"}
        Order of the in-place sweeps over the AoI tiles (forward needed 1.5x fewer sweeps than
        reverse on processes 1-4).
    extrapolate : bool
        One-mode extrapolation of the bias when the bracket shrinks at a steady rate
        (:class:`~.extrapolate.Extrapolator`; needs a second value vector, used only if it fits).
    candidates_rel : float
        Value iteration only: once the certificate's relative width is at most this (1e-2), the
        improvement sweeps between two certificates try only candidate actions (``candidates``;
        0: every action, always). The certificate passes always try every action, so the
        bracket is unchanged; this only makes the improvement sweeps cheaper.
    candidates : {"row", "config"}
        Where the candidates are set: per row (the last AoI axis of a configuration's box; the
        default), the actions within ``candidates_near`` x the last certificate's width of the
        minimum somewhere on the row, as the certificate pass finds them; or per configuration,
        the actions the last certificate's greedy policy takes somewhere in its box (the union
        over a whole box: 1.7 actions a configuration at cap 20 against ~1.0-1.3 a row, so an
        improvement sweep over them cost 1.15-1.3x one over a row's; docs/matrix-free.md).
    candidates_near : float
        >= 0 (1.0): the margin of the row candidates, in widths of the certificate before (0:
        the greedy policy's actions on the row only, which missed policy changes the margin
        catches: processes 1-4 cap 12, 110 passes against 92).
    aggregate : bool
        After each certificate whose relative width is at most ``aggregate_rel``, the coarse
        correction of :mod:`~.aggregate` (one group per configuration: the aggregated
        evaluation of the certificate's greedy policy, its solution added to h). Off by
        default: docs/matrix-free.md has the sweeps it saves (evaluations) and costs (the
        optimum's modified policy iteration).
    aggregate_rel : float
        > 0 (1e-2).
    gain_hint : float or None
        Value iteration only: the in-place sweeps' shift (their estimate of the gain) while the
        certificate's relative width exceeds ``wide_rel``, clipped into the intersection of
        the certificates so far (g* lies in it); None: the bracket's midpoint (or
        ``wide_shift``). A coarse start (``coarse_ratio``) sets it to the coarse gain when not
        given. The certificate is unaffected; a hint only sets how far a shift off the gain
        distorts the in-place sweeps (by about the error, 1/relax - the share of successors
        already updated): from h = 0 the first bracket is [min c, max c], whose midpoint can be
        many times the gain (measured: docs/matrix-free.md).
    wide_shift : {"mid", "lo", "best", "geo"}
        Without a hint, the shift while the width exceeds ``wide_rel``: the last bracket's
        midpoint (default), its lower end, the midpoint of the intersection of the brackets so
        far, or that intersection's geometric midpoint (when its lower end is > 0). Measured and
        left off (docs/matrix-free.md): none beat the midpoint at every cap.
    wide_rel : float
        > 0 (1.0): the relative width above which the bracket counts as wide.
    coarse_ratio : float
        Value iteration only, in [0, 1) (2/3): solve first at the caps ``coarse_ratio`` x the caps
        (rounded, :func:`~.iterate.coarse_caps`) to ``coarse_tol``, start from that bias with
        each AoI clamped into the smaller boxes (:func:`~.start.clamped_values`) and take its
        gain as ``gain_hint``; only for a layout of at least ``coarse_states`` states, without
        an ``h0``, and where the configurations do not change with the caps (not the preemption
        model's, which hold AoI values). 0: never. Processes 1-4 at cap 30: docs/matrix-free.md.
    coarse_states : int
        >= 0 (100,000,000): the layout size from which the coarse start is made (below it the
        first brackets of the measured models do not widen, and the start gains nothing).
    coarse_tol : float
        > 0 (0.1): the relative width the coarse solve is taken to (its bias and gain start a
        solve whose first brackets are far wider; 1e-2, the earlier default, took 37-43
        coarse sweeps against 25-31 for the same passes at cap 30: docs/matrix-free.md).
    coarse_far : float
        >= 0 (10): the coarse start is used only when the first bracket's midpoint from h = 0,
        (min c + max c) / 2 over the AoI box (:func:`~.iterate.first_midpoint`), is at least this
        multiple of the coarse gain (a lower bound on g*, which grows with the caps): the
        distortion that start cures; otherwise the solve starts from zero with the midpoints, as
        without it (a coarse gain far below g* is a hint that costs passes).
    warm_start : bool or None
        Jacobi sweeps first, until the bracket is within ``warm_rel`` (at most ``warm_max``
        sweeps); it shares the extrapolation's second vector. None: on for an evaluation, off for
        value iteration.
    warm_rel : float
        > 0.
    warm_max : int
        >= 0.
    force : bool
        Value iteration only: skip the size guard (:func:`wncs_lp.models.guard.check_size` with
        ``method="matrix-free"``, which refuses a layout whose vectors would not fit).
    """

    tol: float = VI_TOL
    on_interrupt: str = "return"
    scheme: str = "auto"
    relax: float = 0.8
    eval_sweeps: int = 2
    threads: int | None = None
    domain: str = "auto"
    tile_order: str = "forward"
    extrapolate: bool = True
    candidates_rel: float = 1e-2
    candidates: str = "row"
    candidates_near: float = 1.0
    aggregate: bool = False
    aggregate_rel: float = 1e-2
    gain_hint: float | None = None
    wide_shift: str = "mid"
    wide_rel: float = 1.0
    coarse_ratio: float = 2 / 3
    coarse_states: int = 100_000_000
    coarse_tol: float = 0.1
    coarse_far: float = 10.0
    warm_start: bool | None = None
    warm_rel: float = 0.05
    warm_max: int = 100
    force: bool = False

    def __post_init__(self) -> None:
        super().__post_init__()
        _choice("scheme", self.scheme, SCHEMES)
        _choice("domain", self.domain, DOMAINS)
        _choice("tile_order", self.tile_order, TILE_ORDERS)
        _choice("candidates", self.candidates, CANDIDATES)
        _choice("wide_shift", self.wide_shift, WIDE_SHIFTS)
        if self.gain_hint is not None and not (is_real(self.gain_hint) and math.isfinite(self.gain_hint)):
            raise SolverError(f"gain_hint must be a finite number (or None), got {self.gain_hint!r}")
        if not (is_real(self.wide_rel) and math.isfinite(self.wide_rel) and self.wide_rel > 0):
            raise SolverError(f"wide_rel must be a finite number > 0, got {self.wide_rel!r}")
        if not (is_real(self.coarse_ratio) and 0.0 <= self.coarse_ratio < 1.0):
            raise SolverError(f"coarse_ratio must be in [0, 1) (0: no coarse start), got {self.coarse_ratio!r}")
        if not (is_int(self.coarse_states) and self.coarse_states >= 0):
            raise SolverError(f"coarse_states must be an integer >= 0, got {self.coarse_states!r}")
        if not (is_real(self.coarse_tol) and math.isfinite(self.coarse_tol) and self.coarse_tol > 0):
            raise SolverError(f"coarse_tol must be a finite number > 0, got {self.coarse_tol!r}")
        if not (is_real(self.coarse_far) and math.isfinite(self.coarse_far) and self.coarse_far >= 0):
            raise SolverError(f"coarse_far must be a finite number >= 0, got {self.coarse_far!r}")
        if not (is_real(self.relax) and 0.0 < self.relax <= 1.0):
            raise SolverError(f"relax must be in (0, 1], got {self.relax!r}")
        if not (is_real(self.candidates_rel) and math.isfinite(self.candidates_rel) and self.candidates_rel >= 0):
            raise SolverError(f"candidates_rel must be a finite number >= 0, got {self.candidates_rel!r}")
        if not (is_real(self.candidates_near) and math.isfinite(self.candidates_near) and self.candidates_near >= 0):
            raise SolverError(f"candidates_near must be a finite number >= 0, got {self.candidates_near!r}")
        if not (is_real(self.warm_rel) and math.isfinite(self.warm_rel) and self.warm_rel > 0):
            raise SolverError(f"warm_rel must be a finite number > 0, got {self.warm_rel!r}")
        for name in ("eval_sweeps", "warm_max"):
            v = getattr(self, name)
            if not (is_int(v) and v >= 0):
                raise SolverError(f"{name} must be an integer >= 0, got {v!r}")
        if self.threads is not None and not (is_int(self.threads) and self.threads >= 1):
            raise SolverError(f"threads must be an integer >= 1 (or None: the usable cores), got {self.threads!r}")
        if not (is_real(self.aggregate_rel) and math.isfinite(self.aggregate_rel) and self.aggregate_rel > 0):
            raise SolverError(f"aggregate_rel must be a finite number > 0, got {self.aggregate_rel!r}")
        for name in ("extrapolate", "force", "aggregate"):
            if not isinstance(getattr(self, name), bool):
                raise SolverError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if self.warm_start is not None and not isinstance(self.warm_start, bool):
            raise SolverError(f"warm_start must be True, False or None, got {self.warm_start!r}")


def _choice(name: str, value: object, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise SolverError(f"unknown {name} {value!r}; expected one of {', '.join(allowed)}")

