"""Exact evaluation of a stationary policy on an enumerated MDP.

For a unichain stationary policy (deterministic or randomised) with stationary distribution
pi over the states and action probabilities beta(a | s), this module reports

* the gain g = sum_s pi(s) c(s) (the long-run average cost),
* the per-process average MSE  E[q_k(tau_k)] = sum_s pi(s) q_k(tau_k(s)), which sum to g,
* the per-server utilisation   sum_{s, a} pi(s) beta(a | s) busy_m(C(s), a), the long-run
  fraction of slots in which server m performs a service step (see :attr:`System.busy`).

Only the stationary distribution is needed, and it lives on the recurrent class R of the
induced chain (for the AoI models usually a small part of the states: a deterministic policy
visits few of the tau vectors of the box). So the chain's closed classes are found first
(:class:`wncs_lp.chain.PolicyChain`); a unichain policy's pi is then the stationary law of
its class R (:func:`wncs_lp.chain.class_stationary`: a sparse LU of size |R|, or power
iteration on a class of 20,000 states or more, residual checked); pi = 0 off R. This is the same quantity as
:func:`wncs_lp.solvers.dp.evaluate_policy` computes (tests check the two agree) but avoids
its factorisation of the whole n x n system, which can take minutes (90 s for the greedy
policy on the 185,916-state three-process MDP, against 3 s here). A chain with several
recurrent classes raises :class:`~wncs_lp.errors.PolicyError`.

Multichain policies (e.g. deterministic policies at p = 1, whose cycles can settle in several
phases) have no single gain. With ``multichain="initial"`` the evaluation reports instead the
long-run averages *from the initial state* s0 (first initial configuration, every tau_k at its
cap: the start of :func:`wncs_lp.simulate.simulate`). With recurrent classes R_1..R_m,
stationary distributions pi_i on them and absorption probabilities b_i(s0),

    mu = sum_i b_i(s0) pi_i,    g(s0) = mu . c_pi,

where b(s0) comes from the expected visits y to the transient states T,
(I - P_TT)^T y = e_{s0}, b_i = y^T P_{T, R_i} 1 (or b = e_i when s0 lies in R_i).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from .chain import ITERATIVE_MIN_STATES, STATIONARY_METHODS, PolicyChain, recurrent_classes, stationary_law
from .errors import PolicyError
from .mdp import MDP
from .models.system import System
from .policy_forms import policy_array
from .truncation import CapMass, cap_mass

__all__ = ["Evaluation", "evaluate", "memory_chain", "MultichainEvaluationError"]


class MultichainEvaluationError(PolicyError):
    """The evaluated policy's chain has several recurrent classes (a :class:`PolicyError`).

    ``detail`` is the message without the remedy, so a caller (the command line) can name its
    own way out (``--from-initial``) instead of the library's (``multichain="initial"``).
    """

    def __init__(self, detail: str, remedy: str = "evaluate with multichain=\"initial\" for the averages from "
                                                 "the initial state"):
        self.detail = detail
        super().__init__(f"{detail} ({remedy})")


@dataclass(frozen=True)
class Evaluation:
    """The exact long-run averages of one stationary policy.

    Attributes
    ----------
    policy : str
        Policy name.
    gain : float
        Average cost g = E_pi[c(s)].
    mse : tuple of float
        E_pi[q_k(tau_k)] per process (sum = gain).
    utilisation : tuple of float
        Fraction of slots in which each server performs a service step.
    process_names, server_names : tuple of str
    randomised : bool
        Whether the evaluated policy was randomised.
    residual : float
        ||pi P - pi||_inf of the computed stationary distribution.
    recurrent_classes : int
        1 for a unichain policy; more only with ``multichain="initial"`` (then the averages
        are those from the initial state).
    n_states, n_pairs : int
        Size of the MDP.
    seconds : float
        Wall time of the evaluation (policy mapping and solve).
    cap_mass : CapMass or None
        The share of the long-run time with some AoI at its cap, in all and per process
        (:mod:`wncs_lp.truncation`), from the same stationary law; None where no law was formed.
    method : str
        How the stationary law was solved: ``"lu"`` or ``"iterative"`` (:func:`wncs_lp.chain.class_stationary`).
    gain_lower, gain_upper : float
        With ``certify=True``, the certified bracket of the gain by the certified value iteration
        of the policy's chain (NaN otherwise).
    """

    policy: str
    gain: float
    mse: tuple[float, ...]
    utilisation: tuple[float, ...]
    process_names: tuple[str, ...]
    server_names: tuple[str, ...]
    randomised: bool
    residual: float
    recurrent_classes: int
    n_states: int
    n_pairs: int
    seconds: float
    cap_mass: CapMass | None = None
    method: str = "lu"
    gain_lower: float = float("nan")
    gain_upper: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (lists instead of tuples; ``cap_mass`` as :meth:`CapMass.to_dict`)."""
        d = {k: v for k, v in asdict(self).items() if k != "cap_mass"}
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
        d["cap_mass"] = None if self.cap_mass is None else self.cap_mass.to_dict()
        return d


