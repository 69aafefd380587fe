"""Searches over policies by exact evaluation: the best static assignment."""
from __future__ import annotations

import numpy as np

from ..errors import PolicyError
from ..evaluate import evaluate
from ..mdp import MDP
from ..models import build
from ..models.system import System
from ..scenario import Scenario
from .rules import StaticPolicy, static_assignments

__all__ = ["best_static"]


def best_static(system: System | Scenario, mdp: MDP | None = None) -> StaticPolicy:
    """The static policy of least exact average cost over :func:`static_assignments`.

    Each candidate is evaluated exactly on ``mdp``; ties keep the first assignment in the
    lexicographic order. The returned policy's ``gain_search`` maps every assignment tried to
    its gain (``inf`` for one whose chain is multichain).

    Parameters
    ----------
    system : System or Scenario
        A scenario is turned into its system.
    mdp : MDP, optional
        The enumerated MDP (built from the scenario when omitted).
    """
    if isinstance(system, Scenario):
        system = System.from_scenario(system)
    if mdp is None:
        mdp = build(system.scenario)
    best: StaticPolicy | None = None
    best_gain = np.inf
    search: dict[tuple[int, ...], float] = {}
    for a in static_assignments(system.scenario):
        pol = StaticPolicy(system, a)
        try:
            g = float(evaluate(mdp, pol).gain)
        except PolicyError:
            g = np.inf
        search[a] = g
        if g < best_gain:
            best, best_gain = pol, g
    if best is None:
        raise PolicyError("every static assignment induces a multichain chain; no best static policy")
    best.gain_search = search
    best.name = "best_" + best.name
    return best
