r"""Relaxation 1: private servers, averaged capacity (a weakly coupled MDP relaxation).

The processes of the Section II model interact only through the servers. Give every process k
its own copy of every server (the private system: process k alone, idling allowed; state
:math:`(\tau_k, C_k)`, :math:`C_k` its own jobs) and keep of the coupling only the long-run
capacity of each server m. The resource is the **claim**

.. math:: \text{claim}_{m}(s, a) = 1[\text{slot } t + U_m \text{ of server } m
          \text{ is held by a job of process } k \text{ or taken by the update sent now}],

which :meth:`wncs_lp.models.base.Model.claims` reads off a configuration (job in service with
:math:`d \ge U_m + 1`, an uplink update still running then, or :math:`a_m = k`). A server
accepts exactly when slot :math:`t + U_m` is free and jobs never overlap, so in every
state-action pair of the real system :math:`\sum_k \text{claim}_{m} = 1` (no idling,
:math:`N \ge M`) or :math:`\le 1` (an accepting server left unused).

**Why it is a lower bound.** Under any stationary policy of the real system, process k's AoI and
own jobs evolve exactly as in its private copy under the projected action (a real acceptance is
a private one: the private server holds a subset of the jobs), so the real stationary law
projects onto a stationary law :math:`x_k` of each private MDP, and
:math:`\sum_k E_{x_k}[\text{claim}_m] = 1` (or :math:`\le 1`). Hence for every :math:`\lambda`
(of any sign with the equality, :math:`\lambda \ge 0` with the inequality)

.. math:: g^* \ge \sum_k \min_{x_k} E_{x_k}\Bigl[q_k + \sum_m \lambda_m \text{claim}_m\Bigr]
          - \sum_m \lambda_m \ge \sum_k \underline g_k(\lambda) - \sum_m \lambda_m = LB(\lambda),

where :math:`\underline g_k(\lambda)` is the certified lower end of process k's priced chain
(policy iteration's Bellman bracket :math:`\min_s (T h - h)(s)`, which is below the cost of
every stationary law of that MDP). No LP status enters the bound.

**The multipliers.** :math:`\lambda \mapsto \sum_k g_k(\lambda) - \sum_m \lambda_m` is concave
and piecewise linear (each :math:`g_k` is a minimum of lines, one per policy). Each priced
solve also gives a line from above: the computed policy's exact averages
:math:`\bar q_k, \rho_{k,m}` (its stationary law) give
:math:`g_k(\lambda') \le \bar q_k + \lambda' \cdot \rho_k` for every :math:`\lambda'`. A
cutting-plane (Kelley) master over these lines, one model per distinct private chain, inside
a box around the multipliers, proposes the next :math:`\lambda` and its optimum is an upper
bound on the relaxation's value (``relaxation_upper``); the loop stops when the certified
bound is within ``tol`` of it. M is the number of servers (2 or 3), so a few dozen solves of
chains of a few thousand states suffice, whatever the number of processes; identical processes
share one chain.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import linprog

from ..chain import PolicyChain
from ..errors import SolverError
from ..mdp import MDP
from ..models import Model, model_for
from ..models.guard import check_size
from ..models.system import System
from ..progress import as_progress
from ..scenario import Scenario
from ..solvers import policy_iteration
from ..status import MAX_ITER, OPTIMAL
from .inputs import bound_system, check_private_chains
from .result import BoundResult, ValueTables

__all__ = ["PrivateChain", "private_chains", "private_bound", "private_lower_bound_at", "build_private_chain",
           "chain_key", "capacity_sense", "search_multipliers"]

#: Name of this relaxation in :class:`BoundResult`.
RELAXATION = "private-servers"


# ============================================================================ the private chains
@dataclass(frozen=True, eq=False)
class PrivateChain:
    """The private MDP of one process (or of several identical ones), its cost split in two.

    Attributes
    ----------
    processes : tuple of int
        The (0-based) processes whose private system this is.
    scenario : Scenario
        The 1-process scenario (:meth:`Model.private_scenario`).
    model : Model
    mdp : MDP
        Its enumerated MDP (states (tau_k, C_k) reachable from the idle configuration).
    aoi_cost : (L,) array
        q_k(tau_k) of every pair.
    claims : (L, M) array
        claim_m of every pair.
    claim_table : (|C_k|, A_k, M) array
        claim_m of every private (configuration, local action).
    config_index : dict
        Private configuration -> its id.
    """

    processes: tuple
    scenario: Scenario
    model: Model
    mdp: MDP
    aoi_cost: np.ndarray
    claims: np.ndarray
    claim_table: np.ndarray
    config_index: dict

    @property
    def cap(self) -> int:
        return int(self.scenario.tau_caps[0])

    @property
    def n_configs(self) -> int:
        return len(self.config_index)

    def priced(self, lam: np.ndarray) -> MDP:
        """The MDP with cost q_k + sum_m lambda_m claim_m."""
        return replace(self.mdp, cost=self.aoi_cost + self.claims @ np.asarray(lam, float),
                       name=f"{self.mdp.name} priced")

    def value_table(self, bias: np.ndarray) -> np.ndarray:
        """(|C_k|, tau_hat_k) table of a bias over the private states; entries of unreachable
        (tau, C_k) take the value at the nearest reachable tau of the same configuration (the
        joint system never reads them from a reachable state)."""
        st = self.mdp.states
        out = np.full((self.n_configs, self.cap), np.nan)
        out[np.asarray(st.config), np.asarray(st.tau)[:, 0] - 1] = bias
        for row in out:
            known = np.flatnonzero(~np.isnan(row))
            if known.size < row.size:
                nearest = known[np.abs(np.arange(row.size)[:, None] - known[None, :]).argmin(axis=1)]
                row[:] = row[nearest]
        return out


def chain_key(sc: Scenario) -> str:
    """What makes two private systems the same chain (the process names aside)."""
    return repr(([(pr.A.tolist(), pr.R.tolist(), pr.weight, pr.tau_cap, pr.cost, pr.arrival_probability)
                  for pr in sc.processes], sc.model,
                 [(s.uplink_delay, s.downlink_delay, s.processing_time, s.p_up, s.p_down) for s in sc.servers]))


def build_private_chain(processes: tuple, sc: Scenario) -> PrivateChain:
    """The enumerated private MDP of ``sc`` (one process, or a group of them: the claims of its
    processes on each server are summed), with its AoI cost and claims per pair."""
    model = model_for(sc)
    check_size(sc, model=model)  # a large group's chain is an MDP like any other: refused before it is built
    mdp = model.build()
    auto = model.automaton
    M = sc.n_servers
    amax = max(len(a) for a in auto.actions)
    table = np.zeros((len(auto.configs), amax, M))
    for c, (cfg, acts) in enumerate(zip(auto.configs, auto.actions)):
        table[c, : len(acts)] = model.claims(cfg, np.array(acts, dtype=np.int64)).sum(axis=2)
    st = mdp.states
    s = mdp.s_indices
    j = np.arange(mdp.n_pairs) - mdp.pair_ptr[s]
    cfg_of = np.asarray(st.config)[s]
    q = np.asarray(mdp.cost, float)  # the private MDP's cost is sum_k q_k(tau_k) over its processes
    return PrivateChain(processes, sc, model, mdp, q, table[cfg_of, j], table,
                        {cfg: i for i, cfg in enumerate(auto.configs)})


def private_chains(model: Model) -> tuple[list[PrivateChain], np.ndarray]:
    """The distinct private chains of a scenario's model and, per process, the index of its chain.

    Raises
    ------
    ModelError
        The model kind has no private-servers relaxation (the message says why).
    """
    scenarios = [model.private_scenario(k) for k in range(model.scenario.n_processes)]
    groups: dict[str, list[int]] = {}
    for k, sc in enumerate(scenarios):
        groups.setdefault(chain_key(sc), []).append(k)
    chains = [build_private_chain(tuple(ks), scenarios[ks[0]]) for ks in groups.values()]
    which = np.empty(len(scenarios), dtype=np.int64)
    for i, ch in enumerate(chains):
        which[list(ch.processes)] = i
    return chains, which


# ============================================================================ projections
def _columns(system: System, chains: list[PrivateChain], which: np.ndarray) -> tuple:
    """Per process k: the private configuration id of k's projection of every joint configuration."""
    model = system.model
    cols = []
    for k in range(system.n_processes):
        index = chains[which[k]].config_index
        try:
            cols.append(np.array([index[model.project(cfg, k)] for cfg in system.automaton.configs], np.int64))
        except KeyError as exc:  # the projection argument says this cannot happen
            raise SolverError(f"internal error: the projection {exc} of a joint configuration on process {k + 1} "
                              "is not a configuration of its private system") from None
    return tuple(cols)