def evaluate(
    mdp: MDP,
    policy: Any = None,
    system: System | None = None,
    name: str | None = None,
    *,
    sigma: Any = None,
    multichain: str = "error",
    method: str = "auto",
    certify: bool = False,
) -> Evaluation:
    """Evaluate a stationary policy exactly on an enumerated MDP.

    Parameters
    ----------
    mdp : MDP
        Built by :func:`wncs_lp.models.build` (its ``states`` decode tau and C).
    policy : Policy, Solution or array
        A :class:`~wncs_lp.policies.Policy` (anything with ``on_mdp``, ``system`` and ``name``:
        mapped with ``policy.on_mdp(mdp)``; a policy with memory, such as round robin, on its
        augmented chain over (memory, state): :func:`memory_chain`), a solution of ``mdp`` (its ``policy``), or directly
        an (n,) int array of pair indices or an (L,) float array of pair probabilities.
    system : System, optional
        The cost tables and the busy table; default ``policy.system``, else the system of the
        scenario ``mdp`` was built from.
    name : str, optional
        Name reported (default ``policy.name``, ``"sigma"`` or ``"array"``).
    sigma : (n,) int array, optional
        The policy as an action per state instead (a row of ``mdp.action_table``, as
        :attr:`Solution.sigma`; see :mod:`wncs_lp.policy_forms`).
    multichain : {"error", "initial"}
        What to do with a multichain induced chain: raise (default), or report the long-run
        averages from the initial state (see the module docstring).
    method : {"auto", "lu", "iterative"}
        How each recurrent class's stationary law is solved (:func:`wncs_lp.chain.class_stationary`):
        a sparse LU, or BiCGSTAB with its true residual checked; ``"auto"``: the LU below
        :data:`wncs_lp.chain.ITERATIVE_MIN_STATES` states, BiCGSTAB from there on (where the LU
        fills in: the crossover measured in ``benchmarks/evaluation.py``).
    certify : bool
        Also bracket the gain by the certified value iteration of the policy's chain (the solvers'
        certified driver, :func:`wncs_lp.solvers.dp.value_iteration` on the chain as a one-action
        MDP): ``gain_lower <= g <= gain_upper``, and the stationary law's gain checked inside it.

    Returns
    -------
    Evaluation

    Raises
    ------
    PolicyError
        Malformed policy, an MDP of another scenario, or (:class:`MultichainEvaluationError`) a
        multichain induced chain (the message names the policy and two recurrent classes).
    """
    t0 = time.perf_counter()
    if multichain not in ("error", "initial"):
        raise PolicyError(f"multichain must be 'error' or 'initial', got {multichain!r}")
    if method not in STATIONARY_METHODS:
        raise PolicyError(f"unknown evaluation method {method!r}; expected one of {', '.join(STATIONARY_METHODS)}")
    if hasattr(policy, "act_memory") and sigma is None:  # a policy with memory: its augmented chain
        system = system or policy.system
        name = name or policy.name
        x, residual, classes, chain = _memory_law(mdp, policy, system, name, multichain, method)
        randomised = False
    else:
        arr, system, name = _policy_array(mdp, policy, system, name, sigma)
        pi, residual, classes, chain = _long_run_law(mdp, arr, system, name, multichain, method)
        x = _pair_frequencies(mdp, arr, pi)
        randomised = not np.issubdtype(arr.dtype, np.integer)
    pi = np.bincount(mdp.s_indices, weights=x, minlength=mdp.n_states)
    gain = float(x @ np.asarray(mdp.cost, dtype=float))
    lo = hi = float("nan")
    if certify:
        lo, hi = _certified_gain(*chain, gain, name)
    solved = method if method != "auto" else (
        "iterative" if max(c.size for c in classes) >= ITERATIVE_MIN_STATES else "lu")
    tau = np.asarray(mdp.states.tau, dtype=np.int64)
    sc = system.scenario
    return Evaluation(
        policy=name,
        gain=gain,
        mse=tuple(float(pi @ system.q[k][tau[:, k] - 1]) for k in range(system.n_processes)),
        utilisation=_utilisation(mdp, x, system),
        process_names=tuple(p.name for p in sc.processes),
        server_names=tuple(s.name for s in sc.servers),
        randomised=randomised,
        residual=residual,
        recurrent_classes=len(classes),
        n_states=mdp.n_states,
        n_pairs=mdp.n_pairs,
        seconds=time.perf_counter() - t0,
        cap_mass=cap_mass(mdp, pi),
        method=solved,
        gain_lower=lo,
        gain_upper=hi,
    )


