"""Report types of the structural checks and the helpers that fill them.

:class:`Tolerance` (the tie tolerance), :class:`Violation` (one violation), :class:`CheckReport`
(the outcome of one check) and the helpers every check uses to build a report:
:func:`split_counts`, :func:`pick_examples`, :func:`make_report`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ModelError
from ..files import json_ready
from .verdict import structural_verdict, witness_rank


__all__ = ["Tolerance", "Violation", "CheckReport", "split_counts", "pick_examples"]


@dataclass(frozen=True)
class Tolerance:
    r"""The tie tolerance ``tol = atol + rtol * scale`` with ``scale = span(V)``.

    Parameters
    ----------
    atol : float
        Absolute part (same unit as the cost).
    rtol : float
        Part relative to the value scale ``max V - min V``.
    """

    atol: float = 1e-9
    rtol: float = 1e-9

    def __post_init__(self) -> None:
        if not (self.atol >= 0 and self.rtol >= 0 and np.isfinite(self.atol) and np.isfinite(self.rtol)):
            raise ModelError(f"tolerance parts must be finite and >= 0, got atol={self.atol}, rtol={self.rtol}")

    def resolve(self, scale: float) -> float:
        """The absolute tolerance for a value scale."""
        return float(self.atol + self.rtol * scale)


@dataclass(frozen=True)
class Violation:
    """One violation (or counterexample) of a structural property.

    Attributes
    ----------
    kind : str
        Which sub-check found it (``"adjacent"``, ``"dominance"``, ``"ray"``, ``"line-gap"``,
        ``"preempt"``, ``"cancel"``).
    size : float
        How large it is, in the unit stated by the check (a value or Q-value difference, or a
        probability for consistency).
    states : tuple[int, ...]
        The state ids involved.
    labels : tuple[str, ...]
        Their decoded labels (``tau=(..) | configuration``).
    recurrent : bool
    at_cap : bool
    stationary : tuple[float, ...] or None
        Stationary probability of each state under the solution's policy, when available.
    info : dict
        Check-specific data (axis, actions, z, trajectory...), JSON-ready.
    cap_distance : int or None
        How far the witness lies from the cap: the smallest ``tau_hat_k - tau_k`` over its states
        (0: it touches the cap; :func:`~wncs_lp.verify.verdict.cap_distance`).
    observable : bool or None
        Every state recurrent and visited at least :data:`~wncs_lp.verify.verdict.NEGLIGIBLE`
        of the time (None: no stationary law).
    """

    kind: str
    size: float
    states: tuple[int, ...]
    labels: tuple[str, ...]
    recurrent: bool
    at_cap: bool
    stationary: tuple[float, ...] | None = None
    info: dict = field(default_factory=dict)
    cap_distance: int | None = None
    observable: bool | None = None

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {
            "kind": self.kind,
            "size": float(self.size),
            "states": [int(s) for s in self.states],
            "labels": list(self.labels),
            "recurrent": bool(self.recurrent),
            "at_cap": bool(self.at_cap),
            "stationary": None if self.stationary is None else [float(x) for x in self.stationary],
            "info": json_ready(self.info),
            "cap_distance": None if self.cap_distance is None else int(self.cap_distance),
            "observable": None if self.observable is None else bool(self.observable),
        }


@dataclass(frozen=True)
class CheckReport:
    """The outcome of one structural check.

    Attributes
    ----------
    name : str
        ``"monotonicity"``, ``"threshold"`` or ``"consistency"``.
    claim : str
        The paper's statement checked and the claim id.
    holds : bool
        No violation beyond the tolerance (see ``notes`` for what exactly enters it).
    verdict : str (property)
        HOLDS / FAILS / DEPENDS from ``holds`` and ``split`` by :mod:`wncs_lp.verify.verdict`: FAILS
        needs a violation that is recurrent and below the cap.
    checked : int
        Number of cases examined (the unit is in ``unit``).
    violations : int
        Number of violating cases (same unit).
    recurrent_violations, at_cap_violations : int
        Among the violations: how many are recurrent, how many touch the AoI cap.
    ties : int
        Cases that differ from the claim only within the tolerance (not violations).
    split : dict
        The violations by (recurrent | transient) x (at cap | below cap), and ``observable_below_cap``
        (recurrent, every witness state of weight at least
        :data:`~wncs_lp.verify.verdict.NEGLIGIBLE`, below the cap: these decide FAILS).
    tol, atol, rtol, value_scale : float
        The resolved tolerance ``tol = atol + rtol * value_scale``.
    recurrence_rule : str
    unit : str
        What one case is.
    worst : Violation or None
        The largest violation (by ``|size|``).
    examples : tuple[Violation, ...]
        Up to K violations, recurrent and below-cap ones first, then by size.
    details : dict
        Sub-counts (JSON-ready).
    notes : str
    model : str
    seconds : float
    weight : dict
        The stationary probability, under the solution's policy, of the states of the violations'
        witnesses (``mass``, over ``states`` distinct states) and of those of the violations
        counted recurrent and below the cap (``mass_recurrent_below_cap``): the weight of the
        counterexamples. None when the stationary law is not known.
    """

    name: str
    claim: str
    holds: bool
    checked: int
    violations: int
    recurrent_violations: int
    at_cap_violations: int
    ties: int
    split: dict
    tol: float
    atol: float
    rtol: float
    value_scale: float
    recurrence_rule: str
    unit: str
    worst: Violation | None
    examples: tuple[Violation, ...]
    details: dict
    notes: str
    model: str
    seconds: float
    weight: dict = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        """HOLDS, FAILS or DEPENDS by the one rule shared with the reproduction
        (:func:`wncs_lp.verify.verdict.structural_verdict`)."""
        obs = self.split.get("observable_below_cap")
        return structural_verdict(self.holds, self.split.get("recurrent_below_cap", 0), obs)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (strict JSON once NaN/inf are mapped to null by the caller)."""
        return {
            "name": self.name,
            "claim": self.claim,
            "verdict": self.verdict,
            "holds": bool(self.holds),
            "checked": int(self.checked),
            "violations": int(self.violations),
            "recurrent_violations": int(self.recurrent_violations),
            "at_cap_violations": int(self.at_cap_violations),
            "ties": int(self.ties),
            "split": json_ready(self.split),
            "unit": self.unit,
            "tol": float(self.tol),
            "atol": float(self.atol),
            "rtol": float(self.rtol),
            "value_scale": float(self.value_scale),
            "recurrence_rule": self.recurrence_rule,
            "worst": None if self.worst is None else self.worst.to_json(),
            "examples": [v.to_json() for v in self.examples],
            "details": json_ready(self.details),
            "notes": self.notes,
            "model": self.model,
            "seconds": float(self.seconds),
            "weight": json_ready(self.weight),
        }

    def summary(self) -> str:
        """One line: verdict and counts."""
        w = "" if self.worst is None else f", worst {self.worst.size:.4g}"
        if self.weight.get("mass") is not None and self.violations:
            w += f", stationary mass {self.weight['mass']:.3g}"
        return (
            f"{self.name}: {self.verdict} -- {self.violations} violation(s) in {self.checked} {self.unit} "
            f"({self.recurrent_violations} recurrent, {self.at_cap_violations} at cap, {self.ties} ties{w}; "
            f"tol {self.tol:.3g})"
        )



