"""The result type every solver returns."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..files import scalars
from ..status import (FAILED, INACCURATE, INFEASIBLE, INTERRUPTED, MAX_ITER, OPTIMAL, STATUS_CODES, status_code,
                      status_message)

__all__ = ["Solution", "Certified", "certificate_summary", "describe_array", "result_repr", "certificate_rows",
           "stats_row", "OPTIMAL", "INACCURATE", "MAX_ITER", "INTERRUPTED", "INFEASIBLE", "FAILED", "STATUS_CODES"]


def certificate_summary(result: Any) -> dict[str, Any]:
    """The keys every result's JSON starts with: method, status (code, message), gain and its
    certificate ``[gain_lower, gain_upper]`` with its relative width (a :class:`Solution` or a
    :class:`~wncs_lp.constrained.ConstrainedSolution`)."""
    return {
        "method": result.method,
        "status": result.status,
        "status_code": result.status_code,
        "message": result.message,
        "gain": float(result.gain),
        "gain_lower": float(result.gain_lower),
        "gain_upper": float(result.gain_upper),
        "certificate_gap": float(result.gap),
    }


class Certified:
    """What every result with a Bellman certificate offers: the certificate's relative width,
    the status as a code and in words, and the JSON scalars (:meth:`summary`). A result class
    mixes it in and has the fields ``method``, ``status``, ``gain``, ``gain_lower``,
    ``gain_upper``, ``iterations``, ``seconds`` and ``stats``."""

    method: str
    status: str
    gain: float
    gain_lower: float
    gain_upper: float
    iterations: int
    seconds: float
    stats: dict[str, Any]

    @property
    def gap(self) -> float:
        """Relative width of the certificate, (hi - lo) / max(|gain|, 1e-300)."""
        return (self.gain_upper - self.gain_lower) / max(abs(self.gain), 1e-300)

    @property
    def ok(self) -> bool:
        """``status_code == OPTIMAL``."""
        return self.status == OPTIMAL

    @property
    def status_code(self) -> str:
        """The status as one of :data:`wncs_lp.status.STATUS_CODES` (``"inaccurate:certificate"`` ->
        ``INACCURATE``)."""
        return status_code(self.status)

    @property
    def message(self) -> str:
        """What the status means, in words (:func:`wncs_lp.status.status_message`)."""
        return status_message(self.status)

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars (no arrays): :func:`certificate_summary`, ``iterations``, ``seconds``
        and the scalar entries of ``stats``."""
        out = {
            **certificate_summary(self),
            "iterations": int(self.iterations),
            "seconds": float(self.seconds),
        }
        out.update(scalars(self.stats))
        return out


def describe_array(a: Any, what: str) -> str:
    """``"array of 1,234 floats (float64)"``: an array in a result's printout, by size."""
    if a is None:
        return "None"
    a = np.asarray(a)
    return f"array of {a.size:,} {what} ({a.dtype})"


def result_repr(head: str, rows: list[tuple[str, str]]) -> str:
    """Multi-line, scipy ``OptimizeResult`` style: a head line, then names right-aligned."""
    width = max(len(k) for k, _ in rows)
    return "\n".join([head] + [f"{k:>{width + 2}}: {v}" for k, v in rows])


def certificate_rows(res: Certified) -> list[tuple[str, str]]:
    """The printout rows every certified result starts with (status ... seconds)."""
    return [
        ("status", f"{res.status}" + ("" if res.status == res.status_code else f" (code {res.status_code})")),
        ("message", res.message),
        ("gain", f"{res.gain:.12g}"),
        ("gain_lower", f"{res.gain_lower:.12g}"),
        ("gain_upper", f"{res.gain_upper:.12g}"),
        ("gap", f"{res.gap:.3g} (relative certificate width)"),
        ("iterations", f"{res.iterations}"),
        ("seconds", f"{res.seconds:.3g}"),
    ]


def stats_row(stats: dict[str, Any]) -> tuple[str, str]:
    return ("stats", f"{len(stats)} entries: " + ", ".join(list(stats)[:8]) + (", ..." if len(stats) > 8 else ""))


