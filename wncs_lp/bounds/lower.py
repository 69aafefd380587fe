"""The entry point of the bounds room: :func:`lower_bound`, the relaxation asked for or the best
certified one (``"auto"``).

It lives apart from the package's ``__init__`` so that the policy factory can offer the bound's
policy by name without importing :mod:`~wncs_lp.bounds.gaps`, which takes its comparators from
that factory.
"""
from __future__ import annotations

import importlib
from dataclasses import replace
from typing import Any

from ..errors import WncsError
from ..models.system import System
from ..scenario import Scenario
from .private import private_bound
from .result import BoundResult

__all__ = ["RELAXATIONS", "AUTO_SEARCH", "lower_bound", "parse_relaxation"]

#: The relaxations :func:`lower_bound` knows, and their short names (the command line's 1 / 2).
RELAXATIONS = ("auto", "private-servers", "joint-configuration")
_SHORT = {"1": "private-servers", "2": "joint-configuration"}


#: Relaxation 2's search under ``"auto"`` unless given: ``time_limit`` seconds as a guard and
#: ``max_iter`` bundle steps (a count, so the bound and its policy are the same on every machine).
#: Where its LP is small enough (``joint.IPM_MAX_NNZ``: processes 1-4 up to cap 30) relaxation 2
#: solves it by the interior point and needs no bundle steps unless the guard stops the interior
#: point (it gets 80% of the time; stopped, it leaves no tables and the bundle takes the rest).
#: Its bound is certified whatever stops the search, and it starts at relaxation 1's, so a short
#: search is still at least as tight (``lower_bound(x, 2)`` keeps its own defaults, 1000 steps
#: and 10 minutes).
AUTO_SEARCH = {"max_iter": 30, "time_limit": 300.0}


def parse_relaxation(name: str | int) -> str:
    """``1`` / ``"1"`` / ``"private-servers"`` -> ``"private-servers"`` (likewise 2 and auto).

    Raises
    ------
    WncsError
        An unknown name (the message lists the allowed ones).
    """
    text = _SHORT.get(str(name).strip(), str(name).strip())
    if text not in RELAXATIONS:
        raise WncsError(f"unknown relaxation {name!r}; expected one of 1, 2, {', '.join(RELAXATIONS)}")
    return text


def _joint_module() -> tuple[Any, str]:
    """(the relaxation-2 module or None, why not)."""
    try:
        return importlib.import_module(f"{__package__}.joint"), ""
    except ModuleNotFoundError as exc:
        if exc.name != f"{__package__}.joint":
            raise
        return None, "relaxation 2 (wncs_lp.bounds.joint) is not installed"


def lower_bound(scenario_or_system: Scenario | System, relaxation: str | int = "auto", **options: Any) -> BoundResult:
    """A certified lower bound on the optimal gain g* of a Section II scenario.

    Parameters
    ----------
    scenario_or_system : Scenario or System
    relaxation : {"auto", "private-servers", "joint-configuration"} or 1 / 2
        ``"auto"``: the larger of the two certified bounds when relaxation 2 is installed and
        the instance is within its reach (relaxation 2 on a tie), else relaxation 1;
        ``stats["auto_choice"]`` and ``stats["auto_reason"]`` say which was taken and why.
        Relaxation 2's search then stops as :data:`AUTO_SEARCH` says unless ``max_iter`` /
        ``time_limit`` are given.
    **options
        Keyword arguments of the relaxation's function (e.g. ``tol``, ``progress``). Under
        ``"auto"`` relaxation 1 takes only ``tol`` and ``progress``; the others go to relaxation 2.

    Returns
    -------
    BoundResult

    Raises
    ------
    WncsError
        An unknown relaxation, relaxation 2 asked for but not installed, or a model without the
        relaxation (the preemption model), refused before any work with the reason.
    """
    name = parse_relaxation(relaxation)
    if not isinstance(scenario_or_system, (Scenario, System)):
        raise WncsError(f"expected a Scenario or a System, got {type(scenario_or_system).__name__}")
    if name == "private-servers":
        return private_bound(scenario_or_system, **options)
    joint, why_not = _joint_module()
    if name == "joint-configuration":
        if joint is None:
            raise WncsError(f"relaxation joint-configuration asked for, but {why_not}")
        return joint.joint_bound(_as_system(scenario_or_system), **options)
    res1 = None
    options = {**AUTO_SEARCH, **options}
    if joint is not None:
        system = _as_system(scenario_or_system)
        res, why_not = _try_joint(joint, system, options)
        if res is not None:
            res1 = _try_private(system, options)
            if res1 is None or res.lower_bound >= res1.lower_bound:
                return res
            why_not = (f"relaxation 1's certified bound {res1.lower_bound:.10g} beats relaxation 2's "
                       f"{res.lower_bound:.10g} (its search stopped early)")
        scenario_or_system = system
    res = res1 if res1 is not None else private_bound(scenario_or_system, **_private_options(options))
    return replace(res, stats={**res.stats, "auto_choice": res.relaxation, "auto_reason": why_not})


def _private_options(options: dict) -> dict:
    """What relaxation 1 takes of auto's options: the tolerance and the progress (the search
    options, ``max_iter`` and ``time_limit``, are relaxation 2's under auto)."""
    return {k: v for k, v in options.items() if k in ("tol", "progress")}


def _try_private(system: System, options: dict) -> BoundResult | None:
    """Relaxation 1 for comparison with relaxation 2 (None where the model has no relaxation 1)."""
    try:
        return private_bound(system, **_private_options(options))
    except WncsError:
        return None


def _try_joint(joint: Any, system: System, options: dict) -> tuple[BoundResult | None, str]:
    """Relaxation 2 when the instance is within its reach: (its result, "") or (None, why not)."""
    reach = getattr(joint, "joint_reach", None)
    why_not = reach(system) if reach is not None else None
    if why_not is not None:
        return None, f"beyond relaxation 2's reach: {why_not}"
    try:
        res = joint.joint_bound(system, **options)
    except WncsError as exc:
        return None, f"relaxation 2 could not run: {exc}"
    reason = "relaxation 2 is within reach and its certified bound is at least relaxation 1's"
    return replace(res, stats={**res.stats, "auto_choice": res.relaxation, "auto_reason": reason}), ""


def _as_system(obj: Scenario | System) -> System:
    return obj if isinstance(obj, System) else System.from_scenario(obj)
