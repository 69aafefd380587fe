r"""Trade-off curves: the constrained optimum as one constraint's bound is swept (a study).

For every bound b of the grid, ``wncs_lp.solve(mdp, method, constraints=constraints')`` where
constraints' is the list with constraint ``index`` given the bound b on ``side`` (its other
bound, if any, and every other constraint unchanged). The curve b -> g*_C(b) is piecewise
linear and convex in a ``max`` bound (non-increasing), its slope is -lambda(b) (the multiplier
of the point), and it reaches the optimum *without* the constraint at the bound where the
constraint stops binding: the constraint's value under that optimum's policy (the
"threshold").

Warm start. Consecutive points differ only in one right-hand side, so when the LP solves them
(``method="lp"``, or ``"auto"`` choosing it) one after another, the LP is kept in one HiGHS
model (:class:`~wncs_lp.constrained.warm.WarmConstrainedLP`): the first point is solved cold
(HiGHS interior point + crossover, method ``"lp-highs"``), each next one by the dual simplex
from the previous point's basis (method ``"lp-warm"``). ``warm=False`` (CLI ``--cold``), or
``max_workers > 1``, solves every point cold with Clarabel as before (method ``"lp"``). A warm
point that does not certify as optimal is solved again cold (``"lp-warm->lp"``).

Every point keeps its certificate ``[gain_lower, gain_upper]``. A bound no policy meets is a
point with status ``"infeasible"`` and ``reachable`` = the least (``max``) / largest (``min``)
value any policy reaches, not an exception; a solver failure is a point with status
``"error: ..."``.

Files (with ``out``, a folder, created; :class:`~wncs_lp.studies.folder.StudyFolder`):

=========================== ===================================================================
``tradeoff.csv``            one row per point (:data:`COLUMNS`), rewritten atomically after each
``tradeoff.json``           settings, the reference optimum, threshold and every point
``tradeoff_meta.json``      the settings a resumed run must match
``tradeoff.png``            the figure (``plot=True``)
=========================== ===================================================================

Resume. A rerun into the same folder keeps the points already in ``tradeoff.csv`` (complete
rows whose fingerprint checks out and whose status is not ``error``) and solves only the
missing bounds; the grid may grow or shrink freely. A second run into the folder waits for the
first. The settings must match: the MDP (a digest of its arrays, and the
scenario fingerprint when it has one), the swept constraint (quantity, per-pair values, side,
its other bound), every other constraint (values and bounds) and the method (warm or cold is not
a setting: both solve the same LP to the same certificate, so a folder may hold ``lp``,
``lp-highs`` and ``lp-warm`` rows, each saying how it was solved). A folder holding
another curve is *refused* with a :class:`~wncs_lp.errors.WncsError` naming the settings that
differ (points of two different problems are never mixed on one curve; use another folder or
delete it).
"""
from __future__ import annotations

import hashlib
import json
import math
import sys
import time
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..constrained.problem import LinearConstraint
from ..constrained.registry import row_that_runs
from ..errors import InfeasibleConstraintsError, PolicyError, WncsError
from ..files import dumps
from ..mdp import MDP
from ..methods import BASIS, DEFAULT_METHOD
from ..methods import method as method_row
from .folder import FINGERPRINT, StudyFolder, read_table
from .grid import parse_values, value_key
from .runner import run_grid

__all__ = ["tradeoff", "TradeoffPoint", "TradeoffResult", "read_points", "COLUMNS", "quantity_unit"]

#: Columns of ``tradeoff.csv`` (the fingerprint last).
COLUMNS = ("bound", "gain", "gain_lower", "gain_upper", "multiplier", "randomized_states", "value", "reachable",
           "status", "method", "seconds", FINGERPRINT)
_DATA = COLUMNS[:-1]

#: Unit of each quantity's long-run average (axis labels).
_UNITS = {"send_rate": "updates per slot", "aoi": "slots", "cost": "MSE, sum of traces",
          "process_cost": "MSE, trace"}

_SIDES = ("max", "min")


