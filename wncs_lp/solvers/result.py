"""What every certified result shares, and the result type every solver returns.

* :class:`Certificate` -- the one certificate value: ``lower <= g <= upper`` (a frozen pair).
* :class:`Certified` -- the base of every result with a certificate and a status
  (:class:`Solution`, :class:`~wncs_lp.constrained.ConstrainedSolution`,
  :class:`~wncs_lp.solvers.matrix_free.MatrixFreeSolution`,
  :class:`~wncs_lp.solvers.matrix_free.MatrixFreeEvaluation`, the trade-off points, ...): ``ok``,
  ``status_code``, ``status_reason``, ``message``, ``gap``, ``summary()``, the printout, the HTML
  form and ``to_frame()`` (:mod:`wncs_lp.display`).
* :func:`takes_bounds` -- a result class holding a ``certificate`` field is still made (and
  ``dataclasses.replace``-d) with ``gain_lower=`` / ``gain_upper=``; both stay readable as properties.
"""
from __future__ import annotations

import functools
import inspect
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..display import Display, describe_array, fmt, text_block
from ..files import scalars
from ..status import (FAILED, INACCURATE, INFEASIBLE, INTERRUPTED, MAX_ITER, OPTIMAL, STATUS_CODES, Code, Status,
                      as_status)
from .certify import width_closed

__all__ = ["Certificate", "Certified", "Solution", "takes_bounds", "certificate_summary", "describe_array",
           "result_repr", "certificate_rows", "stats_row", "NO_CERTIFICATE", "OPTIMAL", "INACCURATE", "MAX_ITER",
           "INTERRUPTED", "INFEASIBLE", "FAILED", "STATUS_CODES"]


@dataclass(frozen=True)
class Certificate:
    """A certified interval ``lower <= g <= upper`` for a gain g (the optimal gain g*, or a
    policy's gain): a Bellman bracket, a Lagrangian bound and an exact cost, or a one-sided bound
    (``upper = inf``, e.g. a relaxation's lower bound).

    NaN ends mean "no certificate" (an infeasible point of a trade-off curve). The ends are not
    required to be ordered: a solver's dual bound can exceed the exact cost by its tolerance, and
    the certificate then says so (``width < 0``) rather than hiding it.

    Attributes
    ----------
    lower, upper : float
    """

    lower: float
    upper: float = math.inf

    def __post_init__(self) -> None:
        for name in ("lower", "upper"):
            v = getattr(self, name)
            try:
                if isinstance(v, (str, bytes, bool, np.bool_)):
                    raise TypeError
                object.__setattr__(self, name, float(v))
            except (TypeError, ValueError):
                raise TypeError(f"Certificate.{name} must be a real number, got {v!r}") from None

    @property
    def width(self) -> float:
        """``upper - lower`` (inf for a one-sided certificate)."""
        return self.upper - self.lower

    @property
    def midpoint(self) -> float:
        """``(lower + upper) / 2`` (inf for a one-sided certificate)."""
        return 0.5 * (self.lower + self.upper)

    def gap_at(self, gain: float) -> float:
        """The relative width at ``gain``: ``width / max(|gain|, 1e-300)``."""
        return self.width / max(abs(float(gain)), 1e-300)

    @property
    def gap(self) -> float:
        """The relative width at the midpoint (:meth:`gap_at`)."""
        return self.gap_at(self.midpoint)

    def contains(self, g: float, rtol: float = 0.0) -> bool:
        """``lower <= g <= upper``, each end widened by ``rtol * |g|``."""
        slack = rtol * abs(float(g))
        return bool(self.lower - slack <= g <= self.upper + slack)

    def closed(self, rtol: float, atol: float = 0.0, *, gain: float | None = None, cost_scale: float = 0.0) -> bool:
        """Whether the width meets the tolerance, by the one rule
        (:func:`~wncs_lp.solvers.certify.width_closed`): ``width <= rtol |gain|`` (gain: the
        midpoint unless given), or ``<= atol``, or below the round-off floor ``1e-13 cost_scale``."""
        return bool(width_closed(self.lower, self.upper, self.midpoint if gain is None else gain, rtol, atol=atol,
                                 cost_scale=cost_scale))

    def __str__(self) -> str:
        up = "" if self.upper == math.inf else f" <= {fmt(self.upper, 12)}"
        return f"{fmt(self.lower, 12)} <= g{up}"


