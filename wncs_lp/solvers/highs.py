"""HiGHS as a backend of the occupation-measure LP (``solve_lp(backend="highs")``), through highspy.

The LP is the scaled standard form of :mod:`wncs_lp.solvers.lp`,

.. math:: \\min_y q^T y \\quad\\text{s.t.}\\quad A y = b,\\; y \\ge 0,

handed to HiGHS column-wise (CSC, no copy of the pattern beyond highspy's own). HiGHS reports
row duals ``lambda`` with reduced costs ``q - A^T lambda >= 0``; Clarabel's equality multipliers
satisfy ``q + A^T z >= 0``, so ``z = -lambda`` and the rest of the pipeline (unscaling, policy
extraction, polish, certificate) is shared unchanged.

Variants (``HIGHS_VARIANTS``; measured in ``benchmarks/lp_backends.py``):

* ``"ipx"`` -- HiGHS's interior-point solver IPX (what ``scipy.optimize.linprog(method=
  "highs-ipm")`` runs), then crossover to a vertex.
* ``"simplex"`` -- the dual simplex (``linprog(method="highs-ds")``).

HiGHS's own model status (``highspy.HighsModelStatus``, by its name: ``kOptimal``, ``kTimeLimit``,
...) maps into the toolkit's codes by :data:`HIGHS_STATUS`, this backend's table (as cvxpy keeps
one ``STATUS_MAP`` per solver); the name itself is kept verbatim, as ``stats["solver_status"]``
and as the reason of a status that is not optimal (``max_iter:kTimeLimit``), never translated into
another backend's words. ``stats["highs_status"]`` adds HiGHS's sentence for it.
"""
from __future__ import annotations

import os
import sys
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from ..errors import SolverError
from ..progress import Progress
from ..status import FAILED, INFEASIBLE, INTERRUPTED, MAX_ITER, OPTIMAL, Code, Status, from_backend

__all__ = ["HIGHS_VARIANTS", "HIGHS_DEFAULT_VARIANT", "HIGHS_STATUS", "highs_status", "new_highs", "solve_highs",
           "run_highs"]

#: The HiGHS solver variants :func:`solve_highs` accepts.
HIGHS_VARIANTS = ("ipx", "simplex")
#: The variant ``backend="highs"`` runs unless ``settings={"variant": ...}`` says otherwise.
HIGHS_DEFAULT_VARIANT = "ipx"

#: HiGHS model status (``highspy.HighsModelStatus`` name) -> code of :mod:`wncs_lp.status`.
#: Only ``kOptimal`` is solved. A limit (time, iterations, an objective bound or target asked
#: for) is ``MAX_ITER``: the point HiGHS holds then is used and certified, its status says which
#: limit (``max_iter:kIterationLimit``). ``INFEASIBLE`` and ``FAILED`` leave no usable solution (a
#: :class:`SolverError`). Every LP of the toolkit has a bounded feasible set (x is a probability
#: vector), so "unbounded or infeasible" is infeasible and "unbounded" a numerical failure. A
#: status missing here (a newer HiGHS) is ``FAILED``, its name kept.
HIGHS_STATUS: dict[str, Code] = {
    "kOptimal": OPTIMAL,
    "kInfeasible": INFEASIBLE,
    "kUnboundedOrInfeasible": INFEASIBLE,
    "kUnbounded": FAILED,
    "kTimeLimit": MAX_ITER,
    "kIterationLimit": MAX_ITER,
    "kObjectiveBound": MAX_ITER,
    "kObjectiveTarget": MAX_ITER,
    "kSolutionLimit": MAX_ITER,
    "kInterrupt": INTERRUPTED,
    "kHighsInterrupt": INTERRUPTED,
    "kMemoryLimit": FAILED,
    "kNotset": FAILED,
    "kLoadError": FAILED,
    "kModelError": FAILED,
    "kPresolveError": FAILED,
    "kSolveError": FAILED,
    "kPostsolveError": FAILED,
    "kModelEmpty": FAILED,
    "kUnknown": FAILED,
}


def highs_status(model_status: str) -> Status:
    """The status of a HiGHS model status name (:data:`HIGHS_STATUS`; the name is the reason)."""
    return from_backend(HIGHS_STATUS, model_status)


def _variant_options(variant: str) -> dict[str, Any]:
    if variant == "ipx":
        return {"solver": "ipx", "run_crossover": "on"}
    if variant == "simplex":
        return {"solver": "simplex", "simplex_strategy": 1}
    raise SolverError(f"unknown HiGHS variant {variant!r}; expected one of {', '.join(HIGHS_VARIANTS)}")


