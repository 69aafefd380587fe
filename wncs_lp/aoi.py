r"""The long-run distribution of each process's age of information, and its quantiles.

Under a stationary policy the fraction of slots in which process k's AoI equals x converges to

.. math:: p_k(x) = \sum_{s:\ \tau_k(s) = x} \pi(s), \qquad x = 1, \dots, \hat\tau_k,

:math:`\pi` the stationary law of the chain the policy induces. Two ways to it:

* **exact** (:func:`aoi_distribution`), on an enumerated MDP: the stationary law of the policy's
  chain (:class:`wncs_lp.chain.PolicyChain`, the toolkit's one stationary solver), summed over the
  states of each AoI value;
* **simulated**: :func:`wncs_lp.simulate.simulate` counts the slots of each AoI value in every
  replication after the burn-in (:attr:`SimulationResult.aoi`), with a standard error per value
  from the independent replications.

The quantile of level q is the smallest x with :math:`F_k(x) = \sum_{y \le x} p_k(y) \ge q`.
The mass at :math:`\hat\tau_k` is the time at the cap: the distribution above the cap is not
modelled (the AoI is truncated there), so a quantile equal to the cap means "at least the cap".
A simulation without the cap (:mod:`wncs_lp.untruncated`) counts AoI values up to
:data:`wncs_lp.simulate.AOI_BINS_MAX`, the last one read "at least" the same way.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .chain import PolicyChain
from .display import Display, describe_array, fmt
from .errors import PolicyError
from .mdp import MDP
from .models.system import System
from .policy_forms import policy_array

__all__ = ["AoIDistribution", "aoi_distribution", "aoi_from_law", "aoi_from_counts"]


@dataclass(frozen=True, eq=False, repr=False)
class AoIDistribution(Display):
    """Each process's long-run AoI distribution (module docstring).

    Attributes
    ----------
    pmf : (N, max cap) array
        ``pmf[k, x - 1]`` = the long-run fraction of slots with tau_k = x (0 past process k's cap);
        every row sums to 1.
    caps : tuple of int
        tau_hat_k per process.
    process_names : tuple of str
    how : {"exact", "monte-carlo"}
    policy : str
    stderr : (N, max cap) array or None
        Monte Carlo: the standard error of each entry across the independent replications (NaN
        with one replication); None when exact.
    samples : int
        Monte Carlo: slots counted (replications x slots); 0 when exact.
    """

    pmf: np.ndarray
    caps: tuple[int, ...]
    process_names: tuple[str, ...]
    how: str
    policy: str = ""
    stderr: np.ndarray | None = None
    samples: int = 0

    @property
    def n_processes(self) -> int:
        return len(self.caps)

    def cdf(self) -> np.ndarray:
        """(N, max cap) cumulative distribution F_k(x) = P(tau_k <= x) (1 past the cap)."""
        return np.minimum(np.cumsum(self.pmf, axis=1), 1.0)

    def quantile(self, q: float | Sequence[float]) -> np.ndarray:
        """The smallest x with F_k(x) >= q, per process: (N,) for one level, (N, len(q)) for several."""
        levels = np.atleast_1d(np.asarray(q, dtype=float))
        if np.any((levels <= 0) | (levels > 1)):
            raise PolicyError(f"quantile levels must be in (0, 1], got {levels.tolist()}")
        F = self.cdf()
        # the 1e-12 keeps a level hit exactly by a sum of probabilities from moving past its value
        out = np.stack([np.argmax(F >= lv - 1e-12, axis=1) + 1 for lv in levels], axis=1)
        out = np.minimum(out, np.asarray(self.caps)[:, None])
        return out[:, 0] if np.ndim(q) == 0 else out

    def mean(self) -> np.ndarray:
        """(N,) long-run average AoI, E[tau_k]."""
        return self.pmf @ np.arange(1, self.pmf.shape[1] + 1, dtype=float)

    @property
    def at_cap(self) -> np.ndarray:
        """(N,) the fraction of slots at the cap, P(tau_k = tau_hat_k)."""
        return self.pmf[np.arange(self.n_processes), np.asarray(self.caps) - 1]

    def plot(self, ax=None, *, processes: Sequence[int] | None = None, show: str = "pmf"):
        """The distributions as step curves (:func:`wncs_lp.viz.simulation.plot_aoi`); returns the Axes."""
        from .viz.simulation import plot_aoi

        return plot_aoi(self, ax=ax, processes=processes, show=show)

    def _display_head(self) -> str:
        src = "exact" if self.how == "exact" else f"Monte Carlo, {self.samples:,} slots"
        return f"AoIDistribution of {self.n_processes} processes ({src}{', ' + self.policy if self.policy else ''})"

    def _display_rows(self) -> list[tuple[str, str]]:
        med, q90, q99 = self.quantile([0.5, 0.9, 0.99]).T
        mean, cap = self.mean(), self.at_cap
        rows = [(name, f"mean {fmt(m, 5)}, median {a}, 90% {b}, 99% {c}, at cap {fmt(p, 4)} (cap {k})")
                for name, m, a, b, c, p, k in zip(self.process_names, mean, med, q90, q99, cap, self.caps)]
        return rows + [("pmf", describe_array(self.pmf, "probabilities"))]

    def _frame_records(self):
        """One row per process and AoI value up to its cap."""
        F = self.cdf()
        recs = []
        for k, name in enumerate(self.process_names):
            for x in range(1, self.caps[k] + 1):
                r = {"process": name, "aoi": x, "probability": float(self.pmf[k, x - 1]), "cdf": float(F[k, x - 1])}
                if self.stderr is not None:
                    r["stderr"] = float(self.stderr[k, x - 1])
                recs.append(r)
        cols = ["process", "aoi", "probability", "cdf"] + (["stderr"] if self.stderr is not None else [])
        return cols, recs

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the pmf per process (up to its cap), the mean, median, 90% and 99% quantiles."""
        q = self.quantile([0.5, 0.9, 0.99])
        return {"how": self.how, "policy": self.policy, "samples": self.samples,
                "processes": [{"name": n, "cap": int(c), "pmf": self.pmf[k, :c].tolist(),
                               "mean": float(self.mean()[k]), "median": int(q[k, 0]), "q90": int(q[k, 1]),
                               "q99": int(q[k, 2]), "at_cap": float(self.at_cap[k])}
                              for k, (n, c) in enumerate(zip(self.process_names, self.caps))]}


def aoi_from_law(tau: np.ndarray, weights: np.ndarray, caps: Sequence[int], process_names: Sequence[str],
                 policy: str = "") -> AoIDistribution:
    """The exact distribution from a law over states: ``tau`` (n, N) AoI of each state, ``weights`` (n,)."""
    tau = np.asarray(tau, dtype=np.int64)
    w = np.asarray(weights, dtype=float)
    width = int(max(caps))
    pmf = np.stack([np.bincount(tau[:, k] - 1, weights=w, minlength=width)[:width] for k in range(len(caps))])
    total = pmf.sum(axis=1, keepdims=True)
    return AoIDistribution(pmf / np.where(total > 0, total, 1.0), tuple(int(c) for c in caps),
                           tuple(process_names), "exact", policy)


def aoi_from_counts(counts: np.ndarray, caps: Sequence[int], process_names: Sequence[str], policy: str = ""
                    ) -> AoIDistribution:
    """The simulated distribution from per-replication slot counts ``counts`` (R, N, max cap):
    the pooled frequencies, and each entry's standard error across the replications."""
    counts = np.asarray(counts, dtype=float)
    per_rep = counts.sum(axis=2, keepdims=True)
    freq = counts / np.where(per_rep > 0, per_rep, 1.0)  # (R, N, K)
    R = counts.shape[0]
    pmf = counts.sum(axis=0) / max(float(per_rep.sum(axis=0)[0, 0]), 1.0)
    stderr = freq.std(axis=0, ddof=1) / np.sqrt(R) if R > 1 else np.full(pmf.shape, np.nan)
    return AoIDistribution(pmf, tuple(int(c) for c in caps), tuple(process_names), "monte-carlo", policy, stderr,
                           int(per_rep.sum(axis=0)[0, 0]))


def aoi_distribution(mdp: MDP, policy: Any = None, system: System | None = None, *, sigma: Any = None
                     ) -> AoIDistribution:
    """The exact long-run AoI distribution of a unichain stationary policy on an enumerated MDP.

    Parameters
    ----------
    mdp : MDP
        Built from a scenario (its ``states`` decode tau).
    policy : Policy, Solution or array
        As :func:`wncs_lp.evaluate.evaluate`: a :class:`~wncs_lp.policies.Policy`, a solution of
        ``mdp``, or (n,) pair indices / (L,) pair probabilities.
    system : System, optional
        Default: the policy's, else the scenario's the MDP was built from.
    sigma : (n,) int array, optional
        The policy as an action per state instead.

    Raises
    ------
    PolicyError
        A malformed policy, or a chain with several recurrent classes (no single long-run law).
    """
    if hasattr(policy, "on_mdp") and hasattr(policy, "system") and sigma is None:
        arr = policy.on_mdp(mdp)
        arr = arr if isinstance(arr, np.ndarray) else policy_array(mdp, arr)
        system = system or policy.system
    else:
        arr = policy_array(mdp, policy, sigma)
    if system is None:
        model = getattr(getattr(mdp, "states", None), "model", None)
        if model is None:
            raise PolicyError("the AoI distribution of a policy given as an array needs the System (system=...)")
        system = System.from_scenario(model.scenario, model)
    name = getattr(policy, "name", None) or getattr(policy, "method", None) or ("sigma" if sigma is not None else "")
    chain = PolicyChain(mdp, arr)
    if not chain.is_unichain:
        raise PolicyError(f"policy {name or 'array'} induces {chain.n_classes} recurrent classes: no single long-run "
                          "AoI distribution (simulate from a start state instead)")
    return aoi_from_law(mdp.states.tau, chain.stationary, system.caps.tolist(),
                        [p.name for p in system.scenario.processes], str(name))