def _private_actions(system: System, chain: PrivateChain, k: int, col: np.ndarray) -> np.ndarray:
    """(|C|, A_max) local index, in k's private system, of k's projection of every joint action."""
    proj = system.model.project_labels(system.labels, k)  # (C, A, M)
    C, A, M = proj.shape
    base = int(max(proj.max(), 0)) + 2  # one integer key per (private configuration, label)
    key = np.repeat(col, A)
    for m in range(M):
        key = key * base + (proj[:, :, m].reshape(-1) + 1)
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    acts = chain.model.automaton.actions
    index = [{tuple(a): j for j, a in enumerate(acts[c])} for c in range(chain.n_configs)]
    cols, labels = np.repeat(col, A)[first], proj.reshape(C * A, M)[first]
    local = np.array([index[c].get(tuple(int(x) for x in lab), -1) for c, lab in zip(cols, labels)], np.int64)
    out = local[inv.ravel()].reshape(C, A)
    if np.any(out[system.action_valid] < 0):
        raise SolverError(f"internal error: a projected action of process {k + 1} is not feasible in its "
                          "private system")
    return out


def capacity_sense(system: System, chains: list[PrivateChain], which: np.ndarray, columns: tuple) -> str:
    """``"equality"`` when the claims of all processes on every server sum to 1 in every
    state-action pair of the joint system, ``"inequality"`` when they sum to at most 1.

    On a lazily explored system (:attr:`System.is_lazy`) the pairs are not all known, so the
    sense is not read off: ``"inequality"``, which holds on every pair of every system (a server
    holds one job at a time, so the claims on it sum to at most 1), at the price of lambda >= 0.

    Raises
    ------
    SolverError
        Some pair has claims summing above 1 (the relaxation would not be valid).
    """
    if system.is_lazy:
        return "inequality"
    total = np.zeros(system.labels.shape, float)
    for k in range(system.n_processes):
        ch = chains[which[k]]
        j = _private_actions(system, ch, k, columns[k])
        total += ch.claim_table[columns[k][:, None], np.maximum(j, 0)]
    valid = system.action_valid
    if np.any(total[valid] > 1 + 1e-12):
        raise SolverError("internal error: the server claims of the processes sum above 1 in some state-action pair")
    return "equality" if np.all(total[valid] == 1) else "inequality"