def quantity_unit(quantity: str) -> str:
    """The unit of a constrained quantity's average (``"updates per slot"`` for ``send_rate``...)."""
    return _UNITS.get(quantity, "")




def _num(x: Any) -> float:
    return math.nan if x is None or x == "" else float(x)


# ----------------------------------------------------------------------------- one point
@dataclass(frozen=True)
class TradeoffPoint:
    """One bound of a trade-off curve.

    Attributes
    ----------
    bound : float
        The swept bound.
    gain : float
        The constrained optimal gain (exact cost of the returned policy); NaN when infeasible.
    gain_lower, gain_upper : float
        The certificate ``gain_lower <= g*_C(bound) <= gain_upper``.
    multiplier : float
        lambda >= 0 of the swept side: the curve's slope is ``-multiplier`` for a ``max``
        bound (``+multiplier`` for a ``min`` bound).
    randomized_states : int
        States where the returned policy randomises.
    value : float
        The swept quantity's average under the returned policy (``<= bound`` for ``max``).
    reachable : float
        For an infeasible bound: the least (``max``) / largest (``min``) value of the quantity
        any stationary policy reaches (NaN when only the combination with the other
        constraints is infeasible). NaN for a feasible bound.
    status : str
        ``"optimal"``, ``"inaccurate:<why>"`` (see :class:`ConstrainedSolution`),
        ``"infeasible"`` or ``"error: <message>"``.
    method : str
        The route that solved it (``"lp"``, ``"lagrangian"``, ...).
    seconds : float
    """

    bound: float
    gain: float = math.nan
    gain_lower: float = math.nan
    gain_upper: float = math.nan
    multiplier: float = math.nan
    randomized_states: int = 0
    value: float = math.nan
    reachable: float = math.nan
    status: str = "optimal"
    method: str = ""
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.status == "optimal"

    @property
    def feasible(self) -> bool:
        """A policy was found (status ``optimal`` or ``inaccurate:...``)."""
        return self.status != "infeasible" and not self.status.startswith("error")

    def to_dict(self) -> dict[str, Any]:
        return {c: (None if isinstance(getattr(self, c), float) and not math.isfinite(getattr(self, c))
                    else getattr(self, c)) for c in _DATA}

    def to_csv(self) -> list[str]:
        """The point's cells, without its fingerprint."""
        def f(x: float) -> str:
            return repr(float(x)) if math.isfinite(x) else ""

        return [repr(float(self.bound)), f(self.gain), f(self.gain_lower), f(self.gain_upper), f(self.multiplier),
                str(int(self.randomized_states)), f(self.value), f(self.reachable), self.status, self.method,
                repr(float(self.seconds))]

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> "TradeoffPoint":
        """From a CSV record or a :meth:`to_dict` dictionary (ValueError for values no curve
        writes: a negative count, an empty status, a non-finite bound)."""
        p = cls(bound=float(rec["bound"]), gain=_num(rec["gain"]), gain_lower=_num(rec["gain_lower"]),
                gain_upper=_num(rec["gain_upper"]), multiplier=_num(rec["multiplier"]),
                randomized_states=int(rec["randomized_states"]), value=_num(rec["value"]),
                reachable=_num(rec["reachable"]), status=str(rec["status"]), method=str(rec["method"] or ""),
                seconds=float(rec["seconds"] or 0.0))
        if not math.isfinite(p.bound) or p.randomized_states < 0 or not p.status or not p.seconds >= 0:
            raise ValueError(f"not a trade-off point: {rec}")
        return p

    def __repr__(self) -> str:
        if not self.feasible:
            extra = f", reachable={self.reachable:.6g}" if math.isfinite(self.reachable) else ""
            return f"TradeoffPoint(bound={self.bound:g}, status={self.status!r}{extra})"
        return (f"TradeoffPoint(bound={self.bound:g}, gain={self.gain:.10g}, bracket=[{self.gain_lower:.10g}, "
                f"{self.gain_upper:.10g}], multiplier={self.multiplier:.6g}, randomized_states="
                f"{self.randomized_states}, status={self.status!r})")


