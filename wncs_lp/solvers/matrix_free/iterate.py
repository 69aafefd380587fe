"""Certified value iteration (:func:`matrix_free_value_iteration`) and exact policy evaluation
(:func:`matrix_free_evaluate`) over a :class:`~.layout.BoxLayout`: the matrix-free passes
(:class:`BoxSweeps`) run by the toolkit's one loop, :func:`wncs_lp.solvers.iteration.certified_iteration`."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...errors import PolicyError, SolverError
from ...models.system import System
from ...progress import Progress, as_progress
from ...scenario import Scenario
from ...status import INTERRUPTED, of
from ..iteration import IterationOutcome, IterationScheme, certified_iteration, gamma, options_from
from .aggregate import Aggregator
from .extrapolate import Extrapolator
from .layout import BoxLayout, check_local_actions, layout_states, resolve_domain
from .operator import Operator, Reduce, Write, with_cost
from .options import MatrixFreeOptions
from .result import MatrixFreeEvaluation, MatrixFreeSolution, as_system
from .start import clamped_values, start_vector
from .sweeper import Sweeper, load_kernels, reachable_mask

__all__ = ["matrix_free_value_iteration", "matrix_free_evaluate", "policy_table", "matrix_free_bytes",
           "BoxSweeps", "BYTES_PER_STATE", "JACOBI_TAU"]

#: Bytes per state of a solve at its floor: one float64 value vector and the uint8 policy (the
#: extrapolation, a Jacobi iteration or the stall fallback add a second vector: 17 bytes).
BYTES_PER_STATE = 9

#: The aperiodicity transform of the Jacobi passes (warm start, scheme ``"jacobi"``, fallback).
JACOBI_TAU = 0.5


def matrix_free_bytes(n_states: int, *, vectors: int = 1, mask: bool = False) -> int:
    """Memory of a matrix-free solve over ``n_states`` layout states (value vectors, policy,
    optional reachability mask)."""
    return int(n_states) * (8 * int(vectors) + 1 + (1 if mask else 0))


def _second_vector_fits(n: int) -> bool:
    """Whether a second value vector (the Jacobi fallback's) fits in the memory available now."""
    from ...models.guard import available_memory

    return 8 * n * 1.25 <= available_memory()


def _mb(nbytes: float) -> str:
    return f"{nbytes / 2**20:,.0f} MiB"


# ============================================================================ setup
@dataclass
class Setup:
    """What a matrix-free solve works on: the system, its layout and operator tables, the
    reachable mask (or None), the kernel caller and the starting h."""

    system: System
    layout: BoxLayout
    op: Operator
    mask: np.ndarray | None
    sw: Sweeper
    h: np.ndarray
    closes: bool

    @property
    def n(self) -> int:
        return self.layout.n_states

    def domain_stats(self) -> dict[str, Any]:
        return {"threads": self.sw.threads, "domain": "reachable" if self.mask is not None else "hull",
                "hull_closes": self.closes, "n_states": self.n}


def _setup(system: System, opts: MatrixFreeOptions, h0: Any, cost: Any = None,
           layout: BoxLayout | None = None) -> Setup:
    """Layout, operator (with ``cost`` instead of the MSE when given), mask, sweeper and h0."""
    use_mask, closes = resolve_domain(system, opts.domain)
    layout = BoxLayout.from_system(system, "hull") if layout is None else layout
    op = Operator.build(system, layout)
    if cost is not None:
        op = with_cost(op, cost)
    mask = reachable_mask(system, layout) if use_mask else None
    sw = Sweeper(op, opts.threads, mask, reverse=opts.tile_order == "reverse")
    return Setup(system, layout, op, mask, sw, start_vector(h0, layout), closes)


# ============================================================================ the passes
class BoxSweeps(IterationScheme):
    """The passes of a matrix-free iteration, as :func:`~wncs_lp.solvers.iteration.certified_iteration`
    drives them: relaxed in-place sweeps between certificates, certificate passes on a fixed h
    (or, in the Jacobi scheme and the warm start, Jacobi passes with the aperiodicity transform
    into a second vector), and the one-mode extrapolation of h (:class:`~.extrapolate.Extrapolator`).
    A subclass says what one pass is (:meth:`pass_`)."""

    label = "matrix-free"

    def __init__(self, st: Setup, opts: MatrixFreeOptions, main: str, warm_default: bool):
        self.st, self.sw, self.h = st, st.sw, st.h
        self.main, self.relax = main, opts.relax
        fits = _second_vector_fits(st.n)
        self.ex = Extrapolator(st.n, opts.extrapolate and main != "jacobi" and fits)
        self.h_out = np.empty(st.n) if main == "jacobi" else None
        warm = opts.warm_start if opts.warm_start is not None else warm_default
        self.name = "warm" if warm and self.ex.enabled else main
        self.warm_rel, self.warm_max = opts.warm_rel, opts.warm_max
        self.vectors = 1 + (self.h_out is not None) + self.ex.enabled
        self.iters = 0  # improvement sweeps (the extrapolation's clock)
        self.agg = Aggregator(st.system, st.op, st.sw.threads) if opts.aggregate and main != "jacobi" else None
        self.agg_rel = opts.aggregate_rel
        self.agg_unseen = False  # a correction made since the last certificate
        self.bracket = (np.inf, -np.inf)  # the last certificate's
        self.gain_hint, self.wide_shift, self.wide_rel = opts.gain_hint, opts.wide_shift, opts.wide_rel
        self.best = (-np.inf, np.inf)  # the intersection of every certificate: g* lies in it
        self._out: np.ndarray | None = None  # where the last certificate pass wrote the next iterate

    def pass_(self, h: np.ndarray, h_out: np.ndarray | None, write: Write, relax: float, shift: float) -> tuple[float, float]:
        """One pass over the layout; (min, max) of T h - h on the h it read (an in-place pass
        computes none: (inf, -inf))."""
        raise NotImplementedError

    def evaluation_sweeps(self, shift: float) -> int:
        """Sweeps after each improvement sweep (modified policy iteration); returns how many."""
        return 0

    def agg_policy(self) -> np.ndarray | None:
        """The policy (one local action per state) whose evaluation the coarse correction
        targets: the greedy policy of the last certificate's h (None: no correction)."""
        return None

    @property
    def in_place(self) -> bool:
        return self.name in ("mpi", "gs")

    @property
    def aperiodic_jacobi(self) -> bool:
        return self.name == "jacobi"

    @property
    def warming(self) -> bool:
        return self.name == "warm"

    def improve(self, sweeps: int, shift: float) -> int:
        evals = 0
        for i in range(sweeps):
            if i == 0 and self.ex.want_save():
                self.ex.save(self.h, self.iters)
            self.pass_(self.h, None, Write.IN_PLACE, self.relax, shift)
            self.iters += 1
            evals += self.evaluation_sweeps(shift)
        return evals

    def certify(self, shift: float) -> tuple[float, float]:
        self._out = self.ex.prev if self.name == "warm" else self.h_out if self.name == "jacobi" else None
        if self._out is None:
            bracket = self.pass_(self.h, None, Write.NONE, self.relax, shift)
        else:
            bracket = self.pass_(self.h, self._out, Write.OUT, JACOBI_TAU, shift)
        self.ex.certified()
        self.bracket, self.agg_unseen = bracket, False
        return bracket

    def next_shift(self, lo: float, hi: float) -> float:
        # While the bracket is wide its midpoint can be far off the gain (processes 1-4 at cap 30
        # start with [10, 113074] around a gain of 1628), and the in-place sweeps then drift
        # unevenly by about that error each sweep, which widens the next bracket; a hint (or a
        # rule) holds the shift near the gain until the bracket is narrow enough to take over.
        b0, b1 = max(self.best[0], lo), min(self.best[1], hi)
        self.best = (b0, b1)
        mid = 0.5 * (lo + hi)
        if not (hi - lo > self.wide_rel * abs(mid)):
            return mid
        if self.gain_hint is not None:
            return min(max(self.gain_hint, b0), b1)
        if self.wide_shift == "lo":
            return lo
        if self.wide_shift == "best":
            return 0.5 * (b0 + b1)
        if self.wide_shift == "geo" and b0 > 0:
            return float(np.sqrt(b0 * b1))
        return mid

    def advance(self) -> None:
        out, self._out = self._out, None
        if out is None:
            return
        out -= out[0]
        if self.name == "warm":
            self.h, self.ex.prev = out, self.h
        else:
            self.h, self.h_out = out, self.h

    def leave_warm(self, width: float, mid: float, used: int, max_iter: int) -> bool:
        # Jacobi passes until the bracket is within warm_rel: their bounds are monotone and a
        # wrong shift only adds a constant, whereas in-place sweeps started with the wide first
        # bracket's midpoint as the gain distort h for hundreds of sweeps (suboptimal policy,
        # cap 12: 212 -> 173 sweeps)
        if width <= self.warm_rel * abs(mid) or used >= self.warm_max or used >= max_iter - 1:
            self.name = self.main
            return True
        return False

    def after_check(self, width: float, progress: Progress) -> bool:
        if self.name == "jacobi":
            return False
        note = self.ex.step(self.h, self.iters, width)
        if note is not None:
            progress.phase(f"[{self.label}] {note}")
        if self.ex.pending is not None or (note is not None and "undone" in note):
            return True
        pol = self.agg_policy()
        mid = 0.5 * (self.bracket[0] + self.bracket[1])
        if self.agg is not None and pol is not None and self.in_place and width <= self.agg_rel * abs(mid):
            # the certificate left in pol the greedy policy of h (T_pol h = T h): the coarse
            # correction of that policy's evaluation (.aggregate), certified by the next certificate
            self.agg_unseen = self.agg.correct(self.h, pol)
        return False

    def fall_back(self) -> str | None:
        if self.name == "jacobi":
            return None
        if not _second_vector_fits(self.st.n):
            return " (no memory for the Jacobi fallback's second vector: continuing)"
        self.name = "jacobi"
        self.h_out = np.empty(self.st.n)
        self.vectors += 1
        return ""

    def interrupt(self) -> None:
        self.ex.pending = None

    def settle(self) -> None:
        if self.agg_unseen:  # the run ended before a certificate of the corrected h
            self.agg.undo(self.h)
            self.agg_unseen = False
        self.ex.settle(self.h)

    def h_range(self) -> tuple[float, float]:
        # one pass on the solve's threads, where two numpy passes left the other core idle
        return self.sw.value_range(self.h)

    def roundoff(self) -> float:
        lo, hi = self.h_range()
        return gamma(self.st.op.roundoff_terms) * (self.st.op.cost_scale + 2.0 * max(hi, -lo))

    def cost_note(self) -> str:
        return (f"the costs (up to {self.st.op.cost_scale:.3g} a slot) are too large for float64 arithmetic: lower "
                "the caps or rescale the processes")


class _Improve(BoxSweeps):
    """Value iteration: passes of every action (the Bellman operator, the greedy policy into
    ``pol``), and in ``"mpi"`` ``n_eval`` sweeps of that policy after each improvement sweep."""

    def __init__(self, st: Setup, opts: MatrixFreeOptions):
        main = "mpi" if opts.scheme == "auto" else opts.scheme
        super().__init__(st, opts, main, warm_default=False)
        self.pol = np.zeros(st.n, np.uint8)
        self.n_eval = opts.eval_sweeps if main == "mpi" else 0
        self.candidates_rel = opts.candidates_rel
        self.cand_rows = opts.candidates == "row"
        self.near_rel = opts.candidates_near
        self._near, self._nbits = -1.0, None
        self.cand: np.ndarray | None = None  # the candidate actions of the improvement sweeps, when on

    def pass_(self, h, h_out, write, relax, shift):
        write_pol = write != Write.IN_PLACE or self.n_eval > 0
        cand = self.cand if write == Write.IN_PLACE else None
        near = self._near if write == Write.NONE else -1.0
        return self.sw.all_actions(h, h_out, self.pol, None, Reduce.MIN, write, write_pol, relax, shift, cand,
                                   self.cand_rows, near, self._nbits if near >= 0 else None)

    def certify(self, shift: float) -> tuple[float, float]:
        # A certificate pass tries every action and leaves the greedy policy of its h in pol; once
        # the bracket is narrow the improvement sweeps until the next one try, per configuration,
        # only the actions that policy takes somewhere in the configuration's box (the others
        # cost most of an improvement sweep's work and are rarely chosen near the fixed point).
        # The certificate is unaffected: it always takes the minimum over every action.
        prev = self.bracket[1] - self.bracket[0]
        if self.cand_rows and self.near_rel > 0 and np.isfinite(prev) and self.in_place:
            # the certificate marks, per row, the actions within near_rel x the last width of the
            # minimum somewhere on the row: those the policy may switch to before the next one
            if self._nbits is None:
                self._nbits = np.zeros(self.sw.n_rows, np.uint64)
            self._near = self.near_rel * prev
        else:
            self._near = -1.0
        lo, hi = super().certify(shift)
        mid = 0.5 * (lo + hi)
        if self.candidates_rel > 0 and np.isfinite(hi - lo) and hi - lo <= self.candidates_rel * abs(mid):
            if self.cand_rows:
                if self._near >= 0:
                    self.cand = self._nbits
                else:
                    if self.cand is None or self.cand is self._nbits:
                        self.cand = np.zeros(self.sw.n_rows, np.uint64)
                    self.sw.row_actions(self.pol, self.cand)
            else:
                if self.cand is None:
                    self.cand = np.zeros(self.st.layout.n_configs, np.uint64)
                self.sw.used_actions(self.pol, self.cand)
        else:
            self.cand = None
        return lo, hi

    def agg_policy(self) -> np.ndarray:
        return self.pol

    def evaluation_sweeps(self, shift: float) -> int:
        for _ in range(self.n_eval):
            self.sw.fixed(self.h, None, self.pol, Write.IN_PLACE, self.relax, shift)
        return self.n_eval


class _Evaluate(BoxSweeps):
    """Policy evaluation: passes of one local action per state (``table``) or of the
    per-configuration action weights ``W`` (a tau-independent randomised policy)."""

    def __init__(self, st: Setup, opts: MatrixFreeOptions, table: np.ndarray | None, W: np.ndarray | None,
                 name: str):
        super().__init__(st, opts, "gs", warm_default=True)
        self.table, self.W = table, W
        self._none = np.zeros(1, np.uint8)
        self.label = f"matrix-free eval {name}"

    def agg_policy(self) -> np.ndarray | None:
        return self.table

    def pass_(self, h, h_out, write, relax, shift):
        if self.table is None:
            return self.sw.all_actions(h, h_out, self._none, self.W, Reduce.WEIGHTED, write, False, relax, shift)
        return self.sw.fixed(h, h_out, self.table, write, relax, shift)


# ============================================================================ value iteration
def matrix_free_value_iteration(system_or_scenario: Scenario | System, options: MatrixFreeOptions | None = None, *,
                                h0: Any = None, progress: bool | Progress | None = None,
                                **fields: Any) -> MatrixFreeSolution:
    """Certified average-cost value iteration without a transition matrix.

    The iteration is that of :func:`wncs_lp.solvers.dp.value_iteration` (modified policy
    iteration: relaxed Gauss-Seidel improvement sweeps, ``eval_sweeps`` sweeps of the policy
    they found, and every ``check_every`` improvement sweeps a certificate pass), on the
    matrix-free kernels, run by :func:`wncs_lp.solvers.iteration.certified_iteration` (closing
    rule with the round-off band, precision stop, Jacobi fallback, interrupt). The certificate
    pass computes d = T h - h over **every** state of the layout (or of the exact reachable set,
    see ``domain``) on one fixed h. It writes nothing but the greedy policy of that h, so the
    returned ``bias`` is exactly the h of the certificate and ``local_actions`` its greedy
    policy (whose gain is <= ``gain_upper``).

    Parameters
    ----------
    system_or_scenario : Scenario or System
    options : MatrixFreeOptions, optional
        How to iterate; any of its fields can be given as a keyword instead (or on top), e.g.
        ``tol=1e-10, threads=2`` (an unknown keyword is a :class:`~wncs_lp.errors.SolverError`
        naming the fields).
    h0 : array, MatrixFreeSolution, MatrixFreeEvaluation, value tables or BoundResult, optional
        Warm start (:func:`~.start.start_vector`): one value per layout state, a solution's bias,
        or a separable value function sum_k h_k(tau_k, column_k(c)) such as the tables of
        :func:`wncs_lp.bounds.lower_bound` (written straight into the solve's value vector).
        The certificate holds whatever the start; a good one saves sweeps. Without one, a
        layout of at least ``coarse_states`` states starts from a coarse solve at smaller caps
        (``coarse_ratio``; :class:`~.options.MatrixFreeOptions`).
    progress : bool or Progress
        The setup, then the certificate passes (sweeps, bracket, relative width) on stderr.

    Returns
    -------
    MatrixFreeSolution
        ``method = "matrix-free"``; ``stats``: ``scheme``, ``final_scheme``, ``threads``,
        ``domain``, ``n_states`` (layout), ``n_reachable`` (with a mask), ``sweeps``,
        ``eval_sweeps``, ``checks``, ``rel_gap``, ``bytes`` (the solve's arrays),
        ``seconds_setup`` (the coarse solve included), ``fallback``, ``hull_closes``,
        ``roundoff_delta``, ``stop``, ``gain_hint``, ``coarse`` (None, or the coarse solve's
        ``caps``, ``sweeps``, ``eval_sweeps``, ``gain``, ``gain_lower``, ``gain_upper``,
        ``seconds``, ``first_midpoint_over_gain`` and whether it was ``used``; its passes are not
        in ``sweeps``; ``coarse_used``, ``coarse_sweeps``, ``coarse_eval_sweeps`` and
        ``coarse_seconds`` repeat them as scalars, None without one) and ``history``: one ``(sweeps,
        eval_sweeps, seconds, lo, hi)`` per certificate pass.
    """
    opts = options_from(MatrixFreeOptions, options, fields, "matrix_free_value_iteration")
    t0 = time.perf_counter()
    load_kernels()
    system = as_system(system_or_scenario)
    if not opts.force:
        from ...models.guard import check_size

        check_size(system.scenario, method="matrix-free", model=system.model)
    if int(system.n_actions.max()) > 255:  # pragma: no cover - the paper's models have <= 12
        raise SolverError("more than 255 actions in a configuration: the uint8 policy cannot hold them")
    prog = as_progress(progress)
    stopped = False
    try:
        coarse = _coarse_solve(system, opts, prog) if h0 is None else None
    except KeyboardInterrupt:
        if opts.on_interrupt == "raise":
            raise
        # Ctrl-C during the coarse solve: one certificate of the start, returned "interrupted"
        coarse, stopped, opts = None, True, replace(opts, max_iter=1)
    st = _setup(system, opts, h0)
    coarse_stats = None
    if coarse is not None:
        used = not coarse.stats.get("dropped", False)
        coarse_stats = {"caps": [int(c) for c in coarse.system.caps], "sweeps": coarse.iterations,
                        "eval_sweeps": coarse.stats["eval_sweeps"], "gain": coarse.gain,
                        "gain_lower": coarse.gain_lower, "gain_upper": coarse.gain_upper, "seconds": coarse.seconds,
                        "first_midpoint_over_gain": coarse.stats["far"], "used": used}
        if used:
            clamped_values(coarse.layout, coarse.bias, st.layout, st.h, st.sw.threads)
            st.h -= st.h[0]
            if opts.gain_hint is None:
                opts = replace(opts, gain_hint=float(coarse.gain))
        del coarse
    sweeps = _Improve(st, opts)
    t_setup = time.perf_counter() - t0
    _announce(prog, st, sweeps, t_setup)
    out = certified_iteration(sweeps, opts, cost_scale=st.op.cost_scale, progress=prog, label=sweeps.label, t0=t0)
    if stopped and not out.converged:
        out.status = of(INTERRUPTED)
    lo, hi, delta = _bracket(sweeps, out, prog, opts.tol)
    h = sweeps.h
    h -= h[0]
    stats = {"scheme": sweeps.main, "final_scheme": sweeps.name, **st.domain_stats(),
             "n_reachable": int(st.mask.sum()) if st.mask is not None else None, "n_configs": st.layout.n_configs,
             "sweeps": out.used, "eval_sweeps": out.evals, "value_vectors": sweeps.vectors,
             "bytes": matrix_free_bytes(st.n, vectors=sweeps.vectors, mask=st.mask is not None),
             "coarse": coarse_stats, "gain_hint": opts.gain_hint,
             # the same as scalars, which is what --json keeps: the passes above are at these caps only
             **{f"coarse_{k}": None if coarse_stats is None else coarse_stats[k]
                for k in ("used", "sweeps", "eval_sweeps", "seconds")},
             **_common_stats(out, opts, sweeps, lo, hi, delta, t_setup)}
    return MatrixFreeSolution(method="matrix-free", status=out.status, gain=0.5 * (lo + hi), gain_lower=lo,
                              gain_upper=hi, bias=h, local_actions=sweeps.pol, iterations=out.used,
                              seconds=time.perf_counter() - t0, stats=stats, layout=st.layout, system=system,
                              mask=st.mask)


def coarse_caps(caps: Any, ratio: float) -> np.ndarray:
    """The caps of a coarse solve: ratio cap_k rounded to the nearest integer, at least 2 and at
    most cap_k."""
    caps = np.asarray(caps, dtype=np.int64)
    return np.minimum(np.maximum(np.floor(ratio * caps + 0.5).astype(np.int64), 2), caps)


def _coarse_solve(system: System, opts: MatrixFreeOptions, prog: Progress) -> MatrixFreeSolution | None:
    """The solve at the smaller caps :func:`coarse_caps` (to ``coarse_tol``) whose bias, each AoI
    clamped into its boxes, starts the solve and whose gain is its ``gain_hint``; None when
    ``coarse_ratio`` is 0, the layout has fewer than ``coarse_states`` states, the caps would
    not shrink, or the smaller caps' automaton has other configurations."""
    if opts.coarse_ratio <= 0 or layout_states(system) < opts.coarse_states:
        return None
    caps = coarse_caps(system.caps, opts.coarse_ratio)
    if np.array_equal(caps, system.caps):
        return None
    sc = system.scenario.with_overrides({f"process.{k + 1}.tau_cap": int(c) for k, c in enumerate(caps)})
    small = System.from_scenario(sc)
    if small.automaton.configs != system.automaton.configs:  # the preemption model's hold AoI values
        return None
    prog.phase(f"[matrix-free] a coarse solve first, at caps {tuple(int(c) for c in caps)} to {opts.coarse_tol:g}: "
               "its bias starts the solve and its gain is the shift while the bracket is wide")
    sub = replace(opts, tol=opts.coarse_tol, coarse_ratio=0.0, gain_hint=None, force=True, on_interrupt="raise")
    sol = matrix_free_value_iteration(small, sub, progress=prog)
    # what the start cures is a first shift far above the gain: the midpoint of [min c, max c]
    # (processes 1-4 at cap 30: 36x the cap-20 gain); where it is near (the six-process mix at
    # cap 10: 2.0x the cap-7 gain of 494, itself 0.42x the gain) that gain is a hint far below
    # g*, and the clamped bias no better a start than zero
    far = first_midpoint(system) / max(abs(sol.gain), 1e-300)
    sol.stats["far"] = far
    if not far >= opts.coarse_far:
        prog.phase(f"[matrix-free] the coarse start is dropped: the first midpoint is {far:.3g}x its gain "
                   f"(< coarse_far = {opts.coarse_far:g}); starting from zero")
        sol.stats["dropped"] = True
    return sol


def first_midpoint(system: System) -> float:
    """(min c + max c) / 2 over the AoI box, c(tau) = sum_k q_k(tau_k): the midpoint of the
    first certificate from h = 0 (on the box; the hull's is within it)."""
    lo = sum(float(np.min(np.asarray(q)[:int(c)])) for q, c in zip(system.q, system.caps))
    hi = sum(float(np.max(np.asarray(q)[:int(c)])) for q, c in zip(system.q, system.caps))
    return 0.5 * (lo + hi)


def _announce(prog: Progress, st: Setup, sweeps: BoxSweeps, t_setup: float) -> None:
    if not prog.enabled:
        return
    reach = f" ({int(st.mask.sum()):,} reachable)" if st.mask is not None else ""
    mem = _mb(matrix_free_bytes(st.n, vectors=sweeps.vectors, mask=st.mask is not None))
    prog.phase(f"[{sweeps.label}] {st.n:,} states over {st.layout.n_configs} configurations{reach}, {mem} with "
               f"{sweeps.vectors} value vector(s), {st.sw.threads} thread(s), setup {t_setup:.2f}s")


def _bracket(sweeps: BoxSweeps, out: IterationOutcome, prog: Progress, tol: float) -> tuple[float, float, float]:
    """The final certificate (widened by the round-off bound at the precision stop) and delta."""
    from ..iteration import cert_line

    delta = sweeps.roundoff()
    lo, hi = out.lo, out.hi
    prog.done(f"[{sweeps.label}] sweep {out.used:,}: {out.stop}" if out.stop is not None
              else cert_line(f"{sweeps.label}:{sweeps.name}", out.used, lo, hi, tol))
    if out.at_floor:
        lo, hi = lo - delta, hi + delta
    return lo, hi, delta


def _common_stats(out: IterationOutcome, opts: MatrixFreeOptions, sweeps: BoxSweeps, lo: float, hi: float,
                  delta: float, t_setup: float) -> dict[str, Any]:
    gain = 0.5 * (lo + hi)
    return {"checks": out.checks, "relax": opts.relax, "tol": opts.tol, "span": hi - lo,
            "rel_gap": (hi - lo) / max(abs(gain), 1e-300), "converged": out.converged,
            "roundoff_delta": delta, "span_computed": out.hi - out.lo, "stop": out.stop,
            "seconds_setup": t_setup, "fallback": out.fallback, "history": out.history,
            "extrapolations": sweeps.ex.count, "extrapolations_undone": sweeps.ex.reverted,
            "aggregations": sweeps.agg.count if sweeps.agg is not None else 0}


# ============================================================================ evaluation
def policy_table(system: System, layout: BoxLayout, policy: Any, *, batch: int = 1 << 21) -> np.ndarray:
    """(n,) uint8 local action of a deterministic ``policy`` at every layout state (``policy.act``
    called on batches of whole configurations; every answer checked against its configuration)."""
    n = layout.n_states
    out = np.empty(n, np.uint8)
    nact = system.n_actions
    rng = np.random.default_rng(0)
    c = 0
    nC = layout.n_configs
    while c < nC:
        c1 = c + 1
        while c1 < nC and layout.off[c1 + 1] - layout.off[c] <= batch:
            c1 += 1
        taus = np.concatenate([layout.config_taus(i) for i in range(c, c1)])
        cfg = np.repeat(np.arange(c, c1, dtype=np.int64), np.diff(layout.off[c:c1 + 1]))
        j = np.asarray(policy.act(taus, cfg, rng), dtype=np.int64)
        if j.shape != cfg.shape or np.any(j < 0) or np.any(j >= nact[cfg]):
            raise PolicyError(f"policy {getattr(policy, 'name', policy)!r}: a local action index is out of range")
        out[layout.off[c]:layout.off[c1]] = j
        c = c1
    return out


def _policy_input(policy: Any, system: System, layout: BoxLayout,
                  name: str | None) -> tuple[np.ndarray | None, np.ndarray | None, str]:
    """(local action table or None, action weights W or None, name) of the policy to evaluate,
    every table checked against the layout (:func:`~.layout.check_local_actions`)."""
    if isinstance(policy, MatrixFreeSolution):
        pname = name or "optimal"
        return check_local_actions(policy.local_actions, layout, system.n_actions, f"policy {pname!r}"), None, pname
    if hasattr(policy, "table") and hasattr(policy, "layout"):  # a wncs_lp.policies.MatrixFreePolicy
        pname = name or policy.name
        return check_local_actions(policy.table, layout, system.n_actions, f"policy {pname!r}"), None, pname
    if hasattr(policy, "act"):  # any wncs_lp.policies.Policy (duck-typed: solvers sit below policies)
        pname = name or policy.name
        probs = getattr(policy, "probs", None)
        if probs is not None:
            return None, _check_weights(probs, system, pname), pname
        if policy.randomised:
            raise PolicyError(f"policy {pname}: matrix-free evaluation takes a deterministic policy or a "
                              "tau-independent randomised one (a probs table)")
        return policy_table(system, layout, policy), None, pname
    pname = name or "array"
    return check_local_actions(policy, layout, system.n_actions, "a policy array"), None, pname


def _check_weights(probs: Any, system: System, pname: str) -> np.ndarray:
    """A tau-independent policy's (configurations, actions) probabilities, checked."""
    W = np.asarray(probs, dtype=float)
    nact = np.asarray(system.n_actions)
    if W.ndim != 2 or W.shape[0] != system.n_configs or W.shape[1] < int(nact.max()):
        raise PolicyError(f"policy {pname}: matrix-free evaluation takes a probs table of shape (configurations, "
                          f"actions) = ({system.n_configs}, {int(nact.max())}); got shape {W.shape}")
    valid = np.arange(W.shape[1])[None, :] < nact[:, None]
    rows = np.where(valid, W, 0.0).sum(axis=1)
    if not (np.all(np.isfinite(W)) and np.all(W >= 0) and np.allclose(rows, 1.0, rtol=0, atol=1e-9)):
        raise PolicyError(f"policy {pname}: each row of probs must be a probability vector over the actions of its "
                          "configuration")
    return np.ascontiguousarray(W)


def matrix_free_evaluate(system_or_scenario: Scenario | System, policy: Any, options: MatrixFreeOptions | None = None,
                         *, h0: Any = None, progress: bool | Progress | None = None, name: str | None = None,
                         cost: Any = None, **fields: Any) -> MatrixFreeEvaluation:
    """Exact average cost of a stationary policy, certified, without a transition matrix.

    Relaxed Gauss-Seidel sweeps of the fixed-policy operator
    (T_pi h)(s) = c(s) + sum_{s'} P_pi(s' | s) h(s'), and every ``check_every`` sweeps a pass
    computing ``lo = min (T_pi h - h) <= g_pi <= max (T_pi h - h) = hi`` on one fixed h over
    every layout state (or the exact reachable set, as in :func:`matrix_free_value_iteration`),
    after a warm start of Jacobi passes (``warm_start``); the loop is
    :func:`wncs_lp.solvers.iteration.certified_iteration`'s.

    Parameters
    ----------
    policy : Policy, MatrixFreeSolution or array
        A deterministic :class:`~wncs_lp.policies.Policy` (``act`` is called once on every
        layout state), a tau-independent randomised one (anything with a ``probs`` table of
        action probabilities per configuration, e.g. the random policy: evaluated with those
        weights), a :class:`MatrixFreeSolution` (its policy), or an (n,) array of local
        action indices over the layout. Every table is checked against the layout first: an
        index out of its configuration's range is a :class:`~wncs_lp.errors.PolicyError`
        naming the state.
    options : MatrixFreeOptions, optional
        As :func:`matrix_free_value_iteration` (``scheme``, ``eval_sweeps`` and ``force`` do not
        apply; ``warm_start`` defaults to on); fields can be keywords.
    name : str, optional
        The policy's name in the result and on the progress lines.
    cost : array, optional
        A separable per-slot cost c(s) = sum_k cost[k, tau_k - 1] instead of the MSE: an
        (N, max cap) table (entries past a process's cap are ignored). With
        :func:`~.capmass.cap_cost` it measures the time spent at the cap.

    Returns
    -------
    MatrixFreeEvaluation
    """
    opts = options_from(MatrixFreeOptions, options, fields, "matrix_free_evaluate")
    t0 = time.perf_counter()
    load_kernels()
    system = getattr(policy, "system", None)
    if not isinstance(system, System):
        system = as_system(system_or_scenario)
    layout = BoxLayout.from_system(system, "hull")
    table, W, pname = _policy_input(policy, system, layout, name)
    st = _setup(system, opts, h0, cost, layout)
    prog = as_progress(progress)
    sweeps = _Evaluate(st, opts, table, W, pname)
    t_setup = time.perf_counter() - t0
    prog.phase(f"[{sweeps.label}] {st.n:,} states, setup (policy table) {t_setup:.2f}s")
    out = certified_iteration(sweeps, opts, cost_scale=st.op.cost_scale, progress=prog, label=sweeps.label, t0=t0)
    lo, hi, delta = _bracket(sweeps, out, prog, opts.tol)
    h = sweeps.h
    h -= h[0]
    stats = {**st.domain_stats(), "randomised": W is not None, **_common_stats(out, opts, sweeps, lo, hi, delta, t_setup)}
    return MatrixFreeEvaluation(policy=pname, status=out.status, gain=0.5 * (lo + hi), gain_lower=lo, gain_upper=hi,
                                bias=h, iterations=out.used, seconds=time.perf_counter() - t0, stats=stats)
