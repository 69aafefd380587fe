"""The matrix-free solver on a built MDP, answered on the MDP (:func:`run_on_mdp`, the registry's
``matrix-free`` row for an MDP: ``wncs_lp.solve(mdp, method="matrix-free")``). A scenario is
solved through the one route, :func:`wncs_lp.workflow.route.run_scenario`."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from ... import moved
from ...errors import SolverError
from ...models.system import System
from ..result import Solution
from .iterate import matrix_free_value_iteration

__all__ = ["run_on_mdp"]


def run_on_mdp(mdp, **kw: Any) -> Solution:
    """``wncs_lp.solve(mdp, "matrix-free")``: the matrix-free solve of the MDP's scenario, returned on
    the MDP (pair-index policy, bias on its states; :meth:`MatrixFreeSolution.on_mdp`)."""
    model = getattr(getattr(mdp, "states", None), "model", None)
    scenario = getattr(model, "scenario", None)
    if scenario is None:
        raise SolverError("method 'matrix-free' needs an MDP built from a scenario (mdp.states.model.scenario); "
                          "this one has none")
    system = System.from_automaton(scenario, model.automaton, model)
    sol = matrix_free_value_iteration(system, **kw)
    out = sol.on_mdp(mdp)
    return replace(out, stats={**out.stats, "n_mdp_states": mdp.n_states})


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
