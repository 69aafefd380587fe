r"""Numerical verifiers of the paper's structural theorems (claims C7, C8, C9, C10).

Each verifier reads a solved model -- an :class:`~wncs_lp.mdp.MDP` whose ``states`` is a
:class:`~wncs_lp.models.space.StateSpace` and a :class:`~wncs_lp.solvers.result.Solution` (bias
``V``, chosen pair per state ``pi``) -- and returns a frozen :class:`CheckReport` with the counts
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
* consistency -- the start state (then every state of its tree is recurrent too, so the
  violation happens with positive long-run frequency).

A violation *touches the cap* when one of the states involved has some ``tau_k = tau_hat_k``
(consistency: when every violating path from the start passes through such a state). The cap
truncates an infinite chain, so such findings may be truncation artefacts.

Checks
------
:func:`check_monotonicity` (Theorem 1), :func:`check_threshold` (Theorem 2 for the Section II
model; the switching-curve form of Figs. 11-12 for the preemption model),
:func:`check_consistency` (Theorem 3, preemption model), :func:`verify_all`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from .errors import ModelError
from .mdp import MDP
from .solvers.certify import q_values
from .solvers.dp import evaluate_policy, recurrent_classes
from .solvers.result import Solution

__all__ = [
    "Tolerance",
    "Violation",
    "CheckReport",
    "PolicyContext",
    "policy_context",
    "model_kind",
    "idle_configs",
    "check_monotonicity",
    "check_threshold",
    "check_consistency",
    "verify_all",
]

#: Default number of example violations kept in a report.
DEFAULT_EXAMPLES = 10
#: Largest model whose stationary distribution is computed automatically (by
#: :func:`~wncs_lp.solvers.dp.evaluate_policy`: sparse LU, or BiCGSTAB from 50,000 states) for the
#: probabilities printed with examples; recurrence never needs it (graph criterion).
STATIONARY_SOLVE_LIMIT = 300_000


# ============================================================================ report types
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
    """

    kind: str
    size: float
    states: tuple[int, ...]
    labels: tuple[str, ...]
    recurrent: bool
    at_cap: bool
    stationary: tuple[float, ...] | None = None
    info: dict = field(default_factory=dict)

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
            "info": _jsonable(self.info),
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
        No violation beyond the tolerance (see ``notes`` for what exactly enters the verdict).
    checked : int
        Number of cases examined (the unit is in ``unit``).
    violations : int
        Number of violating cases (same unit).
    recurrent_violations, at_cap_violations : int
        Among the violations: how many are recurrent, how many touch the AoI cap.
    ties : int
        Cases that differ from the claim only within the tolerance (not violations).
    split : dict
        The violations by (recurrent | transient) x (at cap | below cap).
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

    @property
    def verdict(self) -> str:
        return "HOLDS" if self.holds else "FAILS"

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
            "split": _jsonable(self.split),
            "unit": self.unit,
            "tol": float(self.tol),
            "atol": float(self.atol),
            "rtol": float(self.rtol),
            "value_scale": float(self.value_scale),
            "recurrence_rule": self.recurrence_rule,
            "worst": None if self.worst is None else self.worst.to_json(),
            "examples": [v.to_json() for v in self.examples],
            "details": _jsonable(self.details),
            "notes": self.notes,
            "model": self.model,
            "seconds": float(self.seconds),
        }

    def summary(self) -> str:
        """One line: verdict and counts."""
        w = "" if self.worst is None else f", worst {self.worst.size:.4g}"
        return (
            f"{self.name}: {self.verdict} -- {self.violations} violation(s) in {self.checked} {self.unit} "
            f"({self.recurrent_violations} recurrent, {self.at_cap_violations} at cap, {self.ties} ties{w}; "
            f"tol {self.tol:.3g})"
        )


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Violation):
        return obj.to_json()
    return obj


# ============================================================================ shared context
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
        return Violation(kind, float(size), st, tuple(self.label(s) for s in st), bool(recurrent), bool(at_cap),
                         stat, dict(info or {}))