def read_points(path: str | Path) -> list[TradeoffPoint]:
    """Complete rows of a ``tradeoff.csv`` (a truncated or malformed line is skipped)."""
    return read_table(path, COLUMNS, TradeoffPoint.from_record)


# ----------------------------------------------------------------------------- the curve
@dataclass(frozen=True)
class TradeoffResult:
    """A trade-off curve: the constrained optimum against one constraint's bound.

    Attributes
    ----------
    constraint : str
        What is bounded, e.g. ``"send_rate[remote]"``.
    quantity : str
    index : int
        0-based position of the swept constraint in the list given.
    side : str
        ``"max"`` or ``"min"``.
    points : tuple of TradeoffPoint
        In increasing bound order.
    unconstrained_gain, unconstrained_lower, unconstrained_upper : float
        The optimum without the swept bound (the other constraints, and the swept constraint's
        other bound if it has one, kept) and its certificate: certified value iteration
        (``wncs_lp.solve(mdp, "vi")``) when nothing else is bounded, else a constrained solve.
    threshold : float
        The swept quantity's value under that optimum's policy: a ``max`` bound at or above it
        (a ``min`` bound at or below it) does not bind, and the curve is flat at
        ``unconstrained_gain`` there. NaN when that policy's chain is multichain.
    reachable : float
        The least (``max``) / largest (``min``) value of the quantity any policy reaches on its
        own; bounds beyond it are infeasible.
    others : tuple of str
        Labels of the constraints kept fixed.
    method : str
        The method requested.
    out_dir : Path or None
    files : dict
        Paths written (``csv``, ``json``, ``meta``, ``png``).
    computed, reused : int
        Points solved in this run / taken from ``tradeoff.csv``.
    seconds : float
    """

    constraint: str
    quantity: str
    index: int
    side: str
    points: tuple[TradeoffPoint, ...]
    unconstrained_gain: float
    unconstrained_lower: float
    unconstrained_upper: float
    threshold: float
    reachable: float
    others: tuple[str, ...] = ()
    method: str = DEFAULT_METHOD
    out_dir: Path | None = None
    files: dict[str, str] = field(default_factory=dict)
    computed: int = 0
    reused: int = 0
    seconds: float = 0.0

    # ------------------------------------------------------------------ columns
    def _col(self, name: str, only_feasible: bool = False) -> np.ndarray:
        return np.array([getattr(p, name) for p in self.points if p.feasible or not only_feasible], dtype=float)

    @property
    def bounds(self) -> np.ndarray:
        return self._col("bound")

    @property
    def gains(self) -> np.ndarray:
        """Optimal gain per point (NaN where infeasible)."""
        return self._col("gain")

    @property
    def multipliers(self) -> np.ndarray:
        return self._col("multiplier")

    @property
    def feasible_points(self) -> tuple[TradeoffPoint, ...]:
        return tuple(p for p in self.points if p.feasible)

    @property
    def ok(self) -> bool:
        """Every point is optimal or infeasible (no inaccurate solve, no error)."""
        return all(p.ok or p.status == "infeasible" for p in self.points)

    @property
    def unit(self) -> str:
        return quantity_unit(self.quantity)

    def point(self, bound: float) -> TradeoffPoint:
        """The point at ``bound`` (KeyError when it is not on the grid)."""
        for p in self.points:
            if value_key(p.bound) == value_key(bound):
                return p
        raise KeyError(f"no point at bound {bound:g}")

    def slopes(self) -> tuple[np.ndarray, np.ndarray]:
        """Finite-difference slopes of the curve between consecutive feasible points.

        Returns ``(midpoints, slopes)``; for a ``max`` bound the slope is ``-lambda`` between
        two kinks.
        """
        pts = self.feasible_points
        b = np.array([p.bound for p in pts])
        g = np.array([p.gain for p in pts])
        if b.size < 2:
            return np.zeros(0), np.zeros(0)
        return (b[1:] + b[:-1]) / 2, np.diff(g) / np.diff(b)

    # ------------------------------------------------------------------ export
    def table(self) -> list[dict[str, Any]]:
        """The points as JSON-ready dictionaries (the CSV's columns)."""
        return [p.to_dict() for p in self.points]

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the curve's settings, reference optimum, threshold and points."""
        return json.loads(dumps({
            "constraint": self.constraint, "quantity": self.quantity, "index": self.index, "side": self.side,
            "unit": self.unit, "method": self.method, "others": list(self.others),
            "unconstrained_gain": self.unconstrained_gain, "unconstrained_lower": self.unconstrained_lower,
            "unconstrained_upper": self.unconstrained_upper, "threshold": self.threshold,
            "reachable": self.reachable, "points": self.table(), "files": self.files, "computed": self.computed,
            "reused": self.reused, "seconds": self.seconds,
        }))

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> "TradeoffResult":
        """Rebuild a result from :meth:`summary` (e.g. a cached or saved ``tradeoff.json``)."""
        return cls(constraint=d["constraint"], quantity=d["quantity"], index=int(d["index"]), side=d["side"],
                   points=tuple(TradeoffPoint.from_record(p) for p in d["points"]),
                   unconstrained_gain=_num(d["unconstrained_gain"]), unconstrained_lower=_num(d["unconstrained_lower"]),
                   unconstrained_upper=_num(d["unconstrained_upper"]), threshold=_num(d["threshold"]),
                   reachable=_num(d["reachable"]), others=tuple(d.get("others", ())), method=d.get("method", ""),
                   out_dir=None, files=dict(d.get("files", {})), computed=int(d.get("computed", 0)),
                   reused=int(d.get("reused", 0)), seconds=float(d.get("seconds", 0.0)))

    def __repr__(self) -> str:
        op = "<=" if self.side == "max" else ">="
        bad = sum(not p.feasible for p in self.points)
        return (f"TradeoffResult({self.constraint} {op} b for {len(self.points)} bounds in "
                f"[{min(self.bounds, default=math.nan):g}, {max(self.bounds, default=math.nan):g}]"
                f"{f' ({bad} infeasible or failed)' if bad else ''}, unconstrained gain "
                f"{self.unconstrained_gain:.10g}, no longer binds at {self.threshold:.6g}, method={self.method!r})")


