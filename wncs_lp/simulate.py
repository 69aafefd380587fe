"""Monte Carlo simulation straight from the configuration automaton (no tau enumeration).

R independent replications run side by side as numpy arrays. In slot t every replication r
is in a state (tau_r, C_r); the policy picks local actions ``j = policy.act(tau, C, rng)``,
one uniform u_r in [0, 1) per replication selects the outcome o of (C_r, j_r) from the padded
cumulative-probability table (``o = #{i : u_r >= cum[C_r, j_r, i]}``), and

    C_r <- nxt[C_r, j_r, o],   tau_{r,k} <- min(tau_{r,k} + 1, delta_k if delta_k > 0, tau_hat_k).

The cost of slot t is c(s_t) = sum_k q_k(tau_k(t)). After ``burn_in`` slots the next ``slots``
slot costs are averaged per replication: Y_r = (1/T) sum_t c(s_t). The estimate is the mean of
the Y_r with the standard error s / sqrt(R) (s the sample standard deviation over the
independent replications, ddof = 1).

Random numbers: the channel uniforms and the policy's own draws use two independent streams
spawned from ``numpy.random.SeedSequence(seed)``, so two policies simulated with one seed see
the same channel uniforms (common random numbers).
"""
from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .errors import PolicyError
from .mdp import MDP
from .policies import Policy, as_policy

__all__ = ["SimulationResult", "simulate"]


@dataclass(frozen=True)
class SimulationResult:
    """A Monte Carlo estimate of a policy's average cost.

    Attributes
    ----------
    policy : str
    mean : float
        Mean over replications of the per-replication time-average cost.
    stderr : float
        Standard error of ``mean`` across the independent replications (NaN for R = 1).
    rep_means : tuple of float
        The per-replication time averages Y_r.
    process_means : tuple of float
        Time-and-replication average of q_k(tau_k) per process (sum = ``mean``).
    utilisation : tuple of float
        Average per slot of the probability that each server performs a service step.
    slots, reps, burn_in : int
    seed : int or None
    seconds : float
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

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


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
        Independent replications R (vectorised).
    seed : int or None
        Seed of ``numpy.random.SeedSequence``.
    burn_in : int
        Slots discarded before averaging.
    initial_tau : (N,) int array, optional
        Initial AoI (default: every tau_k at its cap), in the first initial configuration
        (every server idle).
    progress : bool, optional
        tqdm progress bar on stderr; default: only when stderr is a terminal.

    Returns
    -------
    SimulationResult

    Raises
    ------
    PolicyError
        Bad sizes, a policy in no documented form (an array without its MDP, a malformed array:
        the message says what was expected), or an action index out of range returned by the policy.
    """
    slots, reps, burn_in, seed = checked_run(slots, reps, burn_in, seed)
    policy = as_policy(policy, mdp, sigma=sigma)
    check_run_memory(reps, policy.system.n_processes)
    t0 = time.perf_counter()
    chan_ss, pol_ss = np.random.SeedSequence(seed).spawn(2)
    tau = _initial_tau(policy.system, reps, initial_tau)
    bar = _progress_bar(policy, burn_in + slots, progress)
    try:
        proc_sum, busy_sum = _run_slots(policy, tau, burn_in, slots, np.random.default_rng(chan_ss),
                                        np.random.default_rng(pol_ss), bar)
    finally:
        if bar is not None:
            bar.close()
    return _result(policy, proc_sum, busy_sum, slots, reps, burn_in, seed, time.perf_counter() - t0)


#: The longest run simulated, burn-in included (months at the few thousand slots a second of the
#: vectorised loop): a longer one is refused before it starts, as it would not end.
MAX_SLOTS = 10**10
#: Bytes a replication holds in the vectorised loop, per process and fixed (measured: ~100 (N + 1)
#: for the suboptimal policy on four processes), with a margin.
REP_BYTES_PER_PROCESS = 256