#: The certificate of a result that has none (an infeasible or failed point).
NO_CERTIFICATE = Certificate(math.nan, math.nan)


def takes_bounds(cls):
    """Class decorator (above ``@dataclass``) of a result with a ``certificate`` field: it is also
    made with ``gain_lower=`` and ``gain_upper=`` (keywords), and ``dataclasses.replace(result,
    gain_lower=...)`` moves one end of its certificate. The generated ``__init__`` is kept."""
    init = cls.__init__
    sig = inspect.signature(init)
    extra = [inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=None, annotation="float | None")
             for n in ("gain_lower", "gain_upper")]
    params = list(sig.parameters.values())
    pos = [p for p in params if p.kind is not inspect.Parameter.KEYWORD_ONLY]

    @functools.wraps(init)
    def __init__(self, *args, gain_lower=None, gain_upper=None, **kwargs):
        if gain_lower is not None or gain_upper is not None:
            if "certificate" in kwargs and kwargs["certificate"] is not None:
                old = kwargs["certificate"]
            elif gain_lower is None or gain_upper is None:
                raise TypeError(f"{cls.__name__}: give both gain_lower and gain_upper, or a certificate")
            else:
                old = None
            kwargs["certificate"] = Certificate(old.lower if gain_lower is None else gain_lower,
                                                old.upper if gain_upper is None else gain_upper)
        init(self, *args, **kwargs)

    __init__.__signature__ = sig.replace(parameters=pos + extra + [p for p in params if p not in pos])
    cls.__init__ = __init__
    return cls


def certificate_summary(result: Any) -> dict[str, Any]:
    """The keys every result's JSON starts with: method, status (code, message), gain and its
    certificate ``[gain_lower, gain_upper]`` with its relative width."""
    return {
        "method": result.method,
        "status": str(result.status),
        "status_code": str(result.status_code),
        "message": result.message,
        "gain": float(result.gain),
        "gain_lower": float(result.gain_lower),
        "gain_upper": float(result.gain_upper),
        "certificate_gap": float(result.gap),
    }


class Certified(Display):
    """What every result with a certificate and a status offers.

    A subclass is a dataclass with the fields ``status`` (a :class:`~wncs_lp.status.Status`, or
    a status text turned into one when the result is made), ``gain`` and ``certificate`` (a
    :class:`Certificate`), and usually ``method``, ``iterations``, ``seconds``, ``stats``.
    """

    status: Status
    gain: float
    certificate: Certificate

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", as_status(self.status))
        if not isinstance(self.certificate, Certificate):
            raise TypeError(f"{type(self).__name__}: certificate must be a Certificate (or give gain_lower= and "
                            f"gain_upper=), got {self.certificate!r}")

    # ------------------------------------------------------------------ the certificate
    @property
    def gain_lower(self) -> float:
        """The certificate's lower end: ``gain_lower <= g``."""
        return self.certificate.lower

    @property
    def gain_upper(self) -> float:
        """The certificate's upper end: ``g <= gain_upper``."""
        return self.certificate.upper

    @property
    def gap(self) -> float:
        """Relative width of the certificate, (hi - lo) / max(|gain|, 1e-300)."""
        return self.certificate.gap_at(self.gain)

    # ------------------------------------------------------------------ the status
    @property
    def ok(self) -> bool:
        """``status_code is OPTIMAL``."""
        return self.status.code is OPTIMAL

    @property
    def success(self) -> bool:
        """scipy's name for :attr:`ok` (``OptimizeResult.success``): the certificate closed."""
        return self.ok

    @property
    def status_code(self) -> Code:
        """The status's code, one of :data:`wncs_lp.status.STATUS_CODES`."""
        return self.status.code

    @property
    def status_reason(self) -> str | None:
        """Why the status is not optimal, in one word (``"precision"``, ``"MaxIterations"``), or None."""
        return self.status.reason

    @property
    def message(self) -> str:
        """What the status means, in words (:func:`wncs_lp.status.status_message`)."""
        return self.status.message

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

    def _display_rows(self) -> list[tuple[str, str]]:
        return certificate_rows(self)


def result_repr(head: str, rows: list[tuple[str, str]]) -> str:
    """Multi-line, scipy ``OptimizeResult`` style: a head line, then names right-aligned."""
    return text_block(head, rows)


