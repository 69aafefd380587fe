"""The result type every solver returns."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..files import scalars

__all__ = ["Solution"]


@dataclass(frozen=True, eq=False)
class Solution:
    """An average-cost solution of an :class:`~wncs_lp.mdp.MDP`, with its certificate.

    Attributes
    ----------
    method : str
        ``"lp"`` (Clarabel direct), ``"lp-cvxpy"``, ``"rvi"``, ``"vi"``, ``"pi"`` or ``"auto"``
        (then ``stats["auto_choice"]`` says whose answer it is).
    status : str
        ``"optimal"`` when the certificate closes to the requested tolerance, otherwise a word
        saying what went wrong (``"inaccurate"``, ``"max_iter"``, the solver's own status...).
    gain : float
        The best estimate of the optimal gain g* (for LP: the exact gain of the returned policy
        when polishing verified it, else the LP objective).
    gain_lower, gain_upper : float
        The certificate lo <= g* <= hi from one Bellman step on ``bias``:
        lo = min_s (T h - h)(s), hi = max_s (T h - h)(s).
    bias : (n,) array
        A relative value function h (normalised so that h[0] = 0).
    policy : (n,) int array
        The chosen pair index of each state (``mdp.a_indices[policy]`` gives the actions).
    occupation : (L,) array or None
        The stationary state-action frequencies x(s, a) (sum 1) when the method gives them.
    iterations : int
    seconds : float
        Wall time of the whole solve (build of the solver's matrices included).
    stats : dict
        Method-specific numbers: residuals, solver status, raw LP objective, span, ...
    """

    method: str
    status: str
    gain: float
    gain_lower: float
    gain_upper: float
    bias: np.ndarray
    policy: np.ndarray
    occupation: np.ndarray | None = None
    iterations: int = 0
    seconds: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def gap(self) -> float:
        """Relative width of the certificate, (hi - lo) / max(|gain|, 1e-300)."""
        return (self.gain_upper - self.gain_lower) / max(abs(self.gain), 1e-300)

    @property
    def ok(self) -> bool:
        return self.status == "optimal"

    def actions(self, mdp) -> np.ndarray:
        """The action index (into ``mdp.action_table``) chosen in each state."""
        return mdp.a_indices[self.policy]

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars (no arrays)."""
        out = {
            "method": self.method,
            "status": self.status,
            "gain": float(self.gain),
            "gain_lower": float(self.gain_lower),
            "gain_upper": float(self.gain_upper),
            "certificate_gap": float(self.gap),
            "iterations": int(self.iterations),
            "seconds": float(self.seconds),
        }
        out.update(scalars(self.stats))
        return out
