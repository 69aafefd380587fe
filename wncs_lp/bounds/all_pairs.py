r"""Relaxation 5 (``"joint-all-pairs"``): the level-2 relaxation as a bound of
:func:`~wncs_lp.bounds.lower_bound`, with tables for the bound's policies.

The maths -- every pair's ages kept jointly with the joint configuration, all pairs at once and
consistent through each process's measure; why the LP is at most g*; the certificate of the LP's
size -- is :mod:`wncs_lp.bounds.level2`'s. This module packs its result the way the other
relaxations do: a :class:`~wncs_lp.bounds.result.BoundResult` whose ``lower_bound`` is the
certified value and whose ``tables`` are the value function the certificate checked,

.. math:: V(\tau, C) = \sum_{k<l} h_{kl}(\mathrm{class}(\tau_k), \mathrm{class}(\tau_l), C)
          + \sum_k h_k(\tau_k, C),

as :class:`~wncs_lp.bounds.result.GroupTables` over a *cover* (every pair, and each process whose
own table is not zero), so the greedy policy, the lookahead and the rollout of
:func:`~wncs_lp.bounds.gaps.policy_gaps` read it as they read relaxation 4's pair tables.

The LP is solved whole (:func:`~wncs_lp.bounds.level2.level2_bound`): :func:`all_pairs_bound`
checks its size against the memory this process may use before it is built
(:func:`all_pairs_size`). ``"auto"`` runs it where IPX's CPU time, predicted from that count
(:func:`all_pairs_seconds`, a measured model: the same nonzeros cost several times more where the
automaton has more outcomes per (configuration, action), on two servers than on one), fits its
budget (:data:`~wncs_lp.bounds.lower.AUTO_ALL_PAIRS_BUDGET`).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..errors import SolverError
from ..models.guard import require_memory
from ..models.system import System
from ..progress import as_progress
from ..status import INACCURATE, OPTIMAL
from .joint_chains import JointData
from .level2 import Level2Layout, Level2Tables, level2_bound, level2_shape
from .result import BoundResult, GroupTables

__all__ = ["all_pairs_bound", "all_pairs_size", "all_pairs_seconds", "time_features", "cover_tables",
           "ALL_PAIRS_BYTES_PER_NNZ", "ALL_PAIRS_TIME_MODEL"]

#: Peak bytes of the whole solve per nonzero of the LP (the matrix, the solver's copy and its
#: factorisation) by solver, the memory guard's estimate. Measured (docs/bounds.md, "Relaxation
#: 5"): IPX 485-566 bytes on one server (edge 4 sensors cap 40, 5 sensors cap 25: 357k and 282k
#: nonzeros), Clarabel 6.2 kB on two (three sensors, cap 16: 7.4 GB at 1.19M); IPX is given 4x
#: its one-server figure, the two servers' factorisation being denser.
ALL_PAIRS_BYTES_PER_NNZ = {"ipx": 2_000, "pdlp": 1_000, "clarabel": 8_000}


#: IPX's CPU seconds on the level-2 LP (HiGHS, no crossover, the implied rows dropped, tolerance
#: 1e-8) as a power law of its size, ``coef * (nnz / 1e6) ** a * (c / 10) ** b * (P / 100) ** d``:
#: nnz :func:`all_pairs_size`'s count, c the pair chains' mean length (the ages kept apart: the cap
#: or the lumping threshold; longer chains take IPX more iterations and denser basis factors) and
#: P = |C x A|, the (configuration, action) pairs (4-10 on one edge server, 18-100 on the cloud
#: server with its pipeline, 42-620 on both servers), where the same nonzeros cost IPX several
#: times more. Fitted (least squares in logs) on ``python benchmarks/level2_lp.py --scan``'s runs on
#: the calibration systems (benchmarks/level2_time.csv; docs/bounds.md, "Relaxation 5", with its
#: fit on held-out points). CPU time: IPX is serial, so the load of the machine does not enter.
ALL_PAIRS_TIME_MODEL = {"coef": 124.9, "a": 1.778, "b": 1.607, "d": 0.923}


def time_features(size: dict) -> tuple:
    """The positive quantities whose logs :data:`ALL_PAIRS_TIME_MODEL` is linear in: nonzeros in
    millions, the pair chains' mean length (the lumped ages kept apart, c_k) over 10, and the
    (configuration, action) pairs over 100."""
    return (size["nnz"] / 1e6, size["mean_lump"] / 10.0, size["pairs_ca"] / 100.0)


def all_pairs_seconds(size: dict) -> float:
    """Predicted CPU seconds of IPX on the level-2 LP of :func:`all_pairs_size`'s ``size``
    (:data:`ALL_PAIRS_TIME_MODEL`)."""
    m = ALL_PAIRS_TIME_MODEL
    nnz, length, pairs = time_features(size)
    return float(m["coef"] * nnz ** m["a"] * length ** m["b"] * pairs ** m["d"])


def all_pairs_size(system: System | JointData, lump=None, solver: str = "ipx") -> dict:
    """The level-2 LP's size without building it.

    Counted from the caps, |C|, |C x A| and the automaton's outcomes alone
    (:func:`~wncs_lp.bounds.level2.level2_shape`): for a ``System`` from its flat automaton, which
    its construction already holds, so the count costs milliseconds at sixteen processes.

    Returns
    -------
    dict
        ``rows``, ``cols``, ``nnz`` (an upper bound), ``pairs`` (of processes), ``configurations``,
        ``pairs_ca`` (|C x A|), ``outcomes``, ``memory_bytes`` (:data:`ALL_PAIRS_BYTES_PER_NNZ` of
        ``solver`` a nonzero), Python integers, and ``predicted_seconds`` (IPX's CPU,
        :func:`all_pairs_seconds`).
    """
    if isinstance(system, JointData):
        caps, n_c, n_p, n_e = system.caps, system.n_configs, int(system.act_ptr[-1]), system.n_outcomes
    else:
        fl = system.automaton.flat(system.n_processes)
        caps, n_c, n_p, n_e = system.caps, int(fl.act_ptr.size - 1), int(fl.act_ptr[-1]), int(fl.out_nxt.size)
    lay = level2_shape(caps, n_c, n_p, n_e, lump)
    per = ALL_PAIRS_BYTES_PER_NNZ.get(solver, max(ALL_PAIRS_BYTES_PER_NNZ.values()))
    size = {"rows": int(lay.rows), "cols": int(lay.cols), "nnz": int(lay.nnz), "pairs": len(lay.pairs),
            "configurations": n_c, "pairs_ca": n_p, "outcomes": n_e, "mean_lump": float(np.mean(lay.lumps)),
            "memory_bytes": int(lay.nnz) * per}
    return {**size, "predicted_seconds": all_pairs_seconds(size)}


def cover_tables(lay: Level2Layout, tables: Level2Tables) -> GroupTables:
    """The level-2 tables as one value function over a cover: each pair's table spread from its
    lumped ages to every age (an age t of process k reads class min(t, c_k - 1)), then each
    process's own table where it has one."""
    groups, h = [], []
    for i, (k, l) in enumerate(lay.pairs):
        a, b = lay.lumps[k], lay.lumps[l]
        cls = (np.minimum(np.arange(lay.caps[k]), a - 1)[:, None] * b
               + np.minimum(np.arange(lay.caps[l]), b - 1)[None, :])
        groups.append((k, l))
        h.append(np.ascontiguousarray(np.asarray(tables.pair[i], float)[:, cls]))
    for k, own in enumerate(tables.single):
        if own is not None:
            groups.append((k,))
            h.append(np.asarray(own, float))
    column = np.arange(lay.n_configs, dtype=np.int64)
    return GroupTables(tuple(groups), tuple(h), tuple(column for _ in groups))


