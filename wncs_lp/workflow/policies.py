"""A policy by name on a scenario: the system, the MDP when needed, the solve of ``optimal`` by the
one route, then the factory (:func:`wncs_lp.policies.make_policy`)."""
from __future__ import annotations

import time
from typing import Any, Sequence

from ..errors import PolicyError
from ..methods import DEFAULT_METHOD
from ..models.system import System
from ..policies import MatrixFreePolicy
from ..policies.factory import NEED_MDP, OPTIMAL, POLICY_NAMES, PolicySetup, make_policy, parse_assignment
from ..progress import as_progress
from ..solvers.route import build_scenario
from .route import solve_scenario

__all__ = ["policy_for"]


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
    (:func:`wncs_lp.workflow.solve_scenario`), which without ``need_mdp`` may take the
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
        run = solve_scenario(scenario, method, constrained=False, force=force, threads=threads, progress=prog,
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