@dataclass(frozen=True, eq=False)
class Solution(Certified):
    """An average-cost solution of an :class:`~wncs_lp.mdp.MDP`, with its certificate.

    Printing one shows its scalars, scipy ``OptimizeResult`` style (``print(sol)``)::

        Solution of 10,419 states by pi
             status: optimal (the certificate closed: ...)
               gain: 749.8343263
         gain_lower: 749.8343263
         ...

    Attributes
    ----------
    method : str
        ``"lp"`` (Clarabel direct), ``"lp-highs"``, ``"lp-cvxpy"``, ``"rvi"``, ``"vi"``, ``"pi"`` or ``"auto"``
        (then ``stats["auto_choice"]`` says whose answer it is).
    status : str
        ``"optimal"`` when the certificate closes to the requested tolerance, otherwise
        ``"max_iter"``, ``"inaccurate"`` or ``"inaccurate:<reason>"`` (the reason: ``certificate``,
        ``polish_max_iter``, ``cross_check`` or the LP solver's own status). Branch on
        :attr:`status_code` (one of the constants of :mod:`wncs_lp.status`: ``OPTIMAL``,
        ``INACCURATE``, ``MAX_ITER``, ``INTERRUPTED``, ``INFEASIBLE``, ``FAILED``) and show
        :attr:`message` to a person; the string itself stays as it was for older code.
    gain : float
        The best estimate of the optimal gain g* (for LP: the exact gain of the returned policy
        when polishing verified it, else the LP objective).
    gain_lower, gain_upper : float
        The certificate lo <= g* <= hi from one Bellman step on ``bias``:
        lo = min_s (T h - h)(s), hi = max_s (T h - h)(s).
    bias : (n,) array
        A relative value function h (normalised so that h[0] = 0).
    policy : (n,) int array
        The chosen **pair** index of each state (the MDP's state-action-pair layout:
        ``mdp.s_indices[policy[s]] == s``). For the action per state, see :attr:`sigma`.
    occupation : (L,) array or None
        The stationary state-action frequencies x(s, a) (sum 1) when the method gives them.
    iterations : int
    seconds : float
        Wall time of the whole solve (build of the solver's matrices included).
    stats : dict
        Method-specific numbers: residuals, solver status, raw LP objective, span, ...
    pair_actions : (L,) int array or None
        The MDP's ``a_indices`` (the action of every pair), which the solvers attach so that
        :attr:`sigma` needs no MDP; None for a Solution made by hand.

    Conventions for readers of other toolkits: :attr:`sigma` is QuantEcon's ``DiscreteDP``
    ``sigma`` (an action index per state, here a row of ``mdp.action_table``); :meth:`chain`
    is the Markov chain the policy induces (QuantEcon's ``mc``), a
    :class:`~wncs_lp.chain.PolicyChain` with its transition matrix ``P``, recurrent classes and
    stationary law.
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
    pair_actions: np.ndarray | None = field(default=None, repr=False)

    @property
    def sigma(self) -> np.ndarray | None:
        """The action index chosen in each state, (n,) int: QuantEcon's ``sigma``.

        ``mdp.action_table[sol.sigma[s]]`` is the decoded action of state s (for the wncs model,
        what each server is sent). The same as :meth:`actions`, without the MDP; None when the
        solution carries no :attr:`pair_actions` (made by hand): use ``actions(mdp)`` then.
        """
        if self.pair_actions is None:
            return None
        return np.asarray(self.pair_actions)[np.asarray(self.policy, dtype=np.int64)]

    def actions(self, mdp) -> np.ndarray:
        """The action index (into ``mdp.action_table``) chosen in each state (= :attr:`sigma`)."""
        return mdp.a_indices[self.policy]

    def chain(self, mdp):
        """The Markov chain the policy induces on ``mdp`` (a :class:`wncs_lp.chain.PolicyChain`:
        ``P``, ``cost``, ``recurrent_classes``, ``is_unichain``, ``stationary``)."""
        from ..chain import PolicyChain

        return PolicyChain(mdp, np.asarray(self.policy, dtype=np.int64))

    def __repr__(self) -> str:
        return _repr(self)


def _repr(sol: Solution) -> str:
    """Multi-line, scipy ``OptimizeResult`` style: names right-aligned, scalars, arrays by size."""
    n = np.asarray(sol.policy).size
    used = sol.method
    if "auto_choice" in sol.stats:
        used = f"{sol.method} -> {sol.stats['auto_choice']}"
    rows = certificate_rows(sol) + [
        ("bias", describe_array(sol.bias, "floats") + ", h[0] = 0"),
        ("policy", describe_array(sol.policy, "pair indices") + ", one per state"),
        ("sigma", "None (use actions(mdp))" if sol.pair_actions is None
         else describe_array(sol.sigma, "action indices") + ", one per state"),
        ("occupation", describe_array(sol.occupation, "pair frequencies")),
        stats_row(sol.stats),
    ]
    return result_repr(f"{type(sol).__name__} of {n:,} states by {used}", rows)