# ----------------------------------------------------------------------------- helpers
def _what(label: str) -> str:
    """The quantity part of a label made by ``constraints_for`` (``0.1 <= aoi[p1] <= 4`` -> ``aoi[p1]``)."""
    parts = label.split(" <= ")

    def number(t: str) -> bool:
        try:
            float(t)
        except ValueError:
            return False
        return True

    rest = [p for p in parts if not number(p)]
    return rest[0] if len(rest) == 1 else label


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def _mdp_digest(mdp: MDP) -> str:
    P = mdp.P.tocsr()
    return _digest(mdp.s_indices, mdp.a_indices, mdp.cost, P.indptr, P.indices, P.data)


def _meta(mdp: MDP, cons: Sequence[LinearConstraint], index: int, side: str, method: str) -> dict[str, Any]:
    c = cons[index]
    other_side = "min" if side == "max" else "max"
    ob = getattr(c, other_side)
    return {
        "kind": "wncs_lp tradeoff",
        "mdp": _mdp_digest(mdp),
        "scenario_fingerprint": (mdp.meta or {}).get("fingerprint"),
        "states": int(mdp.n_states),
        "pairs": int(mdp.n_pairs),
        "constraint": _what(c.label),
        "quantity": c.quantity,
        "constraint_values": _digest(c.values),
        "side": side,
        f"constraint_{other_side}": None if ob is None else float(ob),
        "others": [{"label": o.label, "values": _digest(o.values), "max": o.max, "min": o.min}
                   for j, o in enumerate(cons) if j != index],
        "method": method,
    }


