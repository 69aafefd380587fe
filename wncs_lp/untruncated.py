r"""The answer without the AoI cap: an interval for the untruncated optimum.

Every exact result of the toolkit is computed with a cap :math:`\hat\tau_k` on the AoI; the
paper's system has none. With :math:`g^*_\infty` the optimal average cost of the untruncated
system (``docs/model.md``, "The truncation and the untruncated optimum", proves both ends):

* **lower end.** :math:`g^*(\hat\tau) \le g^*_\infty`: under common channel outcomes the capped
  AoI is :math:`\min(\tau, \hat\tau)`, never above the true one, and q_k is nondecreasing. So the
  certified lower end of a truncated solve (``gain_lower``), and any certified lower bound on
  it (:mod:`wncs_lp.bounds`), is a lower bound on :math:`g^*_\infty`;
* **upper end.** any policy of the truncated model, applied to the clipped AoI
  :math:`\min(\tau, \hat\tau)`, is a policy of the untruncated system, so its untruncated gain is
  at least :math:`g^*_\infty`. It is simulated without the cap (:func:`simulate_uncapped`: the
  true AoI grows freely and is charged the true cost; the policy sees the clipped AoI), and the
  upper end is the one-sided upper confidence limit of that estimate (independent replications,
  Student t with R - 1 degrees of freedom): a statement at that confidence level, not a
  certificate.

The upper end is only as good as the simulation: when (1 - p) rho(A)^2 approaches 1 the
untruncated cost has heavy tails (and beyond it an infinite mean), which a finite run
under-reports; :attr:`UntruncatedInterval.max_tau` (the largest AoI the run reached) shows how
far the run went past the cap.

No upper end is simulated for a system with random arrivals or with a cost given as a table
(:func:`uncapped_refusal` says why, naming the field): the capped system keeps the ages of the
sensors' updates only up to the cap (``docs/model.md``, "Random arrivals"), so a run without the
cap would deliver an old update with a smaller age than its true one and under-report the cost;
and a table defines q only up to its last value. The lower end holds for both.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as sps

from .errors import ModelError, SolverError
from .mdp import MAX_COST
from .models.cost import process_cost
from .policies import ClippedPolicy, Policy, as_policy
from .simulate import SimulationResult, checked_run, simulate

__all__ = ["UntruncatedInterval", "Candidate", "UncappedPolicy", "UnboundedCost", "simulate_uncapped",
           "untruncated_interval", "uncapped_refusal"]


class UnboundedCost(ModelError):
    """An uncapped run reached an AoI whose cost passes the largest the toolkit takes: the policy
    starves that process, and its untruncated cost is unbounded in effect."""

    def __init__(self, message: str, note: str):
        super().__init__(message)
        self.note = note


def uncapped_refusal(scenario: Any) -> str:
    """Why no policy can be simulated without the cap on ``scenario`` (empty when it can).

    * random arrivals (``arrival_probability < 1``): the configurations keep a sensor's age and
      the jobs' ages at send only up to a_k (lumped, ``docs/model.md``), exact for the capped model
      only; without the cap a delivered old update would set the AoI to the cap instead of its true
      age, a cost below the true one -- no upper end;
    * a cost given as a table: q is defined only up to the table's last value, and the system
      without the cap needs q at every AoI.
    """
    for k, pr in enumerate(scenario.processes, start=1):
        if pr.has_arrivals:
            return (f"process[{k}].arrival_probability = {pr.arrival_probability:g} ({pr.name}): with random "
                    "arrivals the capped system keeps the sensors' and the jobs' ages only up to the cap, so a run "
                    "without the cap cannot carry an old update's true age")
        if pr.cost.family == "table":
            return (f"process[{k}].cost ({pr.name}) is a table of {len(pr.cost.table)} values: the cost past AoI "
                    f"{len(pr.cost.table)} is not defined, and the system without the cap needs it")
    return ""


class _GrowingCost:
    """q_k(1..L) of one process, extended (doubling L) whenever an AoI past L is asked for; the
    largest AoI asked for is kept (:attr:`max_tau`).

    Where doubling would pass the largest cost the solvers take (:data:`~wncs_lp.mdp.MAX_COST`),
    the table grows once to the longest length that stays below it (a bisection, O(L log L) in
    all) and that length is remembered (:attr:`ceiling`): an AoI past it raises
    :class:`UnboundedCost` at once. (Extending to exactly the AoI asked for instead recomputed
    the whole table at every step of a starving process: 150 s of the default reproduction.)"""

    def __init__(self, process: Any, length: int, source: str):
        self.process, self.source = process, source
        self.table = process_cost(process, int(length), source)
        self.max_tau = 0
        self.ceiling: int | None = None  # the longest table below MAX_COST, once a doubling hit it

    def _fits(self, length: int) -> np.ndarray | None:
        try:
            return process_cost(self.process, length, self.source)
        except ModelError:
            return None

    def _grow(self, need: int) -> None:
        if self.ceiling is None:
            table = self._fits(max(need, 2 * self.table.size))
            if table is not None:
                self.table = table
                return
            good, bad = self.table, max(need, 2 * self.table.size)  # q fits up to good.size, not up to bad
            while bad - good.size > 1:
                mid = (good.size + bad) // 2
                table = self._fits(mid)
                if table is None:
                    bad = mid
                else:
                    good = table
            self.table, self.ceiling = good, int(good.size)
        if need > self.table.size:
            try:
                process_cost(self.process, need, self.source)  # raises: the message names the AoI
            except ModelError as exc:
                note = f"the AoI of {self.process.name} reached {need}, where its cost passes {MAX_COST:g}"
                raise UnboundedCost(f"uncapped simulation: {exc}. Without the cap {note}: the policy starves it, "
                                    "and its untruncated average cost is unbounded in effect", note) from None
            raise AssertionError("a cost table past its ceiling did not overflow")  # pragma: no cover

    def __getitem__(self, idx: Any) -> np.ndarray:
        need = int(np.max(idx)) + 1
        self.max_tau = max(self.max_tau, need)
        if need > self.table.size:
            self._grow(need)
        return self.table[idx]

    def __len__(self) -> int:
        return int(self.table.size)


class UncappedPolicy(ClippedPolicy):
    """A policy of the truncated model acting on the untruncated system.

    Its :attr:`system` is the scenario's system with the caps raised to ``horizon`` (an AoI no
    run of that many slots can reach, so nothing is ever held at a cap) and cost tables that grow
    on demand. A rule defined for any AoI (``policy.aoi_free``: the rank rules, round robin,
    random) acts on the true AoI (:meth:`~wncs_lp.policies.Policy.on_system`); any other policy
    (a table over its AoI box: optimal, suboptimal) on the clipped AoI min(tau, tau_hat)
    (:class:`ClippedPolicy`).
    """

    def __init__(self, policy: Policy, horizon: int):
        base = policy.system
        sc = base.scenario
        why = uncapped_refusal(sc)
        if why:
            raise ModelError(f"{sc.source}: no run without the AoI cap: {why}")
        q = tuple(_GrowingCost(pr, max(2 * int(c), 64), sc.source) for pr, c in zip(sc.processes, base.caps))
        caps = np.full_like(base.caps, max(int(horizon), int(base.caps.max())))
        free = dataclasses.replace(base, caps=caps, q=q)
        super().__init__(policy.on_system(free) if policy.aoi_free else policy, free)
        if policy.aoi_free:
            self.caps = caps  # nothing to clip: the rule reads the true AoI

    @property
    def max_tau(self) -> tuple[int, ...]:
        """The largest AoI of each process that the cost was asked for (how far past the cap a run went)."""
        return tuple(int(t.max_tau) for t in self.system.q)

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "uncapped": True}


def simulate_uncapped(policy: Any, mdp: Any = None, *, slots: int = 40_000, reps: int = 20, seed: int | None = 0,
                      burn_in: int = 1_000, initial_tau: Any = None,
                      progress: bool | None = None) -> tuple[SimulationResult, tuple[int, ...]]:
    """Simulate a policy on the untruncated system (:class:`UncappedPolicy`): the true AoI grows
    without a cap and is charged q_k(tau_k); the policy sees min(tau, tau_hat).

    With the same seed as :func:`wncs_lp.simulate.simulate` of the same policy, the two runs see the
    same channel outcomes and take the same actions, so every replication's untruncated average is
    at least its truncated one (the coupling of ``docs/model.md``).

    Returns
    -------
    (SimulationResult, max_tau)
        The estimate, and the largest AoI of each process the run reached.
    """
    slots, reps, burn_in, seed = checked_run(slots, reps, burn_in, seed)  # before anything is built
    pol = as_policy(policy, mdp)
    start = pol.system.caps if initial_tau is None else initial_tau
    wrapped = UncappedPolicy(pol, int(np.max(start)) + burn_in + slots + 1)
    res = simulate(wrapped, slots=slots, reps=reps, seed=seed, burn_in=burn_in, initial_tau=start, progress=progress)
    return res, wrapped.max_tau


@dataclass(frozen=True)
class Candidate:
    """One policy simulated without the cap for the upper end.

    Attributes
    ----------
    policy : str
    mean, stderr : float
        The estimate of its untruncated gain (+inf when the run showed it unbounded).
    upper : float
        Its one-sided upper confidence limit at the level each candidate gets (+inf unbounded).
    max_tau : tuple of int
        The largest AoI of each process the run reached.
    note : str
        Why it is unbounded (a process starved: its AoI's cost passed the largest the toolkit
        takes), else empty.
    """

    policy: str
    mean: float
    stderr: float
    upper: float
    max_tau: tuple[int, ...]
    note: str = ""


@dataclass(frozen=True)
class UntruncatedInterval:
    r"""An interval for the optimal average cost of the untruncated system, :math:`g^*_\infty`.

    Attributes
    ----------
    lower : float
        Certified: the truncated optimum's certified lower end (or a certified bound below it).
    upper : float
        The least upper confidence limit of the candidate policies simulated without the cap
        (+inf when none was simulated or all were unbounded). With K candidates each limit is
        taken at the level 1 - (1 - ``confidence``) / K (Bonferroni), so the least of them holds
        at the level ``confidence``.
    lower_from : str
        What the lower end is (the certified truncated optimum, a bound).
    policy : str
        The candidate that gave the upper end.
    mean, stderr : float
        Its estimate.
    confidence : float
    slots, reps, seed : int
    max_tau : tuple of int
        The largest AoI of each process in its run (how far past the cap it went).
    caps : tuple of int
    candidates : tuple of Candidate
        Every policy simulated, in the order given.
    seconds : float
    note : str
        Why no policy was simulated although some were given (:func:`uncapped_refusal`), else empty.
    """

    lower: float
    upper: float
    lower_from: str
    policy: str
    mean: float
    stderr: float
    confidence: float
    slots: int
    reps: int
    seed: int | None
    max_tau: tuple[int, ...]
    caps: tuple[int, ...]
    candidates: tuple[Candidate, ...] = ()
    seconds: float = 0.0
    note: str = ""

    @property
    def width(self) -> float:
        return self.upper - self.lower

    def message(self) -> str:
        """One line in words."""
        if self.note:
            return (f"untruncated optimum (no AoI cap): g*_inf >= {self.lower:.10g} ({self.lower_from}); no upper end: "
                    f"{self.note}")
        if not self.candidates:
            return (f"untruncated optimum (no AoI cap): g*_inf >= {self.lower:.10g} ({self.lower_from}); no upper end "
                    "simulated")
        starved = [f"{c.policy} ({c.note})" for c in self.candidates if c.note]
        tail = f"; unbounded without the cap: {'; '.join(starved)}" if starved else ""
        if not np.isfinite(self.upper):
            return (f"untruncated optimum (no AoI cap): g*_inf >= {self.lower:.10g} ({self.lower_from}); no finite upper "
                    f"end from {len(self.candidates)} polic{'y' if len(self.candidates) == 1 else 'ies'} simulated"
                    + tail)
        level = f"one-sided {100 * self.confidence:g}% upper confidence limit"
        if len(self.candidates) > 1:
            level += f", the least of {len(self.candidates)} policies' (Bonferroni)"
        return (f"untruncated optimum (no AoI cap): {self.lower:.10g} <= g*_inf <= {self.upper:.10g} (lower: "
                f"{self.lower_from}; upper: {self.policy} simulated without the cap, {self.mean:.8g} +- "
                f"{self.stderr:.3g}, {level}, {self.reps} x {self.slots} slots, seed {self.seed}; largest AoI "
                f"reached {list(self.max_tau)} against caps {list(self.caps)}){tail}")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["candidates"] = [{k: list(v) if isinstance(v, tuple) else v for k, v in c.items()} for c in d["candidates"]]
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def untruncated_interval(lower: float, policy: Any = None, mdp: Any = None, *, lower_from: str | None = None,
                         slots: int = 40_000, reps: int = 20, seed: int | None = 0, burn_in: int = 1_000,
                         confidence: float = 0.95, progress: bool | None = None) -> UntruncatedInterval:
    r"""The interval [lower, upper] for the untruncated optimum :math:`g^*_\infty` (module docstring).

    Parameters
    ----------
    lower : float
        A certified lower bound on the truncated optimum: ``solution.gain_lower`` of a solve, or a
        bound's ``lower_bound``. Since :math:`g^*(\hat\tau) \le g^*_\infty`, it bounds the
        untruncated optimum too.
    policy : Policy, Solution, MatrixFreeSolution, or a sequence of them, optional
        The candidate(s) for the upper end (with ``mdp`` for a ``Solution``): usually the truncated
        optimum's policy, and the field's baselines beside it -- a policy optimal at a small cap can
        starve a process once its AoI passes the cap (it costs nothing more there), and then its
        untruncated cost is unbounded. None: no upper end (+inf); none either, with
        :attr:`UntruncatedInterval.note` saying why, on a system no run without the cap can
        simulate (:func:`uncapped_refusal`: random arrivals, a cost table).
    lower_from : str, optional
        What ``lower`` is, for the message.
    slots, reps, seed, burn_in : int
        The uncapped simulation of each candidate (:func:`simulate_uncapped`; one seed for all:
        common random numbers).
    confidence : float
        Level of the upper end, in [0.5, 1); with K candidates each is simulated to the level
        1 - (1 - confidence) / K.

    Returns
    -------
    UntruncatedInterval
    """
    if not 0.5 <= confidence < 1:
        raise SolverError(f"confidence must be in [0.5, 1), got {confidence}")
    t0 = time.perf_counter()
    lower_from = lower_from or "certified lower bound"
    if policy is None:
        return UntruncatedInterval(float(lower), float("inf"), lower_from, "", float("nan"), float("nan"), confidence,
                                   0, 0, seed, (), (), (), 0.0)
    if reps < 2:
        raise SolverError("the upper end needs at least 2 replications (for its confidence limit)")
    many = isinstance(policy, (list, tuple))
    pols = [as_policy(p, mdp) for p in (policy if many else [policy])]
    why = uncapped_refusal(pols[0].system.scenario) if pols else ""
    if why:
        return UntruncatedInterval(float(lower), float("inf"), lower_from, "", float("nan"), float("nan"), confidence,
                                   0, 0, seed, (), (), (), time.perf_counter() - t0, why)
    t = float(sps.t.ppf(1.0 - (1.0 - confidence) / len(pols), reps - 1))
    cands = [_candidate(p, t, slots, reps, seed, burn_in, progress) for p in pols]
    best = min(range(len(cands)), key=lambda i: cands[i].upper)
    b = cands[best]
    caps = tuple(int(c) for c in pols[0].system.caps)
    return UntruncatedInterval(float(lower), b.upper, lower_from, b.policy, b.mean, b.stderr, confidence, slots, reps,
                               seed, b.max_tau, caps, tuple(cands), time.perf_counter() - t0)


def _candidate(pol: Policy, t: float, slots: int, reps: int, seed: int | None, burn_in: int,
               progress: bool | None) -> Candidate:
    """One policy simulated without the cap; a cost past the toolkit's largest ends its run as unbounded."""
    try:
        res, max_tau = simulate_uncapped(pol, slots=slots, reps=reps, seed=seed, burn_in=burn_in, progress=progress)
    except UnboundedCost as exc:
        inf = float("inf")
        return Candidate(pol.name, inf, inf, inf, (), exc.note)
    return Candidate(pol.name, float(res.mean), float(res.stderr), float(res.mean + t * res.stderr), max_tau)