def _require_space(mdp: MDP) -> Any:
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
        ``STATIONARY_SOLVE_LIMIT`` states and by the lazy power method above that;
        False: not computed (examples then carry no probabilities; recurrence uses the graph
        criterion anyway).

    Raises
    ------
    ModelError
        If the MDP has no AoI state space, or the solution does not fit the MDP.
    """
    space = _require_space(mdp)
    tolerance = tolerance or Tolerance()
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
    q = q_values(mdp, bias)
    act = mdp.a_indices[pol]
    scale = float(bias.max() - bias.min()) if n else 0.0
    tol = tolerance.resolve(scale)

    # recurrence
    stationary_off = stationary is False
    if stationary is False:
        stationary = None
    elif stationary is None:
        occ = getattr(solution, "occupation", None)
        if occ is not None and getattr(solution, "method", "") == "pi":
            stationary = np.add.reduceat(np.asarray(occ, float), mdp.pair_ptr[:-1])
        elif n <= STATIONARY_SOLVE_LIMIT:
            try:
                stationary = evaluate_policy(mdp, pol).stationary
            except Exception:  # multichain or numerically hard: recurrence still comes from the graph
                stationary = None
    classes = None
    if stationary is None and n > STATIONARY_SOLVE_LIMIT and not stationary_off:
        classes = recurrent_classes(mdp.P[pol])
        stationary = _power_stationary(mdp.P[pol], classes)
    if stationary_tol > 0:
        if stationary is None:
            raise ModelError("stationary_tol > 0 needs the stationary distribution, which could not be computed")
        recurrent = np.asarray(stationary) > stationary_tol
        rule = f"stationary probability > {stationary_tol:g}"
    else:
        recurrent = np.zeros(n, bool)
        for cl in (classes if classes is not None else recurrent_classes(mdp.P[pol])):
            recurrent[cl] = True
        rule = "in a closed communicating class of the policy's chain (stationary probability > 0)"

    caps = np.asarray(space.caps)
    at_cap = np.any(np.asarray(space.tau) >= caps[None, :], axis=1)

    # action offsets per configuration (the action list depends on the configuration only)
    nC = len(space.configs)
    nA = int(mdp.action_table.shape[0])
    offsets = np.full((nC, nA), -1, dtype=np.int64)
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
    # guard: the chosen action's offset must point at the chosen pair in every state
    if n and np.any(mdp.pair_ptr[:-1] + offsets[cfg, act] != pol):
        raise ModelError("the action lists of the states of one configuration differ; structure checks need them equal")
    return PolicyContext(mdp, solution, q, act, q[pol], tolerance, tol, scale, recurrent,
                         None if stationary is None else np.asarray(stationary), at_cap, offsets, rule)


def _power_stationary(P_pi: Any, classes: list[np.ndarray], *, max_iter: int = 50_000,
                      tol: float = 1e-13) -> np.ndarray | None:
    r"""Stationary distribution of a unichain policy by the lazy power method (large models).

    Iterates :math:`\pi \leftarrow \tfrac12 \pi + \tfrac12 \pi P_\pi` (aperiodic, same fixed
    point) from the uniform distribution on the recurrent class until the L1 change is below
    ``tol``; None when the chain is multichain or the iteration does not converge.
    """
    if len(classes) != 1:
        return None
    PT = P_pi.T.tocsr()
    pi = np.zeros(P_pi.shape[0])
    pi[classes[0]] = 1.0 / classes[0].size
    for _ in range(max_iter):
        new = 0.5 * (pi + PT @ pi)
        if np.abs(new - pi).sum() < tol:
            return new / new.sum()
        pi = new
    return None


def model_kind(mdp: MDP) -> str:
    """``"wncs"`` or ``"preemption"`` (from ``mdp.meta["kind"]`` or the configuration shape)."""
    kind = mdp.meta.get("kind") if isinstance(mdp.meta, dict) else None
    if kind in ("wncs", "preemption"):
        return kind
    space = _require_space(mdp)
    c = space.configs[0] if space.configs else None
    if hasattr(c, "_fields") and getattr(c, "_fields", ()) == ("b", "job", "stack", "down"):
        return "preemption"
    return "wncs"


def _is_idle_wncs(cfg: Any) -> bool:
    try:
        return all(job == 0 and d == 0 and not any(up) and not any(down) for (up, job, d, down) in cfg)
    except (TypeError, ValueError):
        return False


def idle_configs(mdp: MDP) -> list[int]:
    """Ids of the idle-server configurations of a Section II model (every server idle, every
    pipeline empty); normally exactly one."""
    space = _require_space(mdp)
    return [i for i, c in enumerate(space.configs) if _is_idle_wncs(c)]


def _split(rec: np.ndarray, cap: np.ndarray) -> dict[str, int]:
    rec = np.asarray(rec, bool)
    cap = np.asarray(cap, bool)
    return {
        "recurrent_below_cap": int(np.count_nonzero(rec & ~cap)),
        "recurrent_at_cap": int(np.count_nonzero(rec & cap)),
        "transient_below_cap": int(np.count_nonzero(~rec & ~cap)),
        "transient_at_cap": int(np.count_nonzero(~rec & cap)),
    }


def _pick_examples(rec: np.ndarray, cap: np.ndarray, size: np.ndarray, k: int) -> np.ndarray:
    """Indices of up to k violations: recurrent first, then below the cap, then by |size|."""
    if size.size == 0 or k <= 0:
        return np.zeros(0, np.int64)
    order = np.lexsort((-np.abs(size), cap.astype(int), (~rec).astype(int)))
    return order[:k]


def _report(name: str, claim: str, ctx: PolicyContext, *, holds: bool, checked: int, violations: int,
            rec: np.ndarray, cap: np.ndarray, ties: int, unit: str, worst: Violation | None,
            examples: Iterable[Violation], details: dict, notes: str, t0: float) -> CheckReport:
    return CheckReport(
        name=name,
        claim=claim,
        holds=bool(holds),
        checked=int(checked),
        violations=int(violations),
        recurrent_violations=int(np.count_nonzero(rec)),
        at_cap_violations=int(np.count_nonzero(cap)),
        ties=int(ties),
        split=_split(rec, cap),
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
    )


def _ctx(mdp, solution, tolerance, stationary_tol, ctx) -> PolicyContext:
    if ctx is not None:
        if ctx.mdp is not mdp:
            raise ModelError("the given PolicyContext was computed for another MDP")
        return ctx
    return policy_context(mdp, solution, tolerance, stationary_tol=stationary_tol)


# ============================================================================ Theorem 1
def check_monotonicity(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    ctx: PolicyContext | None = None,
) -> CheckReport:
    r"""Theorem 1 (claim C7): ``V`` is nondecreasing in each ``tau_k`` with the configuration fixed.

    For every configuration C, every reachable state ``s = (tau, C)`` and every k such that
    ``s + e_k = (tau + e_k, C)`` is reachable, the check is

    .. math:: V(s + e_k) \ge V(s) - \mathrm{tol}.

    A violation is a pair with ``V(s) - V(s + e_k) > tol``; its size is that difference.
    By transitivity these adjacent pairs imply ``V(s^1) >= V(s^2)`` for every comparable pair
    ``tau^1 >= tau^2`` joined by a monotone path of reachable states (up to ``tol`` per step).
    Reachable sets can have holes, so the check also tests *every* comparable pair at once:
    with ``M(tau) = max {V(tau', C) : tau' <= tau, (tau', C) reachable}`` (a prefix maximum
    over the box, one ``np.maximum.accumulate`` per axis), a state violates dominance when
    ``M(tau) - V(tau, C) > tol`` (``details["dominance"]``).

    Works for any model over an AoI state space (Section II or preemption).

    Parameters
    ----------
    mdp : MDP
    solution : Solution
    tolerance : Tolerance, optional
        Default ``Tolerance()`` (atol = rtol = 1e-9, rtol relative to span(V)).
    examples : int
        Number of example violations kept (K).
    stationary_tol : float
        See :func:`policy_context`.
    ctx : PolicyContext, optional
        Precomputed shared data (from :func:`policy_context`).

    Returns
    -------
    CheckReport
        ``checked`` = adjacent comparable pairs; ``violations`` = adjacent pairs violating;
        ``holds`` = no adjacent and no dominance violation. A pair is recurrent when both its
        states are, at the cap when one of them has some tau at its cap.
    """
    t0 = time.perf_counter()
    ctx = _ctx(mdp, solution, tolerance, stationary_tol, ctx)
    space = mdp.states
    V = np.asarray(solution.bias, float)
    caps = tuple(int(c) for c in space.caps)
    N = len(caps)
    nC = len(space.configs)
    grids = np.stack([space.lookup_grid(c) for c in range(nC)])  # (nC, *caps)
    tol = ctx.tol

    lows, highs, axes = [], [], []
    checked = 0
    per_axis = {}
    for k in range(N):
        if caps[k] < 2:
            per_axis[f"tau_{k + 1}"] = {"checked": 0, "violations": 0}
            continue
        lo = np.take(grids, np.arange(caps[k] - 1), axis=k + 1)
        hi = np.take(grids, np.arange(1, caps[k]), axis=k + 1)
        m = (lo >= 0) & (hi >= 0)
        s1, s2 = lo[m], hi[m]
        checked += s1.size
        bad = V[s1] - V[s2] > tol
        per_axis[f"tau_{k + 1}"] = {"checked": int(s1.size), "violations": int(np.count_nonzero(bad))}
        lows.append(s1[bad])
        highs.append(s2[bad])
        axes.append(np.full(int(np.count_nonzero(bad)), k))
    s1 = np.concatenate(lows) if lows else np.zeros(0, np.int64)
    s2 = np.concatenate(highs) if highs else np.zeros(0, np.int64)
    ax = np.concatenate(axes) if axes else np.zeros(0, np.int64)
    size = V[s1] - V[s2]
    rec = ctx.recurrent[s1] & ctx.recurrent[s2]
    any_rec = int(np.count_nonzero(ctx.recurrent[s1] | ctx.recurrent[s2]))
    cap = ctx.at_cap[s1] | ctx.at_cap[s2]

    def make(i: int) -> Violation:
        a, b = int(s1[i]), int(s2[i])
        return ctx.violation(
            "adjacent", size[i], (a, b), rec[i], cap[i],
            {"axis": int(ax[i]) + 1, "V_low_tau": float(V[a]), "V_high_tau": float(V[b]),
             "recurrent_each": [bool(ctx.recurrent[a]), bool(ctx.recurrent[b])]},
        )

    ex = [make(int(i)) for i in _pick_examples(rec, cap, size, examples)]
    worst = make(int(np.argmax(size))) if size.size else None

    # every comparable pair, through the prefix maximum
    W = np.where(grids >= 0, V[np.maximum(grids, 0)], -np.inf)
    M = W
    for k in range(N):
        M = np.maximum.accumulate(M, axis=k + 1)
    with np.errstate(invalid="ignore"):
        gap = np.where(grids >= 0, M - W, 0.0)
    dom_bad = gap > tol
    n_dom = int(np.count_nonzero(dom_bad))
    dom: dict[str, Any] = {
        "states_checked": int(np.count_nonzero(grids >= 0)),
        "violating_states": n_dom,
        "note": "a state violates dominance when some reachable state of its configuration with "
                "componentwise smaller or equal tau has a larger V (beyond tol)",
    }
    if n_dom:
        flat = int(np.argmax(gap))
        c, *tau0 = np.unravel_index(flat, gap.shape)
        hi_state = int(grids[(c, *tau0)])
        sub = tuple(slice(0, t + 1) for t in tau0)
        block = np.where(grids[c][sub] >= 0, V[np.maximum(grids[c][sub], 0)], -np.inf)
        lo_state = int(grids[c][sub][np.unravel_index(int(np.argmax(block)), block.shape)])
        r = bool(ctx.recurrent[lo_state] and ctx.recurrent[hi_state])
        cp = bool(ctx.at_cap[lo_state] or ctx.at_cap[hi_state])
        dom["worst"] = ctx.violation("dominance", float(gap[(c, *tau0)]), (lo_state, hi_state), r, cp,
                                     {"V_low_tau": float(V[lo_state]), "V_high_tau": float(V[hi_state])}).to_json()
        dom_states = grids[dom_bad]
        dom["recurrent_states"] = int(np.count_nonzero(ctx.recurrent[dom_states]))
        dom["at_cap"] = int(np.count_nonzero(ctx.at_cap[dom_states]))
    details = {"per_axis": per_axis, "dominance": dom, "configurations": nC,
               "violations_with_some_recurrent_state": any_rec}
    notes = (
        "Adjacent pairs (s, s+e_k) in one configuration; by transitivity they cover every comparable pair "
        "joined by a monotone path of reachable states. The dominance sub-check covers all comparable pairs, "
        "also across unreachable cells; 'holds' requires both to be free of violations."
    )
    return _report(
        "monotonicity", "Theorem 1 (C7): V nondecreasing in each tau_k, configuration fixed", ctx,
        holds=(size.size == 0 and n_dom == 0), checked=checked, violations=size.size, rec=rec, cap=cap,
        ties=0, unit="adjacent comparable pairs", worst=worst, examples=ex, details=details, notes=notes, t0=t0,
    )


# ============================================================================ lines of the box
def _lines(caps: Sequence[int], d: Sequence[int]) -> np.ndarray:
    """All maximal lines ``x0, x0 + d, x0 + 2d, ...`` of the box, as flat indices.

    Returns an (n_lines, L) int64 array, padded with -1 (``d`` nonnegative, nonzero).
    """
    caps = np.asarray(caps, dtype=np.int64)
    d = np.asarray(d, dtype=np.int64)
    if np.any(d < 0) or not np.any(d):
        raise ModelError(f"line direction must be nonnegative and nonzero, got {tuple(d)}")
    coords = np.indices(tuple(caps)).reshape(len(caps), -1).T
    starts = coords[np.any(coords - d < 0, axis=1)]
    pos = d > 0
    lengths = np.min((caps[pos][None, :] - 1 - starts[:, pos]) // d[pos][None, :] + 1, axis=1)
    L = int(lengths.max()) if lengths.size else 0
    t = np.arange(L)
    pts = starts[:, None, :] + t[None, :, None] * d[None, None, :]
    valid = t[None, :] < lengths[:, None]
    pts = np.where(valid[..., None], pts, 0)
    flat = np.ravel_multi_index(tuple(np.moveaxis(pts, -1, 0)), tuple(caps))
    return np.where(valid, flat, -1)


def _direction_name(d: Sequence[int]) -> str:
    ks = [k + 1 for k, x in enumerate(d) if x]
    if len(ks) == 1:
        return f"axis tau_{ks[0]}"
    return "diagonal " + "+".join(f"tau_{k}" for k in ks)


def _line_structure(ctx: PolicyContext, configs: Sequence[int], directions: Sequence[tuple[int, ...]]
                    ) -> tuple[dict, list[tuple]]:
    """Whether each action region is an interval on every line of the given directions.

    Tie-robust: a state x is *compatible* with action a when pi(x) = a or
    ``|Q(x, a) - Q(x, pi(x))| <= tol``. A line has a gap for action a when two states with
    pi = a enclose a reachable state not compatible with a.

    Returns (summary per direction, list of gaps (direction, config, action, first, gap, last)).
    """
    mdp = ctx.mdp
    space = mdp.states
    caps = tuple(int(c) for c in space.caps)
    summary: dict[str, dict] = {}
    gaps: list[tuple] = []
    for d in directions:
        lines = _lines(caps, d)
        name = _direction_name(d)
        entry = summary.setdefault(name, {"lines": 0, "checked": 0, "gaps": 0, "gap_lines_by_action": {}})
        if lines.shape[1] < 3:
            continue
        for c in configs:
            G = space.lookup_grid(c).ravel()
            S = np.where(lines >= 0, G[np.maximum(lines, 0)], -1)
            keep = np.count_nonzero(S >= 0, axis=1) >= 3
            S = S[keep]
            if S.shape[0] == 0:
                continue
            entry["lines"] += int(S.shape[0])
            valid = S >= 0
            Ssafe = np.maximum(S, 0)
            A = np.where(valid, ctx.act[Ssafe], -1)
            feas = np.flatnonzero(ctx.offsets[c] >= 0)
            if feas.size < 2:
                continue
            L = S.shape[1]
            idx = np.arange(L)[None, :]
            for a in feas:
                isA = A == a
                has = isA.any(axis=1)
                entry["checked"] += int(np.count_nonzero(has))
                first = np.argmax(isA, axis=1)
                last = L - 1 - np.argmax(isA[:, ::-1], axis=1)
                qa = np.where(valid, ctx.q_of(Ssafe.ravel(), np.full(Ssafe.size, a)).reshape(S.shape), np.nan)
                qp = np.where(valid, ctx.q_pi[Ssafe], np.nan)
                incompatible = valid & (A != a) & (np.abs(qa - qp) > ctx.tol)
                inside = (idx > first[:, None]) & (idx < last[:, None]) & has[:, None]
                bad = incompatible & inside
                rows = np.flatnonzero(bad.any(axis=1))
                if rows.size:
                    lab = str(ctx.action(a))
                    entry["gaps"] += int(rows.size)
                    entry["gap_lines_by_action"][lab] = entry["gap_lines_by_action"].get(lab, 0) + int(rows.size)
                    for r in rows:
                        j = int(np.argmax(bad[r]))
                        gaps.append((name, c, int(a), int(S[r, first[r]]), int(S[r, j]), int(S[r, last[r]]),
                                     float(qa[r, j] - qp[r, j])))
    return summary, gaps


def _gap_violations(ctx: PolicyContext, gaps: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if not gaps:
        z = np.zeros(0, bool)
        return z, z, np.zeros(0)
    trip = np.asarray([[x[3], x[4], x[5]] for x in gaps], dtype=np.int64)
    rec = ctx.recurrent[trip].all(axis=1)
    cap = ctx.at_cap[trip].any(axis=1)
    size = np.asarray([x[6] for x in gaps])
    return rec, cap, size


def _gap_violation(ctx: PolicyContext, gap: tuple, rec: bool, cap: bool) -> Violation:
    name, c, a, s_first, s_gap, s_last, size = gap
    return ctx.violation(
        "line-gap", size, (s_first, s_gap, s_last), rec, cap,
        {"direction": name, "action": list(ctx.action(a)), "action_at_gap": list(ctx.action(ctx.act[s_gap])),
         "meaning": "states 1 and 3 choose the action; state 2 between them on the line strictly prefers another "
                    "(size = Q(gap, action) - Q(gap, pi(gap)))"},
    )


# ============================================================================ Theorem 2
def _theorem2_direction(label: tuple[int, ...], N: int) -> tuple[int, ...] | None:
    sent = [k for k in label if k]
    if len(sent) < 2 or len(set(sent)) != len(sent):
        return None
    d = [0] * N
    for k in sent:
        d[k - 1] = 1
    return tuple(d)


def check_threshold(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    configs: str | Sequence[int] | None = None,
    ctx: PolicyContext | None = None,
) -> CheckReport:
    r"""Theorem 2 (claim C8) for the Section II model; the switching-curve form for preemption.

    **Section II model** (``kind = "wncs"``), in the idle-server configuration(s): for every
    reachable idle state s with ``pi(s) = a`` sending distinct processes ``k1 != k2`` (in general
    the set K of the processes a sends, |K| >= 2), and every ``z >= 1`` with
    ``s' = s + z * sum_{k in K} e_k`` reachable in the box, the claim is ``pi(s') = a``.
    If ``pi(s') != a`` the case is a *tie* when ``|Q(s', a) - Q(s', pi(s'))| <= tol`` (``a`` is
    optimal at s' within tol) and a *violation* otherwise; its size is
    ``Q(s', a) - Q(s', pi(s'))``. One case = one (s, z). A violation is recurrent when s and s'
    both are (``details["target_recurrent"]`` counts those with s' recurrent), at the cap when s
    or s' has some tau at its cap; ``details["violating_target_stationary_mass"]`` is the
    stationary probability of the distinct states s' where the claim fails.

    Sub-counts (``details["lines"]``, not part of the verdict for this model): whether each
    action's region is an *interval* on every line parallel to a tau axis and to every
    diagonal ``e_i + e_j`` -- a line has a gap for action a when two states choosing a enclose a
    reachable state that strictly prefers another action (beyond tol).

    **Preemption model**: Theorem 2 does not apply; claim C9 ("the preemption policy is of
    threshold type", Figs. 11-12) is checked as the interval property above, in every
    configuration with at least two feasible actions, along every axis and diagonal; one case
    = one (line, action) pair where the action occurs; a violation = a gap.

    Parameters
    ----------
    mdp, solution, tolerance, examples, stationary_tol, ctx
        As in :func:`check_monotonicity`.
    configs : "idle", "all" or sequence of configuration ids, optional
        Where to look. Default: the idle configuration (Section II), every configuration with
        >= 2 feasible actions (preemption).

    Returns
    -------
    CheckReport
    """
    t0 = time.perf_counter()
    ctx = _ctx(mdp, solution, tolerance, stationary_tol, ctx)
    space = mdp.states
    kind = model_kind(mdp)
    caps = tuple(int(c) for c in space.caps)
    N = len(caps)
    nfeas = np.count_nonzero(ctx.offsets >= 0, axis=1)
    if configs is None:
        configs = "idle" if kind == "wncs" else "all"
    if isinstance(configs, str):
        if configs == "idle":
            cfg_ids = idle_configs(mdp)
            if not cfg_ids:
                raise ModelError(f"{mdp.name}: no idle-server configuration (is this a Section II model?)")
        elif configs == "all":
            cfg_ids = [c for c in range(len(space.configs)) if nfeas[c] >= 2]
        else:
            raise ModelError(f"configs must be 'idle', 'all' or a list of configuration ids, got {configs!r}")
    else:
        cfg_ids = [int(c) for c in configs]
        for c in cfg_ids:
            if not 0 <= c < len(space.configs):
                raise ModelError(f"configuration id {c} out of range 0..{len(space.configs) - 1}")
    directions: list[tuple[int, ...]] = [tuple(int(i == k) for i in range(N)) for k in range(N)]
    directions += [tuple(int(i in (a, b)) for i in range(N)) for a in range(N) for b in range(a + 1, N)]
    line_summary, gaps = _line_structure(ctx, cfg_ids, directions)
    grec, gcap, gsize = _gap_violations(ctx, gaps)

    if kind != "wncs":
        order = _pick_examples(grec, gcap, gsize, examples)
        ex = [_gap_violation(ctx, gaps[int(i)], grec[i], gcap[i]) for i in order]
        worst = None
        if gaps:
            i = int(np.argmax(np.abs(gsize)))
            worst = _gap_violation(ctx, gaps[i], grec[i], gcap[i])
        checked = sum(v["checked"] for v in line_summary.values())
        serving = [c for c in cfg_ids if space.configs[c][1] is not None]
        details = {"lines": line_summary, "configurations": len(cfg_ids), "configurations_serving": len(serving)}
        notes = ("Preemption model: Theorem 2 is stated for the Section II model; here the C9 reading is checked -- "
                 "each action's region is an interval on every axis-parallel and diagonal line of every configuration "
                 "with >= 2 feasible actions (tie-robust).")
        return _report("threshold", "C9 (Figs. 11-12): preemption policy of threshold (switching-curve) type", ctx,
                       holds=not gaps, checked=checked, violations=len(gaps), rec=grec, cap=gcap, ties=0,
                       unit="(line, action) pairs", worst=worst, examples=ex, details=details, notes=notes, t0=t0)

    # ---- Theorem 2 rays
    n_checked = 0
    n_ties = 0
    per_action: dict[str, dict[str, int]] = {}
    recs: list[np.ndarray] = []
    rows: list[np.ndarray] = []  # columns: s, s', z, a, size
    table = mdp.action_table
    dir_of = {a: _theorem2_direction(tuple(int(x) for x in np.atleast_1d(table[a])), N) for a in range(table.shape[0])}
    dirs = sorted({d for d in dir_of.values() if d is not None})
    n_sources = 0
    for d in dirs:
        lines = _lines(caps, d)
        L = lines.shape[1]
        if L < 2:
            continue
        iu, ju = np.triu_indices(L, 1)
        acts_d = np.array([a for a, dd in dir_of.items() if dd == d], dtype=np.int64)
        for c in cfg_ids:
            G = space.lookup_grid(c).ravel()
            S = np.where(lines >= 0, G[np.maximum(lines, 0)], -1)
            src, tgt = S[:, iu], S[:, ju]
            zz = np.broadcast_to(ju - iu, src.shape)
            ok = (src >= 0) & (tgt >= 0)
            ok[ok] &= np.isin(ctx.act[src[ok]], acts_d)
            s, t, z = src[ok], tgt[ok], zz[ok]
            a = ctx.act[s]
            n_checked += s.size
            srcs = S[(S >= 0)]
            n_sources += int(np.count_nonzero(np.isin(ctx.act[srcs], acts_d)))
            diff_act = ctx.act[t] != a
            qa = ctx.q_of(t, a)
            gap = qa - ctx.q_pi[t]
            tie = diff_act & (np.abs(gap) <= ctx.tol)
            bad = diff_act & ~tie
            n_ties += int(np.count_nonzero(tie))
            for aa in np.unique(a):
                lab = str(ctx.action(aa))
                e = per_action.setdefault(lab, {"checked": 0, "violations": 0, "ties": 0})
                m = a == aa
                e["checked"] += int(np.count_nonzero(m))
                e["violations"] += int(np.count_nonzero(bad & m))
                e["ties"] += int(np.count_nonzero(tie & m))
            rows.append(np.stack([s[bad], t[bad], z[bad], a[bad]], axis=1))
            recs.append(gap[bad])
    R = np.concatenate(rows) if rows else np.zeros((0, 4), np.int64)
    size = np.concatenate(recs) if recs else np.zeros(0)
    rec = (ctx.recurrent[R[:, 0]] & ctx.recurrent[R[:, 1]]) if R.size else np.zeros(0, bool)
    cap = (ctx.at_cap[R[:, 0]] | ctx.at_cap[R[:, 1]]) if R.size else np.zeros(0, bool)

    def make(i: int) -> Violation:
        s, t, z, a = (int(x) for x in R[i])
        return ctx.violation(
            "ray", size[i], (s, t), rec[i], cap[i],
            {"z": z, "action_at_s": list(ctx.action(a)), "action_at_s_prime": list(ctx.action(ctx.act[t])),
             "Q_claimed": float(ctx.q_of(np.array([t]), np.array([a]))[0]), "Q_chosen": float(ctx.q_pi[t]),
             "recurrent_each": [bool(ctx.recurrent[s]), bool(ctx.recurrent[t])],
             "meaning": "pi(s) = action_at_s but at s' = s + z(e_k1 + e_k2) the claimed action is worse by size"},
        )

    ex = [make(int(i)) for i in _pick_examples(rec, cap, size, examples)]
    worst = make(int(np.argmax(np.abs(size)))) if size.size else None
    violating_sources = int(np.unique(R[:, 0]).size) if R.size else 0
    targets = np.unique(R[:, 1]) if R.size else np.zeros(0, np.int64)
    details = {
        "configurations": [space.describe_config(space.configs[c]) for c in cfg_ids],
        "source_states": n_sources,
        "violating_source_states": violating_sources,
        "violating_target_states": int(targets.size),
        "target_recurrent": int(np.count_nonzero(ctx.recurrent[R[:, 1]])) if R.size else 0,
        "violating_target_stationary_mass": (None if ctx.stationary is None
                                             else float(ctx.stationary[targets].sum())),
        "per_action": per_action,
        "lines": line_summary,
        "line_gaps": {"count": len(gaps), "split": _split(grec, gcap),
                      "examples": [_gap_violation(ctx, gaps[int(i)], grec[i], gcap[i]).to_json()
                                   for i in _pick_examples(grec, gcap, gsize, examples)]},
    }
    notes = ("Theorem 2 in the idle-server configuration: one case per (s, z); ties (claimed action optimal at s' "
             "within tol) are not violations. 'details.lines' reports, separately and outside the verdict, whether "
             "every action region is an interval along each tau axis and each diagonal e_i + e_j.")
    return _report("threshold", "Theorem 2 (C8): pi(s) = (k1, k2) => pi(s + z(e_k1 + e_k2)) = (k1, k2) in idle states",
                   ctx, holds=(R.shape[0] == 0), checked=n_checked, violations=R.shape[0], rec=rec, cap=cap,
                   ties=n_ties, unit="(state, z) pairs", worst=worst, examples=ex, details=details, notes=notes, t0=t0)


# ============================================================================ Theorem 3
def check_consistency(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
    ctx: PolicyContext | None = None,
) -> CheckReport:
    r"""Theorem 3 (claim C10, preemption model): a started job is not preempted before it completes.

    *Starts.* A state s starts a job when ``pi(s) = (k,)`` with ``k != 0``: process k's fresh update
    enters service as ``(k, T_k, U)`` (on an idle server, preempting another process's job, or
    cancelling k's own job in service -- sub-counted).

    *Tree.* While the started job is in service, the next state is random (arrivals, downlink
    outcome). From each start the check follows **every** positive-probability successor
    under the policy (the rows of ``P``: equal next states of different channel outcomes are one
    branch). At a state x reached with the job still in service:

    * if ``pi(x) = (0,)`` (keep going) the job gets one more slot; if it had ``d = 1`` slot
      left it completes there (the path ends, consistent); otherwise every successor is followed;
    * if ``pi(x) = (j,)`` with ``j != 0`` the job is preempted (``j != k``) or cancelled
      (``j = k``) before completing: the path ends in a **violation** -- unless keeping going is
      optimal within tol, ``|Q(x, 0) - Q(x, pi(x))| <= tol``, which counts as a tie and the
      keep-going branch is followed instead.

    The job's identity is the job of process k in service (at most one job per process exists),
    so the exploration is memoised on the state x alone; each tree has depth <= T_k - 1.

    Counts: ``checked`` = start states; ``violations`` = start states whose tree contains a
    violating path; ``details["by_start_type"]`` splits both by the kind of start (on an idle
    server, preempting another process's job -- claim C10's reading --, restarting its own
    process; and whether another process's update was also available, i.e. the start was a
    choice); ``details`` adds the number of paths and of violating paths (over all trees),
    the probability that a start is later preempted/cancelled (max, and the long-run frequency
    ``sum_s pi(s) P(violation | start at s)``), and the starts by type. A violating start is
    recurrent when the start state is; it is *at cap* when every violating path from it passes
    through a state with some tau at its cap. The worst violation is the start with the largest
    violation probability; ``details["counterexample"]`` is one violating path in full (recurrent
    and below the cap when one exists).

    Raises
    ------
    ModelError
        If the model is not a preemption model.
    """
    t0 = time.perf_counter()
    if model_kind(mdp) != "preemption":
        raise ModelError(f"{mdp.name}: the consistency check (Theorem 3) applies to the preemption model only")
    ctx = _ctx(mdp, solution, tolerance, stationary_tol, ctx)
    space = mdp.states
    nC = len(space.configs)
    table = mdp.action_table
    a_lab = np.asarray(table[:, 0], dtype=np.int64)  # action index -> process started (0 = keep going)
    cfg = np.asarray(space.config)
    job_k = np.zeros(nC, np.int64)
    job_d = np.zeros(nC, np.int64)
    for c, conf in enumerate(space.configs):
        job = conf[1]
        if job is not None:
            job_k[c], job_d[c] = int(job[0]), int(job[1])
    zero_idx = np.flatnonzero(a_lab == 0)
    if zero_idx.size != 1:
        raise ModelError("the preemption model must have exactly one keep-going action (0,)")
    a0 = int(zero_idx[0])
    n = mdp.n_states
    P = mdp.P
    pol = np.asarray(solution.policy, dtype=np.int64)
    started = a_lab[ctx.act]  # process started in each state (0 = none)
    pair0 = mdp.pair_ptr[:-1] + ctx.offsets[cfg, a0]
    q0 = ctx.q[pair0]
    tie_at = (started != 0) & (np.abs(q0 - ctx.q_pi) <= ctx.tol)

    # memo over states "our job (the job of process job_k in service) in service at x"
    paths = np.full(n, -1, dtype=np.int64)
    bad = np.zeros(n, np.int64)
    bad_free = np.zeros(n, np.int64)
    pviol = np.zeros(n)
    ties_seen = np.zeros(n, bool)
    kind_of = np.zeros(n, np.int8)  # at a violating node: 1 preempt, 2 cancel

    def succ(pair: int) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = P.indptr[pair], P.indptr[pair + 1]
        return P.indices[lo:hi], P.data[lo:hi]

    def node(x: int) -> None:
        if paths[x] >= 0:
            return
        c = cfg[x]
        k = job_k[c]
        if k == 0:
            raise ModelError(f"internal error: no job in service at {ctx.label(x)} while following a started job")
        j = started[x]
        if j != 0 and not tie_at[x]:
            paths[x], bad[x], pviol[x] = 1, 1, 1.0
            bad_free[x] = 0 if ctx.at_cap[x] else 1
            kind_of[x] = 2 if j == k else 1
            return
        if tie_at[x]:
            ties_seen[x] = True
        pair = int(pol[x]) if j == 0 else int(pair0[x])
        if job_d[c] <= 1:  # completes in this slot
            paths[x], bad[x], bad_free[x], pviol[x] = 1, 0, 0, 0.0
            return
        cols, probs = succ(pair)
        tp = tb = tbf = 0
        pv = 0.0
        for y, p in zip(cols, probs):
            node(int(y))
            tp += paths[y]
            tb += bad[y]
            tbf += bad_free[y]
            pv += p * pviol[y]
        paths[x], bad[x], pviol[x] = tp, tb, pv
        bad_free[x] = 0 if ctx.at_cap[x] else tbf

    starts = np.flatnonzero(started != 0)
    s_paths = np.zeros(starts.size, np.int64)
    s_bad = np.zeros(starts.size, np.int64)
    s_bad_free = np.zeros(starts.size, np.int64)
    s_pv = np.zeros(starts.size)
    start_type = np.zeros(starts.size, np.int8)  # 0 idle, 1 preempting, 2 restart own
    for i, s in enumerate(starts):
        s = int(s)
        k = int(started[s])
        cur = job_k[cfg[s]]
        start_type[i] = 0 if cur == 0 else (2 if cur == k else 1)
        cols, probs = succ(int(pol[s]))
        tp = tb = tbf = 0
        pv = 0.0
        if cols.size and job_k[cfg[int(cols[0])]] != k:
            tp = 1  # T_k = 1: the job completes within the start slot (every successor agrees)
        else:
            for y, p in zip(cols, probs):
                y = int(y)
                node(y)
                tp += paths[y]
                tb += bad[y]
                tbf += bad_free[y]
                pv += p * pviol[y]
        s_paths[i], s_bad[i], s_pv[i] = tp, tb, pv
        s_bad_free[i] = 0 if ctx.at_cap[s] else tbf
    viol = s_bad > 0
    vs = starts[viol]
    rec = ctx.recurrent[vs]
    cap = s_bad_free[viol] == 0
    size = s_pv[viol]

    def trajectory(s: int) -> list[dict]:
        """One violating path from start s: prefer cap-free branches, then the likeliest."""
        steps = [{"state": s, "label": ctx.label(s), "action": list(ctx.action(ctx.act[s])), "prob": 1.0,
                  "at_cap": bool(ctx.at_cap[s]), "recurrent": bool(ctx.recurrent[s])}]
        pair = int(pol[s])
        k = int(started[s])
        while True:
            cols, probs = succ(pair)
            best, key = None, None
            for y, p in zip(cols, probs):
                y = int(y)
                if job_k[cfg[y]] != k or paths[y] < 0 or bad[y] == 0:
                    continue
                kk = (bad_free[y] > 0, p)
                if key is None or kk > key:
                    best, key = (y, float(p)), kk
            if best is None:
                raise ModelError("internal error: lost the violating branch while rebuilding a trajectory")
            y, p = best
            j = int(started[y])
            step = {"state": y, "label": ctx.label(y), "action": list(ctx.action(ctx.act[y])), "prob": p,
                    "at_cap": bool(ctx.at_cap[y]), "recurrent": bool(ctx.recurrent[y])}
            if j != 0 and not tie_at[y]:
                step["event"] = "preempts the started job" if j != k else "cancels (restarts) the started job"
                step["Q_keep_going_minus_Q_chosen"] = float(q0[y] - ctx.q_pi[y])
                steps.append(step)
                return steps
            if tie_at[y]:
                step["note"] = "preempting ties with keeping going; followed keep-going"
            steps.append(step)
            pair = int(pol[y]) if j == 0 else int(pair0[y])

    def make(i: int) -> Violation:
        s = int(vs[i])
        traj = trajectory(s)
        last = traj[-1]
        return ctx.violation(
            "preempt" if "preempts" in last.get("event", "") else "cancel",
            size[i], (s, last["state"]), rec[i], cap[i],
            {"violation_probability": float(size[i]), "violating_paths": int(s_bad[viol][i]),
             "paths": int(s_paths[viol][i]), "cap_free_violating_paths": int(s_bad_free[viol][i]),
             "steps": len(traj) - 1, "trajectory": traj},
        )

    ex_idx = _pick_examples(rec, cap, size, examples)
    ex = [make(int(i)) for i in ex_idx]
    worst = make(int(np.argmax(size))) if size.size else None
    counterexample = ex[0].info["trajectory"] if ex else None
    stationary = ctx.stationary
    freq = float(np.dot(stationary[starts], s_pv)) if stationary is not None and starts.size else None
    start_freq = float(stationary[starts].sum()) if stationary is not None and starts.size else None
    vnodes = np.flatnonzero(kind_of > 0)
    types = {0: "idle_server", 1: "preempting", 2: "restarting_own"}
    # was another process's update available at the start (the start was a choice between two)?
    other = np.array([any(x for j, x in enumerate(space.configs[cfg[s]][0], 1) if j != started[s])
                      for s in starts], dtype=bool) if starts.size else np.zeros(0, bool)
    rec_all = ctx.recurrent[starts]
    cap_all = s_bad_free == 0

    def breakdown(sel: np.ndarray) -> dict[str, int]:
        v = sel & viol
        return {"checked": int(np.count_nonzero(sel)), "violations": int(np.count_nonzero(v)),
                "recurrent_violations": int(np.count_nonzero(v & rec_all)),
                "at_cap_violations": int(np.count_nonzero(v & cap_all)),
                "recurrent_below_cap": int(np.count_nonzero(v & rec_all & ~cap_all))}

    selections = {types[t]: start_type == t for t in types}
    selections["other_update_available"] = other
    selections["preempting_with_other_available"] = (start_type == 1) & other
    by_type = {name: breakdown(sel) for name, sel in selections.items()}
    for name, sel in selections.items():  # one counterexample per kind of start
        cand = np.flatnonzero(sel & viol)
        if cand.size:
            best = cand[np.lexsort((-s_pv[cand], cap_all[cand], ~rec_all[cand]))[0]]
            i = int(np.searchsorted(vs, starts[best]))
            by_type[name]["counterexample"] = make(i).to_json()
    details = {
        "starts_by_type": {types[t]: int(np.count_nonzero(start_type == t)) for t in types},
        "violating_starts_by_type": {types[t]: int(np.count_nonzero(start_type[viol] == t)) for t in types},
        "by_start_type": by_type,
        "paths": int(s_paths.sum()),
        "violating_paths": int(s_bad.sum()),
        "cap_free_violating_paths": int(s_bad_free.sum()),
        "violating_nodes": {"preempt": int(np.count_nonzero(kind_of == 1)), "cancel": int(np.count_nonzero(kind_of == 2)),
                            "recurrent": int(np.count_nonzero(ctx.recurrent[vnodes]))},
        "max_violation_probability": float(s_pv.max()) if s_pv.size else 0.0,
        "long_run_start_frequency": start_freq,
        "long_run_violation_frequency": freq,
        "tie_nodes": int(np.count_nonzero(ties_seen)),
        "counterexample": counterexample,
    }
    notes = ("One case = one state where the policy starts a job; a violation = a start whose tree of every "
             "positive-probability successor (until the job completes) contains a state where the policy preempts "
             "or cancels that job; a path = a root-to-leaf branch of that tree. Ties (keeping going optimal within "
             "tol) are followed as keep-going and counted in 'ties' (tie states visited).")
    return _report("consistency", "Theorem 3 (C10): a started job is not preempted or cancelled before it completes",
                   ctx, holds=not viol.any(), checked=starts.size, violations=int(viol.sum()), rec=rec, cap=cap,
                   ties=int(np.count_nonzero(ties_seen)), unit="start states", worst=worst, examples=ex,
                   details=details, notes=notes, t0=t0)


# ============================================================================ all
def verify_all(
    mdp: MDP,
    solution: Solution,
    *,
    tolerance: Tolerance | None = None,
    examples: int = DEFAULT_EXAMPLES,
    stationary_tol: float = 0.0,
) -> list[CheckReport]:
    """Run every check that applies to the model kind.

    Section II (``wncs``): monotonicity, threshold (Theorem 2). Preemption: monotonicity,
    threshold (C9 switching-curve form), consistency (Theorem 3). The shared data
    (Q-values, recurrence) is computed once.

    Returns
    -------
    list[CheckReport]
    """
    ctx = policy_context(mdp, solution, tolerance, stationary_tol=stationary_tol)
    out = [
        check_monotonicity(mdp, solution, examples=examples, ctx=ctx),
        check_threshold(mdp, solution, examples=examples, ctx=ctx),
    ]
    if model_kind(mdp) == "preemption":
        out.append(check_consistency(mdp, solution, examples=examples, ctx=ctx))
    return out
