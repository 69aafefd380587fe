"""Policies by name: :func:`make_policy`, the factory the command line and the sweeps use (the
policies room's own, :func:`~wncs_lp.policies.factory.make_basic_policy`, and the bounds room's,
:func:`~wncs_lp.bounds.named.named_policy`), and :func:`policy_for`, a policy by name on a
scenario (its system, its MDP when needed, ``optimal`` solved by the one route)."""
from __future__ import annotations

import time
from typing import Any, Sequence

from ..bounds.named import named_policy
from ..errors import PolicyError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD
from ..models.system import System
from ..policies import MatrixFreePolicy, Policy
from ..policies.factory import (BOUND_POLICY_NAMES, NEED_MDP, OPTIMAL, POLICY_NAMES, PolicySetup, check_policy_request,
                                make_basic_policy, parse_assignment)
from ..progress import as_progress
from ..solvers.route import build_scenario
from .route import run_scenario

__all__ = ["make_policy", "policy_for"]


def make_policy(
    name: str,
    system: System,
    mdp: MDP | None = None,
    *,
    method: str = DEFAULT_METHOD,
    solution: Any = None,
    assignment: Sequence[int] | None = None,
    progress: Any = False,
) -> Policy:
    """Build a policy by name.

    Parameters
    ----------
    name : {"optimal", "suboptimal", "static", "best_static", "greedy", "random", "relaxation", "lookahead", \
            "index", "max_age", "max_weight", "round_robin"}
        ``max_age``, ``max_weight`` and ``round_robin`` are the field's baselines
        (:mod:`wncs_lp.policies.baselines`: max-age-first, max-weighted-cost-first, round robin, a
        policy with memory). ``relaxation`` is the greedy policy of the certified lower bound
        (:func:`wncs_lp.bounds.lower_bound` with ``relaxation="auto"``, then
        :func:`wncs_lp.bounds.bound_policy`): it needs no MDP, so it reaches any number of processes.
        ``lookahead`` is the two-step lookahead on the same tables
        (:class:`wncs_lp.bounds.LookaheadPolicy`), ``index`` the Whittle-type index policy of
        relaxation 1's priced chains (:class:`wncs_lp.bounds.IndexPolicy`); neither needs an MDP.
    system : System
    mdp : MDP, optional
        Needed by ``optimal`` (solved with ``method`` unless ``solution`` is given) and
        ``best_static`` (exact evaluation of every assignment).
    method : str
        Solver method for ``optimal`` (:data:`wncs_lp.methods.METHODS`, default ``"auto"``).
    solution : Solution, optional
        A solution of ``mdp`` to wrap instead of solving.
    assignment : sequence of int, optional
        For ``static`` (0-based servers); default :func:`~wncs_lp.policies.default_assignment`.
    progress : bool or Progress
        The solver's progress on stderr (``optimal``).

    Raises
    ------
    PolicyError
        Unknown name (the message lists the allowed ones), or a needed MDP missing.
    """
    check_policy_request(name, system, mdp)
    if name in BOUND_POLICY_NAMES:
        return named_policy(name, system)
    return make_basic_policy(name, system, mdp, method=method, solution=solution, assignment=assignment,
                             progress=progress)


def policy_for(
    scenario: Any,
    name: str,
    *,
    method: str = DEFAULT_METHOD,
    assignment: str | Sequence[int] | None = None,
    need_mdp: bool = False,
    force: bool = False,
    threads: int | None = None,
    progress: Any = False,
) -> PolicySetup:
    """Build a scenario's system, its MDP when needed, and the policy ``name`` on them.

    The MDP is built (after the size guard) when the policy needs it (``optimal``,
    ``best_static``) or ``need_mdp`` is true; ``optimal`` is solved by the one route
    (:func:`wncs_lp.workflow.route.run_scenario`), which without ``need_mdp`` may take the
    matrix-free method when the stored matrix would not fit (``auto``, or ``matrix-free`` asked
    for): the policy is then a :class:`~wncs_lp.policies.MatrixFreePolicy` and no MDP is built.

    Parameters
    ----------
    scenario : Scenario
    name : str
        One of :data:`POLICY_NAMES`.
    method : str
        Solver method of ``optimal`` (:data:`wncs_lp.methods.METHODS`, default ``"auto"``); with
        an LP method the size guard counts the LP's memory too.
    assignment : str or sequence of int, optional
        For ``static``: text for :func:`parse_assignment` or 0-based server indices.
    need_mdp : bool
        Build the MDP even when the policy does not need it (for an exact evaluation).
    force : bool
        Build even when the size guard refuses.
    threads : int, optional
        Kernel threads of the solver of ``optimal`` (default: the solver's).
    progress : bool or Progress
        Phases and the solver's progress on stderr.

    Raises
    ------
    PolicyError
        Unknown name or bad assignment.
    SizeLimitError
        The MDP is too large and ``force`` is False.
    """
    if name not in POLICY_NAMES:
        raise PolicyError(f"unknown policy {name!r}; expected one of {', '.join(POLICY_NAMES)}")
    prog = as_progress(progress)
    t0 = time.perf_counter()
    if isinstance(assignment, str):
        assignment = parse_assignment(assignment, scenario)
    # a policy that needs no MDP runs on a lazily explored system where the automaton is too large to enumerate
    lean = name not in NEED_MDP and name != OPTIMAL and not need_mdp
    system = System.from_scenario(scenario, explore="auto" if lean else "full")
    mdp = solution = None
    if name == OPTIMAL:
        run = run_scenario(scenario, method, constrained=False, force=force, threads=threads, progress=prog,
                             need_mdp=need_mdp)
        if not run.built:  # auto's matrix-free route (the stored matrix would not fit): its one byte a state
            return PolicySetup(system, None, MatrixFreePolicy.from_solution(run.solution),
                               time.perf_counter() - t0, run.solution.status)
        mdp, solution = run.mdp, run.solution
    elif name in NEED_MDP or need_mdp:
        mdp, _ = build_scenario(scenario, force=force, progress=prog)
    if name == "best_static":
        prog.phase("evaluating every static assignment exactly")
    policy = make_policy(name, system, mdp, method=method, solution=solution, assignment=assignment, progress=prog)
    return PolicySetup(system, mdp, policy, time.perf_counter() - t0, None if solution is None else solution.status)