def split_counts(rec: np.ndarray, cap: np.ndarray, obs: np.ndarray | None = None) -> dict[str, int]:
    """The violations by (recurrent | transient) x (at cap | below cap); with ``obs`` (per
    violation: its witness observable, every state of weight) also ``observable_below_cap``, the
    violations that decide FAILS (:func:`~wncs_lp.verify.verdict.structural_verdict`)."""
    rec = np.asarray(rec, bool)
    cap = np.asarray(cap, bool)
    out = {
        "recurrent_below_cap": int(np.count_nonzero(rec & ~cap)),
        "recurrent_at_cap": int(np.count_nonzero(rec & cap)),
        "transient_below_cap": int(np.count_nonzero(~rec & ~cap)),
        "transient_at_cap": int(np.count_nonzero(~rec & cap)),
    }
    if obs is not None:
        out["observable_below_cap"] = int(np.count_nonzero(np.asarray(obs, bool) & rec & ~cap))
    return out


def pick_examples(rec: np.ndarray, cap: np.ndarray, size: np.ndarray, k: int, obs: np.ndarray | None = None,
                  dist: np.ndarray | None = None) -> np.ndarray:
    """Indices of up to k violations: by the class of their witness
    (:func:`~wncs_lp.verify.verdict.witness_rank`: observable and below the cap first, then
    recurrent and below the cap, then below the cap, ...), then farthest from the cap (``dist``,
    per violation the smallest ``tau_hat_k - tau_k`` over its witness), then by |size|."""
    if size.size == 0 or k <= 0:
        return np.zeros(0, np.int64)
    far = np.zeros(size.size, np.int64) if dist is None else -np.asarray(dist, np.int64)
    order = np.lexsort((-np.abs(size), far, witness_rank(rec, cap, obs)))
    return order[:k]