def checked_run(slots: Any, reps: Any, burn_in: Any, seed: Any) -> tuple[int, int, int, int | None]:
    """The run's sizes as whole numbers in range, and the seed (None or a whole number >= 0);
    one :class:`~wncs_lp.errors.ArgumentError` naming the argument otherwise."""
    from .arguments import seed as check_seed
    from .arguments import whole

    slots = whole(slots, "slots", lo=1, hi=MAX_SLOTS)
    burn_in = whole(burn_in, "burn_in", lo=0, hi=MAX_SLOTS - slots)
    return slots, whole(reps, "reps", lo=1), burn_in, check_seed(seed)


def check_run_memory(reps: int, n_processes: int) -> None:
    """Refuse (:class:`~wncs_lp.errors.ArgumentError` naming ``reps``) replications whose state
    would not fit in half of the memory available, before anything is allocated."""
    from .errors import ArgumentError
    from .models.guard import MEMORY_FRACTION, available_memory

    need = reps * REP_BYTES_PER_PROCESS * (n_processes + 2)
    room = int(MEMORY_FRACTION * available_memory())
    if need > room:
        raise ArgumentError("reps", f"{reps:,} replications of {n_processes} processes would hold about "
                                    f"{need / 2**30:,.1f} GiB, over {room / 2**30:.1f} GiB ({MEMORY_FRACTION:.0%} of "
                                    "the memory available); run fewer replications at a time")


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


def _run_slots(policy, tau: np.ndarray, burn_in: int, slots: int, chan: np.random.Generator,
               prng: np.random.Generator, bar) -> tuple[np.ndarray, np.ndarray]:
    """The slot loop, all replications at once: per replication and process the summed q_k(tau_k)
    after the burn-in, and per server the number of busy slots (summed over replications)."""
    sysm = policy.system
    ot, caps, q, busy, n_act = sysm.outcome_tables, sysm.caps, sysm.q, sysm.busy, sysm.n_actions
    reps, N = tau.shape
    c = np.full(reps, sysm.initial_config, dtype=np.int64)
    mem = policy.start_memory(reps) if hasattr(policy, "act_memory") else None  # a policy with memory
    proc_sum = np.zeros((reps, N))
    busy_sum = np.zeros(sysm.n_servers)
    chunk = 1000
    for t in range(burn_in + slots):
        if t >= burn_in:
            for k in range(N):
                proc_sum[:, k] += q[k][tau[:, k] - 1]
        j = policy.act(tau, c, prng) if mem is None else policy.act_memory(tau, c, mem, prng)
        if t == 0 or t % 997 == 0:  # cheap periodic sanity check of the policy's output
            if j.shape != (reps,) or np.any(j < 0) or np.any(j >= n_act[c]):
                raise PolicyError(f"policy {policy.name} returned action indices out of range")
        if t >= burn_in:
            busy_sum += busy[c, j].sum(axis=0)
        if mem is not None:
            mem = policy.next_memory(mem, c, j)
        o = (chan.random(reps)[:, None] >= ot.cum[c, j]).sum(axis=1)
        d = ot.delta[c, j, o]
        c = ot.nxt[c, j, o]
        tnew = np.minimum(tau + 1, caps)
        tau = np.where(d > 0, np.minimum(tnew, d), tnew)
        if bar is not None and (t + 1) % chunk == 0:
            bar.update(chunk)
    if bar is not None:
        bar.update(burn_in + slots - bar.n)
    return proc_sum, busy_sum


def _result(policy, proc_sum: np.ndarray, busy_sum: np.ndarray, slots: int, reps: int, burn_in: int,
            seed: int | None, seconds: float) -> SimulationResult:
    per_proc = proc_sum / slots  # (R, N)
    rep_means = per_proc.sum(axis=1)
    stderr = float(rep_means.std(ddof=1) / np.sqrt(reps)) if reps > 1 else float("nan")
    return SimulationResult(
        policy=policy.name,
        mean=float(rep_means.mean()),
        stderr=stderr,
        rep_means=tuple(float(x) for x in rep_means),
        process_means=tuple(float(x) for x in per_proc.mean(axis=0)),
        utilisation=tuple(float(x) for x in busy_sum / (slots * reps)),
        slots=int(slots),
        reps=int(reps),
        burn_in=int(burn_in),
        seed=None if seed is None else int(seed),
        seconds=seconds,
    )