# ============================================================================ priced solves
@dataclass(frozen=True, eq=False)
class _Priced:
    """One certified solve of a priced private chain."""

    lower: float  # gain_lower of the bracket
    upper: float
    aoi: float  # exact E[q_k] under the computed policy's stationary law
    rate: np.ndarray  # exact E[claim_m] under it
    bias: np.ndarray
    policy: np.ndarray
    status: str


def _solve_priced(chain: PrivateChain, lam: np.ndarray, policy0: np.ndarray | None, tol: float) -> _Priced:
    sol = policy_iteration(chain.priced(lam), policy0=policy0, tol=tol)
    occ = sol.occupation
    if occ is None:  # a multichain policy: the equal mixture of its classes' laws is stationary too
        chain_pi = PolicyChain(chain.mdp, sol.policy)
        occ = np.zeros(chain.mdp.n_pairs)
        occ[sol.policy] = chain_pi.stationary
    return _Priced(float(sol.gain_lower), float(sol.gain_upper), float(occ @ chain.aoi_cost),
                   occ @ chain.claims, sol.bias, sol.policy, sol.status)


def private_lower_bound_at(chains: list[PrivateChain], mult: np.ndarray, lam: np.ndarray, tol: float = 1e-10,
                           policies: list | None = None) -> tuple[float, list]:
    """LB(lambda) = sum_k gain_lower_k(lambda) - sum_m lambda_m and the solves it took."""
    solves = [_solve_priced(ch, lam, None if policies is None else policies[i], tol) for i, ch in enumerate(chains)]
    return float(sum(w * s.lower for w, s in zip(mult, solves)) - np.sum(lam)), solves


