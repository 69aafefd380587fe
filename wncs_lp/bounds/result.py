"""The result of a relaxation: a certified lower bound on g* and the value tables it gives."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..display import Display, fmt
from ..files import json_ready
from ..status import MAX_ITER, OPTIMAL

__all__ = ["ValueTables", "GroupTables", "BoundResult"]


@dataclass(frozen=True, eq=False)
class ValueTables:
    """Per-process value tables h_k(tau_k, c) of a separable value function
    h(tau, C) ~ sum_k h_k(tau_k, column_k(C)).

    Attributes
    ----------
    h : tuple of arrays
        ``h[k][col, tau - 1]``, shape (n_cols_k, tau_hat_k): process k's value table (the layout
        of :class:`wncs_lp.policies.suboptimal.ProcessPoisson`'s ``h``).
    column : tuple of int arrays
        ``column[k][c]``, shape (|C|,): the column of ``h[k]`` that joint configuration ``c`` (an
        id of the system's automaton) reads. The identity for a relaxation over the joint
        configuration; process k's projection of ``c`` for a relaxation over private servers.
    """

    h: tuple
    column: tuple

    @property
    def n_processes(self) -> int:
        return len(self.h)

    def value(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """sum_k h_k(tau_k, column_k(C)) for an (R, N) array of AoI vectors and (R,) configuration ids."""
        tau = np.asarray(tau, dtype=np.int64)
        c = np.asarray(config_ids, dtype=np.int64)
        out = np.zeros(tau.shape[0])
        for k, (hk, col) in enumerate(zip(self.h, self.column)):
            out += hk[col[c], tau[:, k] - 1]
        return out


@dataclass(frozen=True, eq=False)
class GroupTables:
    """Per-group value tables h_G(tau_G, c) of a value function separable across groups of
    processes, h(tau, C) ~ sum_G h_G(tau_G, column_G(C)) (the grouped relaxation's).

    Attributes
    ----------
    groups : tuple of tuples of int
        The groups (0-based, increasing in each group): a partition of the processes for
        relaxations 3 and 4, or a cover whose groups overlap (the level-2 relaxation's every pair);
        the value function is the sum over the groups either way.
    h : tuple of arrays
        ``h[i][col, tau_{G[0]} - 1, tau_{G[1]} - 1, ...]``, shape (n_cols_i, tau_hat of each member).
    column : tuple of int arrays
        ``column[i][c]``, shape (|C|,): the column of ``h[i]`` that joint configuration ``c`` reads
        (group i's projection of ``c``).
    """

    groups: tuple
    h: tuple
    column: tuple

    @property
    def n_processes(self) -> int:
        """The number of distinct processes the groups hold (a process in several groups counts once)."""
        return len({int(k) for g in self.groups for k in g})

    def value(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """sum_G h_G(tau_G, column_G(C)) for an (R, N) array of AoI vectors and (R,) configuration ids."""
        tau = np.asarray(tau, dtype=np.int64)
        c = np.asarray(config_ids, dtype=np.int64)
        out = np.zeros(tau.shape[0])
        for g, hg, col in zip(self.groups, self.h, self.column):
            out += hg[(col[c],) + tuple(tau[:, k] - 1 for k in g)]
        return out


@dataclass(frozen=True, eq=False, repr=False)
class BoundResult(Display):
    """A certified lower bound on the optimal gain g* of a scenario, from one relaxation.

    Attributes
    ----------
    relaxation : str
        ``"private-servers"`` (relaxation 1), ``"joint-configuration"`` (relaxation 2) or
        ``"grouped-private-servers"`` (relaxation 3).
    lower_bound : float
        The certified bound: ``lower_bound <= g*``. It holds whatever ``status`` says.
    relaxation_upper : float
        An upper bound on the relaxation's own optimum where the method gives one (else +inf):
        ``relaxation_upper - lower_bound`` says how much more this relaxation could give.
    status : str
        A code of :mod:`wncs_lp.status`: ``"optimal"`` when the relaxation was solved to its
        tolerance, else ``"inaccurate"`` / ``"max_iter"`` / ``"interrupted"``.
    certified_by : str
        How the bound was certified, in words (e.g. the priced per-process chains solved to a
        Bellman certificate, or a feasible (g, h) checked constraint by constraint). Never an LP
        solver's status alone.
    multipliers : numpy array
        The prices / dual solution at which the bound was certified.
    process_gains : array
        Each process's part of the bound (its certified gain at the multipliers); for the grouped
        relaxation each group's, in the order of ``tables.groups``.
    tables : ValueTables or GroupTables
        The value tables of the relaxation, for the greedy policy of the bound.
    seconds : float
    iterations : int
    stats : dict
    alternatives : tuple of BoundResult
        The other certified results ``lower_bound(relaxation="auto")`` computed beside this one
        (their tables, for the policy side: :func:`~wncs_lp.bounds.gaps.policy_source`); empty
        otherwise. Not part of :meth:`summary`.
    """

    relaxation: str
    lower_bound: float
    relaxation_upper: float
    status: str
    certified_by: str
    multipliers: np.ndarray
    process_gains: np.ndarray
    tables: ValueTables
    seconds: float
    iterations: int
    stats: dict[str, Any] = field(default_factory=dict)
    alternatives: tuple = field(default=(), repr=False)

    def gap_of(self, gain: float) -> float:
        """The certified relative optimality gap of a policy of gain ``gain``: (gain - LB) / LB."""
        return (float(gain) - self.lower_bound) / self.lower_bound

    @property
    def ok(self) -> bool:
        """The relaxation was solved to its tolerance (the bound holds either way)."""
        return self.status == OPTIMAL

    @property
    def certified(self) -> bool:
        """A finite certified bound came out: the relaxation solved to its tolerance, or its search
        stopped at its own budget (``max_iter``, ``time_limit``) with the best tables certified.
        The certificate never depends on how the search ended; only an interrupted or failed run
        is not this."""
        return self.status in (OPTIMAL, MAX_ITER) and bool(np.isfinite(self.lower_bound))

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars and short lists (not the value tables)."""
        return {
            "relaxation": self.relaxation,
            "lower_bound": float(self.lower_bound),
            "relaxation_upper": float(self.relaxation_upper),
            "status": self.status,
            "certified_by": self.certified_by,
            "multipliers": np.asarray(self.multipliers, float).ravel().tolist() if np.size(self.multipliers) <= 64
            else f"{np.size(self.multipliers)} values",
            "process_gains": np.asarray(self.process_gains, float).tolist(),
            "seconds": float(self.seconds),
            "iterations": int(self.iterations),
            "stats": json_ready(self.stats),
        }

    def __repr__(self) -> str:
        up = "" if not np.isfinite(self.relaxation_upper) else f" (relaxation <= {self.relaxation_upper:.10g})"
        return (f"BoundResult({self.relaxation}: g* >= {self.lower_bound:.10g}{up}, status {self.status}, "
                f"{self.iterations} iterations, {self.seconds:.2f} s)")

    # the HTML form in Jupyter and to_frame() (wncs_lp.display): the bound, then one row per part
    def _display_head(self) -> str:
        return f"BoundResult: g* >= {fmt(self.lower_bound)} ({self.relaxation})"

    def _display_rows(self) -> list[tuple[str, str]]:
        rows = [("lower_bound", fmt(self.lower_bound)), ("status", self.status),
                ("certified_by", self.certified_by)]
        if np.isfinite(self.relaxation_upper):
            rows.append(("relaxation_upper", fmt(self.relaxation_upper)))
        rows += [("multipliers", ", ".join(fmt(x, 8) for x in np.asarray(self.multipliers, float).ravel()[:8])
                  + (" ..." if np.size(self.multipliers) > 8 else "")),
                 ("iterations", fmt(self.iterations)), ("seconds", f"{self.seconds:.2f}")]
        return rows

    def _frame_records(self):
        """One record per process (per group for the grouped relaxation): its part of the bound."""
        groups = getattr(self.tables, "groups", None)
        parts = np.asarray(self.process_gains, float).ravel()
        names = ([",".join(str(k + 1) for k in g) for g in groups] if groups is not None
                 else [str(k + 1) for k in range(parts.size)])
        return (["processes", "part_of_bound"],
                [{"processes": n, "part_of_bound": float(v)} for n, v in zip(names, parts)])
