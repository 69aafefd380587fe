"""Policies by name: the names, their checks, and the policies this room makes.

The factory the command line and the sweeps use, :func:`wncs_lp.workflow.make_policy`, lives on
the workflow floor: it makes the bounds room's policies (:data:`BOUND_POLICY_NAMES`, from
:func:`wncs_lp.bounds.named.named_policy`) and this room's (:func:`make_basic_policy`);
:func:`wncs_lp.workflow.policy_for` adds a scenario's system, its MDP when needed and the solve of
``optimal`` by the one route.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

from .. import moved
from ..arguments import shown
from ..errors import ArgumentError, PolicyError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD
from ..models.system import System
from ..solvers.registry import run_average
from .base import Policy
from .baselines import MaxAgePolicy, MaxWeightPolicy, RoundRobinPolicy
from .optimal import OptimalPolicy
from .rules import GreedyPolicy, RandomPolicy, StaticPolicy, default_assignment
from .search import best_static
from .suboptimal import SuboptimalPolicy

__all__ = ["POLICY_NAMES", "BASIC_POLICY_NAMES", "BOUND_POLICY_NAMES", "NEED_MDP", "OPTIMAL", "PolicySetup",
           "check_policy_request", "make_basic_policy", "parse_assignment", "parse_policy_names"]

#: Policy names understood by :func:`wncs_lp.workflow.make_policy` and the command line.
POLICY_NAMES = ("optimal", "suboptimal", "static", "best_static", "greedy", "random", "relaxation", "lookahead",
                "lookahead3", "rollout", "index", "max_age", "max_weight", "round_robin", "tuned", "tuned_lookahead",
                "tuned_rollout")
#: The policies the bounds room makes (:func:`wncs_lp.bounds.named.named_policy`), and those of this
#: room (:func:`make_basic_policy`).
BOUND_POLICY_NAMES = ("relaxation", "lookahead", "lookahead3", "rollout", "index", "tuned", "tuned_lookahead",
                      "tuned_rollout")
BASIC_POLICY_NAMES = tuple(n for n in POLICY_NAMES if n not in BOUND_POLICY_NAMES)
#: The policy a solve makes, and those that need the enumerated MDP.
OPTIMAL = "optimal"
NEED_MDP = ("optimal", "best_static")
#: The field's baselines (:mod:`wncs_lp.policies.baselines`), by name.
_BASELINES = {"max_age": MaxAgePolicy, "max_weight": MaxWeightPolicy, "round_robin": RoundRobinPolicy}


def check_policy_request(name: Any, system: Any, mdp: MDP | None) -> None:
    """The checks of a policy asked for by name, before any work: a name of :data:`POLICY_NAMES`,
    the system of a scenario, and the enumerated MDP where the policy needs it."""
    if not isinstance(name, str) or name not in POLICY_NAMES:
        raise PolicyError(f"name: unknown policy {name!r}; expected one of {', '.join(POLICY_NAMES)}")
    if not isinstance(system, System):
        raise ArgumentError("system", f"expected the System of a scenario (System.from_scenario, from "
                                      "wncs_lp.models.system), "
                                      f"got {shown(system)}")
    if name in NEED_MDP and mdp is None:
        raise PolicyError(f"policy {name!r} needs the enumerated MDP")


def make_basic_policy(
    name: str,
    system: System,
    mdp: MDP | None = None,
    *,
    method: str = DEFAULT_METHOD,
    solution: Any = None,
    assignment: Sequence[int] | None = None,
    progress: Any = False,
) -> Policy:
    """Build a policy of this room by name: ``name`` one of :data:`BASIC_POLICY_NAMES`, the
    other arguments and the errors as :func:`wncs_lp.workflow.make_policy`, the full factory, which
    makes the bounds room's policies too and calls this one for the rest."""
    check_policy_request(name, system, mdp)
    if name in BOUND_POLICY_NAMES:
        raise PolicyError(f"policy {name!r} comes from the bounds room: wncs_lp.workflow.make_policy makes it")
    if name == OPTIMAL:
        if solution is None:
            solution = run_average(mdp, method=method, progress=progress)
        return OptimalPolicy(mdp, solution, system)
    if name == "suboptimal":
        return SuboptimalPolicy(system)
    if name == "static":
        return StaticPolicy(system, default_assignment(system.scenario) if assignment is None else assignment)
    if name == "best_static":
        return best_static(system, mdp)
    if name == "greedy":
        return GreedyPolicy(system)
    if name in _BASELINES:
        return _BASELINES[name](system)
    return RandomPolicy(system)


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


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