def _certified_gain(P: sp.csr_matrix, c: np.ndarray, gain: float, name: str) -> tuple[float, float]:
    """The certified bracket of a chain's gain by the certified value iteration (the chain as an MDP
    with one action per state), with the stationary law's ``gain`` checked inside it."""
    from .solvers.dp import value_iteration

    n = P.shape[0]
    one = MDP.from_arrays(np.arange(n), np.zeros(n, dtype=np.int64), c, P, n, name=f"chain of {name}")
    sol = value_iteration(one)
    lo, hi = float(sol.gain_lower), float(sol.gain_upper)
    slack = 1e-9 * max(abs(gain), 1.0)
    if not lo - slack <= gain <= hi + slack:
        raise PolicyError(f"policy {name}: the stationary law's gain {gain:.12g} is outside the certified bracket "
                          f"[{lo:.12g}, {hi:.12g}] of its chain (status {sol.status})")
    return lo, hi


def _policy_array(mdp: MDP, policy: Any, system: System | None, name: str | None,
                  sigma: Any = None) -> tuple[np.ndarray, System, str]:
    """``(pair indices or pair probabilities, system, name)`` of a Policy, a solution, an array or
    an action per state (``sigma``)."""
    if hasattr(policy, "on_mdp") and hasattr(policy, "system") and sigma is None:
        arr = policy.on_mdp(mdp)
        arr = arr if isinstance(arr, np.ndarray) else policy_array(mdp, arr)
        return arr, system or policy.system, name or _name_of(policy) or "array"
    system = system if system is not None else _system_of(mdp)
    system.check_mdp(mdp)
    default = "sigma" if sigma is not None else _name_of(policy)
    return policy_array(mdp, policy, sigma), system, name or default or "array"


def _name_of(policy: Any) -> str | None:
    """A policy's name, or the method of a solution (which has no name)."""
    return getattr(policy, "name", None) or getattr(policy, "method", None)


def _system_of(mdp: MDP) -> System:
    """The system of the scenario an MDP was built from (its state space keeps the model)."""
    model = getattr(getattr(mdp, "states", None), "model", None)
    if model is None:
        raise PolicyError("evaluating a policy given as an array needs the System (system=...): this MDP carries "
                          "no model (read back from a file, or made by hand)")
    return System.from_scenario(model.scenario, model)


def _long_run_law(mdp: MDP, arr: np.ndarray, system: System, name: str, multichain: str, method: str):
    """``(pi, residual, recurrent classes, (P, c))``: the stationary law of a unichain policy, or
    the limit from the initial state of a multichain one (``"initial"``), and its chain."""
    try:
        chain = PolicyChain(mdp, arr, method)
    except PolicyError as exc:
        raise PolicyError(f"policy {name}: {exc}") from None
    classes = chain.recurrent_classes
    if len(classes) == 1:
        return chain.stationary, chain.residual, classes, (chain.P, chain.cost)
    if multichain == "error":
        raise _multichain(mdp, name, classes)
    pi, residual = _limit_from_initial(chain.P, classes, _initial_state(mdp, system), method)
    return pi, residual, classes, (chain.P, chain.cost)


def _multichain(mdp: MDP, name: str, classes: list, n: int | None = None) -> MultichainEvaluationError:
    """The error of a multichain policy (states of an augmented chain of size m n are named by
    their state s = index mod n)."""
    n = mdp.n_states if n is None else n
    a, b = classes[0], classes[1]
    return MultichainEvaluationError(
        f"policy {name} induces a multichain Markov chain with {len(classes)} recurrent classes "
        f"(e.g. state {mdp.state_label(int(a[0]) % n)} in a class of {a.size} state(s) and "
        f"state {mdp.state_label(int(b[0]) % n)} in another of {b.size}); the average cost depends on "
        "the start state"
    )


def _initial_state(mdp: MDP, system: System) -> int:
    """The initial state of :func:`wncs_lp.simulate.simulate`: every tau_k at its cap, first
    initial configuration."""
    s0 = mdp.states.find(system.caps, system.initial_config)
    if s0 < 0:  # pragma: no cover - the initial configuration's whole box is in every MDP
        raise PolicyError("the initial state is not a state of the MDP")
    return int(s0)