# ============================================================================ the master
def _master(cuts: list, mult: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[float, np.ndarray]:
    """max over lambda in [lo, hi] of sum_j mult_j t_j - sum_m lambda_m s.t.
    t_j <= aoi + rate . lambda for every cut (j, aoi, rate); returns (value, lambda)."""
    M, J = lo.size, mult.size
    A = np.zeros((len(cuts), M + J))
    b = np.zeros(len(cuts))
    for r, (j, aoi, rate) in enumerate(cuts):
        A[r, :M] = -rate
        A[r, M + j] = 1.0
        b[r] = aoi
    c = np.concatenate([np.ones(M), -mult])
    bounds = [(float(a), float(z)) for a, z in zip(lo, hi)] + [(None, None)] * J
    res = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
    if res.status != 0:
        raise SolverError(f"the multiplier master LP failed: {res.message}")
    # HiGHS may return a bound violated by round-off (lambda = -6e-14 where lambda >= 0); the chains
    # are priced at the lambda proposed, so it is put back inside the box before it is used
    return float(-res.fun), np.clip(np.asarray(res.x[:M], float), lo, hi)


def _on_boundary(lam: np.ndarray, lo: np.ndarray, hi: np.ndarray, free_below: bool) -> bool:
    """Whether lambda touches a side of the box that is only a search limit (not lambda >= 0)."""
    tight = 1e-9 * np.maximum(1.0, np.abs(hi))
    return bool(np.any(lam >= hi - tight) or (free_below and np.any(lam <= lo + tight)))


# ============================================================================ the bound
def private_bound(
    scenario_or_system: Scenario | System,
    *,
    tol: float = 1e-6,
    max_iter: int = 80,
    solve_tol: float = 1e-10,
    progress: Any = False,
) -> BoundResult:
    """The private-servers lower bound on g* (relaxation 1), certified.

    Parameters
    ----------
    scenario_or_system : Scenario or System
        A Section II scenario (any number of processes and servers).
    tol : float
        Stop when the certified bound is within ``tol`` (relative) of the cutting-plane upper
        bound on the relaxation's value.
    max_iter : int
        Maximum number of multiplier points (each one priced solve per distinct private chain).
    solve_tol : float
        Relative certificate width asked of each priced solve (policy iteration).
    progress : bool or Progress

    Returns
    -------
    BoundResult
        ``relaxation="private-servers"``; ``multipliers`` the lambda (one per server) at which
        the bound was certified; ``tables.h[k]`` process k's bias h_k(tau_k, C_k) there and
        ``tables.column[k]`` the private configuration of k's projection of every joint one.

    Raises
    ------
    ModelError
        A model kind without this relaxation (the preemption model), refused before any work.
    """
    t0 = time.perf_counter()
    prog = as_progress(progress)
    if isinstance(scenario_or_system, System):  # checked; cost tables of its own honoured
        scenario_or_system = bound_system(scenario_or_system)
    model = scenario_or_system.model if isinstance(scenario_or_system, System) else model_for(scenario_or_system)
    model.private_scenario(0)  # refuses a kind without the relaxation before any exploration
    prog.phase("building every process's private chain (its own copy of the servers, idling allowed)")
    chains, which = private_chains(model)
    system = scenario_or_system if isinstance(scenario_or_system, System) else System.from_scenario(
        scenario_or_system, model)
    columns = _columns(system, chains, which)
    check_private_chains(system, [(k,) for k in range(len(which))], [chains[i] for i in which], columns, "relaxation 1")
    sense = capacity_sense(system, chains, which, columns)
    search = search_multipliers(system, chains, which, sense, tol, max_iter, solve_tol, prog)
    lam, solves = search["lambda"], search["solves"]
    tables = ValueTables(h=tuple(chains[which[k]].value_table(solves[which[k]].bias) for k in range(len(which))),
                         column=columns)
    rates = np.array([solves[which[k]].rate for k in range(len(which))])
    stats = {
        "capacity": sense,
        "multiplier_sign": "free" if sense == "equality" else ">= 0",
        "private_chains": len(chains),
        "chain_states": [int(ch.mdp.n_states) for ch in chains],
        "claim_rates": rates.tolist(),
        "claims_per_server": rates.sum(axis=0).tolist(),
        "box": search["box"],
        "cuts": search["cuts"],
        "priced_solves": search["solves_done"],
        "priced_status": sorted({s.status for s in solves}),
    }
    return BoundResult(
        relaxation=RELAXATION,
        lower_bound=search["lb"],
        relaxation_upper=search["upper"],
        status=OPTIMAL if search["converged"] else MAX_ITER,
        certified_by=("sum over processes of the lower end gain_lower of the Bellman bracket of each priced private "
                      "chain q_k + lambda . claim (solved by policy iteration), minus sum_m lambda_m; valid for every "
                      + ("lambda (the claims sum to 1 in every state-action pair)" if sense == "equality"
                         else "lambda >= 0 (the claims sum to at most 1)")),
        multipliers=lam,
        process_gains=np.array([solves[which[k]].lower for k in range(len(which))]),
        tables=tables,
        seconds=time.perf_counter() - t0,
        iterations=search["iterations"],
        stats=stats,
    )


def search_multipliers(system: System, chains: list, which: np.ndarray, sense: str, tol: float, max_iter: int,
                       solve_tol: float, prog, lam0: np.ndarray | None = None, policies0: list | None = None,
                       expired: Any = None) -> dict:
    """Kelley's cutting planes on the multipliers, inside a box that doubles while the answer
    touches it. ``which[i]`` is the chain of the i-th member (a process, or a group of them);
    the first point is ``lam0`` (default 0; the box grows to hold it); the search also stops when
    ``expired()`` (optional: a time limit, after at least one point) is True; ``policies0[j]`` (or None)
    starts chain j's first policy iteration."""
    mult = np.bincount(which, minlength=len(chains)).astype(float)
    M = system.n_servers
    half = float(sum(q[-1] for q in system.q))  # the cost scale: every AoI at its cap
    free = sense == "equality"
    lo, hi = np.full(M, -half if free else 0.0), np.full(M, half)
    if lam0 is not None:  # the box holds the first point
        lam0 = np.asarray(lam0, float)
        hi = np.maximum(hi, 2 * np.abs(lam0))
        lo = np.minimum(lo, -2 * np.abs(lam0)) if free else lo
    lam = np.zeros(M) if lam0 is None else np.clip(lam0, lo, hi)
    best = {"lb": -np.inf, "lambda": lam, "solves": None}
    cuts: list = []
    policies = policies0
    upper, converged, it = np.inf, False, 0
    for it in range(1, max_iter + 1):
        lb, solves = private_lower_bound_at(chains, mult, lam, solve_tol, policies)
        policies = [s.policy for s in solves]
        if lb > best["lb"]:
            best = {"lb": lb, "lambda": lam.copy(), "solves": solves}
        cuts += [(j, s.aoi, s.rate) for j, s in enumerate(solves)]
        upper, lam = _master(cuts, mult, lo, hi)
        prog.tick(f"[bound] point {it}: LB {lb:.10g}, best {best['lb']:.10g}, model {upper:.10g}", force=True)
        if upper - best["lb"] <= tol * max(abs(best["lb"]), 1e-300):
            if not _on_boundary(best["lambda"], lo, hi, free):
                converged = True
                break
            lo, hi = (2 * lo if free else lo), 2 * hi
            upper, lam = _master(cuts, mult, lo, hi)
        if expired is not None and expired():
            break
    interior = converged or not _on_boundary(lam, lo, hi, free)
    return {"lb": best["lb"], "lambda": best["lambda"], "solves": best["solves"], "converged": converged,
            "upper": float(upper) if interior else float("inf"), "iterations": it, "cuts": len(cuts),
            "solves_done": it * len(chains), "box": [lo.tolist(), hi.tolist()]}