def _solve_point(mdp: MDP, cons: tuple[LinearConstraint, ...], index: int, side: str, bound: float,
                 method: str, fallback: str | None = None, warm: Any = None) -> TradeoffPoint:
    """One constrained solve at one bound (module level: a picklable task for worker processes).

    With ``fallback``, a point that ``method`` does not certify as optimal (status
    ``inaccurate:...`` or a solver error) is solved again with ``fallback``; the optimal (else
    the better-certified) of the two is kept and its ``method`` reads ``"lagrangian->lp"``.

    With ``warm`` (a :class:`~wncs_lp.constrained.warm.WarmConstrainedLP` of the sweep), the
    point is re-solved from the previous point's basis; one it does not certify as optimal, or
    a HiGHS failure, is solved again cold (``"lp"``, or ``fallback`` when given) and the better
    one is kept (``"lp-warm->lp"``).
    """
    t0 = time.perf_counter()
    c = cons[index].with_bounds(**{side: float(bound)})
    trial = cons[:index] + (c,) + cons[index + 1:]
    first = _one_solve(mdp, trial, index, side, bound, c.label, method, warm)
    best = first
    second_method = fallback if fallback else ("lp" if warm is not None else None)
    if second_method and (warm is not None or second_method != method) and not first.ok \
            and first.status != "infeasible":
        second = _one_solve(mdp, trial, index, side, bound, c.label, second_method)
        if second.ok or (second.feasible and (not first.feasible or _width(second) < _width(first))):
            best = second
        best = replace(best, method=f"{first.method or method}->{second.method or second_method}"
                       if best is second else f"{first.method or method} (->{second_method}: {second.status})")
    return replace(best, seconds=time.perf_counter() - t0)


def _warm_route(mdp: MDP, cons: Sequence[LinearConstraint], method: str) -> bool:
    """Whether :func:`~wncs_lp.constrained.registry.run_constrained` would solve these by an LP that a
    warm HiGHS model can re-solve from the previous basis (the method's registry row, or the row
    ``auto``'s rule picks)."""
    return row_that_runs(method, mdp, cons).warm_start == BASIS


def _width(p: TradeoffPoint) -> float:
    w = p.gain_upper - p.gain_lower
    return w if math.isfinite(w) else math.inf


def _one_solve(mdp: MDP, trial: tuple[LinearConstraint, ...], index: int, side: str, bound: float, label: str,
               method: str, warm: Any = None) -> TradeoffPoint:
    from ..constrained import registry  # its run_constrained looked up at call time (tests count the solves)

    try:
        sol = warm.solve(trial) if warm is not None else registry.run_constrained(mdp, trial, method)
    except InfeasibleConstraintsError as exc:
        reach = math.nan
        for lab, r, s in zip(exc.constraints, exc.reachable, exc.sides):
            if lab == label and s == side:
                reach = float(r)
        return TradeoffPoint(bound=float(bound), reachable=reach, status="infeasible",
                             method="lp-warm" if warm is not None else method)
    except WncsError as exc:
        msg = str(exc).replace("\n", " ")
        return TradeoffPoint(bound=float(bound), status=f"error: {msg}", method="lp-warm" if warm is not None else method)
    rep = sol.constraints[index]
    lam = 0.0 if (rep.side is not None and rep.side != side) else float(rep.multiplier)
    return TradeoffPoint(bound=float(bound), gain=float(sol.gain), gain_lower=float(sol.gain_lower),
                         gain_upper=float(sol.gain_upper), multiplier=lam, randomized_states=sol.n_randomized,
                         value=float(rep.value), status=sol.status, method=sol.method)


