r"""Certified optimality gaps: policies evaluated against a lower bound.

For a policy :math:`\pi` with long-run average cost :math:`g_\pi` and a certified bound
:math:`LB \le g^*`,

.. math:: \frac{g_\pi - g^*}{g^*} \le \frac{\bar g_\pi - LB}{LB},

where :math:`\bar g_\pi \ge g_\pi` is

* the upper end of the certified bracket of the matrix-free policy evaluation
  (:func:`wncs_lp.solvers.matrix_free.matrix_free_evaluate`) where the AoI box is small enough
  (``exact_max_states``): a certified statement;
* beyond, the one-sided upper confidence limit of a seeded Monte Carlo estimate
  (:func:`wncs_lp.simulate.simulate`, independent replications, Student t with R - 1 degrees
  of freedom: :func:`wncs_lp.intervals.replication_interval`): a statement at that confidence
  level, not a certificate.

The Monte Carlo estimate uses the bound's own tables h as a control variate by default: beside
its cost, each replication averages C = E[h(s_{t+1}) | s_t, a_t] - h(s_t), a zero-mean martingale
plus a boundary term (:mod:`wncs_lp.simulate`), and the estimate is the average of the Bellman
residual c(s_t) + E[h(s_{t+1}) | s_t, a_t] - h(s_t), the cost's average plus C's. It estimates
the same g_pi under any policy; the closer h is to the policy's relative values, the smaller its
variance (at 8 processes, cap 20, the variance of relaxation
3's policy falls about 200-fold with relaxation 3's tables: ``benchmarks/README.md``). Every
policy is simulated with the same seed, so they see the same channel outcomes (common random
numbers).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
from scipy import stats as sps

from ..errors import PolicyError, SizeLimitError, SolverError
from ..models.system import System
from ..policies import Policy
from ..policies.factory import BOUND_POLICY_NAMES, make_basic_policy
from ..progress import as_progress
from ..simulate import simulate
from .index import IndexPolicy, whittle_indices
from .lookahead import LookaheadPolicy, TableRolloutPolicy, auto_candidates
from .named import named_policy
from .policy import bound_policy
from .projected import PROJECTED, ProjectedValue
from .result import BoundResult
from .tuned import TUNE_SEED_OFFSET, TUNED_NAMES, tune_tables, tuned_policy

__all__ = ["PolicyGap", "GapReport", "policy_gaps", "policy_by_name", "policy_source", "DEFAULT_POLICIES",
           "EXACT_MAX_STATES", "PILOT", "PILOT_MARGIN"]

#: The policies :func:`policy_gaps` evaluates by default.
DEFAULT_POLICIES = ("bound", "lookahead", "suboptimal", "static", "greedy")
#: Largest AoI box (states of the matrix-free layout) evaluated exactly by default.
EXACT_MAX_STATES = 50_000_000
#: :func:`policy_source`'s pilot: each candidate's greedy policy simulated ``reps`` x ``slots`` slots
#: after ``burn_in``, on seed ``seed + seed_offset`` (not the report's own seed, so that the choice
#: does not select on the noise the report then measures).
PILOT = {"slots": 2_000, "reps": 8, "burn_in": 200, "seed_offset": 1}
#: Another result's tables replace the bound's own for the policies only when their greedy pilot's
#: mean is below the bound's own by more than this fraction of it (a guard against tables whose
#: greedy policy fails, not a fine ranking).
PILOT_MARGIN = 0.05


@dataclass(frozen=True)
class PolicyGap:
    """One policy against the bound.

    Attributes
    ----------
    policy : str
    how : {"exact", "monte-carlo"}
    gain : float
        The policy's average cost (exact: the bracket's midpoint; Monte Carlo: the mean).
    gain_upper : float
        What the gap uses: the certified upper end (exact) or the upper confidence limit.
    gap : float
        (gain_upper - LB) / LB, an upper bound on the policy's relative distance to g*.
    detail : dict
        Exact: status, gain_lower, iterations. Monte Carlo: stderr, reps, slots, burn_in, seed,
        confidence, interval (how the limit was made), control (the control variate's tables, or
        None), control_coef (its coefficient, 1), plain_mean and plain_stderr (the plain time average), variance_reduction, agreement
        (:attr:`wncs_lp.simulate.SimulationResult.agreement`).
    seconds : float
    """

    policy: str
    how: str
    gain: float
    gain_upper: float
    gap: float
    detail: dict = field(default_factory=dict)
    seconds: float = 0.0

    def summary(self) -> dict[str, Any]:
        return {"policy": self.policy, "how": self.how, "gain": self.gain, "gain_upper": self.gain_upper,
                "gap": self.gap, **self.detail, "seconds": self.seconds}


@dataclass(frozen=True)
class GapReport:
    """Policies evaluated against one certified bound (:func:`policy_gaps`)."""

    lower_bound: float
    relaxation: str
    rows: tuple[PolicyGap, ...]
    how: str
    states: int
    seconds: float
    #: (policy name, reason) of each comparator that could not run on this system (it needs the
    #: whole automaton of a lazily explored system, or more memory than there is).
    skipped: tuple = ()
    #: The relaxation whose tables the policies were built on when not the bound's own
    #: (:func:`policy_source`), else "".
    tables_from: str = ""

    def __repr__(self) -> str:
        lines = [f"GapReport({self.relaxation}, LB = {self.lower_bound:.10g}, {self.how}, {self.states:,} states)"]
        lines += [f"  {r.policy:<28} gain {r.gain:.10g}  upper {r.gain_upper:.10g}  gap <= {100 * r.gap:.3f}%"
                  for r in self.rows]
        lines += [f"  {name:<28} not evaluated: {why}" for name, why in self.skipped]
        if self.rows:
            lines.append(f"  best: {self.best.policy}")
        return "\n".join(lines)

    @property
    def best(self) -> PolicyGap:
        """The row of the least upper value ``gain_upper``: the policy with the smallest certified
        (or, by Monte Carlo, confidence-limit) gap; the first of equals."""
        return min(self.rows, key=lambda r: r.gain_upper)

    def row(self, policy: str) -> PolicyGap:
        """The row of a policy by name (a bound's policy also answers to ``"bound"``)."""
        for r in self.rows:
            if r.policy == policy or (policy == "bound" and r.policy.startswith("bound")):
                return r
        raise KeyError(policy)

    def summary(self) -> dict[str, Any]:
        return {"lower_bound": self.lower_bound, "relaxation": self.relaxation, "how": self.how,
                "states": self.states, "policies": [r.summary() for r in self.rows],
                "best": self.best.policy if self.rows else None, "seconds": self.seconds,
                "skipped": [{"policy": name, "reason": why} for name, why in self.skipped],
                "tables_from": self.tables_from or self.relaxation}


def policy_by_name(name: str | Policy, bound: BoundResult, system: System, *,
                   tune_seed: int = TUNE_SEED_OFFSET, tune: dict | None = None) -> Policy:
    """A policy of a gap report by name: ``"bound"`` (the bound's greedy policy) and
    ``"lookahead"`` on this bound's tables, ``"lookahead3"`` (depth 3, the ``middle`` 2 best actions
    at the intermediate state, the same candidates), ``"rollout"``
    (:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`: the bound's greedy policy simulated a few
    slots ahead of each candidate action, the tables as terminal value and control variate), ``"index"`` priced from relaxation 1 (this bound when
    it is relaxation 1's, else computed: seconds), any other name by the policy factory's rooms
    (:func:`~wncs_lp.bounds.named.named_policy`, :func:`~wncs_lp.policies.factory.make_basic_policy`);
    ``"tuned"``, ``"tuned_lookahead"``, ``"tuned_rollout"`` the greedy policy, the lookahead or the
    rollout on this bound's tables reweighted per class of processes by a simulation on ``tune_seed``
    (:func:`~wncs_lp.bounds.tuned.tune_tables`, with the settings ``tune`` if given); a
    :class:`Policy` is returned as it is."""
    if isinstance(name, Policy):
        return name
    if name == "bound":
        return bound_policy(bound, system)
    if name == "lookahead":
        return LookaheadPolicy(bound_policy(bound, system), auto_candidates(system))
    if name == "lookahead3":
        return LookaheadPolicy(bound_policy(bound, system), auto_candidates(system), depth=3, middle=2)
    if name == "rollout":
        return TableRolloutPolicy(bound_policy(bound, system))
    if name == "index":
        return IndexPolicy(system, whittle_indices(system, bound if bound.relaxation == "private-servers" else None))
    if name in TUNED_NAMES:
        return tuned_policy(tune_tables(bound, system, TUNED_NAMES[name], seed=tune_seed, **(tune or {})), system)
    if name in BOUND_POLICY_NAMES:
        return named_policy(name, system)
    return make_basic_policy(name, system)


def policy_source(bound: BoundResult, system: System, *, seed: int = 0) -> tuple[BoundResult, str]:
    """The result whose tables a gap report's policies are built on: ``bound`` itself, or one of its
    ``alternatives`` (the other relaxations ``"auto"`` computed) whose tables' greedy policy is
    clearly better. The bound of the report stays ``bound.lower_bound`` either way (any policy's
    gain is at least g*, whatever tables it was built on).

    The largest certified bound need not have the best tables: at the paper's four process types
    four times, relaxation 2's Lagrangian at relaxation 1's prices gives tables whose greedy
    policy never serves the four copies of type 1 and costs ten times relaxation 3's. Each
    candidate's greedy policy is simulated briefly (:data:`PILOT`, its own tables as the control
    variate); another candidate replaces the bound's own tables only when its pilot mean is below
    theirs by more than :data:`PILOT_MARGIN` of it. Where ``bound`` has no alternatives this
    costs nothing.

    Returns
    -------
    (BoundResult, str)
        The source of the tables, and a sentence saying why ("" when it is ``bound``).
    """
    candidates = [bound, *(r for r in bound.alternatives if np.isfinite(r.lower_bound))]
    if len(candidates) == 1:
        return bound, ""
    means = []
    for c in candidates:
        try:
            pol = bound_policy(c, system)
        except (PolicyError, SizeLimitError):
            means.append(np.inf)
            continue
        res = simulate(pol, slots=PILOT["slots"], reps=PILOT["reps"], seed=seed + PILOT["seed_offset"],
                       burn_in=PILOT["burn_in"], control=_TablesControl(c, system), progress=False)
        means.append(float(res.mean))
    best = int(np.argmin(means))
    if not means[best] < (1.0 - PILOT_MARGIN) * means[0]:
        return bound, ""
    pick = candidates[best]
    return pick, (f"the policies on the {pick.relaxation} tables (bound {pick.lower_bound:.10g}): their greedy "
                  f"policy's pilot mean {means[best]:.8g} against {means[0]:.8g} on the {bound.relaxation} tables "
                  f"({PILOT['reps']} x {PILOT['slots']} slots, seed {seed + PILOT['seed_offset']})")


def _exact_route(system: System, exact: bool | None, exact_max_states: int) -> tuple[bool, int]:
    """(evaluate exactly?, states of the matrix-free layout)."""
    from ..solvers.matrix_free.layout import layout_states

    if system.is_lazy:  # explored lazily: no layout; one configuration's AoI box says the scale
        if exact:
            layout_states(system)  # refuses with the reason
        return False, math.prod(int(c) for c in system.caps)
    n = layout_states(system, "hull")  # a Python integer: 40^16 states do not wrap around
    return (n <= exact_max_states if exact is None else bool(exact)), n


def _exact(policy: Policy, system: System, lb: float, progress: bool) -> PolicyGap:
    from ..solvers.matrix_free import matrix_free_evaluate

    t0 = time.perf_counter()
    if hasattr(policy, "separable_evaluation"):  # round robin: exact on its per-process chains, any size
        g = float(policy.separable_evaluation().gain)
        return PolicyGap(policy.name, "exact", g, g, (g - lb) / lb, {"status": "optimal", "gain_lower": g,
                                                                     "iterations": 0}, time.perf_counter() - t0)
    ev = matrix_free_evaluate(system, policy, progress=progress, name=policy.name)
    return PolicyGap(policy.name, "exact", float(ev.gain), float(ev.gain_upper), (float(ev.gain_upper) - lb) / lb,
                     {"status": ev.status, "gain_lower": float(ev.gain_lower), "iterations": int(ev.iterations)},
                     time.perf_counter() - t0)


class _TablesControl:
    """A bound's tables as the simulator's control variate, named after the relaxation."""

    def __init__(self, bound: BoundResult, system: System):
        # on a lazily explored system the simulation meets configurations the bound's columns do not cover
        lazy = system.is_lazy and bound.relaxation in PROJECTED
        self.value = ProjectedValue(bound, system) if lazy else bound.tables.value
        self.name = f"the {bound.relaxation} tables"


def _monte_carlo(policy: Policy, lb: float, slots: int, reps: int, seed: int, burn_in: int,
                 confidence: float, control: Any) -> PolicyGap:
    if reps < 2:
        raise SolverError("a Monte Carlo gap needs at least 2 replications (for its confidence limit)")
    t0 = time.perf_counter()
    res = simulate(policy, slots=slots, reps=reps, seed=seed, burn_in=burn_in, control=control, progress=False)
    ci = res.interval(confidence, side="upper", method="replications")
    how = "regression on the control over" if res.control_fitted else "over"
    return PolicyGap(policy.name, "monte-carlo", float(res.mean), ci.upper, (ci.upper - lb) / lb,
                     {"stderr": float(res.stderr), "reps": reps, "slots": slots, "burn_in": burn_in, "seed": seed,
                      "confidence": confidence, "interval": f"one-sided t, {ci.df} df ({how} independent replications)",
                      "control": res.control, "control_coef": float(res.control_coef), "plain_mean": float(res.plain_mean),
                      "plain_stderr": float(res.plain_stderr), "variance_reduction": float(res.variance_reduction),
                      "agreement": float(res.agreement)},
                     time.perf_counter() - t0)


def policy_gaps(
    bound: BoundResult,
    system: System,
    policies: Sequence[str | Policy] = DEFAULT_POLICIES,
    *,
    exact: bool | None = None,
    exact_max_states: int = EXACT_MAX_STATES,
    slots: int = 40_000,
    reps: int = 20,
    seed: int = 0,
    burn_in: int = 1_000,
    confidence: float = 0.95,
    control: bool = True,
    progress: Any = False,
    tables: BoundResult | None = None,
    tune: dict | None = None,
) -> GapReport:
    """Evaluate policies and bound their optimality gap by a certified lower bound.

    Parameters
    ----------
    bound : BoundResult
    system : System
        The system the bound was computed on.
    policies : sequence of str or Policy
        ``"bound"`` (the bound's greedy policy), ``"lookahead"`` (the two-step lookahead on the
        bound's tables), ``"lookahead3"`` (one step deeper), ``"rollout"`` (the bound's greedy policy
        simulated a few slots ahead from each candidate action: :class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy`),
        ``"index"`` (the index policy of relaxation 1's chains), ``"tuned"``, ``"tuned_lookahead"``,
        ``"tuned_rollout"`` (the greedy policy, the lookahead, the rollout on the tables reweighted per
        class of processes, :mod:`~wncs_lp.bounds.tuned`: tuned by simulation on ``seed`` +
        :data:`~wncs_lp.bounds.tuned.TUNE_SEED_OFFSET`, then evaluated on ``seed`` like every other
        policy, so the upper limit is on fresh randomness; the row's ``detail["tuning"]`` says how), any name of
        :func:`wncs_lp.workflow.make_policy` that needs no enumerated MDP (``suboptimal``,
        ``static``, ``greedy``, ``random``), or policies.
    exact : bool, optional
        Evaluate by the certified matrix-free evaluation (True) or by Monte Carlo (False);
        default: exact when the AoI box has at most ``exact_max_states`` states.
    slots, reps, seed, burn_in : int
        The Monte Carlo run of each policy (same seed for every policy: common random numbers).
    confidence : float
        Level of the one-sided upper confidence limit of a Monte Carlo gain.
    control : bool
        Monte Carlo with the bound's tables as the control variate (default; module docstring);
        False: the plain time average.
    progress : bool or Progress
    tables : BoundResult, optional
        Build the bound's policies (``"bound"``, ``"lookahead"``, ``"rollout"``, ...) and the
        control variate on this result's tables instead of ``bound``'s (:func:`policy_source`);
        the gaps are still against ``bound.lower_bound``.
    tune : dict, optional
        Settings of the tuned policies' tuning (keywords of :func:`~wncs_lp.bounds.tuned.tune_tables`
        but its seed: ``slots``, ``reps``, ``burn_in``, ``steps``, ``max_evaluations``, ``accept_se``, ``proxy``; default
        :data:`~wncs_lp.bounds.tuned.TUNE`).

    Returns
    -------
    GapReport
    """
    if not 0.5 <= confidence < 1:
        raise SolverError(f"confidence must be in [0.5, 1), got {confidence}")
    if not bound.lower_bound > 0:
        raise SolverError(f"a relative gap needs a positive lower bound, found {bound.lower_bound}")
    t0 = time.perf_counter()
    prog = as_progress(progress)
    use_exact, n = _exact_route(system, exact, exact_max_states)
    rows, skipped = [], []
    pol_tuning = {}  # a tuned policy's row says how it was tuned (its seed is not the evaluation's)
    source = bound if tables is None else tables
    for name in policies:
        try:
            pol = policy_by_name(name, source, system, tune_seed=seed + TUNE_SEED_OFFSET, tune=tune)
        except (PolicyError, SizeLimitError) as exc:  # a comparator that does not fit this system: say so, go on
            if not isinstance(name, str) or name == "bound":
                raise
            skipped.append((name, str(exc)))
            continue
        if getattr(pol, "tuning", None):
            pol_tuning[pol.name] = pol.tuning
        prog.phase(f"evaluating the {pol.name} policy " + ("exactly (matrix-free)" if use_exact else
                                                           f"by Monte Carlo ({reps} x {slots} slots)"))
        if use_exact:
            try:
                rows.append(_exact(pol, system, bound.lower_bound, bool(prog)))
                continue
            except SolverError:  # no numba here: the default route falls back to Monte Carlo
                if exact is not None:
                    raise
                use_exact = False
        rows.append(_monte_carlo(pol, bound.lower_bound, slots, reps, seed, burn_in, confidence,
                                 _TablesControl(source, system) if control else None))
    rows = [replace(r, detail={**r.detail, "tuning": pol_tuning[r.policy]}) if r.policy in pol_tuning else r
            for r in rows]
    how = sorted({r.how for r in rows})
    return GapReport(float(bound.lower_bound), bound.relaxation, tuple(rows), "+".join(how), n,
                     time.perf_counter() - t0, tuple(skipped),
                     tables_from="" if source is bound else source.relaxation)
