r"""Numerical verifiers of the paper's structural theorems (claims C7, C8, C9, C10).

Each verifier reads a solved model -- an :class:`~wncs_lp.mdp.MDP` whose ``states`` is a
:class:`~wncs_lp.models.statespace.StateSpace` and a :class:`~wncs_lp.solvers.result.Solution`
(bias ``V``, chosen pair per state ``pi``) -- and returns a frozen :class:`CheckReport` with the counts
that decide the claim, never a bare verdict.

Notation: a state is ``s = (tau, C)`` with ``tau`` in the box ``1..tau_hat`` and ``C`` a
configuration (server pipelines, jobs, arrivals); ``e_k`` is the k-th unit vector;
``Q(s, a) = c(s) + sum_{s'} P(s' | s, a) V(s')`` are the pair values of the solution's bias
(:func:`~wncs_lp.solvers.certify.q_values`).

Tolerance
---------
A difference is significant only beyond ``tol = atol + rtol * span(V)``, with
``span(V) = max_s V(s) - min_s V(s)`` the value scale (invariant under the normalisation of the
bias). Both parts and the resolved ``tol`` are recorded in every report. The defaults
(``atol = rtol = 1e-9``) are fixed a priori at the round-off level of an exactly evaluated bias;
the worst violation is always reported with its size, so a reader can judge it against ``tol``
and against the solution's certificate.

Classification of a violation
-----------------------------
*Recurrent* states are those of the closed communicating classes of the chain ``P_pi`` of the
solution's policy (an exact graph criterion: the states with positive stationary probability);
with ``stationary_tol > 0`` the rule is instead ``stationary(s) > stationary_tol``. A violation
is *recurrent* when **every** state involved is recurrent, i.e. when it is observable in the
long-run behaviour of the optimal policy (the looser "some state involved is recurrent" count is
given in ``details``):

* monotonicity -- both states of the pair;
* threshold -- both s and s' (``details["target_recurrent"]``: s' alone); a line gap -- all three
  states;
* switching curve (C9) -- the three states of a gap; the four states of an order reversal;
* consistency -- the start state (then every state of its tree is recurrent too, so the
  violation happens with positive long-run frequency).

A violation *touches the cap* when one of the states involved has some ``tau_k = tau_hat_k``
(consistency: when every violating path from the start passes through such a state). The cap
truncates an infinite chain, so such findings may be truncation artefacts.

Verdict
-------
Each report's ``verdict`` follows the one rule of :mod:`.verdict`, shared with the reproduction:
HOLDS (no violation), FAILS (a violation whose states are all recurrent and none at the cap),
DEPENDS (violations only in transient states or touching the cap).

Checks
------
:func:`check_monotonicity` (Theorem 1), :func:`check_threshold` (Theorem 2 for the Section II
model; for the preemption model the switching-curve form of Figs. 11-12: each action's region an
interval along every axis-parallel line, and the switches between two actions in one order on
all parallel lines -- a monotone curve; gaps along diagonals are described, not counted),
:func:`check_consistency` (Theorem 3, preemption model, on jobs started by preempting as the
theorem says; every start split by kind in its details), :func:`verify_all`. Which checks apply,
and how the threshold check reads a model, the model class says
(:attr:`~wncs_lp.models.base.Model.checks`, :attr:`~wncs_lp.models.base.Model.threshold_form`).

Modules: :mod:`.report` (report types), :mod:`.verdict` (the verdict rule), :mod:`.context` (the
shared :class:`PolicyContext`),
:mod:`.lines` (line geometry of the AoI box), one module per check (:mod:`.monotonicity`,
:mod:`.threshold`, :mod:`.consistency`).
"""
from __future__ import annotations

from ..errors import ModelError
from ..mdp import MDP
from ..models import model_type
from ..solvers.result import Solution
from .consistency import check_consistency
from .context import DEFAULT_EXAMPLES, PolicyContext, idle_configs, policy_context
from .monotonicity import check_monotonicity
from .report import CheckReport, Tolerance, Violation
from .threshold import check_threshold

__all__ = [
    "Tolerance",
    "Violation",
    "CheckReport",
    "PolicyContext",
    "policy_context",
    "idle_configs",
    "check_monotonicity",
    "check_threshold",
    "check_consistency",
    "verify_all",
]

#: The checks by name (the names of :attr:`wncs_lp.models.base.Model.checks`).
CHECKS = {
    "monotonicity": check_monotonicity,
    "threshold": check_threshold,
    "consistency": check_consistency,
}


def verify_all(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
) -> list[CheckReport]:
    """Run every check that applies to the model, in the order of its
    :attr:`~wncs_lp.models.base.Model.checks`.

    Section II (``wncs``): monotonicity, threshold (Theorem 2). Preemption: monotonicity,
    threshold (C9 switching-curve form), consistency (Theorem 3). The shared data
    (Q-values, recurrence) is computed once.

    Returns
    -------
    list[CheckReport]
    """
    ctx = policy_context(mdp, solution, tolerance, stationary_tol=stationary_tol)
    names = model_type(mdp).checks
    unknown = [name for name in names if name not in CHECKS]
    if unknown:
        raise ModelError(f"{mdp.name}: unknown structural check(s) {', '.join(unknown)}; known: {', '.join(CHECKS)}")
    return [CHECKS[name](mdp, solution, examples=examples, ctx=ctx) for name in names]