def _reference(mdp: MDP, cons: tuple[LinearConstraint, ...], index: int, side: str, method: str,
               unconstrained: str, threads: int | None = None) -> dict[str, Any]:
    """The optimum without the swept constraint, the quantity's value under it, and its reachable end."""
    from ..constrained import evaluate_rows, reachable_range
    from ..constrained.registry import run_constrained
    from ..solvers.registry import average_entry, run_average

    c = cons[index]
    others = cons[:index] + cons[index + 1:]
    if getattr(c, "min" if side == "max" else "max") is not None:  # the constraint's other bound stays
        others = cons[:index] + (c.with_bounds(**{side: None}),) + cons[index + 1:]
    t0 = time.perf_counter()
    if others:
        sol = run_constrained(mdp, others, method)
        probs = np.asarray(sol.policy, dtype=float)
        g, lo, hi, how = sol.gain, sol.gain_lower, sol.gain_upper, f"constrained ({sol.method}) without the swept one"
    else:
        found = average_entry(unconstrained)
        extra = {"threads": threads} if threads is not None and found.takes_keyword("threads", on_mdp=True) else {}
        sol = run_average(mdp, method=unconstrained, **extra)
        probs = np.zeros(mdp.n_pairs)
        probs[np.asarray(sol.policy, dtype=np.int64)] = 1.0
        g, lo, hi, how = sol.gain, sol.gain_lower, sol.gain_upper, f"unconstrained ({sol.method})"
    try:
        threshold = float(evaluate_rows(mdp, probs, [c])["values"][0])
    except PolicyError:
        threshold = math.nan
    return {"gain": float(g), "gain_lower": float(lo), "gain_upper": float(hi), "threshold": threshold,
            "reachable": float(reachable_range(mdp, c, side)), "how": how, "seconds": time.perf_counter() - t0}


def _point_task(mdp: MDP, cons: tuple[LinearConstraint, ...], index: int, side: str, method: str,
                fallback: str | None, warm: bool, bound: float, solver: Any = None,
                emit: Callable[[TradeoffPoint], None] | None = None) -> tuple[list[TradeoffPoint], Any]:
    """One bound as a task of :func:`~wncs_lp.studies.runner.run_grid`: in order (``emit``
    given) the points share one warm HiGHS model (the ``solver`` carried from point to point);
    in worker processes each point is solved cold."""
    if warm and emit is not None and solver is None:
        from ..constrained.warm import WarmConstrainedLP

        solver = WarmConstrainedLP(mdp, cons[:index] + (cons[index].with_bounds(**{side: float(bound)}),)
                                   + cons[index + 1:])
    point = _solve_point(mdp, cons, index, side, bound, method, fallback, solver)
    if emit is not None:
        emit(point)
    return [point], solver


# ----------------------------------------------------------------------------- the sweep
def _checked(mdp: MDP, constraints: Sequence[Any], index: Any, side: str, method: str, fallback: str | None,
             max_workers: int) -> tuple[tuple[LinearConstraint, ...], int]:
    """The constraints as :class:`LinearConstraint` and the index, after checking every argument."""
    from ..constrained import constraints_for

    if side not in _SIDES:
        raise WncsError(f"side must be 'max' or 'min', got {side!r}")
    method_row(method, constrained=True)
    if fallback is not None:
        method_row(fallback, constrained=True)
    if max_workers < 1:
        raise WncsError(f"max_workers must be >= 1, got {max_workers}")
    cons = constraints_for(mdp, constraints)
    if not isinstance(index, (int, np.integer)) or not 0 <= int(index) < len(cons):
        raise WncsError(f"no constraint at index {index} (0-based): there {'is' if len(cons) == 1 else 'are'} "
                        f"{len(cons)} constraint{'' if len(cons) == 1 else 's'}")
    return cons, int(index)


def _bounds(values: Sequence[float] | str, c: LinearConstraint, side: str) -> dict[str, float]:
    """The grid by key (duplicates dropped), none crossing the constraint's other bound."""
    grid: dict[str, float] = {}
    for v in parse_values(values):
        grid.setdefault(value_key(v), float(v))
    other = getattr(c, "min" if side == "max" else "max")
    if other is not None:
        bad = [b for b in grid.values() if (b < other if side == "max" else b > other)]
        if bad:
            raise WncsError(f"{_what(c.label)}: bound(s) {', '.join(f'{b:g}' for b in bad)} cross the constraint's "
                            f"{'min' if side == 'max' else 'max'} = {other:g}")
    return grid


def _say(progress: Callable[[str], None] | bool | None) -> Callable[[str], None] | None:
    if progress is True:
        return lambda line: print(line, file=sys.stderr, flush=True)
    return progress if callable(progress) else None


