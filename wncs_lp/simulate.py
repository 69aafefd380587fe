r"""Monte Carlo simulation straight from the configuration automaton (no tau enumeration).

R independent replications run side by side as numpy arrays. In slot t every replication r
is in a state (tau_r, C_r); the policy picks local actions ``j = policy.act(tau, C, rng)``,
one uniform u_r in [0, 1) per replication selects the outcome o of the pair p = (C_r, j_r) from
the pair-indexed cumulative-probability table of :attr:`System.pairs`
(``o = #{i : u_r >= cum[p, i]}``), and

    C_r <- nxt[p, o],   tau_{r,k} <- min(tau_{r,k} + 1, delta_k if delta_k > 0, tau_hat_k).

The cost of slot t is c(s_t) = sum_k q_k(tau_k(t)). After ``burn_in`` slots the next ``slots``
slot costs are averaged per replication: Y_r = (1/T) sum_t c(s_t), and the estimate is the mean
of the Y_r.

**Intervals.** The R replications are independent, so the t interval over the Y_r (R - 1
degrees of freedom) holds whatever the autocorrelation inside a run
(:func:`wncs_lp.intervals.replication_interval`); every run is also cut into ``batches``
consecutive batches for the batch-means interval (:func:`wncs_lp.intervals.batch_means_interval`,
the one that serves a single long run). :meth:`SimulationResult.interval` gives either, one- or
two-sided; ``stderr`` is the replications' standard error.

**Control variate.** With a value function h(tau, C) (``control``: a bound's tables, or any
vectorised ``value(tau, config_ids)``), the simulator also averages, per replication, the
control

.. math:: C_r = \frac{1}{T} \sum_t \big(\mathrm{E}[h(s_{t+1}) \mid s_t, a_t] - h(s_t)\big),

so that Y_r + C_r is the average of the Bellman residual of h along the path,

.. math:: r_t = c(s_t) + \mathrm{E}[h(s_{t+1}) \mid s_t, a_t] - h(s_t)
          = c(s_t) - D_t + h(s_{t+1}) - h(s_t),
          \qquad D_t = h(s_{t+1}) - \mathrm{E}[h(s_{t+1}) \mid s_t, a_t],

the conditional expectation computed exactly over the outcomes of (C_t, a_t). Over a run,
sum_t r_t = sum_t c(s_t) - sum_t D_t + h(s_T) - h(s_0): the D_t are martingale differences
(mean zero given the past, under *any* policy), and the boundary term has mean zero when the
run starts in the stationary law and is otherwise a transient of the kind the burn-in removes:
C_r has mean zero. When h is the policy's relative value function (its Poisson equation
g + h(s) = c(s) + E[h(s') | s]), r_t = g in every slot: the closer h is to the policy's bias,
the less variance is left in Y_r + C_r (the approximating-martingale control variate of S. G.
Henderson and P. W. Glynn, "Approximating martingales for variance reduction in Markov process
simulation", Math. Oper. Res. 27(2), 2002). The estimate is Y + beta C with ``control_coef``
beta = 1 by default: the residual's average, nothing fitted to the data, R - 1 degrees of
freedom; and where h is the policy's bias the boundary term also cancels the start's transient.
``control_coef="fit"`` fits beta across the replications instead (the regression
control-variate estimator, :func:`wncs_lp.intervals.control_variate_interval`, R - 2 degrees
of freedom), for an h that may be unrelated to the policy. Per batch, the residuals carry no
boundary term, so their batch means stay nearly independent.

**Distributions and paths.** Every run counts its slots at each AoI value of each process
after the burn-in (:attr:`SimulationResult.aoi`, an :class:`wncs_lp.aoi.AoIDistribution` with a
standard error per value across the replications); ``path = T`` keeps the first T slots after
the burn-in of replication 0 (:class:`SamplePath`: AoI, configuration, action and cost arrays,
and a plot).

Random numbers: the channel uniforms and the policy's own draws use two independent streams
spawned from ``numpy.random.SeedSequence(seed)``, so two policies simulated with one seed see
the same channel uniforms (common random numbers); the control variate, the batches, the AoI
counts and the path draw nothing, so they never change the simulated values.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .aoi import AoIDistribution, aoi_from_counts
from .display import Display, describe_array, fmt
from .errors import PolicyError
from .intervals import (AGREEMENT_LEVEL, ConfidenceInterval, batch_means_interval, control_variate_interval,
                        difference_interval, replication_interval, replications_agree)
from .mdp import MDP
from .policies import Policy, as_policy

__all__ = ["SimulationResult", "SamplePath", "simulate", "DEFAULT_BATCHES"]

#: Batches each replication is cut into for the batch-means interval.
DEFAULT_BATCHES = 32
#: Most AoI values the histogram of a process counts; a larger AoI (a system whose caps are raised
#: out of reach, :mod:`wncs_lp.untruncated`) is counted in the last value, read "at least".
AOI_BINS_MAX = 1024


@dataclass(frozen=True, eq=False, repr=False)
class SamplePath(Display):
    """The first slots after the burn-in of one replication.

    Attributes
    ----------
    policy : str
    replication : int
    start : int
        The slot number of the first entry (the burn-in).
    tau : (T, N) int array
        The AoI of each process at each slot.
    config : (T,) int array
        The configuration id (:attr:`System.labels` describes it).
    action : (T,) int array
        The local action index taken.
    cost : (T,) float array
        The slot cost c(s_t) = sum_k q_k(tau_k(t)).
    process_names : tuple of str
    """

    policy: str
    replication: int
    start: int
    tau: np.ndarray
    config: np.ndarray
    action: np.ndarray
    cost: np.ndarray
    process_names: tuple[str, ...]

    @property
    def slots(self) -> np.ndarray:
        """(T,) slot numbers."""
        return self.start + np.arange(self.cost.size)

    def plot(self, ax=None, *, what: str = "aoi", processes=None):
        """The path's AoI (or cost, ``what="cost"``) against the slot (:func:`wncs_lp.viz.simulation.plot_path`);
        returns the Axes."""
        from .viz.simulation import plot_path

        return plot_path(self, ax=ax, what=what, processes=processes)

    def _display_head(self) -> str:
        return f"SamplePath of {self.cost.size:,} slots ({self.policy}, replication {self.replication})"

    def _display_rows(self) -> list[tuple[str, str]]:
        return [("start", fmt(self.start)), ("tau", describe_array(self.tau, "ints")),
                ("cost", describe_array(self.cost, "floats") + f", mean {fmt(float(self.cost.mean()), 8)}"
                 if self.cost.size else "empty")]

    def _frame_records(self):
        cols = ["slot", "config", "action", "cost"] + [f"tau_{n}" for n in self.process_names]
        recs = {"slot": self.slots, "config": self.config, "action": self.action, "cost": self.cost}
        recs.update({f"tau_{n}": self.tau[:, k] for k, n in enumerate(self.process_names)})
        return cols, recs


@dataclass(frozen=True, eq=False, repr=False)
class SimulationResult(Display):
    """A Monte Carlo estimate of a policy's average cost (module docstring).

    Attributes
    ----------
    policy : str
    mean : float
        The estimate: the mean over replications of the per-replication time-average cost Y_r
        (with a control variate: of Y_r + beta C_r).
    stderr : float
        Standard error of ``mean`` across the independent replications (NaN for R = 1; with a
        fitted coefficient, the regression's).
    rep_means : tuple of float
        The per-replication estimates (Y_r + beta C_r with a control variate).
    process_means : tuple of float
        Time-and-replication average of q_k(tau_k) per process (sum = ``plain_mean``).
    utilisation : tuple of float
        Average per slot of the probability that each server performs a service step.
    slots, reps, burn_in : int
    seed : int or None
    seconds : float
    plain_mean, plain_stderr, plain_rep_means
        The plain time average, its standard error and the per-replication averages (without the
        control variate); equal to ``mean``, ``stderr`` and ``rep_means`` when there is none.
    control : str or None
        The value function of the control variate (None without one).
    control_means : tuple of float
        C_r per replication (empty without a control variate).
    control_coef : float
        beta, fitted or given (0 without a control variate).
    control_fitted : bool
        Whether beta was fitted across the replications.
    batch_sums : (R, B) array
        Per replication and batch, the sum of the slot costs (with a control variate: plus beta
        times the control's).
    batch_sizes : (B,) int array
        Slots per batch.
    aoi : AoIDistribution
        The simulated long-run AoI distribution of each process.
    path : SamplePath or None
        The first slots of replication 0 (``simulate(..., path=T)``).
    """

    policy: str
    mean: float
    stderr: float
    rep_means: tuple[float, ...]
    process_means: tuple[float, ...]
    utilisation: tuple[float, ...]
    slots: int
    reps: int
    burn_in: int
    seed: int | None
    seconds: float
    plain_mean: float = math.nan
    plain_stderr: float = math.nan
    plain_rep_means: tuple[float, ...] = ()
    control: str | None = None
    control_means: tuple[float, ...] = ()
    control_coef: float = 0.0
    control_fitted: bool = False
    batch_sums: np.ndarray | None = None
    batch_sizes: np.ndarray | None = None
    aoi: AoIDistribution | None = None
    path: SamplePath | None = None

    @property
    def variance_reduction(self) -> float:
        """plain_stderr^2 / stderr^2: how many times fewer slots the control variate needs for the
        same standard error (1 without a control variate; NaN for one replication)."""
        if self.control is None:
            return 1.0
        return float(self.plain_stderr ** 2 / self.stderr ** 2) if self.stderr > 0 else math.inf

    @property
    def agreement(self) -> float:
        """The p-value of the replications' agreement with their own batches
        (:func:`wncs_lp.intervals.replications_agree`): below :data:`~wncs_lp.intervals.AGREEMENT_LEVEL`
        the runs disagree more than their autocorrelation allows (too short, or several recurrent
        classes), and the printout warns. NaN for one replication."""
        if self.batch_sums is None or self.reps < 2 or self.batch_sizes.size < 2:
            return math.nan
        return replications_agree(self.batch_sums, self.batch_sizes)

    def interval(self, confidence: float = 0.95, side: str = "upper", method: str | None = None
                 ) -> ConfidenceInterval:
        """A confidence interval for the policy's average cost.

        Parameters
        ----------
        confidence : float
        side : {"upper", "lower", "two-sided"}
            ``"upper"`` (default): the one-sided upper confidence limit, what a certified
            optimality gap uses.
        method : {"replications", "batch-means"}, optional
            Default: replications when there are at least 2, else batch means
            (:mod:`wncs_lp.intervals`). With a fitted control coefficient the replications'
            interval is the regression's (R - 2 degrees of freedom); batch means take the
            fitted beta as known.
        """
        method = method or ("replications" if self.reps >= 2 else "batch-means")
        if method == "replications":
            if self.control_fitted:
                return control_variate_interval(self.plain_rep_means, self.control_means, confidence, side)[0]
            return replication_interval(self.rep_means, confidence, side)
        if method == "batch-means":
            if self.batch_sums is None:
                raise PolicyError("this result has no batches (made by hand?)")
            return batch_means_interval(self.batch_sums, self.batch_sizes, confidence, side)
        raise PolicyError(f"method must be 'replications' or 'batch-means', got {method!r}")

    def compare(self, other: "SimulationResult", confidence: float = 0.95, side: str = "two-sided"
                ) -> ConfidenceInterval:
        """An interval for ``self.mean - other.mean``: paired over the replications when both runs
        share their random numbers (same seed, replications, slots and burn-in: common random
        numbers), else Welch's (:func:`wncs_lp.intervals.difference_interval`)."""
        paired = (self.seed is not None and (self.seed, self.reps, self.slots, self.burn_in)
                  == (other.seed, other.reps, other.slots, other.burn_in))
        return difference_interval(self.rep_means, other.rep_means, paired, confidence, side)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready scalars and short lists (not the batches or the path); the AoI distribution's summary."""
        out: dict[str, Any] = {}
        for k in ("policy", "mean", "stderr", "rep_means", "process_means", "utilisation", "slots", "reps", "burn_in",
                  "seed", "seconds", "plain_mean", "plain_stderr", "plain_rep_means", "control", "control_coef",
                  "control_fitted"):
            v = getattr(self, k)
            out[k] = list(v) if isinstance(v, tuple) else v
        out["variance_reduction"] = self.variance_reduction
        out["agreement"] = self.agreement
        out["batches"] = 0 if self.batch_sizes is None else int(self.batch_sizes.size)
        if self.reps >= 2:
            out["upper_95"] = self.interval().upper
        if self.aoi is not None:
            out["aoi"] = self.aoi.to_dict()
        return out

    def _display_head(self) -> str:
        return (f"SimulationResult of {self.policy}: {self.reps} replications x {self.slots:,} slots "
                f"(burn-in {self.burn_in:,}, seed {self.seed})")

    def _display_rows(self) -> list[tuple[str, str]]:
        rows = [("mean", f"{fmt(self.mean)} +- {fmt(self.stderr, 3)} (standard error, replications)")]
        if self.reps >= 2:
            ci = self.interval()
            rows.append(("upper_95", f"{fmt(ci.upper)} (one-sided 95% upper confidence limit, t with {ci.df} df)"))
        if self.agreement < AGREEMENT_LEVEL:
            rows.append(("warning", f"the replications disagree beyond their own batches (p = {self.agreement:.2g}): "
                                    "runs too short, or several recurrent classes"))
        if self.control is not None:
            how = "fitted" if self.control_fitted else "given"
            rows += [("control", f"martingale of {self.control}, beta = {fmt(self.control_coef, 4)} ({how}): variance / "
                                 f"{fmt(self.variance_reduction, 3)}"),
                     ("plain_mean", f"{fmt(self.plain_mean)} +- {fmt(self.plain_stderr, 3)}")]
        rows += [("process_means", ", ".join(fmt(x, 6) for x in self.process_means)),
                 ("utilisation", ", ".join(fmt(x, 4) for x in self.utilisation))]
        if self.aoi is not None:
            rows.append(("aoi", f"median {self.aoi.quantile(0.5).tolist()}, 99% {self.aoi.quantile(0.99).tolist()}, "
                                f"at cap {[round(float(x), 4) for x in self.aoi.at_cap]}"))
        if self.path is not None:
            rows.append(("path", f"{self.path.cost.size:,} slots of replication {self.path.replication}"))
        rows.append(("seconds", fmt(self.seconds, 4)))
        return rows

    def _frame_records(self):
        """One row per replication: its estimate (and its plain average with a control variate)."""
        plain = self.plain_rep_means or self.rep_means
        return ["replication", "mean", "plain_mean"], [{"replication": r, "mean": m, "plain_mean": p}
                                                       for r, (m, p) in enumerate(zip(self.rep_means, plain))]


def _want_progress(progress: bool | None) -> bool:
    if progress is None:
        return bool(getattr(sys.stderr, "isatty", lambda: False)())
    return bool(progress)


def simulate(
    policy: Any = None,
    mdp: MDP | None = None,
    *,
    sigma: Any = None,
    slots: int = 40_000,
    reps: int = 20,
    seed: int | None = 0,
    burn_in: int = 1_000,
    initial_tau: np.ndarray | None = None,
    control: Any = None,
    control_coef: float | str = 1.0,
    batches: int = DEFAULT_BATCHES,
    path: int = 0,
    progress: bool | None = None,
) -> SimulationResult:
    """Simulate a policy on its system for ``burn_in + slots`` slots, ``reps`` replications.

    Parameters
    ----------
    policy : Policy, Solution or array
        Any policy of :mod:`wncs_lp.policies` (its ``system`` gives the automaton; a
        ``MatrixFreeSolution`` too); or, with ``mdp``, a solution of it or its policy as (n,) int
        pair indices or (L,) float pair probabilities (:func:`wncs_lp.policies.as_policy`).
    mdp : MDP, optional
        The enumerated MDP a solution or an array lives on (built from the scenario).
    sigma : (n,) int array, optional
        The policy as an action per state of ``mdp`` instead (a row of ``mdp.action_table``:
        :attr:`Solution.sigma`; see ``docs/policies.md``).
    slots : int
        Slots averaged per replication (the paper uses 40,000).
    reps : int
        Independent replications R (vectorised: more replications cost little more per slot).
    seed : int or None
        Seed of ``numpy.random.SeedSequence``.
    burn_in : int
        Slots discarded before averaging.
    initial_tau : (N,) int array, optional
        Initial AoI (default: every tau_k at its cap), in the first initial configuration
        (every server idle).
    control : value function, optional
        h(tau, C) of the martingale control variate (module docstring): an object with a
        vectorised ``value(tau, config_ids)`` ((R, N) AoI, (R,) configuration ids -> (R,)
        values; the ``tables`` of a :class:`wncs_lp.bounds.BoundResult` are such objects), or
        such a callable. Finite everywhere the chain can go.
    control_coef : float or "fit"
        beta of the estimate Y + beta C: given (default 1, the Bellman residual's average), or
        ``"fit"`` across the replications (the regression estimator; beta = 1 below 3
        replications).
    batches : int
        Batches per replication for the batch-means interval (at most ``slots``).
    path : int
        Keep the first ``path`` slots after the burn-in of replication 0 (:class:`SamplePath`).
    progress : bool, optional
        tqdm progress bar on stderr; default: only when stderr is a terminal.

    Returns
    -------
    SimulationResult

    Raises
    ------
    PolicyError
        Bad sizes, a policy in no documented form (an array without its MDP, a malformed array:
        the message says what was expected), an action index out of range returned by the policy,
        or a control whose values are not finite.
    """
    slots, reps, burn_in, seed = checked_run(slots, reps, burn_in, seed)
    policy = as_policy(policy, mdp, sigma=sigma)
    if batches < 1 or path < 0:
        raise PolicyError(f"need batches >= 1 and path >= 0; got {batches}, {path}")
    value = _control_value(control)
    if not (control_coef == "fit" or isinstance(control_coef, (int, float))):
        raise PolicyError(f"control_coef must be 'fit' or a number, got {control_coef!r}")
    _check_memory(policy.system, int(reps))
    t0 = time.perf_counter()
    chan_ss, pol_ss = np.random.SeedSequence(seed).spawn(2)
    tau = _initial_tau(policy.system, reps, initial_tau)
    acc = _Accumulators(policy.system, reps, slots, min(batches, slots), path, value is not None)
    bar = _progress_bar(policy, burn_in + slots, progress)
    try:
        _run_slots(policy, tau, burn_in, slots, np.random.default_rng(chan_ss), np.random.default_rng(pol_ss),
                   value, acc, bar)
    finally:
        if bar is not None:
            bar.close()
    return _result(policy, acc, slots, reps, burn_in, seed, _control_name(control), control_coef,
                   time.perf_counter() - t0)


def _control_value(control: Any) -> Callable | None:
    if control is None:
        return None
    if hasattr(control, "value") and callable(control.value):
        return control.value
    if callable(control):
        return control
    raise PolicyError(f"control must have a value(tau, config_ids) method or be such a callable; got "
                      f"{type(control).__name__}")


def _control_name(control: Any) -> str | None:
    if control is None:
        return None
    return str(getattr(control, "name", None) or type(control).__name__)


def _check_memory(sysm, reps: int) -> None:
    """Refuse, before allocating, a run whose per-slot arrays would not fit: per replication the AoI
    and cost sums (4 N numbers), the outcome draw (a few O) and a policy's lookahead over the
    actions of its state (about 10 arrays of A_max numbers)."""
    from .models.guard import require_memory

    width = max(int(sysm.n_actions.max(initial=1)), 1)  # lazily explored: the idle configuration's, the most
    per_rep = 8 * (4 * sysm.n_processes + 4 * sysm.pairs.n_outcomes + 10 * width)
    require_memory(reps * per_rep, f"simulating {reps:,} replications side by side ({per_rep:,} bytes each a slot)",
                   ["fewer replications (--reps) with more slots each (--slots)"])


#: The longest run simulated, burn-in included (months at the few thousand slots a second of the
#: vectorised loop): a longer one is refused before it starts, as it would not end.
MAX_SLOTS = 10**10


def checked_run(slots: Any, reps: Any, burn_in: Any, seed: Any) -> tuple[int, int, int, int | None]:
    """The run's sizes as whole numbers in range, and the seed (None or a whole number >= 0);
    one :class:`~wncs_lp.errors.ArgumentError` naming the argument otherwise."""
    from .arguments import seed as check_seed
    from .arguments import whole

    slots = whole(slots, "slots", lo=1, hi=MAX_SLOTS)
    burn_in = whole(burn_in, "burn_in", lo=0, hi=MAX_SLOTS - slots)
    return slots, whole(reps, "reps", lo=1), burn_in, check_seed(seed)


def _initial_tau(sysm, reps: int, initial_tau: np.ndarray | None) -> np.ndarray:
    """(R, N) starting AoI: every tau_k at its cap, or ``initial_tau`` in every replication."""
    caps = sysm.caps
    if initial_tau is None:
        return np.tile(caps, (reps, 1)).astype(np.int64)
    try:
        t_init = np.asarray(initial_tau, dtype=np.int64)
    except (TypeError, ValueError, OverflowError):
        t_init = None
    N = sysm.n_processes
    if t_init is None or t_init.shape != (N,) or np.any(t_init < 1) or np.any(t_init > caps):
        raise PolicyError(f"initial_tau must be {N} integers in 1..tau_hat = {caps.tolist()}")
    return np.tile(t_init, (reps, 1))


def _progress_bar(policy, total: int, progress: bool | None):
    if not _want_progress(progress):
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=f"simulate {policy.name}", unit="slot", file=sys.stderr, mininterval=0.5)


class _Accumulators:
    """What the slot loop adds up after the burn-in: per replication and process the summed
    q_k(tau_k); per server the busy slots; per replication and batch the cost and the control's
    part of the residual, E[h(s_{t+1}) | s_t, a_t] - h(s_t); per replication, process and AoI
    value the slots; the path of replication 0."""

    def __init__(self, sysm, reps: int, slots: int, batches: int, path: int, controlled: bool):
        N, K = sysm.n_processes, int(min(sysm.caps.max(), AOI_BINS_MAX))
        self.aoi_clip = K if K < int(sysm.caps.max()) else None
        self.aoi_caps = np.minimum(sysm.caps, K).tolist()
        self.proc_sum = np.zeros((reps, N))
        self.busy_sum = np.zeros(sysm.n_servers)
        self.batch_of = np.arange(slots, dtype=np.int64) * batches // slots  # slot after burn-in -> batch
        self.batch_sizes = np.bincount(self.batch_of, minlength=batches)
        self.cost_b = np.zeros((reps, batches))
        self.ctrl_b = np.zeros((reps, batches)) if controlled else None
        self.aoi_base = (np.arange(reps)[:, None] * N + np.arange(N)[None, :]) * K - 1  # + tau: the flat bin
        self.aoi_counts = np.zeros(reps * N * K, dtype=np.int64)
        self.shape = (reps, N, K)
        n = min(path, slots)
        self.path = (np.zeros((n, N), np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n))


def _run_slots(policy, tau: np.ndarray, burn_in: int, slots: int, chan: np.random.Generator,
               prng: np.random.Generator, value: Callable | None, acc: _Accumulators, bar) -> None:
    """The slot loop, all replications at once (module docstring), into ``acc``."""
    sysm = policy.system
    pt, caps, q, n_act = sysm.pairs, sysm.caps, sysm.q, sysm.n_actions  # pair-indexed: no padding to A_max
    lazy = sysm.is_lazy
    reps, N = tau.shape
    rows = np.arange(reps)
    c = np.full(reps, sysm.initial_config, dtype=np.int64)
    mem = policy.start_memory(reps) if hasattr(policy, "act_memory") else None  # a policy with memory
    n_path = acc.path[3].size
    chunk = 1000
    for t in range(burn_in + slots):
        after = t >= burn_in
        if after:
            cost = np.zeros(reps)
            for k in range(N):
                qk = q[k][tau[:, k] - 1]
                acc.proc_sum[:, k] += qk
                cost += qk
            b = acc.batch_of[t - burn_in]
            acc.cost_b[:, b] += cost
            seen = tau if acc.aoi_clip is None else np.minimum(tau, acc.aoi_clip)
            acc.aoi_counts[acc.aoi_base + seen] += 1  # one bin per (replication, process): no index repeats
        if lazy and sysm.expand(c):  # a lazily explored automaton: configurations met for the first time
            pt, n_act = sysm.pairs, sysm.n_actions
        j = policy.act(tau, c, prng) if mem is None else policy.act_memory(tau, c, mem, prng)
        if t == 0 or t % 997 == 0:  # cheap periodic sanity check of the policy's output
            if j.shape != (reps,) or np.any(j < 0) or np.any(j >= n_act[c]):
                raise PolicyError(f"policy {policy.name} returned action indices out of range")
        p = pt.first[c] + j
        if after:
            acc.busy_sum += pt.busy[p].sum(axis=0)
            if t - burn_in < n_path:
                i = t - burn_in
                acc.path[0][i], acc.path[1][i], acc.path[2][i], acc.path[3][i] = tau[0], c[0], j[0], cost[0]
        if mem is not None:
            mem = policy.next_memory(mem, c, j)
        o = (chan.random(reps)[:, None] >= pt.cum[p]).sum(axis=1)
        if value is not None and after:
            if t == burn_in:
                h_now = _values(value, tau, c)
            tau, c, h_now = _controlled_step(pt, caps, value, tau, p, o, rows, h_now, acc, b)
        else:
            tau, c = sysm.next_tau(tau, pt.deltas[pt.delta[p, o]]), pt.nxt[p, o]
        if bar is not None and (t + 1) % chunk == 0:
            bar.update(chunk)
    if bar is not None:
        bar.update(burn_in + slots - bar.n)


def _values(value: Callable, tau: np.ndarray, c: np.ndarray) -> np.ndarray:
    v = np.asarray(value(tau, c), dtype=float)
    if v.shape != c.shape or not np.all(np.isfinite(v)):
        raise PolicyError(f"the control variate's value function must give one finite number per state; got shape "
                          f"{v.shape} for {c.size} states" + ("" if v.shape != c.shape else ", not all finite"))
    return v


def _controlled_step(pt, caps, value: Callable, tau, p, o, rows, h_now, acc: _Accumulators, b: int):
    """One transition with the control variate: the next state under every outcome of the pairs
    ``p`` (:attr:`System.pairs`), h there, E[h(s') | s, a] - h(s) into batch b; returns the
    realised next state and h there. Padded outcomes (probability 0) repeat a real one and weigh
    nothing."""
    reps, N = tau.shape
    nx = pt.nxt[p]  # (R, O)
    dl = pt.deltas[pt.delta[p]]  # (R, O, N)
    tnew = np.minimum(tau + 1, caps)[:, None, :]
    tau_o = np.where(dl > 0, np.minimum(tnew, dl), tnew)
    hv = _values(value, tau_o.reshape(-1, N), nx.reshape(-1)).reshape(nx.shape)
    acc.ctrl_b[:, b] += (pt.prob[p] * hv).sum(axis=1) - h_now
    return tau_o[rows, o], nx[rows, o], hv[rows, o]


def _result(policy, acc: _Accumulators, slots: int, reps: int, burn_in: int, seed: int | None,
            control: str | None, coef: float | str, seconds: float) -> SimulationResult:
    per_proc = acc.proc_sum / slots  # (R, N)
    plain = per_proc.sum(axis=1)

    def se(y):
        return float(y.std(ddof=1) / np.sqrt(reps)) if reps > 1 else float("nan")

    mean, stderr, beta, fitted, ctrl = float(plain.mean()), se(plain), 0.0, False, None
    batch_sums = acc.cost_b
    if acc.ctrl_b is not None:
        ctrl = acc.ctrl_b.sum(axis=1) / slots
        if coef == "fit" and reps >= 3:
            ci, beta = control_variate_interval(plain, ctrl)
            mean, stderr, fitted = ci.estimate, ci.stderr, True
        else:
            beta = 1.0 if coef == "fit" else float(coef)
            mean, stderr = float((plain + beta * ctrl).mean()), se(plain + beta * ctrl)
        batch_sums = acc.cost_b + beta * acc.ctrl_b
    rep_means = plain if ctrl is None else plain + beta * ctrl
    sysm = policy.system
    names = tuple(p.name for p in sysm.scenario.processes)
    tau_p, c_p, j_p, cost_p = acc.path
    path = None if cost_p.size == 0 else SamplePath(policy.name, 0, burn_in, tau_p, c_p, j_p, cost_p, names)
    return SimulationResult(
        policy=policy.name,
        mean=mean,
        stderr=stderr,
        rep_means=tuple(float(x) for x in rep_means),
        process_means=tuple(float(x) for x in per_proc.mean(axis=0)),
        utilisation=tuple(float(x) for x in acc.busy_sum / (slots * reps)),
        slots=int(slots),
        reps=int(reps),
        burn_in=int(burn_in),
        seed=None if seed is None else int(seed),
        seconds=seconds,
        plain_mean=float(plain.mean()),
        plain_stderr=se(plain),
        plain_rep_means=tuple(float(x) for x in plain),
        control=control,
        control_means=() if ctrl is None else tuple(float(x) for x in ctrl),
        control_coef=float(beta),
        control_fitted=fitted,
        batch_sums=batch_sums,
        batch_sizes=acc.batch_sizes,
        aoi=aoi_from_counts(acc.aoi_counts.reshape(acc.shape), acc.aoi_caps, names, policy.name),
        path=path,
    )
