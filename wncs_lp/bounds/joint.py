r"""Relaxation 2 of issue 24: joint server configuration, per-process AoI -- a certified lower bound
on g* that scales to many processes.

The relaxation
--------------
States s = (tau, C) of the joint MDP; pairs p = (C, a). Given p, each outcome o (probability
P(o|p)) leads to C'(o) and a delivery age per process, and tau'_k = min(tau_k + 1, delta_k if
> 0, tau_hat_k). The average-cost approximate LP with separable value functions
h(s) = sum_k h_k(tau_k, C) is

.. math::

    \max_{g, h}\; g \quad\text{s.t.}\quad g + \sum_k h_k(\tau_k, C)
    \le \sum_k q_k(\tau_k) + \sum_o P(o|C,a) \sum_k h_k(\tau'_k, C') \quad \forall (\tau, C, a).

Every feasible (g, h) has g <= g* (sum the constraint over the stationary law of an optimal
policy). For fixed p the constraint is a sum of terms in one tau_k each, so it holds for all tau
iff sum_k u_k(p) <= -g with u_k(p) = max_tau [h_k(tau, C) - q_k(tau) - E h_k(tau', C')]. Hence,
for **any** tables h,

.. math::  g(h) = -\max_p \sum_k u_k(p) \le g^*,

checked in N * tau_hat * |C x A| evaluations (:func:`~wncs_lp.bounds.joint_chains.certify_tables`,
which also bounds and subtracts the round-off). That check is the only thing the returned
bound rests on; how the tables were found does not matter.

Finding good tables
-------------------
The LP has N tau_hat |C| + N |C x A| + 1 variables and N tau_hat |C x A| constraints (processes 1-4
at cap 20: 44k and 101k; the paper's four process types twice at cap 20: 567k and 1.96M), and
its optimum mixes the per-process policies at about |C x A| states, so a simplex is slow even on
four processes (HiGHS's dual simplex: minutes at cap 12) and a pure cutting-plane method needs
about |C x A| cuts per process.

**Up to** :data:`IPM_MAX_NNZ` **nonzeros** (``method="auto"``, ``"ipm"``) the LP is solved whole by
HiGHS's interior point, IPX, without crossover (:mod:`~wncs_lp.bounds.joint_ipm`): its row duals
are tables, certified like any others. That reaches the relaxation's optimum, where the bundle
below stalls short of it (docs/bounds.md, "Measured"). The tables returned are then
the priced chains' at the prices of those duals (:func:`_chains_at_ipm_prices`): they certify
as much, and unlike the raw duals -- free wherever the LP's optimum puts no mass -- they satisfy
every chain's Bellman equation, so their greedy policy acts well (the two policies are compared
in docs/bounds.md). A few bundle steps from the prices those tables give are not taken (the
certified bound agrees with IPX's own objective to its tolerance: nothing left to gain); the
bundle runs only when IPX returns no
tables (its time limit: HiGHS then holds no solution).
**Beyond**, or with ``method="bundle"``:

1. **Lagrangian (price) form.** Dualising the shared marginal x(C, a) with prices mu_k(p) that
   sum to zero over k gives L(mu) = sum_k g_k(q_k + mu_k) <= optimum of the LP, g_k the optimal
   gain of process k's chain (tau_k, C) priced by mu_k: a small MDP solved by relative value
   iteration (:func:`~wncs_lp.bounds.joint_chains.solve_chain`). Its bias tables h_k satisfy
   g(h) >= L(mu) up to the chains' bracket widths: *any* prices give certified tables.
2. **Relaxation 1's prices start it** (:func:`relaxation1_start`): mu_k = lambda* . claim_k,
   centred over k, where process k's joint chain is at least its priced private chain, so the
   start certifies at least relaxation 1's bound.
3. **A proximal bundle method raises L**
   (:class:`~wncs_lp.bounds.joint_bundle.PriceBundle`): cuts from the chains' greedy policies,
   one certified evaluation per step, until its stopping test, :data:`STALL` null steps in a
   row, ``max_iter`` steps or ``time_limit``.

``method="pdhg+bundle"`` puts a first-order method first (:class:`~wncs_lp.bounds.joint_lp.HalpernPDHG`,
restarted Halpern PDHG on the equilibrated LP, whose duals are turned into prices -- mu_k =
u_k(h) plus an equal share of each pair's slack -- and repaired by the chains); from relaxation
1's prices it did not help where measured. Each evaluation warm-starts the chains from the last
tables. Ctrl-C and ``time_limit`` return the best certified bound so far.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import SolverError, WncsError
from ..models.system import System
from ..progress import Progress, as_progress
from ..status import INTERRUPTED, MAX_ITER, OPTIMAL
from .joint_ascent import lumped_ascent
from .joint_smooth import smoothed_ascent
from .joint_bundle import PriceBundle
from .joint_chains import (ChainSolution, JointData, Kernels, TableCertificate, certify_tables, column,
                           kernels_available, policy_weights, solve_chain, stationary)
from .joint_ipm import ipm_bytes, ipm_seconds, ipm_tables
from .joint_lp import HalpernPDHG, JointLP, lp_shape, pin_tables
from .inputs import bound_system
from .joint_symmetry import ProcessSymmetry, lumped_chains, process_symmetry, spread_orbit_tables, symmetric_lp_shape
from .private import private_bound
from .result import BoundResult, ValueTables

__all__ = ["joint_bound", "joint_bound_from_tables", "ipm_fits", "ipm_plan", "joint_size", "joint_reach", "relaxation1_start", "JOINT_METHODS",
           "REACH_MAX_NNZ", "REACH_MAX_BYTES", "IPM_BUDGET", "IPM_GUARD"]

#: ``method`` values of :func:`joint_bound`.
JOINT_METHODS = ("auto", "ipm", "bundle", "pdhg", "pdhg+bundle", "ascent", "smooth")
#: ``method="auto"`` solves the LP by the interior point when its predicted CPU time
#: (:func:`~wncs_lp.bounds.joint_ipm.ipm_seconds`, a model measured on this machine's runs) is at
#: most this many seconds and its memory estimate fits :data:`REACH_MAX_BYTES`; beyond, the bundle.
IPM_BUDGET = 600.0
#: The interior point's guard: ``factor`` times its predicted CPU seconds plus ``slack`` seconds, of
#: CPU time (HiGHS's interrupt callback checks it), so that a loaded machine -- wall time up to
#: 16 times the CPU time measured here -- does not cut a solve that would finish; only a run far
#: beyond its prediction is stopped (it then leaves no tables, and the bundle takes over).
IPM_GUARD = {"factor": 10.0, "slack": 120.0}
#: The bundle stops after this many null steps in a row (its model no longer finds ascent).
STALL = 50
#: :func:`joint_size`'s reach rule: at most this many nonzeros in the LP ...
REACH_MAX_NNZ = 40_000_000
#: ... and at most this many bytes of estimated peak memory.
REACH_MAX_BYTES = 6 * 2**30


# ---------------------------------------------------------------------------- size
def joint_size(system: System) -> dict:
    """Size of relaxation 2 for ``system``, and whether it is within reach (cheap: no LP is built).

    Returns
    -------
    dict
        ``processes``, ``configurations``, ``pairs`` (|C x A|), ``outcomes`` (edges of the
        automaton), ``alp_variables`` (N tau_hat |C| + N |C x A| + 1), ``alp_constraints``
        (sum_k tau_hat_k |C x A|), ``lp_rows`` / ``lp_cols`` / ``lp_nnz`` (the occupation-measure
        LP the first-order method runs on), ``memory_bytes`` (estimated peak),
        ``numba`` (whether the fast kernels import), ``within_reach`` and ``rule``.

    Notes
    -----
    The rule: relaxation 2 is within reach when the LP has at most :data:`REACH_MAX_NNZ`
    nonzeros and the estimated peak memory is at most :data:`REACH_MAX_BYTES`, and numba is
    available. One PDHG iteration streams the LP matrix twice and a few thousand iterations are
    what a bound near the relaxation's optimum takes, so the nonzero limit is about ten minutes
    of a first-order search on two cores (docs/bounds.md, "How far it scales"). Without numba the loops run in numpy / scipy, several times
    slower: the rule then says no, and ``lower_bound(relaxation="auto")`` should fall back to
    relaxation 1.
    """
    n = system.n_processes
    fl = system.automaton.flat(n)
    n_c, n_p, n_e = system.n_configs, int(fl.act_ptr[-1]), int(fl.out_nxt.size)
    caps = np.asarray(system.caps, dtype=np.int64)
    shape = lp_shape(caps, n_c, n_p, n_e)
    mem = _memory_estimate(shape, caps, n_c, n_p)
    numba = kernels_available()
    ok = shape["nnz"] <= REACH_MAX_NNZ and mem <= REACH_MAX_BYTES and numba
    return {
        "processes": n, "configurations": n_c, "pairs": n_p, "outcomes": n_e,
        "alp_variables": int(caps.sum()) * n_c + n * n_p + 1, "alp_constraints": int(caps.sum()) * n_p,
        "lp_rows": shape["rows"], "lp_cols": shape["cols"], "lp_nnz": shape["nnz"], "memory_bytes": mem,
        "numba": numba, "within_reach": bool(ok),
        "rule": (f"LP nonzeros {shape['nnz']:,} {'<=' if shape['nnz'] <= REACH_MAX_NNZ else '>'} "
                 f"{REACH_MAX_NNZ:,}, estimated memory {mem / 2**30:.2f} GiB "
                 f"{'<=' if mem <= REACH_MAX_BYTES else '>'} {REACH_MAX_BYTES / 2**30:.0f} GiB, "
                 f"numba {'available' if numba else 'missing'}"),
    }


def joint_reach(system: System) -> str | None:
    """None when relaxation 2 is within reach of this machine (:func:`joint_size`'s rule), else why not."""
    size = joint_size(system)
    return None if size["within_reach"] else f"relaxation 2 is out of reach: {size['rule']}"


def _memory_estimate(shape: dict, caps: np.ndarray, n_c: int, n_p: int) -> int:
    """Peak bytes: assembling and equilibrating the LP (~100 bytes a nonzero, measured), the PDHG's
    vectors, the chains' tables and the bundle's cuts."""
    vectors = 12 * 8 * (shape["rows"] + shape["cols"])
    chains = int(caps.sum()) * (8 * 8 * n_c + 2 * 8 * n_p)
    cuts = 2 * caps.size * 60 * 8 * n_p
    return int(100 * shape["nnz"] + vectors + chains + cuts)


# ---------------------------------------------------------------------------- bookkeeping
@dataclass
class _Best:
    lower_bound: float = -np.inf
    certificate: TableCertificate | None = None
    tables: list | None = None
    prices: np.ndarray | None = None
    gains: np.ndarray | None = None
    found_at: str = ""


@dataclass
class _Run:
    system: System
    data: JointData
    kern: Kernels
    prog: Progress
    tol: float
    deadline: float
    t0: float
    chains: list = field(default_factory=list)
    laws: list = field(default_factory=list)
    best: _Best = field(default_factory=_Best)
    evaluations: int = 0
    chain_sweeps: int = 0
    history: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    symmetry: bool = True
    cpu_limit: float | None = None

    def clock(self, name: str, since: float) -> None:
        self.seconds[name] = self.seconds.get(name, 0.0) + time.monotonic() - since

    def out_of_time(self) -> bool:
        return time.monotonic() >= self.deadline

    @property
    def chain_tol(self) -> float:
        return max(1e-11, 0.02 * self.tol)


def _evaluate(run: _Run, prices: np.ndarray, phase: str, slack: float = 0.0) -> float:
    """Solve every priced chain (warm-started), certify their tables, keep the best (or these
    tables when they certify at most ``slack`` less than the best): returns
    L(prices) = sum_k lower_k (the Lagrangian's value, from the chains' brackets)."""
    data = run.data
    sols: list[ChainSolution] = []
    t = time.monotonic()
    for k in range(data.n_processes):
        h0 = run.chains[k].h if run.chains else None
        sols.append(solve_chain(data, k, prices[k], h0, run.kern, tol=run.chain_tol, stop=run.out_of_time))
    run.clock("chains", t)
    t = time.monotonic()
    run.chains = sols
    run.evaluations += 1
    run.chain_sweeps += sum(s.sweeps for s in sols)
    tables = [s.h for s in sols]
    cert = certify_tables(data, tables)
    if cert.lower_bound > run.best.lower_bound - slack:
        run.best = _Best(cert.lower_bound, cert, tables, prices.copy(), np.array([s.lower for s in sols]), phase)
    run.history.append((round(time.monotonic() - run.t0, 3), phase, cert.lower_bound))
    run.clock("certify", t)
    return float(sum(s.lower for s in sols))


def _prices_from_tables(data: JointData, tables) -> np.ndarray:
    """Zero-sum prices from tables: mu_k = u_k(h) + an equal share of each pair's slack
    -g(h) - sum_k u_k(p) >= 0, centred over k. Any prices are valid; these make h a sub-solution of
    every priced chain, so the chains' solutions certify at least g(h)."""
    cert = certify_tables(data, tables)
    u = cert.u
    mu = u + (-cert.raw - u.sum(axis=0)) / data.n_processes
    return mu - mu.mean(axis=0)


def _cuts(run: _Run, sols: list[ChainSolution]) -> list[tuple[int, float, np.ndarray]]:
    """The cut of each process's greedy policy (its stationary law warm-started from the last one)."""
    out = []
    t = time.monotonic()
    for k, s in enumerate(sols):
        w = policy_weights(run.data, k, s.policy)
        y0 = run.laws[k] if len(run.laws) > k else None
        y, _, _ = stationary(run.data, k, w, run.kern, y0, tol=1e-9)  # cuts steer; they certify nothing
        if len(run.laws) > k:
            run.laws[k] = y
        else:
            run.laws.append(y)
        a, x = column(run.data, k, y, w)
        out.append((k, a, x))
    run.clock("cuts", t)
    return out


def _randomised_cuts(run: _Run, lp: JointLP, z: np.ndarray) -> list[tuple[int, float, np.ndarray]]:
    """Cuts of the randomised policies pi_k(p | tau, C) proportional to the PDHG's occupation
    measures (the chains' greedy policy where they carry no mass)."""
    out = []
    for k, Y in enumerate(lp.occupations(z)):
        Y = np.maximum(Y, 0.0)
        mass = np.zeros((run.data.n_configs, Y.shape[1]))
        np.add.at(mass, run.data.pair_c, Y)
        w = np.where(mass[run.data.pair_c] > 1e-12, Y / np.maximum(mass[run.data.pair_c], 1e-300), 0.0)
        empty = mass <= 1e-12
        cs, ts = np.nonzero(empty)
        w[run.chains[k].policy[cs, ts], ts] = 1.0
        y, _, _ = stationary(run.data, k, w, run.kern, run.laws[k] if len(run.laws) > k else None)
        a, x = column(run.data, k, y, w)
        out.append((k, a, x))
    return out


# ---------------------------------------------------------------------------- phases
def _start(run: _Run, warm: tuple | None) -> tuple[list, np.ndarray]:
    """Zero prices (every process alone on the joint configuration), then relaxation 1's tables and
    prices when given. Returns the PDHG's warm start: the last chains' stationary occupations
    and their mean (C, a) marginal."""
    data = run.data
    _evaluate(run, np.zeros((data.n_processes, data.n_pairs)), "start")
    if warm is not None:
        _offer(run, warm[0], None, "relaxation 1's tables")
        _evaluate(run, warm[1], "relaxation 1's prices")
    occ, xs = [], []
    for k, s in enumerate(run.chains):
        w = policy_weights(data, k, s.policy)
        y, _, _ = stationary(data, k, w, run.kern)
        run.laws.append(y)
        occ.append(y[data.pair_c] * w)
        xs.append(occ[-1].sum(axis=1))
    return occ, np.mean(xs, axis=0)


def _offer(run: _Run, tables: list, prices: np.ndarray | None, phase: str, slack: float = 0.0) -> None:
    """Certify ``tables`` and keep them when they beat the best so far, or certify at most ``slack``
    less (prices: the zero-sum prices that make them sub-solutions of every chain, when none are
    given)."""
    cert = certify_tables(run.data, tables)
    run.history.append((round(time.monotonic() - run.t0, 3), phase, cert.lower_bound))
    if cert.lower_bound > run.best.lower_bound - slack:
        mu = _prices_from_tables(run.data, tables) if prices is None else prices
        run.best = _Best(cert.lower_bound, cert, [np.array(h, float) for h in tables], mu,
                         -cert.u.max(axis=1), phase)


def relaxation1_start(system: System, r1: BoundResult) -> tuple[list, np.ndarray] | None:
    r"""Relaxation 1's tables and prices carried to relaxation 2 (None when the model has no claims).

    Tables: h_k(tau, C) = h^1_k(tau, column_k(C)), the private bias read on k's projection.
    Prices: mu_k(p) = \sum_m \lambda_m claim_{m,k}(p) - (1/N) \sum_j \sum_m \lambda_m claim_{m,j}(p),
    zero-sum over k. Where the claims sum to 1 the priced joint chain of process k is at least
    its priced private chain (every joint action projects to a private one with the same
    transition of (tau_k, C_k)), so relaxation 2 at these prices is at least relaxation 1's bound.
    """
    try:
        claims = _joint_claims(system)
    except WncsError:
        return None
    lam = np.asarray(r1.multipliers, float).ravel()
    mu = np.einsum("m,pmk->kp", lam, claims)
    tables = [np.asarray(h)[np.asarray(col)] for h, col in zip(r1.tables.h, r1.tables.column)]
    return tables, mu - mu.mean(axis=0)


def _joint_claims(system: System) -> np.ndarray:
    """(|C x A|, M, N) claims of every joint pair, pairs in the automaton's flat order."""
    model = system.model
    return np.concatenate([model.claims(cfg, system.labels[c, : system.n_actions[c]])
                           for c, cfg in enumerate(system.automaton.configs)]).astype(float)


def _dual_of(lp: JointLP, tables) -> np.ndarray:
    """A feasible dual of the LP from tables: h_k (pinned), u_k(h) plus slack shares, g(h)."""
    tables = pin_tables(tables)
    cert = certify_tables(lp.data, tables)
    u = cert.u + (-cert.raw - cert.u.sum(axis=0)) / lp.data.n_processes
    return lp.dual_from(tables, u, cert.raw)


def _pdhg_phase(run: _Run, start: tuple, max_iter: int, share: float, patience: int) -> tuple[JointLP, np.ndarray, dict]:
    """PDHG with periodic repairs, until ``patience`` repairs in a row gained nothing, ``max_iter``
    iterations or its time share."""
    data = run.data
    occ, x = start
    run.prog.phase(f"relaxation 2: the start gives {run.best.lower_bound:.6g}; building the LP")
    t = time.monotonic()
    lp = JointLP.build(data, run.kern)
    run.clock("lp_build", t)
    pd = HalpernPDHG(lp, lp.primal_from(occ, x), _dual_of(lp, run.best.tables))
    stop_at = min(run.deadline, time.monotonic() + share * max(run.deadline - time.monotonic(), 0.0))
    chunk, recent = 200, []
    while pd.iterations < max_iter and time.monotonic() < stop_at:
        t_it = time.monotonic()
        pd.run(min(chunk, max_iter - pd.iterations))
        run.clock("pdhg", t_it)
        per_it = (time.monotonic() - t_it) / chunk
        t_rep = time.monotonic()
        before = run.best.lower_bound
        _evaluate(run, _prices_from_tables(data, lp.tables(pd.dual)), "pdhg")
        recent.append(run.best.lower_bound - before)
        # repairs take at most a quarter of the phase
        chunk = int(min(2000, max(200, 3.0 * (time.monotonic() - t_rep) / max(per_it, 1e-9))))
        run.prog.tick(f"PDHG {pd.iterations} its: certified {run.best.lower_bound:.8g} "
                      f"(restarts {pd.restarts}, w {pd.w:.2g})")
        if len(recent) >= patience and sum(recent[-patience:]) <= 0.0:
            break
    return lp, pd.primal, {"pdhg_iterations": pd.iterations, "pdhg_restarts": pd.restarts,
                           "pdhg_primal_weight": pd.w, **{f"pdhg_{k}": v for k, v in pd.residuals().items()}}


def _bundle_phase(run: _Run, max_iter: int, seed_cuts: list) -> tuple[bool, int, PriceBundle]:
    """Proximal bundle from the best prices, until its stopping test (True), :data:`STALL` null
    steps in a row, ``max_iter`` steps or the deadline (False)."""
    data = run.data
    centre = run.best.prices
    value = _evaluate(run, centre, "bundle")
    cuts = seed_cuts + _cuts(run, run.chains)
    X = np.array([x for _, _, x in cuts[-data.n_processes:]])
    spread = float(((X - X.mean(axis=0)) ** 2).sum())
    # a first step the linear model prices at ~1% of L: t ||PZ||^2 ~ 0.01 |L|, PZ ~ the spread of the cuts
    bundle = PriceBundle(centre, value, t=1e-2 * max(abs(value), 1.0) / max(spread, 1e-12))
    for k, a, x in cuts:
        bundle.add_cut(k, a, x)
    it = nulls = 0
    while it < max_iter and not run.out_of_time():
        t = time.monotonic()
        mu = bundle.candidate()
        run.clock("master", t)
        if bundle.converged(run.tol):
            return True, it, bundle
        value = _evaluate(run, mu, "bundle")
        it += 1
        for k, a, x in _cuts(run, run.chains):
            bundle.add_cut(k, a, x)
        nulls = 0 if bundle.report(mu, value) else nulls + 1
        if nulls >= STALL:
            break
        run.prog.tick(f"bundle {it}: certified {run.best.lower_bound:.8g}, L(centre) {bundle.value:.8g}, "
                      f"predicted +{bundle.predicted:.3g}, disagreement {bundle.disagreement:.2g}, t {bundle.t:.3g}")
    return False, it, bundle


# ---------------------------------------------------------------------------- entry point
def joint_bound(system: System, *, tol: float = 1e-4, time_limit: float | None = 600.0, max_iter: int = 1000,
                pdhg_iter: int = 20_000, pdhg_patience: int = 4, method: str = "auto", ipm_tol: float | None = None,
                warm_start: bool = True, symmetry: bool = True, ascent_cpu_limit: float | None = None,
                kernel: str = "auto", threads: int = 1,
                progress: bool | Progress | None = None) -> BoundResult:
    """A certified lower bound on g* from relaxation 2 (joint configuration, per-process AoI).

    Parameters
    ----------
    system : System
        The scenario's automaton and costs (:meth:`System.from_scenario`); the tau box is never
        formed.
    tol : float
        Relative accuracy asked of the relaxation: the bundle stops when its model predicts less
        than ``tol * |L|`` more; the PDHG hands over when two repairs gained less than that.
    time_limit : float or None
        Seconds (default 10 minutes, so that ``wncs-lp bound`` with ``auto`` ends; None: no
        limit); the interior point gets 80% of what is left after the start and at most
        :data:`IPM_GUARD` (a multiple of its predicted time), the PDHG at most 60% of it. The bound returned is certified whatever stops the run (an interior point
        stopped by it leaves no tables: the bound is then the start's or the bundle's).
    max_iter : int
        Bundle steps (each one certified evaluation: N priced chains and the separable check);
        with ``"ipm"`` only when the interior point returned no tables (its time limit).
    pdhg_iter : int
        PDHG iterations at most.
    pdhg_patience : int
        The PDHG hands over after this many repairs in a row that did not raise the bound.
    method : {"auto", "ipm", "bundle", "pdhg", "pdhg+bundle", "ascent", "smooth"}
        ``"auto"`` (default): ``"ipm"`` when :func:`ipm_fits` (predicted within :data:`IPM_BUDGET`
        seconds of CPU and the memory), else ``"bundle"`` (``stats["auto_method"]`` says which,
        ``stats["ipm_plan"]`` why); ``"ipm"``: the LP by
        IPX (the bundle only if IPX returned no tables, stopped by ``time_limit``); ``"bundle"``:
        the bundle from the start; ``"pdhg"``: PDHG with repairs only; ``"pdhg+bundle"``: PDHG
        then bundle. From relaxation
        1's prices the bundle alone beat the PDHG where measured, and the interior point beat both
        (docs/bounds.md, "Measured"). ``"ascent"``: projected supergradient steps on the lumped chains of the
        LP reduced by interchangeable processes (:mod:`~wncs_lp.bounds.joint_ascent`), ``max_iter``
        of them, from relaxation 1's prices; neither the LP nor the N whole chains are built, so it
        runs where the interior point does not fit (sixteen processes). ``"smooth"``: L-BFGS on the
        entropy-smoothed Lagrangian of the same lumped chains at decreasing temperatures
        (:mod:`~wncs_lp.bounds.joint_smooth`), ``max_iter`` smoothed evaluations at most, from
        relaxation 1's prices: where it runs to convergence, within its smoothing error of the LP's
        optimum, which the supergradient steps do not reach.
    ipm_tol : float, optional
        IPX's optimality tolerance (default ``tol``: at processes 1-4 cap 20, 1e-4 took 36
        iterations and certified 6e-6 (relative) less than 1e-6 in 47).
    warm_start : bool
        Solve relaxation 1 first and start from its tables and prices (:func:`relaxation1_start`);
        where its claims sum to 1 this makes relaxation 2's bound at least relaxation 1's.
    symmetry : bool
        Reduce the interior point's LP by the symmetry of interchangeable processes
        (:mod:`~wncs_lp.bounds.joint_symmetry`; checked on the automaton, found in a few seconds;
        the paper's four process types twice at cap 20: 12.5M -> 1.86M nonzeros). The reduced LP
        has the same optimum; its tables are certified on the whole system like any others.
    ascent_cpu_limit : float, optional
        Seconds of this process's CPU time after which the lumped searches (``"ascent"``,
        ``"smooth"``) begin no more steps: a guard beside ``max_iter`` (the best point met is kept).
    kernel : {"auto", "numba", "numpy"}
    threads : int
        numba threads (default 1: numba's OpenMP layer does not survive a fork).
    progress : bool or Progress, optional

    Returns
    -------
    BoundResult
        ``relaxation="joint-configuration"``; ``lower_bound`` <= g* (the separable check of
        ``tables``); ``multipliers`` the zero-sum prices mu (N, |C x A|) whose chains gave the
        tables; ``process_gains`` each chain's certified lower gain there (their sum is within
        round-off of a bound the check never falls below); ``status`` ``"optimal"`` when the
        bundle's stopping test was met, or IPX finished with its (uncertified) primal objective
        within ``tol`` of the certified bound, ``"max_iter"`` when an
        iteration or time budget ran out first, ``"interrupted"`` on Ctrl-C.
        ``relaxation_upper`` is +inf (no primal point of the relaxation is certified).
    """
    if method not in JOINT_METHODS:
        raise SolverError(f"unknown method {method!r} for relaxation 2; expected one of {', '.join(JOINT_METHODS)}")
    if not tol > 0:
        raise SolverError(f"tol must be positive, got {tol!r}")
    t0 = time.monotonic()
    prog = as_progress(progress)
    system = bound_system(system)  # a System checked, its own cost tables honoured
    data = JointData.from_system(system)
    run = _Run(system=system, data=data, kern=Kernels(kernel, threads), prog=prog, tol=float(tol),
               deadline=t0 + (float(time_limit) if time_limit is not None else np.inf), t0=t0, symmetry=bool(symmetry),
               cpu_limit=ascent_cpu_limit)
    prog.phase(f"relaxation 2: {data.n_processes} processes, {data.n_configs:,} configurations, "
               f"{data.n_pairs:,} pairs, caps {tuple(int(c) for c in data.caps)}")
    stats: dict = {"method": method, "kernel": run.kern.name, "threads": run.kern.threads}
    status, it = MAX_ITER, 0
    try:
        warm = _warm_start(system, run, stats) if warm_start else None
        closed, it = _phases(run, warm, method, stats, pdhg_iter, pdhg_patience, max_iter,
                             tol if ipm_tol is None else ipm_tol)
        status = OPTIMAL if closed else MAX_ITER
    except KeyboardInterrupt:
        status = INTERRUPTED
    if run.best.tables is None:
        raise KeyboardInterrupt  # nothing certified yet: nothing to return
    prog.done(f"relaxation 2: certified lower bound {run.best.lower_bound:.10g} ({status})")
    return _result(run, status, it, stats, time.monotonic() - t0)


def joint_bound_from_tables(system: System, tables, *, source: str = "tables given", chains: bool = True,
                            tol: float = 1e-4, kernel: str = "auto") -> BoundResult:
    """Relaxation 2's certified bound from tables found elsewhere (an earlier run, a file).

    Parameters
    ----------
    system : System
    tables : sequence of (|C|, tau_hat_k) arrays
        Any tables h_k(tau, C): the bound is :func:`~wncs_lp.bounds.joint_chains.certify_tables`'s
        check of them on ``system``, so tables of another system (or wrong ones) only certify
        less, never something false; tables of the wrong shape are refused.
    source : str
        Where the tables came from (said in ``certified_by`` and ``stats["found_in"]``).
    chains : bool
        Also solve the priced chains at the prices of these tables and keep their tables when
        they certify within ``tol`` as much (as after the interior point: their greedy policy
        acts on every state, see :func:`joint_bound`).
    tol : float
    kernel : {"auto", "numba", "numpy"}

    Returns
    -------
    BoundResult
        ``status`` ``"optimal"`` (the check is complete whatever the tables).
    """
    t0 = time.monotonic()
    data = JointData.from_system(system)
    run = _Run(system=system, data=data, kern=Kernels(kernel, 1), prog=as_progress(False), tol=float(tol),
               deadline=np.inf, t0=t0)
    tables = [np.asarray(h, dtype=float) for h in tables]
    _offer(run, tables, None, source)
    stats: dict = {"method": "tables", "kernel": run.kern.name, "threads": 1, "source": source}
    if chains:
        _chains_at_ipm_prices(run, tables, stats, label=f"the priced chains at the prices of {source}")
        stats["tables_bound"], stats["chains_bound"] = stats.pop("ipm_tables_bound"), stats.pop("ipm_chains_bound")
    return _result(run, OPTIMAL, 0, stats, time.monotonic() - t0)


def _warm_start(system: System, run: _Run, stats: dict) -> tuple | None:
    """Relaxation 1 solved, its tables and prices carried over (:func:`relaxation1_start`)."""
    t = time.monotonic()
    try:
        r1 = private_bound(system)
    except WncsError as exc:
        stats["warm_start"] = f"none: {exc}"
        return None
    run.clock("relaxation_1", t)
    stats["relaxation_1_bound"] = r1.lower_bound
    warm = relaxation1_start(system, r1)
    stats["warm_start"] = "relaxation 1" if warm is not None else "none: the model defines no claims"
    return warm


def ipm_plan(data: JointData, symmetry: ProcessSymmetry | None = None) -> dict:
    """What the interior point would cost on relaxation 2's LP (reduced by ``symmetry`` when given),
    and whether ``method="auto"`` takes it.

    Returns
    -------
    dict
        ``lp_rows`` / ``lp_cols`` / ``lp_nnz`` (the LP handed to IPX, before its presolve),
        ``classes`` (the classes of interchangeable processes used), ``predicted_seconds`` (CPU,
        :func:`~wncs_lp.bounds.joint_ipm.ipm_seconds`), ``memory_bytes``
        (:func:`~wncs_lp.bounds.joint_ipm.ipm_bytes`), ``fits`` (predicted at most
        :data:`IPM_BUDGET` seconds and memory at most :data:`REACH_MAX_BYTES`) and ``rule`` (the
        rule in words).
    """
    sym = symmetry if symmetry is not None else ProcessSymmetry.none(data.n_processes)
    shape = symmetric_lp_shape(sym, data)
    seconds = ipm_seconds(shape["nnz"], float(np.mean(data.caps)))
    mem = ipm_bytes(shape["nnz"], shape["rows"], shape["cols"])
    fits = seconds <= IPM_BUDGET and mem <= REACH_MAX_BYTES
    classes = [list(c) for c in sym.classes if len(c) > 1]
    rule = (f"interior point predicted {seconds:.0f} s of CPU ({'<=' if seconds <= IPM_BUDGET else '>'} "
            f"{IPM_BUDGET:.0f} s) and {mem / 2**30:.2f} GiB ({'<=' if mem <= REACH_MAX_BYTES else '>'} "
            f"{REACH_MAX_BYTES / 2**30:.0f} GiB) on an LP of {shape['nnz']:,} nonzeros"
            + (f" (reduced by interchangeable processes {classes})" if classes else ""))
    return {"lp_rows": shape["rows"], "lp_cols": shape["cols"], "lp_nnz": shape["nnz"], "classes": classes,
            "predicted_seconds": seconds, "memory_bytes": mem, "fits": bool(fits), "rule": rule}


def ipm_fits(data: JointData, symmetry: ProcessSymmetry | None = None) -> bool:
    """``method="auto"``'s rule (:func:`ipm_plan`): the interior point when it is predicted to take
    at most :data:`IPM_BUDGET` seconds of CPU and its memory estimate is at most :data:`REACH_MAX_BYTES`."""
    return ipm_plan(data, symmetry)["fits"]


def _ipm_phase(run: _Run, stats: dict, tol: float, sym: ProcessSymmetry, plan: dict) -> bool:
    """The LP solved whole by IPX; its duals' tables offered to the certificate. True when IPX
    returned tables (then the bundle is not needed: they are at the relaxation's optimum up to
    IPX's tolerance)."""
    left = run.deadline - time.monotonic()
    if left <= 0:
        stats.update(ipm_status="not run: out of time", ipm_tables=False)
        return False
    run.prog.phase(f"relaxation 2: the start gives {run.best.lower_bound:.8g}; the LP by the interior point "
                   f"(HiGHS IPX, no crossover; {plan['lp_nnz']:,} nonzeros, predicted {plan['predicted_seconds']:.0f} "
                   "s of CPU)")
    t = time.monotonic()
    # 80% of the time left (a run stopped by its limit leaves no tables, and the bundle the rest),
    # and a CPU guard: a multiple of the prediction, which a solve that would finish stays within
    # however loaded the machine is
    guard = IPM_GUARD["factor"] * plan["predicted_seconds"] + IPM_GUARD["slack"]
    limit = 0.8 * left if np.isfinite(left) else None
    ipm = ipm_tables(run.data, symmetry=sym, tol=tol, time_limit=limit, cpu_limit=guard)
    run.clock("ipm", t)
    stats.update(ipm_status=ipm.status, ipm_iterations=ipm.iterations, ipm_objective=ipm.objective,
                 ipm_seconds=round(ipm.seconds, 3), ipm_cpu_seconds=round(ipm.cpu_seconds, 3),
                 ipm_time_limit=limit, ipm_cpu_limit=round(guard, 3), lp_shape=ipm.shape[:2], lp_nnz=ipm.shape[2],
                 ipm_tables=ipm.tables is not None)
    if ipm.tables is not None:
        _offer(run, ipm.tables, None, "the interior point's duals")
        run.prog.tick(f"interior point ({ipm.status}, {ipm.iterations} iterations): certified "
                      f"{run.best.lower_bound:.10g}")
        if sym.trivial or ipm.prices is None:
            _chains_at_ipm_prices(run, ipm.tables, stats)
        else:
            _lumped_at_ipm_prices(run, sym, ipm.prices, stats)
    return ipm.tables is not None


def _chains_at_ipm_prices(run: _Run, tables: list, stats: dict,
                          label: str = "the priced chains at the interior point's prices") -> None:
    """Replace the interior point's duals by the priced chains' bias tables at their prices when
    these certify as much (within ``tol``).

    The duals only need to be tight where the LP's optimum puts mass: elsewhere an interior
    point leaves them anywhere inside the slack, and a greedy policy on them may act far from
    optimal there. The chains' tables satisfy each priced chain's Bellman equation everywhere,
    so their greedy policy acts well, and they certify at least as much within ``tol``
    (docs/bounds.md, "The tables returned and their policy", measures both).
    """
    ipm_bound = run.best.lower_bound
    # kept even when the duals certified a hair more (within tol): the chains' tables are kept for their policy
    _evaluate(run, _prices_from_tables(run.data, tables), label, slack=run.tol * max(abs(ipm_bound), 1.0))
    stats.update(ipm_tables_bound=ipm_bound, ipm_chains_bound=run.history[-1][2])


def _lumped_at_ipm_prices(run: _Run, sym: ProcessSymmetry, prices: list, stats: dict) -> None:
    """With interchangeable processes: the class representatives' lumped chains
    (:class:`~wncs_lp.bounds.joint_symmetry.LumpedChains`) priced by the interior point's coupling
    duals, their biases spread to every process, in place of :func:`_chains_at_ipm_prices`'s N whole
    chains (the same tables up to the chains' tolerance, since the whole chains at symmetric
    prices are the lumped ones read on the orbits; 4 chains of 1,009-1,348 orbits instead of 16
    of 19,845 configurations for the paper's four types four times)."""
    ipm_bound = run.best.lower_bound
    t = time.monotonic()
    lumped = lumped_chains(sym, run.data)
    value, sols = lumped.lagrangian(prices, run.kern, tol=run.chain_tol, stop=run.out_of_time)
    tables = spread_orbit_tables(sym, run.data, [s.h for s in sols])
    run.clock("chains", t)
    run.evaluations += 1
    run.chain_sweeps += sum(s.sweeps for s in sols)
    label = "the lumped chains at the interior point's prices"
    _offer(run, tables, None, label, slack=run.tol * max(abs(ipm_bound), 1.0))
    stats.update(ipm_tables_bound=ipm_bound, ipm_chains_bound=run.history[-1][2], lumped_lagrangian=value)


def _ascent_phase(run: _Run, warm: tuple | None, stats: dict, steps: int, smooth: bool = False) -> None:
    """Projected supergradient steps on the lumped chains (:mod:`~wncs_lp.bounds.joint_ascent`),
    or with ``smooth`` L-BFGS on their smoothed Lagrangian (:mod:`~wncs_lp.bounds.joint_smooth`),
    from relaxation 1's prices (zero prices without them), ``steps`` steps (smoothed evaluations) at
    most; the best prices' biases, spread to every process, offered to the certificate."""
    t = time.monotonic()
    sym = process_symmetry(run.system, run.data) if run.symmetry else ProcessSymmetry.none(run.data.n_processes)
    lumped = lumped_chains(sym, run.data)
    run.clock("symmetry", t)
    if warm is not None:
        _offer(run, warm[0], None, "relaxation 1's tables")
    mu = warm[1] if warm is not None else np.zeros((run.data.n_processes, run.data.n_pairs))
    t = time.monotonic()
    kind = "smoothed ascent" if smooth else "lumped ascent"
    run.prog.phase(f"relaxation 2: {kind} on {len(lumped.chains)} chains of "
                   f"{[c.n_configs for c in lumped.chains]} orbits of configurations, {steps} steps at most")
    if smooth:
        # the smoothed chains' values enter L-BFGS's line searches: brackets much tighter than the bound's
        asc = smoothed_ascent(lumped, lumped.prices_from(mu), run.kern, evaluations=steps,
                              tol=min(run.chain_tol, 1e-9), chain_tol=run.chain_tol,
                              cpu_limit=run.cpu_limit, stop=run.out_of_time, progress=run.prog)
    else:
        asc = lumped_ascent(lumped, lumped.prices_from(mu), run.kern, iterations=steps, tol=run.chain_tol,
                            cpu_limit=run.cpu_limit, stop=run.out_of_time, progress=run.prog)
    run.clock("ascent", t)
    run.evaluations += len(asc.history)
    run.chain_sweeps += sum(s.sweeps for s in asc.solutions)
    _offer(run, spread_orbit_tables(sym, run.data, [s.h for s in asc.solutions]), None, f"the {kind}")
    stats.update(ascent_steps=len(asc.history), ascent_start=asc.history[0], ascent_value=asc.value,
                 ascent_cpu_seconds=round(asc.cpu_seconds, 3),
                 classes=[list(c) for c in sym.classes if len(c) > 1])


def _phases(run: _Run, warm: tuple | None, method: str, stats: dict, pdhg_iter: int, patience: int,
            max_iter: int, ipm_tol: float) -> tuple[bool, int]:
    """The phases of ``method``: (the bundle's stopping test met, its steps). The start's chains
    (:func:`_start`) are solved only for the searches that need them: the interior point, when it
    returns tables, has only relaxation 1's tables offered before it."""
    seed = []
    if method in ("auto", "ipm"):
        sym = process_symmetry(run.system, run.data) if run.symmetry else ProcessSymmetry.none(run.data.n_processes)
        plan = ipm_plan(run.data, sym)
        stats.update(ipm_plan={k: plan[k] for k in ("lp_nnz", "classes", "predicted_seconds", "memory_bytes", "rule")})
        if method == "auto":
            method = "ipm" if plan["fits"] else "bundle"
            stats["auto_method"] = method
    if method == "ipm" and warm is not None:
        _offer(run, warm[0], None, "relaxation 1's tables")
    if method == "ipm" and _ipm_phase(run, stats, ipm_tol, sym, plan):
        # a stopping rule, not a certificate (like the bundle's): IPX finished (kOptimal, or
        # kUnknown when HiGHS's stricter re-check at 1e-7 disagrees) with its primal objective
        # within tol of the duals' own certificate (the chains' tables kept may certify up to tol less)
        gap = stats["ipm_objective"] - max(run.best.lower_bound, stats.get("ipm_tables_bound", -np.inf))
        finished = stats["ipm_status"] in ("kOptimal", "kUnknown")
        return finished and gap <= run.tol * max(abs(run.best.lower_bound), 1.0), 0
    if method in ("ascent", "smooth"):
        _ascent_phase(run, warm, stats, max_iter, smooth=method == "smooth")
        return False, 0
    start = _start(run, warm)
    if method in ("pdhg+bundle", "pdhg"):
        lp, z, pstats = _pdhg_phase(run, start, pdhg_iter, 0.6 if method == "pdhg+bundle" else 1.0, patience)
        stats.update(pstats, lp_shape=lp.shape)
        if method == "pdhg+bundle":
            seed = _randomised_cuts(run, lp, z)
    if method == "pdhg" or max_iter <= 0:
        return False, 0
    closed, it, bundle = _bundle_phase(run, max_iter, seed)
    stats.update(bundle_serious=bundle.serious_steps, bundle_null=bundle.null_steps,
                 bundle_predicted=bundle.predicted, bundle_t=bundle.t, bundle_disagreement=bundle.disagreement,
                 bundle_linearisation_error=bundle.linearisation_error)
    return closed, it


def _result(run: _Run, status: str, bundle_steps: int, stats: dict, seconds: float) -> BoundResult:
    """The best tables, checked once more from scratch: the bound returned is that check's."""
    best, data = run.best, run.data
    cert = certify_tables(data, best.tables)
    n_c = data.n_configs
    tables = ValueTables(h=tuple(np.ascontiguousarray(h) for h in best.tables),
                         column=tuple(np.arange(n_c) for _ in range(data.n_processes)))
    stats.update(evaluations=run.evaluations, chain_sweeps=run.chain_sweeps, bundle_steps=bundle_steps,
                 roundoff=cert.roundoff, raw_bound=cert.raw, binding_pair=cert.binding_pair,
                 found_in=best.found_at, history=run.history, certified=bool(np.isfinite(cert.lower_bound)),
                 seconds_in={k: round(v, 3) for k, v in run.seconds.items()})
    how = ("separable check of the tables h_k(tau, C) over all sum_k tau_hat_k |C x A| = "
           f"{int(data.caps.sum()) * data.n_pairs:,} constraints: g(h) = -max_(C,a) sum_k max_tau "
           f"[h_k - q_k - E h_k] = {cert.raw:.12g}, minus a round-off bound {cert.roundoff:.2g}; the tables "
           f"came from {best.found_at} (each process's chain (tau_k, C) priced at the multipliers, solved "
           "by relative value iteration); how they were found does not enter the bound")
    return BoundResult(relaxation="joint-configuration", lower_bound=float(cert.lower_bound),
                       relaxation_upper=float("inf"), status=status, certified_by=how,
                       multipliers=best.prices, process_gains=best.gains, tables=tables, seconds=float(seconds),
                       iterations=int(run.evaluations), stats=stats)
