r"""Relaxation 2's LP solved whole by an interior point method: tables for the certificate.

The occupation-measure LP of :mod:`wncs_lp.bounds.joint_lp` (the dual of relaxation 2's
approximate LP) is written out as a sparse matrix (:func:`~wncs_lp.bounds.joint_symmetry.symmetric_lp`,
reduced by the symmetry of interchangeable processes where there is one, the flat dual
directions' rows dropped) and handed to HiGHS's interior point solver IPX with
no crossover and without presolve's search for dependent rows (96 s at processes 1-4, cap 20,
for nothing). The row duals of its balance rows are tables h_k(tau, C).

Nothing HiGHS reports enters the bound: the tables go to
:func:`~wncs_lp.bounds.joint_chains.certify_tables`, which turns *any* tables into a certified
g(h) <= g*. An interior point's duals are (nearly) feasible at every iteration -- IPX keeps
the dual residual at round-off here -- so even a loose tolerance gives tables whose
certificate is within about the duality gap of the relaxation's optimum. A run stopped by its
time limit returns no duals at all (HiGHS 1.16 then holds no solution; measured): the caller
falls back to its other search.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..solvers.highs import solve_highs
from .joint_chains import JointData
from .joint_symmetry import ProcessSymmetry, coupling_prices, spread_tables, symmetric_lp

__all__ = ["IpmRun", "ipm_tables", "ipm_bytes", "ipm_seconds", "IPM_TIME_MODEL"]

#: HiGHS's ``presolve_rule_off`` bit of its dependent-equations rule (HiGHS 1.16's rule 10): its
#: search took 96 s of a 275 s run at processes 1-4 cap 20 and removed nothing; without presolve
#: at all IPX took 415 s there (42k rows instead of 19k).
_NO_DEPENDENT_EQUATIONS = 1 << 10


@dataclass(frozen=True, eq=False)
class IpmRun:
    """What the interior point returned.

    Attributes
    ----------
    tables : list of (|C|, tau_hat_k) arrays, or None
        The balance rows' duals (None when HiGHS held no dual solution).
    prices : list of arrays, or None
        The coupling rows' duals per class representative, on its orbits of pairs
        (:func:`~wncs_lp.bounds.joint_symmetry.coupling_prices`: the prices of the lumped chains).
    status : str
        HiGHS's model status name (``kOptimal``, ``kTimeLimit``, ...): a report, not a certificate.
    objective : float
        HiGHS's primal objective (not a bound).
    iterations : int
    seconds : float
        Building the matrix and solving (wall clock).
    cpu_seconds : float
        The same in this process's CPU time (IPX is serial: the wall time of a quiet machine).
    shape : tuple
        (rows, columns, nonzeros) of the LP handed over.
    """

    tables: list | None
    prices: list | None
    status: str
    objective: float
    iterations: int
    seconds: float
    cpu_seconds: float
    shape: tuple


#: IPX's CPU seconds on one core of this machine as a power of the LP's nonzeros (the count of
#: :func:`~wncs_lp.bounds.joint_symmetry.symmetric_lp_shape`, before duplicates merge) and the mean
#: cap: ``coef * (nnz / 1e6) ** a * (cap / 10) ** b``, least squares in logs on the runs of
#: ``python benchmarks/bounds.py --ipm-scan`` (14 LPs of 0.24M-1.4M nonzeros, processes 1-4 at caps
#: 8-30, the 5- and 6-process shapes at caps 4-10, eight processes reduced at caps 3-8, IPX
#: tolerance 1e-4: every one within a factor 1.32 of the model). CPU time, so the load of the
#: machine does not enter (IPX is serial): on the shared machine the wall clock was 5-16 times it.
IPM_TIME_MODEL = {"coef": 63.0, "a": 1.71, "b": 1.18}


def ipm_seconds(lp_nnz: int, mean_cap: float) -> float:
    """Predicted CPU seconds of :func:`ipm_tables` on an LP with ``lp_nnz`` nonzeros whose processes'
    caps average ``mean_cap`` (the chains' length, which sets IPX's iterations and their cost):
    :data:`IPM_TIME_MODEL`."""
    m = IPM_TIME_MODEL
    return float(m["coef"] * (lp_nnz / 1e6) ** m["a"] * (mean_cap / 10.0) ** m["b"])


def ipm_bytes(lp_nnz: int, lp_rows: int, lp_cols: int) -> int:
    """Rough peak bytes of :func:`ipm_tables`: scipy's assembly (COO -> CSR -> CSC, ~40 bytes a
    nonzero), highspy's copy and IPX's own (~3 copies of the matrix, its basis factors and
    ~20 vectors)."""
    return int(100 * lp_nnz + 8 * 25 * (lp_rows + lp_cols))


def ipm_tables(data: JointData, *, symmetry: ProcessSymmetry | None = None, tol: float = 1e-6,
               time_limit: float | None = None, cpu_limit: float | None = None, verbose: bool = False) -> IpmRun:
    """Solve relaxation 2's LP by IPX (no crossover) and read its tables.

    Parameters
    ----------
    data : JointData
    symmetry : ProcessSymmetry, optional
        Interchangeable processes (:func:`~wncs_lp.bounds.joint_symmetry.process_symmetry`): the
        LP reduced by them is solved and its tables spread to every process; None: none.
    tol : float
        IPX's optimality tolerance (relative duality gap; also the feasibility tolerances).
    time_limit : float or None
        Seconds of wall clock for HiGHS (None: none).
    cpu_limit : float or None
        Seconds of this process's CPU time (None: none), checked by HiGHS's interrupt callback: a
        guard that a loaded machine does not bring forward.
    verbose : bool
        HiGHS's log on stdout.
    """
    t0, cpu0 = time.monotonic(), time.process_time()
    sym = symmetry if symmetry is not None else ProcessSymmetry.none(data.n_processes)
    lp = symmetric_lp(sym, data)
    A, b, c = lp.A, lp.b, lp.c
    # no "threads": HiGHS refuses to run when it differs from its scheduler's, set by the first run of
    # the process (another solve's); IPX itself is serial
    settings = {"variant": "ipx", "run_crossover": "off", "presolve_rule_off": _NO_DEPENDENT_EQUATIONS}
    if time_limit is not None:
        settings["time_limit"] = max(float(time_limit) - (time.monotonic() - t0), 1e-3)
    stop = None if cpu_limit is None else (lambda: time.process_time() - cpu0 > cpu_limit)
    _, _, z, stats = solve_highs(A, b, c, tol=float(tol), max_iter=2**31 - 1, verbose=verbose, settings=settings,
                                 interrupt=stop)
    tables = prices = None
    if np.isfinite(z).all():
        lam = np.zeros(lp.keep.size)
        lam[lp.keep] = -z  # solve_highs returns Clarabel's sign, z = -row_dual
        tables = spread_tables(sym, data, lp, lam)
        prices = coupling_prices(lp, lam)
    return IpmRun(tables=tables, prices=prices, status=str(stats["solver_status"]),
                  objective=float(stats["obj_scaled"]),
                  iterations=int(stats["ipm_iterations"]), seconds=time.monotonic() - t0,
                  cpu_seconds=time.process_time() - cpu0, shape=(int(A.shape[0]), int(A.shape[1]), int(A.nnz)))
