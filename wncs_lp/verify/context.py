"""The data every structural check shares, computed once per solved model (:class:`PolicyContext`)."""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Iterable, Sequence

import numpy as np

from ..chain import recurrent_classes, stationary_law
from ..errors import ModelError, PolicyError
from ..mdp import MDP
from ..models import model_type
from ..solvers.certify import q_values
from ..solvers.dp import evaluate_policy
from ..solvers.result import Solution
from .report import CheckReport, Tolerance, Violation, split_counts
from .verdict import NEGLIGIBLE, cap_distance

__all__ = [
    "DEFAULT_EXAMPLES",
    "STATIONARY_SOLVE_LIMIT",
    "PolicyContext",
    "policy_context",
    "use_context",
    "require_space",
    "idle_configs",
    "make_report",
    "violation_weight",
    "witness_flags",
]

#: Default number of example violations kept in a report.
DEFAULT_EXAMPLES = 10
#: Largest model whose stationary distribution is computed by
#: :func:`~wncs_lp.solvers.dp.evaluate_policy` for the probabilities printed with examples (above
#: it: by :func:`~wncs_lp.chain.stationary_law`, unichain policies only); recurrence never needs it
#: (graph criterion).
STATIONARY_SOLVE_LIMIT = 300_000


@dataclass(frozen=True, eq=False)
class PolicyContext:
    r"""What every check needs from a solved model, computed once.

    Attributes
    ----------
    mdp : MDP
    solution : Solution
    q : (L,) array
        Pair values ``Q = c + P V`` of the bias.
    act : (n,) int array
        The action index (row of ``mdp.action_table``) chosen in each state.
    q_pi : (n,) array
        ``Q(s, pi(s))``.
    tolerance : Tolerance
    tol : float
        ``tolerance.resolve(value_scale)``.
    value_scale : float
        ``max V - min V``.
    recurrent : (n,) bool array
    stationary : (n,) array or None
        The stationary distribution of the policy (None when it could not be computed, e.g.
        for a multichain policy).
    at_cap : (n,) bool array
        Some ``tau_k`` equals its cap.
    offsets : (n_configs, n_actions) int array
        ``offsets[c, a]`` = position of action ``a`` among the pairs of any state of
        configuration ``c`` (-1 if infeasible there); the pair of (s, a) is
        ``pair_ptr[s] + offsets[config[s], a]``.
    recurrence_rule : str
    observable : (n,) bool array (property)
        Recurrent and visited at least :data:`~wncs_lp.verify.verdict.NEGLIGIBLE` of the time
        (recurrent, when the stationary law is not known).
    cap_distance : (n,) int array (property)
        ``min_k (tau_hat_k - tau_k)``: 0 at the cap.
    """

    mdp: MDP
    solution: Solution
    q: np.ndarray
    act: np.ndarray
    q_pi: np.ndarray
    tolerance: Tolerance
    tol: float
    value_scale: float
    recurrent: np.ndarray
    stationary: np.ndarray | None
    at_cap: np.ndarray
    offsets: np.ndarray
    recurrence_rule: str

    @cached_property
    def observable(self) -> np.ndarray:
        if self.stationary is None:
            return np.asarray(self.recurrent, bool)
        return np.asarray(self.recurrent, bool) & (np.asarray(self.stationary) >= NEGLIGIBLE)

    @cached_property
    def cap_distance(self) -> np.ndarray:
        return cap_distance(self.mdp.states.tau, self.mdp.states.caps)

    def q_of(self, states: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """``Q(s, a)`` for arrays of states and action indices (NaN where a is infeasible)."""
        states = np.asarray(states, dtype=np.int64)
        actions = np.asarray(actions, dtype=np.int64)
        off = self.offsets[self.mdp.states.config[states], actions]
        out = np.full(states.shape, np.nan)
        ok = off >= 0
        out[ok] = self.q[self.mdp.pair_ptr[states[ok]] + off[ok]]
        return out

    def label(self, s: int) -> str:
        return self.mdp.state_label(int(s))

    def action(self, a: int) -> tuple[int, ...]:
        """The decoded label of action index a."""
        return tuple(int(x) for x in np.atleast_1d(self.mdp.action_table[int(a)]))

    def violation(self, kind: str, size: float, states: Sequence[int], recurrent: bool, at_cap: bool,
                  info: dict | None = None) -> Violation:
        st = tuple(int(s) for s in states)
        stat = None if self.stationary is None else tuple(float(self.stationary[s]) for s in st)
        idx = np.asarray(st, np.int64)
        obs = None if self.stationary is None else bool(recurrent and self.observable[idx].all())
        return Violation(kind, float(size), st, tuple(self.label(s) for s in st), bool(recurrent), bool(at_cap),
                         stat, dict(info or {}), int(self.cap_distance[idx].min()) if st else None, obs)


def require_space(mdp: MDP) -> Any:
    """``mdp.states`` when it is an AoI state space and the actions are decoded, else ModelError."""
    sp_ = mdp.states
    if sp_ is None or not all(hasattr(sp_, a) for a in ("tau", "config", "configs", "caps", "lookup_grid")):
        raise ModelError(
            f"structure checks need an MDP built over an AoI state space (mdp.states a StateSpace); "
            f"{mdp!r} has states={type(sp_).__name__}"
        )
    if mdp.action_table is None:
        raise ModelError(f"structure checks need decoded actions (mdp.action_table); {mdp!r} has none")
    return sp_


def policy_context(
    mdp: MDP,
    solution: Solution,
    tolerance: Tolerance | None = None,
    *,
    stationary_tol: float = 0.0,
    stationary: np.ndarray | bool | None = None,
) -> PolicyContext:
    """Compute the shared data of the checks (Q-values, recurrence, cap mask, action offsets).

    Parameters
    ----------
    mdp : MDP
    solution : Solution
        Any object with ``bias`` (n,) and ``policy`` (n,) pair indices.
    tolerance : Tolerance, optional
    stationary_tol : float
        0 (default): recurrent = in a closed class of the policy's chain (exact). > 0:
        recurrent = stationary probability > stationary_tol.
    stationary : (n,) array, False or None
        A precomputed stationary distribution of the policy; None (default): taken from a
        policy-iteration solution's occupation, else computed by
        :func:`~wncs_lp.solvers.dp.evaluate_policy` when the model has at most
        ``STATIONARY_SOLVE_LIMIT`` states and by :func:`~wncs_lp.chain.stationary_law` above
        that (None for a multichain policy);
        False: not computed (examples then carry no probabilities; recurrence uses the graph
        criterion anyway).

    Raises
    ------
    ModelError
        If the MDP has no AoI state space, or the solution does not fit the MDP.
    """
    space = require_space(mdp)
    tolerance = tolerance or Tolerance()
    pol = _checked_policy(mdp, solution)
    bias = np.asarray(solution.bias, dtype=float)
    q = q_values(mdp, bias)
    act = mdp.a_indices[pol]
    scale = float(bias.max() - bias.min()) if mdp.n_states else 0.0
    stationary, classes = _stationary_of(mdp, solution, pol, stationary)
    recurrent, rule = _recurrence(mdp, pol, classes, stationary, stationary_tol)
    caps = np.asarray(space.caps)
    at_cap = np.any(np.asarray(space.tau) >= caps[None, :], axis=1)
    offsets = _action_offsets(mdp, pol, act)
    return PolicyContext(mdp, solution, q, act, q[pol], tolerance, tolerance.resolve(scale), scale, recurrent,
                         None if stationary is None else np.asarray(stationary), at_cap, offsets, rule)


def _checked_policy(mdp: MDP, solution: Solution) -> np.ndarray:
    """The solution's policy as int64 pair indices, after checking that bias and policy fit the MDP."""
    n = mdp.n_states
    bias = np.asarray(solution.bias, dtype=float)
    pol = np.asarray(solution.policy)
    if bias.shape != (n,) or not np.all(np.isfinite(bias)):
        raise ModelError(f"solution.bias must be a finite array of shape ({n},), got shape {bias.shape}")
    if pol.shape != (n,) or not np.issubdtype(pol.dtype, np.integer):
        raise ModelError(f"solution.policy must be an integer array of pair indices of shape ({n},)")
    pol = pol.astype(np.int64)
    if pol.min() < 0 or pol.max() >= mdp.n_pairs or np.any(mdp.s_indices[pol] != np.arange(n)):
        bad = int(np.flatnonzero((pol < 0) | (pol >= mdp.n_pairs) | (mdp.s_indices[np.clip(pol, 0, mdp.n_pairs - 1)] != np.arange(n)))[0])
        raise ModelError(f"solution.policy[{bad}] = {int(pol[bad])} is not a pair of state {bad}")
    return pol


def _stationary_of(mdp: MDP, solution: Solution, pol: np.ndarray, given: np.ndarray | bool | None
                   ) -> tuple[np.ndarray | None, list[np.ndarray] | None]:
    """The policy's stationary law: ``given`` (False: none), a policy-iteration solution's
    occupation, an exact evaluation up to STATIONARY_SOLVE_LIMIT states, the unichain law above
    (with the recurrent classes it needed, so they are not found twice; else None)."""
    if given is False:
        return None, None
    if given is not None:
        return given, None
    occ = getattr(solution, "occupation", None)
    if occ is not None and getattr(solution, "method", "") == "pi":
        return np.add.reduceat(np.asarray(occ, float), mdp.pair_ptr[:-1]), None
    if mdp.n_states <= STATIONARY_SOLVE_LIMIT:
        try:
            return evaluate_policy(mdp, pol).stationary, None
        except Exception:  # multichain or numerically hard: recurrence still comes from the graph
            return None, None
    P_pi = mdp.P[pol]
    classes = recurrent_classes(P_pi)
    return _unichain_stationary(P_pi, classes), classes


def _recurrence(mdp: MDP, pol: np.ndarray, classes: list[np.ndarray] | None, stationary: np.ndarray | None,
                stationary_tol: float) -> tuple[np.ndarray, str]:
    """(recurrent mask, the rule in words): closed classes of the chain, or the stationary law above a threshold."""
    if stationary_tol > 0:
        if stationary is None:
            raise ModelError("stationary_tol > 0 needs the stationary distribution, which could not be computed")
        return np.asarray(stationary) > stationary_tol, f"stationary probability > {stationary_tol:g}"
    recurrent = np.zeros(mdp.n_states, bool)
    for cl in (classes if classes is not None else recurrent_classes(mdp.P[pol])):
        recurrent[cl] = True
    return recurrent, "in a closed communicating class of the policy's chain (stationary probability > 0)"


def _action_offsets(mdp: MDP, pol: np.ndarray, act: np.ndarray) -> np.ndarray:
    """``offsets[c, a]``: the position of action a among the pairs of configuration c's states (-1:
    infeasible); the action list depends on the configuration only, which is checked on the policy."""
    space = mdp.states
    n = mdp.n_states
    nC = len(space.configs)
    offsets = np.full((nC, int(mdp.action_table.shape[0])), -1, dtype=np.int64)
    first = np.full(nC, -1, dtype=np.int64)
    cfg = np.asarray(space.config)
    order = np.arange(n)[::-1]
    first[cfg[order]] = order  # smallest state id of each configuration
    for c in range(nC):
        s = int(first[c])
        if s < 0:
            continue
        lo, hi = int(mdp.pair_ptr[s]), int(mdp.pair_ptr[s + 1])
        offsets[c, mdp.a_indices[lo:hi]] = np.arange(hi - lo)
    # the chosen action's offset must point at the chosen pair in every state
    if n and np.any(mdp.pair_ptr[:-1] + offsets[cfg, act] != pol):
        raise ModelError("the action lists of the states of one configuration differ; structure checks need them equal")
    return offsets


def _unichain_stationary(P_pi: Any, classes: list[np.ndarray]) -> np.ndarray | None:
    """The stationary law of a unichain policy's chain (large models); None when the chain is
    multichain or the law could not be computed to :data:`~wncs_lp.chain.STATIONARY_TOL`."""
    if len(classes) != 1:
        return None
    try:
        return stationary_law(P_pi, classes)[0]
    except PolicyError:
        return None


def idle_configs(mdp: MDP) -> list[int]:
    """Ids of the idle-server configurations (every server idle, every pipeline empty, as the
    model's :meth:`~wncs_lp.models.base.Model.is_idle` says); normally exactly one."""
    space = require_space(mdp)
    is_idle = model_type(mdp).is_idle
    return [i for i, c in enumerate(space.configs) if is_idle(c)]


def use_context(mdp: MDP, solution: Solution, tolerance: Tolerance | None, stationary_tol: float,
                ctx: PolicyContext | None) -> PolicyContext:
    """``ctx`` when given (it must belong to ``mdp``), else :func:`policy_context` of the arguments."""
    if ctx is not None:
        if ctx.mdp is not mdp:
            raise ModelError("the given PolicyContext was computed for another MDP")
        return ctx
    return policy_context(mdp, solution, tolerance, stationary_tol=stationary_tol)


def violation_weight(ctx: PolicyContext, witnesses: Sequence[Sequence[int]], rec: np.ndarray,
                     cap: np.ndarray, obs: np.ndarray | None = None) -> dict[str, Any]:
    """The stationary probability of the states of the violations' witnesses (all of them, those
    of the violations recurrent and below the cap, and those observable and below the cap); masses
    None without a stationary law."""
    def mass(sel: list[Sequence[int]]) -> tuple[int, float | None]:
        states = np.unique(np.concatenate([np.asarray(w, np.int64) for w in sel])) if sel else np.zeros(0, np.int64)
        return int(states.size), (None if ctx.stationary is None else float(ctx.stationary[states].sum()))

    n_all, m_all = mass(list(witnesses))
    n_rbc, m_rbc = mass([w for w, r, c in zip(witnesses, rec, cap) if r and not c])
    out = {"states": n_all, "mass": m_all, "states_recurrent_below_cap": n_rbc, "mass_recurrent_below_cap": m_rbc}
    if obs is not None:
        n_obc, m_obc = mass([w for w, o, c in zip(witnesses, obs, cap) if o and not c])
        out.update(states_observable_below_cap=n_obc, mass_observable_below_cap=m_obc)
    return out


def witness_flags(ctx: PolicyContext, witnesses: Sequence[Sequence[int]], rec: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Per violation ``(observable, distance to the cap)`` of its witness: every state recurrent
    (``rec``) and visited at least :data:`~wncs_lp.verify.verdict.NEGLIGIBLE` of the time; the
    smallest ``tau_hat_k - tau_k`` over its states."""
    n = len(witnesses)
    obs = np.zeros(n, bool)
    dist = np.zeros(n, np.int64)
    if n:
        W = [np.asarray(w, np.int64) for w in witnesses]
        obs = np.asarray(rec, bool) & np.array([bool(ctx.observable[w].all()) for w in W])
        dist = np.array([int(ctx.cap_distance[w].min()) for w in W], np.int64)
    return obs, dist


def make_report(name: str, claim: str, ctx: PolicyContext, *, holds: bool, checked: int, violations: int,
                rec: np.ndarray, cap: np.ndarray, ties: int, unit: str, worst: Violation | None,
                examples: Iterable[Violation], details: dict, notes: str, t0: float,
                witnesses: Sequence[Sequence[int]] = (), obs: np.ndarray | None = None) -> CheckReport:
    """A :class:`CheckReport` with the tolerance, recurrence rule and model of ``ctx`` (``rec``,
    ``cap``, ``witnesses``: per violation, the witness's flags and states; ``obs``: its
    observability, default :func:`witness_flags` of the witnesses; ``t0``: the check's start,
    from :func:`time.perf_counter`)."""
    if obs is None:
        obs = witness_flags(ctx, witnesses, rec)[0] if len(witnesses) == len(rec) else np.asarray(rec, bool)
    return CheckReport(
        name=name,
        claim=claim,
        holds=bool(holds),
        checked=int(checked),
        violations=int(violations),
        recurrent_violations=int(np.count_nonzero(rec)),
        at_cap_violations=int(np.count_nonzero(cap)),
        ties=int(ties),
        split=split_counts(rec, cap, obs),
        tol=ctx.tol,
        atol=ctx.tolerance.atol,
        rtol=ctx.tolerance.rtol,
        value_scale=ctx.value_scale,
        recurrence_rule=ctx.recurrence_rule,
        unit=unit,
        worst=worst,
        examples=tuple(examples),
        details=details,
        notes=notes,
        model=ctx.mdp.name,
        seconds=time.perf_counter() - t0,
        weight=violation_weight(ctx, witnesses, rec, cap, obs),
    )
