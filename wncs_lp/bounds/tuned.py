r"""Tables tuned for a policy: a bound's value tables reweighted per class of processes.

A relaxation's tables h(s) = sum_G h_G(tau_G, column_G(C)) (one block G a process, a group or a
pair) are each exact for a relaxed problem, not for the real one: the servers' coupling is only
priced, so the relative weight a block's table carries against another's when the greedy policy
(or its lookahead, or its rollout) compares actions is the relaxation's, not the system's. The
tuned tables put one weight on each *class* of blocks (blocks whose private systems are the same
chain: :func:`table_classes`, the interchangeable copies of a process type share one),

.. math:: h_w(s) = \sum_G w_{\kappa(G)}\, h_G(\tau_G, \mathrm{column}_G(C)),

and choose the weights w by a coordinate search on the simulated average cost of the policy built
on h_w (:func:`tune_tables`; or of a cheaper policy on the same tables, :func:`tuning_proxy`, where a
lookahead or rollout decision costs tens to hundreds of greedy ones): from w = 1, each class's weight is multiplied by 1 +- step, the move
kept when it lowers the mean (by more than ``accept_se`` standard errors of the paired difference,
replication by replication on the same seeds, when that is set), the steps shrinking in turn (:data:`TUNE`). Every candidate is simulated
with the same seed (common random numbers: the comparison of two weights is far less noisy than
either mean) and the bound's own tables as the control variate. The weights are normalised to a
mean of 1 over the processes (the greedy policy does not see a common scale; the lookahead and
the rollout add costs to the tables and do).

**The tuning seed is not the evaluation seed.** The search selects on the noise of its own
simulations, so its means are biased low; a gap report evaluates the tuned policy on fresh
randomness: :func:`~wncs_lp.bounds.gaps.policy_gaps` tunes on ``seed + TUNE_SEED_OFFSET`` and
evaluates on ``seed`` (the pilot of :func:`~wncs_lp.bounds.gaps.policy_source` uses ``seed + 1``),
so the reported one-sided upper confidence limit stays an honest limit on the tuned policy,
which is fixed before the evaluation draws its first number. The tuned tables certify nothing
(the reweighted result has no bound, :func:`reweighted`); the gaps stay against the bound's
certificate.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ..errors import PolicyError
from ..models.system import System
from ..policies.base import Policy
from ..simulate import simulate
from .lookahead import LookaheadPolicy, TableRolloutPolicy, auto_candidates
from .policy import BoundPolicy, GroupBoundPolicy, bound_policy
from .private import chain_key
from .projected import PROJECTED, ProjectedValue
from .result import BoundResult, GroupTables, ValueTables

__all__ = ["TunedTables", "tune_tables", "tuned_policy", "tuning_proxy", "table_classes", "reweighted", "TUNE",
           "TUNE_SEED_OFFSET", "TUNED_TARGETS", "TUNED_NAMES", "PROXY_ROLLOUT_CANDIDATES",
           "TUNED_LOOKAHEAD_CANDIDATES"]

#: The tuning's simulation of each candidate (``reps`` x ``slots`` slots after ``burn_in``), the
#: step factors of the coordinate search in turn, and its budget of simulated candidates.
#: ``accept_se``: a move is kept when its paired mean difference is below minus this many of its
#: standard errors. 0 (any lower mean) by default: 2.0 kept the tuning from following the noise where
#: the weights are worth less than it (the paper's four types four times), but also stopped it at
#: w = 1 where a first +-10% move gains less than its noise and the later ones much more (processes
#: 1-3 at cap 12: the greedy policy stayed +2.62% above g*, against +0.046% with 0).
#: ``proxy``: the policy the search simulates (:func:`tuning_proxy`; "auto": where the lookahead by name
#: takes fewer than every action, the greedy policy for the lookahead and the rollout with
#: :data:`PROXY_ROLLOUT_CANDIDATES` candidates for the rollout, else the target itself).
TUNE = {"slots": 2_500, "reps": 8, "burn_in": 300, "steps": (0.1, 0.04), "max_evaluations": 40, "accept_se": 0.0,
        "proxy": "auto"}
#: A move must lower the mean by more than this share of it (rounding), whatever ``accept_se``.
MOVE_RTOL = 1e-9
#: The tuned lookahead's candidates where the lookahead by name takes fewer than every action (16 of
#: 240 at sixteen processes): at the sixteen lab sensors 8 gave the same gain to its noise for two
#: thirds of the evaluation's CPU (docs/bounds.md, "Tuned tables").
TUNED_LOOKAHEAD_CANDIDATES = 8
#: The rollout's candidates in the tuning's search by ``proxy="auto"`` on systems with more than 64
#: actions in some configuration (the rollout by name takes 8 there).
PROXY_ROLLOUT_CANDIDATES = 2
#: The tuning simulates on the evaluation seed plus this (the pilot of ``policy_source`` takes + 1).
TUNE_SEED_OFFSET = 2
#: The policies whose tables can be tuned: the target is the policy the weights are tuned for and
#: the one built on them.
TUNED_TARGETS = ("greedy", "lookahead", "rollout")
#: The policy names (:data:`~wncs_lp.policies.factory.BOUND_POLICY_NAMES`) and the target each tunes.
TUNED_NAMES = {"tuned": "greedy", "tuned_lookahead": "lookahead", "tuned_rollout": "rollout"}


@dataclass(frozen=True, eq=False)
class TunedTables:
    """Weights per class of a bound's table blocks, tuned by simulation (:func:`tune_tables`).

    Attributes
    ----------
    target : str
        The policy the weights were tuned for and are used by (one of :data:`TUNED_TARGETS`).
    weights : numpy array
        One weight per class (mean 1 over the processes).
    classes : numpy array of int
        The class of each block of the tables (:func:`table_classes`).
    result : BoundResult
        The bound's result with the reweighted tables (:func:`reweighted`; no bound of its own).
    base_mean, tuned_mean : float
        The tuning simulation's mean at w = 1 and at the weights returned (on the tuning seed: the
        latter is biased low by the search's selection, see the module docstring).
    evaluations : int
        Candidates simulated.
    seed : int
        The tuning simulation's seed.
    settings : dict
        slots, reps, burn_in, steps, max_evaluations, accept_se, proxy (the policy the search simulated).
    history : tuple of (weights, mean)
        Every accepted move.
    seconds : float
    """

    target: str
    weights: np.ndarray
    classes: np.ndarray
    result: BoundResult
    base_mean: float
    tuned_mean: float
    evaluations: int
    seed: int
    settings: dict
    history: tuple = field(default=(), repr=False)
    seconds: float = 0.0

    def summary(self) -> dict[str, Any]:
        return {"target": self.target, "weights": [float(w) for w in self.weights],
                "classes": [int(c) for c in self.classes], "base_mean": self.base_mean,
                "tuned_mean": self.tuned_mean, "evaluations": self.evaluations, "tuning_seed": self.seed,
                **self.settings, "seconds": self.seconds}


def _blocks(tables: ValueTables | GroupTables) -> list[tuple[int, ...]]:
    return [tuple(int(k) for k in g) for g in tables.groups] if isinstance(tables, GroupTables) else \
        [(k,) for k in range(tables.n_processes)]


def table_classes(tables: ValueTables | GroupTables, system: System) -> np.ndarray:
    """The class of each block of ``tables`` (a process of :class:`ValueTables`, a group of
    :class:`GroupTables`): blocks whose private systems (the block's processes alone with their own
    servers, :meth:`~wncs_lp.models.base.Model.group_scenario`) are the same chain share a class,
    numbered in the order of their first block."""
    keys = [chain_key(system.model.group_scenario(g)) for g in _blocks(tables)]
    first: dict[str, int] = {}
    return np.array([first.setdefault(k, len(first)) for k in keys], np.int64)


def reweighted(result: BoundResult, weights: np.ndarray, classes: np.ndarray) -> BoundResult:
    """``result`` with each block's table multiplied by the weight of its class, and no bound: its
    ``lower_bound`` is NaN and ``certified_by`` says why (only the tables are for use, by the
    policies)."""
    w = np.asarray(weights, float)
    t = result.tables
    if w.ndim != 1 or np.any(~np.isfinite(w)) or np.any(w <= 0) or np.max(classes, initial=-1) >= w.size:
        raise PolicyError(f"weights must be positive and finite, one per class ({int(np.max(classes)) + 1}); got {w}")
    h = tuple(w[c] * np.asarray(hk, float) for c, hk in zip(classes, t.h))
    tables = GroupTables(t.groups, h, t.column) if isinstance(t, GroupTables) else ValueTables(h, t.column)
    return replace(result, lower_bound=float("nan"), relaxation_upper=float("inf"), tables=tables, alternatives=(),
                   certified_by=f"nothing: the {result.relaxation} tables reweighted per class for a policy "
                                f"(weights {np.round(w, 6).tolist()}); the bound is the original result's",
                   stats={**result.stats, "tuned_weights": w.tolist()})


def _builder(target: str, system: System, candidates: int | None = None) -> Callable[[Policy], Policy]:
    """The policy ``target`` on a greedy policy of tables (as the gap reports build it by name: the
    tuned lookahead with :data:`TUNED_LOOKAHEAD_CANDIDATES` candidates where the lookahead by name
    takes fewer than every action; with ``candidates`` the lookahead or the rollout with that many
    candidate actions instead)."""
    auto = auto_candidates(system)
    own = None if auto is None else min(auto, TUNED_LOOKAHEAD_CANDIDATES)
    makers = {"greedy": lambda g: g,
              "lookahead": lambda g: LookaheadPolicy(g, candidates or own),
              "rollout": lambda g: TableRolloutPolicy(g, candidates)}
    if target not in makers:
        raise PolicyError(f"target: expected one of {', '.join(TUNED_TARGETS)}, got {target!r}")
    return makers[target]


def tuning_proxy(system: System, target: str, proxy: int | str | None = "auto") -> tuple[str, int | None]:
    """The policy the tuning's search simulates for the weights of ``target``: (its kind, its candidates).

    ``proxy`` None: ``target`` itself, as it is built by name. ``"greedy"``: the greedy policy on the
    tables. A whole number K: ``target`` (the lookahead or the rollout) with K candidate actions.
    ``"auto"``: where the lookahead by name takes fewer than every action
    (:func:`~wncs_lp.bounds.lookahead.auto_candidates`: some configuration has more than 64 actions,
    where a lookahead or rollout decision costs tens to hundreds of greedy ones) the greedy policy
    for the lookahead and the rollout with :data:`PROXY_ROLLOUT_CANDIDATES` candidates for the
    rollout, else ``target`` itself. Measured (docs/bounds.md, "Tuned tables"): at the sixteen lab
    sensors the lookahead on weights tuned on the greedy policy is as good as on weights tuned on the
    lookahead itself, for a fifth of the tuning's CPU; at the paper's four types four times the
    rollout on greedy-tuned weights came out worse than untuned, on weights tuned on its
    2-candidate self no worse.
    """
    if target not in TUNED_TARGETS:
        raise PolicyError(f"target: expected one of {', '.join(TUNED_TARGETS)}, got {target!r}")
    if not (proxy in (None, "auto", "greedy") or (isinstance(proxy, (int, np.integer)) and not isinstance(proxy, bool)
                                                  and proxy >= 1)):
        raise PolicyError(f"proxy: expected None, 'auto', 'greedy' or a whole number of candidates >= 1, got {proxy!r}")
    if proxy is None or target == "greedy":
        return target, None
    if proxy == "auto":
        if auto_candidates(system) is None:
            return target, None
        return ("greedy", None) if target == "lookahead" else (target, PROXY_ROLLOUT_CANDIDATES)
    return ("greedy", None) if proxy == "greedy" else (target, int(proxy))


def _greedy_on(result: BoundResult, system: System, base: Policy | None, weights: np.ndarray,
               classes: np.ndarray, scratch: list) -> Policy:
    """The greedy policy on ``result`` (the reweighted tables), from ``base`` (the greedy policy on the
    original tables) where its precomputed expectations can be scaled instead of computed again:
    they are linear in the tables (W_k = E[h_k(s')] of :class:`BoundPolicy`, W_G of
    :class:`GroupBoundPolicy`; the same values up to rounding, so actions that tie to rounding may
    go another way than in the policy built on ``result``, which is the one :func:`tuned_policy`
    builds and a report evaluates). The scaled tables are written into ``scratch`` (one buffer per block,
    allocated once: the candidates are simulated one after the other, and a policy built on them
    copies what it keeps). The greedy policy of relaxations 1 and 3 is built again (cheap)."""
    def scaled(tables: tuple) -> tuple:
        if not scratch:
            scratch.extend(np.empty_like(W) for W in tables)
        return tuple(np.multiply(W, weights[c], out=out) for c, W, out in zip(classes, tables, scratch))

    if isinstance(base, BoundPolicy) and base.tables is not None:
        pol = copy.copy(base)
        pol._h = result.tables.h
        pol.tables = scaled(base.tables)
    elif isinstance(base, GroupBoundPolicy) and all(W is not None for W in base.lookahead):
        pol = copy.copy(base)
        pol.tables = result.tables
        pol.lookahead = scaled(base.lookahead)
    else:
        return bound_policy(result, system)
    pol.result = result
    return pol


def tune_tables(bound: BoundResult, system: System, target: str = "greedy", *, seed: int = TUNE_SEED_OFFSET,
                slots: int = TUNE["slots"], reps: int = TUNE["reps"], burn_in: int = TUNE["burn_in"],
                steps: tuple = TUNE["steps"], max_evaluations: int = TUNE["max_evaluations"],
                accept_se: float = TUNE["accept_se"], proxy: int | str | None = TUNE["proxy"]) -> TunedTables:
    """Weights per class of ``bound``'s tables for the policy ``target`` built on them (module docstring).

    Parameters
    ----------
    bound : BoundResult
        Its tables are reweighted (any relaxation's).
    system : System
    target : {"greedy", "lookahead", "rollout"}
        The policy simulated for each candidate: the greedy policy on the tables, the two-step
        lookahead (:data:`TUNED_LOOKAHEAD_CANDIDATES` candidates where some configuration has more than 64
        actions, else every action) or the rollout
        (:class:`~wncs_lp.bounds.lookahead.TableRolloutPolicy` with its defaults).
    seed : int
        The tuning's simulation seed, the same for every candidate (common random numbers). Keep it
        apart from the seed the tuned policy is then evaluated on (``policy_gaps`` takes its own
        seed + :data:`TUNE_SEED_OFFSET`).
    slots, reps, burn_in : int
        Each candidate's simulation.
    steps : tuple of float
        The factors 1 +- step tried on each class's weight, one step size after the other (each
        until a pass over the classes improves nothing).
    max_evaluations : int
        At most this many candidates simulated (the start included).
    accept_se : float
        A move is kept when the mean over replications of (candidate - incumbent), replication by
        replication, is below ``-accept_se`` times its standard error (0: any lower mean), and
        below rounding (:data:`MOVE_RTOL` of the mean) in any case.
    proxy : None, "auto", "greedy" or int
        The policy simulated for each candidate when it is not ``target`` as built by name
        (:func:`tuning_proxy`: tune on a cheaper policy, use the weights on the dearer one).

    Returns
    -------
    TunedTables
        With one class only (every block the same chain) the weights are 1 and nothing is
        simulated: a common scale is all a single weight could change.
    """
    kind, k = tuning_proxy(system, target, proxy)
    build = _builder(kind, system, k)
    if not (isinstance(max_evaluations, (int, np.integer)) and max_evaluations >= 1) or \
            not all(0 < float(x) < 1 for x in steps) or not float(accept_se) >= 0:
        raise PolicyError(f"max_evaluations must be >= 1, each step in (0, 1) and accept_se >= 0; got "
                          f"{max_evaluations}, {steps}, {accept_se}")
    t0 = time.perf_counter()
    classes = table_classes(bound.tables, system)
    sizes = np.array([len(g) for g in _blocks(bound.tables)], float)
    n_cls = int(classes.max()) + 1
    settings = {"slots": int(slots), "reps": int(reps), "burn_in": int(burn_in), "steps": [float(x) for x in steps],
                "max_evaluations": int(max_evaluations), "accept_se": float(accept_se),
                "proxy": kind if k is None else f"{kind}-k{k}"}
    ones = np.ones(n_cls)
    if n_cls == 1:
        return TunedTables(target, ones, classes, reweighted(bound, ones, classes), float("nan"), float("nan"), 0,
                           int(seed), settings, (), time.perf_counter() - t0)
    lazy = system.is_lazy and bound.relaxation in PROJECTED
    control = ProjectedValue(bound, system) if lazy else bound.tables.value

    def normal(w: np.ndarray) -> np.ndarray:
        return w * sizes.sum() / float(np.dot(w[classes], sizes))

    base = bound_policy(bound, system)
    scratch: list = []

    def rep_means(w: np.ndarray) -> np.ndarray:
        greedy = _greedy_on(reweighted(bound, w, classes), system, base, w, classes, scratch)
        res = simulate(build(greedy), slots=slots, reps=reps, seed=seed, burn_in=burn_in, control=control,
                       progress=False)
        return np.asarray(res.rep_means, float)

    def beats(y: np.ndarray, inc: np.ndarray) -> bool:
        d = y - inc
        se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else 0.0
        # by more than rounding too: weights that change no decision give the same paths, whose
        # means then differ in the last bits only, and such a move would let a weight drift
        floor = MOVE_RTOL * abs(float(inc.mean()))
        return float(d.mean()) < -max(float(accept_se) * se, floor)

    w = ones
    inc = rep_means(w)  # the incumbent's per-replication means
    base_mean = float(inc.mean())
    history = [(w.copy(), base_mean)]
    n = 1
    for step in steps:
        improved = True
        while improved and n < max_evaluations:
            improved = False
            for c in range(n_cls):
                trial = []
                for f in (1.0 + step, 1.0 - step):
                    if n >= max_evaluations:
                        break
                    cand = w.copy()
                    cand[c] *= f
                    cand = normal(cand)
                    trial.append((rep_means(cand), cand))
                    n += 1
                if trial:
                    y, cand = min(trial, key=lambda x: float(x[0].mean()))
                    if beats(y, inc):
                        inc, w, improved = y, cand, True
                        history.append((w.copy(), float(inc.mean())))
    return TunedTables(target, w, classes, reweighted(bound, w, classes), base_mean, float(inc.mean()), n, int(seed),
                       settings, tuple(history), time.perf_counter() - t0)


def tuned_policy(tuned: TunedTables, system: System) -> Policy:
    """The policy ``tuned.target`` on the tuned tables, named ``tuned-<target>[...]`` and carrying the
    tuning's summary as ``policy.tuning``."""
    pol = _builder(tuned.target, system)(bound_policy(tuned.result, system))
    pol.name = f"tuned-{tuned.target}[{tuned.result.relaxation}]"
    pol.tuning = tuned.summary()
    return pol