def _pair_frequencies(mdp: MDP, arr: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """(L,) long-run frequencies x(l) = pi(s_l) beta(l) of the pairs."""
    if np.issubdtype(arr.dtype, np.integer):
        return np.bincount(arr.astype(np.int64), weights=pi, minlength=mdp.n_pairs)
    return pi[mdp.s_indices] * arr


def memory_chain(mdp: MDP, policy: Any) -> tuple[sp.csr_matrix, np.ndarray]:
    """The augmented chain of a policy with memory (:class:`~wncs_lp.policies.MemoryPolicy`) on an
    enumerated MDP.

    Its states are the pairs (m, s), numbered m n + s for the memory values m = 0..M-1; in (m, s)
    the policy takes the pair l_m(s) (``act_memory``) and moves its memory to m'_m(s)
    (``next_memory``), so the row of (m, s) is row l_m(s) of P placed in the columns of m'_m(s).

    Returns
    -------
    P : (M n, M n) CSR matrix
    pairs : (M, n) int array
        l_m(s), the pair taken in (m, s).
    """
    n, M = mdp.n_states, int(policy.memory_size)
    policy.system.check_mdp(mdp)
    tau = np.asarray(mdp.states.tau, dtype=np.int64)
    cfg = np.asarray(mdp.states.config, dtype=np.int64)
    rng = np.random.default_rng(0)
    pairs = np.empty((M, n), dtype=np.int64)
    rows, cols, vals = [], [], []
    for m in range(M):
        mem = np.full(n, m, dtype=np.int64)
        j = np.asarray(policy.act_memory(tau, cfg, mem, rng), dtype=np.int64)
        if j.shape != (n,) or np.any(j < 0) or np.any(j >= np.diff(mdp.pair_ptr)):
            raise PolicyError(f"policy {policy.name}: a local action index is out of range")
        pairs[m] = mdp.pair_ptr[:-1] + j
        nxt = np.asarray(policy.next_memory(mem, cfg, j), dtype=np.int64)
        Pm = mdp.P[pairs[m]].tocoo()
        rows.append(m * n + Pm.row)
        cols.append(nxt[Pm.row] * n + Pm.col)
        vals.append(Pm.data)
    P = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(M * n, M * n))
    return P, pairs


def _memory_law(mdp: MDP, policy: Any, system: System, name: str, multichain: str, method: str):
    """``(pair frequencies x, residual, recurrent classes, (P, c))`` of a policy with memory, from
    the stationary law of its augmented chain (:func:`memory_chain`)."""
    P, pairs = memory_chain(mdp, policy)
    classes = recurrent_classes(P)
    if len(classes) == 1:
        law, residual = stationary_law(P, classes, method=method)
    elif multichain == "error":
        raise _multichain(mdp, name, classes)
    else:
        s0 = int(policy.initial_memory) * mdp.n_states + _initial_state(mdp, system)
        law, residual = _limit_from_initial(P, classes, s0, method)
    x = np.bincount(pairs.ravel(), weights=law, minlength=mdp.n_pairs)
    return x, residual, classes, (P, np.asarray(mdp.cost, dtype=float)[pairs.ravel()])


def _utilisation(mdp: MDP, x: np.ndarray, system: System) -> tuple[float, ...]:
    """Each server's long-run fraction of service steps, from the pair frequencies x."""
    used = np.flatnonzero(x)
    states = mdp.s_indices[used]
    local = used - mdp.pair_ptr[states]
    cfg = np.asarray(mdp.states.config, dtype=np.int64)[states]
    busy = system.busy[cfg, local]  # (len(used), M)
    return tuple(float(v) for v in x[used] @ busy)


def _limit_from_initial(P, classes: list, s0: int, method: str = "auto") -> tuple:
    """Limiting state distribution from the state ``s0`` of a multichain chain P.

    The absorption probabilities b_i(s0) are obtained by pushing the distribution of s0
    forward through the transient states until less than 1e-14 of it is left there.
    Returns ``(mu, residual)``.
    """
    n = P.shape[0]
    label = np.full(n, -1, dtype=np.int64)
    for i, cl in enumerate(classes):
        label[cl] = i
    b = np.zeros(len(classes))
    x = np.zeros(n)
    x[s0] = 1.0
    PT = P.T.tocsr()
    trans = label < 0
    for _ in range(max(10 * n, 1000)):
        absorbed = ~trans & (x > 0)
        if absorbed.any():
            b += np.bincount(label[absorbed], weights=x[absorbed], minlength=len(classes))
            x[absorbed] = 0.0
        if x.sum() < 1e-14:
            break
        x = PT @ x
    else:  # pragma: no cover - transient mass decays geometrically
        raise PolicyError("multichain evaluation: the initial state's mass does not leave the transient states")
    mu, res = stationary_law(P, classes, weights=b, method=method)
    residual = max(abs(b.sum() - 1.0), res)
    if residual > 1e-8:
        raise PolicyError(f"multichain evaluation from the initial state is inaccurate (residual {residual:.3g})")
    return mu, residual