_HEADER_SHOWN = False


def new_highs(verbose: bool = False):
    """A ``highspy.Highs``. HiGHS prints its copyright header on stdout when the first one of a
    process is made, whatever ``output_flag`` says; stdout carries results (``solve --json``),
    so that first construction runs with file descriptor 1 on /dev/null unless ``verbose``."""
    import highspy

    global _HEADER_SHOWN
    if verbose or _HEADER_SHOWN:
        return highspy.Highs()
    _HEADER_SHOWN = True
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):  # no usable stdout descriptor: nothing to protect
        return highspy.Highs()
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.close(devnull)
        h = highspy.Highs()
        try:  # the header sits in C's stdout buffer when stdout is a pipe: flush it to /dev/null
            import ctypes

            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return h


def solve_highs(A: sp.csc_matrix, b: np.ndarray, q: np.ndarray, tol: float, max_iter: int, verbose: bool,
                settings: dict | None, prog: Progress | None = None, interrupt: Callable[[], bool] | None = None):
    """Solve ``min q^T y  s.t.  A y = b, y >= 0`` with HiGHS.

    Parameters
    ----------
    A, b, q
        The scaled LP (:class:`~wncs_lp.solvers.lp.LPData`'s ``A_eq``, ``b_eq``, ``q``).
    tol : float
        Primal and dual feasibility tolerances and the IPM optimality tolerance (HiGHS's floor
        is 1e-10 for the feasibility ones; smaller values are raised to it).
    max_iter : int
        The interior-point iteration limit (``ipm_iteration_limit``); the simplex and crossover
        are not limited by it.
    verbose : bool
        HiGHS's log to stdout.
    settings : dict, optional
        ``"variant"`` (one of :data:`HIGHS_VARIANTS`) and any HiGHS option by name, e.g.
        ``{"time_limit": 60, "presolve": "off"}``; an unknown option raises :class:`SolverError`.
    prog : Progress, optional
        Only the phase is shown (highspy offers no cheap per-iteration hook here).
    interrupt : callable, optional
        Polled through HiGHS's interior-point interrupt callback (many times an iteration); a
        true answer stops the run (status ``kInterrupt``: HiGHS then holds no solution).

    Returns
    -------
    (status, y, z_eq, stats)
        ``status`` the :class:`~wncs_lp.status.Status` of HiGHS's model status
        (:func:`highs_status`), ``y`` the primal, ``z_eq = -row_dual`` (Clarabel's sign),
        ``stats`` with ``solver``, ``solver_status`` (the ``HighsModelStatus`` name), ``highs_status``,
        ``highs_variant``, ``solver_iterations`` (IPM + simplex/crossover iterations),
        ``ipm_iterations``, ``simplex_iterations``, ``r_prim`` / ``r_dual`` (HiGHS's max primal /
        dual infeasibility), ``duality_gap``, ``solve_time``, ``obj_scaled``, ``lp_rows``,
        ``lp_cols``, ``lp_nnz``. ``y`` and ``z_eq`` are NaN when HiGHS holds no primal / dual
        solution (the caller raises :class:`SolverError` then).
    """
    opts = dict(settings or {})
    variant = str(opts.pop("variant", HIGHS_DEFAULT_VARIANT))
    A = sp.csc_matrix(A)
    A.sort_indices()
    m, L = A.shape
    h = new_highs(verbose)
    h.setOptionValue("output_flag", bool(verbose))
    _set_options(h, tol, max_iter, variant, opts)
    _pass_model(h, A, b, q)
    if interrupt is not None:
        import highspy

        def _poll(_type, _message, _data_out, data_in, _user):
            if interrupt():
                data_in.user_interrupt = True

        h.setCallback(_poll, None)
        h.startCallback(highspy.cb.HighsCallbackType.kCallbackIpmInterrupt)
    if prog is not None and prog.enabled:
        prog.tick(f"[lp] HiGHS ({variant}) running on {m:,} rows x {L:,} columns")
    run_highs(h)
    return _read_solution(h, variant, A, q)


#: Seconds HiGHS is given to stop after a cancel before it is left to finish in the background.
CANCEL_GRACE = 5.0


def run_highs(h) -> None:
    """``h.run()``, stoppable by Ctrl-C / SIGTERM (:mod:`wncs_lp.stopping`).

    HiGHS runs in a thread of highspy's (``startSolve``) with its interrupt callbacks on; this
    thread waits, and a stop asked meanwhile cancels the solve (HiGHS stops at its next simplex
    or interior-point iteration; the interrupt then reaches the caller). A run that does not stop
    within :data:`CANCEL_GRACE` seconds of the cancel is left to end with the process.
    """
    import time

    from ..stopping import deferred

    h.HandleUserInterrupt = True  # the interrupt callbacks that cancelSolve() trips
    with deferred() as stop:
        h.startSolve()
        cancelled = None
        while not h.wait(0.1)[0]:
            if cancelled is None and stop():
                h.cancelSolve()
                cancelled = time.monotonic()
            if cancelled is not None and time.monotonic() - cancelled > CANCEL_GRACE:
                break