def certificate_rows(res: Certified) -> list[tuple[str, str]]:
    """The printout rows every certified result starts with (status ... seconds)."""
    st = res.status
    rows = [
        ("status", f"{st}" + ("" if st == st.code else f" (code {st.code})")),
        ("message", res.message),
        ("gain", f"{res.gain:.12g}"),
        ("gain_lower", f"{res.gain_lower:.12g}"),
        ("gain_upper", f"{res.gain_upper:.12g}"),
        ("gap", f"{res.gap:.3g} (relative certificate width)"),
    ]
    if hasattr(res, "iterations"):
        rows.append(("iterations", f"{res.iterations}"))
    if hasattr(res, "seconds"):
        rows.append(("seconds", f"{res.seconds:.3g}"))
    return rows


def stats_row(stats: dict[str, Any]) -> tuple[str, str]:
    return ("stats", f"{len(stats)} entries: " + ", ".join(list(stats)[:8]) + (", ..." if len(stats) > 8 else ""))


@takes_bounds
@dataclass(frozen=True, eq=False, repr=False)
class Solution(Certified):
    """An average-cost solution of an :class:`~wncs_lp.mdp.MDP`, with its certificate.

    Printing one shows its scalars, scipy ``OptimizeResult`` style (``print(sol)``)::

        Solution of 10,419 states by pi
             status: optimal
            message: the certificate closed: ...
               gain: 749.8343263
         gain_lower: 749.8343263
         ...

    in Jupyter it shows as a table; :meth:`to_frame` gives the policy state by state.

    Attributes
    ----------
    method : str
        ``"lp"`` (Clarabel direct), ``"lp-highs"``, ``"lp-cvxpy"``, ``"rvi"``, ``"vi"``, ``"pi"`` or ``"auto"``
        (then ``stats["auto_choice"]`` says whose answer it is).
    status : Status
        A code of :mod:`wncs_lp.status` and a reason: ``"optimal"`` when the certificate closes to
        the requested tolerance, otherwise ``"max_iter"``, ``"inaccurate"`` or
        ``"<code>:<reason>"`` (the reason: ``certificate``, ``precision``, ``polish_max_iter``,
        ``cross_check`` or the LP backend's own status word, e.g. ``max_iter:MaxIterations``).
        Branch on :attr:`status_code` / :attr:`status_reason` and show :attr:`message` to a
        person; ``str(status)`` is the text files and the command line show.
    gain : float
        The best estimate of the optimal gain g* (for LP: the exact gain of the returned policy
        when polishing verified it, else the LP objective).
    certificate : Certificate
        lo <= g* <= hi from one Bellman step on ``bias``: lo = min_s (T h - h)(s),
        hi = max_s (T h - h)(s). Also read as :attr:`gain_lower` / :attr:`gain_upper` (and
        given so when a Solution is made: ``Solution(..., gain_lower=lo, gain_upper=hi, ...)``).
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
        Method-specific numbers: residuals, the solver's own status (``solver_status``), raw LP
        objective, span, ...
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
    status: Status
    gain: float
    certificate: Certificate
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

    # ------------------------------------------------------------------ display
    def _display_head(self) -> str:
        n = np.asarray(self.policy).size
        used = self.method
        if "auto_choice" in self.stats:
            used = f"{self.method} -> {self.stats['auto_choice']}"
        return f"{type(self).__name__} of {n:,} states by {used}"

    def _display_rows(self) -> list[tuple[str, str]]:
        return certificate_rows(self) + [
            ("bias", describe_array(self.bias, "floats") + ", h[0] = 0"),
            ("policy", describe_array(self.policy, "pair indices") + ", one per state"),
            ("sigma", "None (use actions(mdp))" if self.pair_actions is None
             else describe_array(self.sigma, "action indices") + ", one per state"),
            ("occupation", describe_array(self.occupation, "pair frequencies")),
            stats_row(self.stats),
        ]

    def _frame_records(self, mdp=None):
        from ..tables import policy_columns

        return policy_columns(mdp, np.asarray(self.policy, dtype=np.int64), bias=self.bias, sigma=self.sigma)

    def to_frame(self, mdp=None):
        """The policy state by state, as a :class:`pandas.DataFrame` (pandas: the ``notebook`` extra).

        Columns: ``state``, then with the ``mdp`` the solution belongs to (its decoded states)
        ``tau_1`` ... ``tau_N``, ``configuration``, ``action`` (the action's name, as on policy
        maps); without it ``pair``; then ``sigma`` (the action index) and ``bias``.
        """
        from ..display import frame

        cols, recs = self._frame_records(mdp)
        return frame(cols, recs)