class _Curve:
    """The points of a trade-off run, in memory and (with a folder) on disk after each one."""

    REFERENCE = "reference"

    def __init__(self, mdp: MDP, cons: tuple[LinearConstraint, ...], index: int, side: str, method: str,
                 grid: dict[str, float], folder: StudyFolder | None, say: Callable[[str], None] | None):
        self.cons, self.index, self.side, self.method, self.grid = cons, index, side, method, grid
        self.folder, self.say = folder, say
        self.c = cons[index]
        self.what = _what(self.c.label)
        self.t_start = time.perf_counter()
        self.files: dict[str, str] = {}
        self.computed = 0
        self.done: dict[str, TradeoffPoint] = {}
        self.reference: dict[str, Any] | None = None
        if folder is not None:
            rows = folder.rows(TradeoffPoint.from_record, lambda p: value_key(p.bound))
            self.done = {k: p for k, p in rows.items() if not p.status.startswith("error")}
            self.reference = self._saved_reference()
        self.reused = sum(1 for k in grid if k in self.done)

    def _saved_reference(self) -> dict[str, Any] | None:
        try:
            saved = json.loads(self.folder.json.read_text())
        except (OSError, ValueError):
            return None
        ref = saved.get(self.REFERENCE) if isinstance(saved, dict) else None
        if not isinstance(ref, dict):
            return None
        return ref if saved.get("reference_fingerprint") == self.folder.seal_json(self.REFERENCE, ref) else None

    def todo(self) -> list[float]:
        return sorted(b for k, b in self.grid.items() if k not in self.done)

    def result(self) -> TradeoffResult:
        ref = self.reference
        pts = tuple(sorted((self.done[k] for k in self.grid if k in self.done), key=lambda p: p.bound))
        return TradeoffResult(
            constraint=self.what, quantity=self.c.quantity, index=self.index, side=self.side, points=pts,
            unconstrained_gain=ref["gain"], unconstrained_lower=ref["gain_lower"],
            unconstrained_upper=ref["gain_upper"], threshold=ref["threshold"], reachable=ref["reachable"],
            others=tuple(o.label for j, o in enumerate(self.cons) if j != self.index), method=self.method,
            out_dir=self.folder.path if self.folder is not None else None, files=dict(self.files),
            computed=self.computed, reused=self.reused, seconds=time.perf_counter() - self.t_start)

    def save(self) -> None:
        if self.folder is None:
            return
        pts = sorted(self.done.values(), key=lambda p: p.bound)  # every point of the folder, on the grid or not
        self.files.update(csv=str(self.folder.csv), json=str(self.folder.json))
        doc = {"settings": self.folder.settings, self.REFERENCE: self.reference,
               "reference_fingerprint": self.folder.seal_json(self.REFERENCE, self.reference),
               **self.result().summary()}
        self.files.update(self.folder.write(((value_key(p.bound), p.to_csv()) for p in pts), doc))

    def record(self, p: TradeoffPoint) -> None:
        self.done[value_key(p.bound)] = p
        self.computed += 1
        self.save()
        if self.say is None:
            return
        op = "<=" if self.side == "max" else ">="
        if p.feasible:
            self.say(f"{self.what} {op} {p.bound:g}: gain {p.gain:.10g} [{p.gain_lower:.10g}, {p.gain_upper:.10g}], "
                     f"multiplier {p.multiplier:.6g}, {p.randomized_states} randomised state(s) "
                     f"({p.seconds:.2f} s) {p.status}")
        else:
            r = f" (reachable: {p.reachable:.10g})" if math.isfinite(p.reachable) else ""
            self.say(f"{self.what} {op} {p.bound:g}: {p.status}{r} ({p.seconds:.2f} s)")