def all_pairs_bound(system: System, *, lump=None, solver: str = "ipx", tol: float = 1e-8,
                    time_limit: float | None = None, cpu_limit: float | None = None,
                    verbose: bool = False, progress: Any = False) -> BoundResult:
    """Relaxation 5's certified lower bound on g* (the level-2 LP solved whole, its duals certified).

    Parameters
    ----------
    system : System
        An enumerated system (the tables live on every joint configuration).
    lump, solver, tol, time_limit, cpu_limit, verbose
        As :func:`~wncs_lp.bounds.level2.level2_bound`.
    progress : bool or Progress
        A line before the solve and one with the bound.

    Returns
    -------
    BoundResult
        ``relaxation="joint-all-pairs"``; ``status`` ``"optimal"`` when the solver reported its
        optimum, else ``"inaccurate"`` (the bound holds either way: any duals are certified);
        ``tables`` a :class:`~wncs_lp.bounds.result.GroupTables` cover; ``stats`` the LP's size,
        the solver's status and objective (not a bound) and the CPU of each phase.

    Raises
    ------
    SizeLimitError
        The LP would not fit the memory this process may use (:func:`all_pairs_size`), before it
        is built.
    SolverError
        The solver returned no duals (nothing to certify), e.g. stopped by ``cpu_limit``.
    """
    t0 = time.monotonic()
    prog = as_progress(progress)
    data = JointData.from_system(system)
    size = all_pairs_size(data, lump, solver)
    require_memory(size["memory_bytes"], f"relaxation 5 on {system.n_processes} processes (the level-2 LP: "
                   f"{size['pairs']:,} pairs, {size['cols']:,} columns, {size['nnz']:,} nonzeros)",
                   ["relaxation 4 (--relaxation 4: pairs of one partition)",
                    "relaxation 5 with lumped ages (lower_bound(x, 5, lump=c))",
                    "relaxation 1 (--relaxation 1: seconds at any size)"])
    prog.phase(f"relaxation 5: the level-2 LP ({size['pairs']:,} pairs, {size['cols']:,} columns) by {solver}")
    res = level2_bound(data, lump=lump, solver=solver, tol=tol, time_limit=time_limit, cpu_limit=cpu_limit,
                       verbose=verbose)
    if res.tables is None or not np.isfinite(res.lower_bound):
        raise SolverError(f"relaxation 5: the {solver} solve of the level-2 LP ({res.rows:,} x {res.cols:,}, "
                          f"{res.nnz:,} nonzeros) returned no usable duals (status {res.status}, "
                          f"{res.solve_cpu:.0f} s of CPU): nothing certified; relaxation 4 or 2 is the cheaper route")
    status = OPTIMAL if res.status in ("kOptimal", "Solved") else INACCURATE
    cert = res.certificate
    stats = {"lp_rows": res.rows, "lp_cols": res.cols, "lp_nnz": res.nnz, "lp_value": res.lp_value,
             "solver": solver, "solver_status": res.status, "solver_iterations": res.iterations,
             "lumps": list(res.layout.lumps), "build_cpu": res.build_cpu, "solve_cpu": res.solve_cpu,
             "certify_cpu": res.certify_cpu, "roundoff": cert.roundoff}
    how = (f"the level-2 LP's duals ({len(res.layout.pairs)} pair tables on (tau_k, tau_l, C) and their "
           f"consistency prices) checked on every (C, a): g = -max U(C, a) less round-off {cert.roundoff:.2g}")
    prog.done(f"relaxation 5: certified lower bound {res.lower_bound:.10g} ({status})")
    return BoundResult(relaxation="joint-all-pairs", lower_bound=float(res.lower_bound),
                       relaxation_upper=float("inf"), status=status, certified_by=how, multipliers=np.empty(0),
                       process_gains=np.empty(0), tables=cover_tables(res.layout, res.tables),
                       seconds=time.monotonic() - t0, iterations=int(res.iterations), stats=stats)
