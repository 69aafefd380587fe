"""What a constrained solve returns: the randomised policy, its exact averages, the certificate."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..files import scalars
from ..solvers.result import Certificate, Certified, certificate_rows, certificate_summary, describe_array, takes_bounds
from ..status import Status

__all__ = ["ConstraintReport", "ConstrainedSolution"]


@dataclass(frozen=True)
class ConstraintReport:
    """One constraint of a constrained solve, judged on the returned policy's own chain.

    Attributes
    ----------
    label, quantity : str
    max, min : float or None
        The bounds asked for.
    value : float
        The long-run average under the returned policy, by exact evaluation of its chain.
    lp_value : float
        The same average under the solver's occupation measure (before the policy was read
        off it); NaN for routes without one.
    active : bool
        A bound holds with equality at the optimum (its multiplier is positive, or the
        value sits on the bound within the feasibility tolerance).
    side : str or None
        ``"max"`` or ``"min"``: the bound that binds (None when neither does).
    multiplier : float
        lambda >= 0, the shadow price: the optimal gain moves by ``multiplier`` per unit of
        the binding bound (down as a ``max`` loosens, up as a ``min`` tightens).
    violation : float
        How far ``value`` lies outside the bounds (0 when it meets them).
    """

    label: str
    quantity: str
    max: float | None
    min: float | None
    value: float
    lp_value: float
    active: bool
    side: str | None
    multiplier: float
    violation: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "quantity": self.quantity,
            "max": self.max,
            "min": self.min,
            "value": float(self.value),
            "lp_value": float(self.lp_value),
            "active": bool(self.active),
            "side": self.side,
            "multiplier": float(self.multiplier),
            "violation": float(self.violation),
        }


@takes_bounds
@dataclass(frozen=True, eq=False, repr=False)
class ConstrainedSolution(Certified):
    r"""The optimum of ``min g`` subject to linear bounds on other long-run averages.

    Attributes
    ----------
    method : str
        ``"lp"`` (Clarabel direct), ``"lp-cvxpy"``, ``"lp-highs"`` / ``"lp-warm"`` (a trade-off point
        solved by HiGHS from scratch / re-solved from the previous point's basis), ``"lagrangian"`` (certified value
        iteration and a one-state mix) or ``"convex"`` (:class:`OccupationProgram`).
    status : Status
        ``"optimal"`` when the certificate closes to the requested tolerance and the returned
        policy meets every bound within the feasibility tolerance; otherwise
        ``"inaccurate:<why>"`` (``certificate``, ``infeasible_policy``, ``multichain``, the
        solver's own status mapped by its backend's table, e.g. ``max_iter:MaxIterations``...). As
        for :class:`~wncs_lp.solvers.result.Solution`, :attr:`status_code` is one of the codes of
        :mod:`wncs_lp.status`, :attr:`status_reason` says why and :attr:`message` says it in words.
    gain : float
        The exact average cost of the returned policy (= ``gain_upper`` when it is feasible).
    certificate : Certificate
        ``gain_lower <= g*_C <= gain_upper`` (read as :attr:`gain_lower` / :attr:`gain_upper`, and
        given so when one is made): the Lagrangian bound
        :math:`L(\lambda) = \underline g_\lambda - \lambda^T b` (weak duality, with
        :math:`\underline g_\lambda` the lower end of a certified Bellman bracket for the cost
        :math:`c + \lambda^T D`) and the exact cost of the returned feasible policy.
    solver_gain : float
        The solver's own objective (the LP value); NaN for routes without one.
    policy : (L,) float array
        Pair probabilities :math:`\pi(a \mid s)` (sum 1 over each state's pairs): usable by
        :func:`wncs_lp.evaluate`, :class:`wncs_lp.policies.MixedPolicy`, the chain tools.
    occupation : (L,) float array
        The occupation measure of the returned policy on its own chain (exact evaluation).
    multipliers : (K,) float array
        lambda per constraint (of its binding side; 0 for a slack constraint).
    constraints : tuple of ConstraintReport
        In the order given.
    randomized_states : (r,) int array
        The states where the policy mixes two or more actions.
    iterations : int
    seconds : float
    stats : dict
        Route-specific numbers: solver status, residuals, crossover, Lagrangian search...
    """

    method: str
    status: Status
    gain: float
    certificate: Certificate
    solver_gain: float
    policy: np.ndarray
    occupation: np.ndarray
    multipliers: np.ndarray
    constraints: tuple[ConstraintReport, ...]
    randomized_states: np.ndarray
    iterations: int = 0
    seconds: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def n_randomized(self) -> int:
        return int(self.randomized_states.size)

    def mixes(self, mdp, limit: int | None = 20) -> list[dict[str, Any]]:
        """The randomised states with their mix: ``[{state, label, mix: {action name: prob}}]``.

        Actions are named as on policy maps (:func:`wncs_lp.policy_grids.action_name`) when the MDP
        has decoded states, else by their label.
        """
        named = getattr(mdp, "states", None) is not None and getattr(mdp.states, "configs", None) is not None
        if named:
            from ..policy_grids import action_name, map_names

            names = map_names(mdp)
        out = []
        for s in self.randomized_states[:limit]:
            s = int(s)
            mix = {}
            for l in mdp.pairs_of(s):
                if self.policy[l] > 0:
                    key = (action_name(mdp, int(mdp.a_indices[l]), int(mdp.states.config[s]), names=names)
                           if named else str(mdp.action_label(l)))
                    mix[key] = float(self.policy[l])
            out.append({"state": s, "label": mdp.state_label(s), "mix": mix})
        return out

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars and the per-constraint reports (no arrays)."""
        out = {
            **certificate_summary(self),
            "solver_gain": float(self.solver_gain),
            "randomized_states": self.n_randomized,
            "iterations": int(self.iterations),
            "seconds": float(self.seconds),
            "constraints": [c.to_dict() for c in self.constraints],
        }
        out.update({k: v for k, v in scalars(self.stats).items() if k not in out})
        return out

    def _display_head(self) -> str:
        n = np.asarray(self.policy).size
        return f"{type(self).__name__} of {n:,} pairs by {self.method}, {len(self.constraints)} constraint(s)"

    def _display_rows(self) -> list[tuple[str, str]]:
        rows = certificate_rows(self) + [("solver_gain", f"{self.solver_gain:.12g}")]
        rows += [("constraint", f"{c.label}: {c.value:.6g}"
                  + (f", active, multiplier {c.multiplier:.6g}" if c.active else ", slack")
                  + (f", VIOLATED by {c.violation:.3g}" if c.violation > 0 else "")) for c in self.constraints]
        return rows + [
            ("policy", describe_array(self.policy, "pair probabilities")),
            ("randomized", f"{self.n_randomized:,} state(s) mix two or more actions"),
        ]

    def _frame_records(self, mdp=None):
        from ..tables import mixed_policy_records

        return mixed_policy_records(mdp, self.policy)

    def to_frame(self, mdp=None):
        """The policy as a :class:`pandas.DataFrame` (pandas: the ``notebook`` extra): one row per
        state and action played (``probability``; a state's rows sum to 1), with the state decoded
        and the action named; needs the ``mdp`` it was solved on."""
        from ..display import frame

        cols, recs = self._frame_records(mdp)
        return frame(cols, recs)
