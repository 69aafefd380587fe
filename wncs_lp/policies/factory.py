"""Policies by name: the factory the command line and the sweeps use.

:func:`wncs_lp.workflow.policy_for` (a scenario's system, its MDP when needed, the solve of
``optimal`` by the one route, then :func:`make_policy`) lives on the workflow floor, above the
route it calls.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Sequence

from .. import moved
from ..arguments import shown
from ..errors import ArgumentError, PolicyError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD
from ..models.system import System
from ..solvers import solve
from .base import Policy
from .baselines import MaxAgePolicy, MaxWeightPolicy, RoundRobinPolicy
from .optimal import OptimalPolicy
from .rules import GreedyPolicy, RandomPolicy, StaticPolicy, default_assignment
from .search import best_static
from .suboptimal import SuboptimalPolicy

__all__ = ["POLICY_NAMES", "NEED_MDP", "OPTIMAL", "PolicySetup", "make_policy", "parse_assignment", "parse_policy_names"]

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


def __getattr__(name: str) -> Any:
    """Names that moved to the workflow floor (:mod:`wncs_lp.moved`): still found here, with a warning."""
    return moved.old_name(__name__, name)
