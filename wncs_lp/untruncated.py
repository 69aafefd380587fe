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
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as sps

from .errors import ModelError, SolverError
from .models.cost import process_cost
from .policies import ClippedPolicy, Policy, as_policy
from .simulate import SimulationResult, simulate

__all__ = ["UntruncatedInterval", "UncappedPolicy", "simulate_uncapped", "untruncated_interval"]


class _GrowingCost:
    """q_k(1..L) of one process, extended (doubling L) whenever an AoI past L is asked for; the
    largest AoI asked for is kept (:attr:`max_tau`)."""

    def __init__(self, process: Any, length: int, source: str):
        self.process, self.source = process, source
        self.table = process_cost(process, int(length), source)
        self.max_tau = 0

    def __getitem__(self, idx: Any) -> np.ndarray:
        need = int(np.max(idx)) + 1
        self.max_tau = max(self.max_tau, need)
        if need > self.table.size:
            try:
                self.table = process_cost(self.process, max(need, 2 * self.table.size), self.source)
            except ModelError:
                try:
                    self.table = process_cost(self.process, need, self.source)
                except ModelError as exc:
                    raise ModelError(f"uncapped simulation: {exc}. Without the cap the AoI of process "
                                     f"'{self.process.name}' reached {need}, where its cost passes the largest the "
                                     "toolkit takes: its untruncated average cost is beyond reach (unbounded in "
                                     "effect)") from None
        return self.table[idx]

    def __len__(self) -> int:
        return int(self.table.size)


class UncappedPolicy(ClippedPolicy):
    """A policy of the truncated model acting on the untruncated system.

    Its :attr:`system` is the scenario's system with the caps raised to ``horizon`` (an AoI no
    run of that many slots can reach, so nothing is ever held at a cap) and cost tables that grow
    on demand; it acts as ``policy`` on the clipped AoI min(tau, tau_hat) (:class:`ClippedPolicy`).
    """

    def __init__(self, policy: Policy, horizon: int):
        base = policy.system
        sc = base.scenario
        q = tuple(_GrowingCost(pr, max(2 * int(c), 64), sc.source) for pr, c in zip(sc.processes, base.caps))
        caps = np.full_like(base.caps, max(int(horizon), int(base.caps.max())))
        super().__init__(policy, dataclasses.replace(base, caps=caps, q=q))

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
    pol = as_policy(policy, mdp)
    start = pol.system.caps if initial_tau is None else initial_tau
    wrapped = UncappedPolicy(pol, int(np.max(start)) + burn_in + slots + 1)
    res = simulate(wrapped, slots=slots, reps=reps, seed=seed, burn_in=burn_in, initial_tau=start, progress=progress)
    return res, wrapped.max_tau


@dataclass(frozen=True)
class UntruncatedInterval:
    r"""An interval for the optimal average cost of the untruncated system, :math:`g^*_\infty`.

    Attributes
    ----------
    lower : float
        Certified: the truncated optimum's certified lower end (or a certified bound below it).
    upper : float
        The one-sided upper confidence limit (level ``confidence``) of the untruncated gain of
        ``policy``, simulated without the cap; +inf when no policy was simulated.
    lower_from, policy : str
        What the lower end is (``"certified truncated optimum at caps [...]"``, a bound), and the
        policy simulated for the upper end.
    mean, stderr : float
        The simulation's estimate of that policy's untruncated gain.
    confidence : float
    slots, reps, seed : int
    max_tau : tuple of int
        The largest AoI of each process in the run (how far past the cap it went).
    caps : tuple of int
    seconds : float
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
    seconds: float

    @property
    def width(self) -> float:
        return self.upper - self.lower

    def message(self) -> str:
        """One line in words."""
        if not np.isfinite(self.upper):
            return (f"untruncated optimum (no AoI cap): g*_inf >= {self.lower:.10g} ({self.lower_from}); no upper end "
                    "simulated")
        return (f"untruncated optimum (no AoI cap): {self.lower:.10g} <= g*_inf <= {self.upper:.10g} (lower: "
                f"{self.lower_from}; upper: {self.policy} simulated without the cap, {self.mean:.8g} +- "
                f"{self.stderr:.3g}, one-sided {100 * self.confidence:g}% upper confidence limit, {self.reps} x "
                f"{self.slots} slots, seed {self.seed}; largest AoI reached {list(self.max_tau)} against caps "
                f"{list(self.caps)})")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
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
    policy : Policy, Solution or MatrixFreeSolution, optional
        The policy whose untruncated gain is the upper end (with ``mdp`` for a ``Solution``);
        usually the truncated optimum's. None: no upper end (+inf).
    lower_from : str, optional
        What ``lower`` is, for the message.
    slots, reps, seed, burn_in : int
        The uncapped simulation (:func:`simulate_uncapped`).
    confidence : float
        Level of the one-sided upper confidence limit, in [0.5, 1).

    Returns
    -------
    UntruncatedInterval
    """
    if not 0.5 <= confidence < 1:
        raise SolverError(f"confidence must be in [0.5, 1), got {confidence}")
    t0 = time.perf_counter()
    if policy is None:
        return UntruncatedInterval(float(lower), float("inf"), lower_from or "certified lower bound", "", float("nan"),
                                   float("nan"), confidence, 0, 0, seed, (), (), 0.0)
    if reps < 2:
        raise SolverError("the upper end needs at least 2 replications (for its confidence limit)")
    pol = as_policy(policy, mdp)
    res, max_tau = simulate_uncapped(pol, slots=slots, reps=reps, seed=seed, burn_in=burn_in, progress=progress)
    ucl = float(res.mean + float(sps.t.ppf(confidence, reps - 1)) * res.stderr)
    caps = tuple(int(c) for c in pol.system.caps)
    return UntruncatedInterval(float(lower), ucl, lower_from or f"certified truncated optimum at caps {list(caps)}",
                               pol.name, float(res.mean), float(res.stderr), confidence, slots, reps, seed, max_tau,
                               caps, time.perf_counter() - t0)