def _set_options(h, tol: float, max_iter: int, variant: str, opts: dict[str, Any]) -> None:
    """Our tolerances and the variant's options, then the caller's (any HiGHS option by name)."""
    import highspy

    ftol = max(float(tol), 1e-10)
    base = {"primal_feasibility_tolerance": ftol, "dual_feasibility_tolerance": ftol,
            "ipm_optimality_tolerance": max(float(tol), 1e-12), "ipm_iteration_limit": int(max_iter),
            # HiGHS drops |a_ij| <= 1e-9 by default; the densified reduced LP of the preemption
            # models has such entries, and dropping them moved the LP gain by 1e-8 relative
            "small_matrix_value": 1e-12,
            **_variant_options(variant)}
    for k, v in {**base, **opts}.items():
        try:
            st = h.setOptionValue(k, v)
        except Exception as exc:  # highspy raises on a type mismatch
            raise SolverError(f"HiGHS option {k!r} rejected value {v!r}: {exc}") from exc
        if st == highspy.HighsStatus.kError:
            raise SolverError(f"unknown HiGHS option {k!r} or bad value {v!r}")


def _pass_model(h, A: sp.csc_matrix, b: np.ndarray, q: np.ndarray) -> None:
    """Hand ``min q^T y  s.t.  A y = b, y >= 0`` to HiGHS column-wise."""
    import highspy

    m, L = A.shape
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = int(L), int(m)
    lp.col_cost_ = np.asarray(q, float)
    lp.col_lower_ = np.zeros(L)
    lp.col_upper_ = np.full(L, highspy.kHighsInf)
    lp.row_lower_ = lp.row_upper_ = np.asarray(b, float)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.num_col_, lp.a_matrix_.num_row_ = int(L), int(m)
    lp.a_matrix_.start_ = A.indptr.astype(np.int32)
    lp.a_matrix_.index_ = A.indices.astype(np.int32)
    lp.a_matrix_.value_ = A.data.astype(float)
    # kWarning: HiGHS dropped entries below small_matrix_value (set to its floor 1e-12 above); the
    # residual checks on the original LP (full_*) and the certificate see what that costs
    if h.passModel(lp) == highspy.HighsStatus.kError:
        raise SolverError("HiGHS rejected the LP (passModel failed)")


def _read_solution(h, variant: str, A: sp.csc_matrix, q: np.ndarray):
    """``(status, y, z_eq, stats)`` of a finished run (see :func:`solve_highs`): the invert step,
    where HiGHS's model status becomes a :class:`~wncs_lp.status.Status` (:data:`HIGHS_STATUS`)."""
    m, L = A.shape
    native = h.modelStatusToString(h.getModelStatus())
    ms = h.getModelStatus().name
    info = h.getInfo()
    sol = h.getSolution()
    y = np.asarray(sol.col_value, float) if sol.value_valid and len(sol.col_value) == L else np.full(L, np.nan)
    z = -np.asarray(sol.row_dual, float) if sol.dual_valid and len(sol.row_dual) == m else np.full(m, np.nan)
    status = highs_status(ms)
    ipm_it = max(int(info.ipm_iteration_count), 0)
    spx_it = max(int(info.simplex_iteration_count), 0) + max(int(info.crossover_iteration_count), 0)
    pobj = float(info.objective_function_value)
    gap = float(info.primal_dual_objective_error) if hasattr(info, "primal_dual_objective_error") else np.nan
    stats = {
        "solver": "highs",
        "solver_status": ms,
        "highs_status": f"{ms} ({native})",
        "highs_variant": variant,
        "solver_iterations": ipm_it + spx_it,
        "ipm_iterations": ipm_it,
        "simplex_iterations": spx_it,
        "r_prim": float(info.max_primal_infeasibility),
        "r_dual": float(info.max_dual_infeasibility),
        "duality_gap": gap,
        "solve_time": float(h.getRunTime()),
        "obj_scaled": pobj if np.isfinite(pobj) else float(np.asarray(q) @ np.nan_to_num(y)),
        "lp_rows": int(m),
        "lp_cols": int(L),
        "lp_nnz": int(A.nnz),
    }
    return status, y, z, stats
