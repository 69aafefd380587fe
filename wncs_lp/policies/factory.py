"""Policies by name: the factory the command line and the sweeps use."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Sequence

from ..arguments import shown
from ..errors import ArgumentError, PolicyError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD
from ..models.system import System
from ..solvers import solve
from ..solvers.route import build_scenario, solve_scenario
from .base import Policy
from .baselines import MaxAgePolicy, MaxWeightPolicy, RoundRobinPolicy
from .optimal import OptimalPolicy
from .rules import GreedyPolicy, RandomPolicy, StaticPolicy, default_assignment
from .search import best_static
from .suboptimal import SuboptimalPolicy

__all__ = ["POLICY_NAMES", "PolicySetup", "make_policy", "parse_assignment", "parse_policy_names", "policy_for"]

#: Policy names understood by :func:`make_policy` and the command line.
POLICY_NAMES = ("optimal", "suboptimal", "static", "best_static", "greedy", "random", "relaxation", "lookahead",
                "index", "max_age", "max_weight", "round_robin")
#: The policy a solve makes, and those that need the enumerated MDP.
OPTIMAL = "optimal"
NEED_MDP = ("optimal", "best_static")
#: The field's baselines (:mod:`wncs_lp.policies.baselines`), by name.
_BASELINES = {"max_age": MaxAgePolicy, "max_weight": MaxWeightPolicy, "round_robin": RoundRobinPolicy}


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
        For ``static`` (0-based servers); default :func:`default_assignment`.
    progress : bool or Progress
        The solver's progress on stderr (``optimal``).

    Raises
    ------
    PolicyError
        Unknown name (the message lists the allowed ones), or a needed MDP missing.
    """
    if not isinstance(name, str) or name not in POLICY_NAMES:
        raise PolicyError(f"name: unknown policy {name!r}; expected one of {', '.join(POLICY_NAMES)}")
    if not isinstance(system, System):
        raise ArgumentError("system", f"expected the System of a scenario (System.from_scenario, from "
                                      "wncs_lp.models.system), "
                                      f"got {shown(system)}")
    if name in NEED_MDP and mdp is None:
        raise PolicyError(f"policy {name!r} needs the enumerated MDP")
    if name == OPTIMAL:
        if solution is None:
            solution = solve(mdp, method=method, progress=progress)
        return OptimalPolicy(mdp, solution, system)
    if name == "suboptimal":
        return SuboptimalPolicy(system)
    if name == "static":
        return StaticPolicy(system, default_assignment(system.scenario) if assignment is None else assignment)
    if name == "best_static":
        return best_static(system, mdp)
    if name == "greedy":
        return GreedyPolicy(system)
    if name in ("relaxation", "lookahead", "index"):
        return _bound_room_policy(name, system)
    if name in _BASELINES:
        return _BASELINES[name](system)
    return RandomPolicy(system)


def _bound_room_policy(name: str, system: System) -> Policy:
    # imported when asked for: the bounds room builds on policies (its policies are a
    # SeparableGreedyPolicy or, for relaxation 3, a Policy on group tables); its gaps module takes
    # comparators from this factory, so only the bound and the policy modules are named here
    if name == "index":
        from ..bounds.index import index_policy

        return index_policy(system)
    from ..bounds.lower import lower_bound
    from ..bounds.policy import bound_policy

    greedy = bound_policy(lower_bound(system, "auto"), system)
    if name == "lookahead":
        from ..bounds.lookahead import LookaheadPolicy

        return LookaheadPolicy(greedy)
    return greedy


def parse_policy_names(text: str | Sequence[str]) -> list[str]:
    """``"optimal,greedy"`` -> ``["optimal", "greedy"]``, checked against :data:`POLICY_NAMES`."""
    items = [s.strip() for s in (text.split(",") if isinstance(text, str) else text) if s.strip()]
    if not items:
        raise PolicyError(f"no policy given; expected names from {', '.join(POLICY_NAMES)}")
    for s in items:
        if s not in POLICY_NAMES:
            raise PolicyError(f"unknown policy {s!r}; expected one of {', '.join(POLICY_NAMES)}")
    return list(dict.fromkeys(items))


def parse_assignment(text: str | None, scenario: Any) -> list[int] | None:
    """``"remote,edge"`` or ``"2,1"`` -> 0-based server indices, one per process (``None`` stays ``None``).

    Each item is a server name of ``scenario`` or its 1-based index.

    Raises
    ------
    PolicyError
        An item that names no server (the message lists the allowed ones).
    """
    if text is None:
        return None
    names = [s.name for s in scenario.servers]
    out = []
    for item in (x.strip() for x in text.split(",")):
        if item.isdigit() and 1 <= int(item) <= len(names):
            out.append(int(item) - 1)
        elif item in names:
            out.append(names.index(item))
        else:
            raise PolicyError(f"--assignment: {item!r} is not a server; expected a name from {names} or 1..{len(names)}")
    n = len(scenario.processes)
    if len(out) != n:
        raise PolicyError(f"--assignment {text!r}: expected one server per process ({n} processes, e.g. "
                          f"{','.join(names[k % len(names)] for k in range(n))}), found {len(out)}")
    return out


@dataclass(frozen=True)
class PolicySetup:
    """What :func:`policy_for` made: the system, the MDP (``None`` when not built), the policy, the
    seconds the whole setup took and, for ``optimal``, the status of its solve (the policy is the
    optimal one only where that status is ``optimal``: its certificate closed)."""

    system: System
    mdp: MDP | None
    policy: Policy
    seconds: float
    status: Any = None


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
    (:func:`wncs_lp.solvers.route.solve_scenario`), which without ``need_mdp`` may take the
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
    from ..progress import as_progress

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
            from .matrix_free import MatrixFreePolicy

            return PolicySetup(system, None, MatrixFreePolicy.from_solution(run.solution),
                               time.perf_counter() - t0, run.solution.status)
        mdp, solution = run.mdp, run.solution
    elif name in NEED_MDP or need_mdp:
        mdp, _ = build_scenario(scenario, force=force, progress=prog)
    if name == "best_static":
        prog.phase("evaluating every static assignment exactly")
    policy = make_policy(name, system, mdp, method=method, solution=solution, assignment=assignment, progress=prog)
    return PolicySetup(system, mdp, policy, time.perf_counter() - t0, None if solution is None else solution.status)