def tradeoff(
    mdp: MDP,
    constraints: Sequence[Any],
    index: int,
    values: Sequence[float] | str,
    *,
    side: str = "max",
    method: str = DEFAULT_METHOD,
    out: str | Path | None = None,
    progress: Callable[[str], None] | bool | None = None,
    plot: bool = True,
    max_workers: int = 1,
    executor: Any = None,
    threads: int | None = None,
    unconstrained: str = "vi",
    fallback: str | None = None,
    warm: bool = True,
) -> TradeoffResult:
    """Sweep the bound of one constraint and solve the constrained problem at each bound.

    Parameters
    ----------
    mdp : MDP
    constraints : sequence of ConstraintSpec or LinearConstraint
        E.g. ``scenario.constraints``. The one at ``index`` is swept; the others keep their bounds.
    index : int
        0-based position of the constraint to sweep.
    values : sequence of float or str
        The bounds: a list or ``"A:B:STEP"`` / ``"a,b,c"`` (:func:`wncs_lp.studies.parse_values`).
        Duplicates are dropped; the points come out in increasing order.
    side : {"max", "min"}
        Which bound of the constraint is swept (its other bound, if any, is kept).
    method : {"auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian"}
        Passed to :func:`~wncs_lp.constrained.registry.run_constrained` at every point.
    out : path, optional
        Output folder (see the module docstring): written after every point and resumed.
    progress : callable or bool, optional
        A callable receives one line per finished point; ``True`` prints them on stderr.
    plot : bool
        With ``out``, also save ``tradeoff.png`` (:func:`wncs_lp.viz.save_tradeoff_figure`).
    max_workers : int
        Bounds solved in parallel worker processes (default 1: in order, in this process).
    executor : None, "process", "dask", str, Client or Executor
        Where the bounds run when not in order (:mod:`wncs_lp.studies.executors`): worker
        processes, a local Dask cluster, the Dask scheduler at an address (``"tcp://..."``),
        your own ``dask.distributed.Client`` or a ``concurrent.futures.Executor``.
    threads : int, optional
        Kernel threads of the reference's unconstrained solve (default: the solver's).
    unconstrained : str
        Method of :func:`wncs_lp.solve` for the reference optimum when the swept constraint is
        the only one (default ``"vi"``, certified value iteration).
    fallback : str, optional
        A second method for the points ``method`` does not certify as optimal (e.g.
        ``method="lagrangian", fallback="lp"``): such a point is solved again and the optimal
        one is kept (its ``method`` column reads ``"lagrangian->lp"``). Not part of the
        settings a resumed run must match.
    warm : bool
        When the points are solved by the LP (``method="lp"``, or ``"auto"`` choosing it) one
        after another (in order): keep the LP in one HiGHS model and re-solve each bound from
        the previous point's basis (dual simplex;
        :class:`~wncs_lp.constrained.warm.WarmConstrainedLP`), instead of a cold Clarabel
        solve per point. The points are certified the same way; their ``method`` column reads
        ``"lp-warm"`` (``"lp-highs"`` for a cold HiGHS start). False: every point cold. Not
        part of the settings a resumed run must match (both solve the same LP).

    Returns
    -------
    TradeoffResult

    Raises
    ------
    WncsError
        No constraint at ``index``, a bad side or grid, a bound crossing the constraint's other
        bound, an output folder holding another curve, or a reference optimum that cannot be
        computed (e.g. the other constraints are infeasible).
    """
    cons, index = _checked(mdp, constraints, index, side, method, fallback, max_workers)
    grid = _bounds(values, cons[index], side)
    folder = StudyFolder(out, "tradeoff", _meta(mdp, cons, index, side, method), COLUMNS,
                         "a trade-off curve") if out is not None else None
    with folder if folder is not None else nullcontext():
        curve = _Curve(mdp, cons, index, side, method, grid, folder, _say(progress))
        if curve.reference is None:
            try:
                curve.reference = _reference(mdp, cons, index, side, method, unconstrained, threads)
            except InfeasibleConstraintsError as exc:
                raise WncsError(f"the other constraints are infeasible without {curve.what}: {exc}") from None
        todo = curve.todo()
        task = partial(_point_task, mdp, cons, index, side, method, fallback,
                       bool(warm and todo and _warm_route(mdp, cons, method)))
        run_grid(todo, task, curve.record, executor=executor, max_workers=max_workers)
        curve.save()
        if folder is not None and plot:
            from ..viz import save_tradeoff_figure

            curve.files.update(save_tradeoff_figure(curve.result(), folder.path / "tradeoff.png"))
            curve.save()  # the JSON lists the figure too
    return curve.result()
