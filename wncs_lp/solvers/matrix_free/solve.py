"""The matrix-free solver's entry points by method name: on a scenario (:func:`solve_scenario`) and
on a built MDP, answered on the MDP (:func:`solve_mdp`)."""
from __future__ import annotations

from dataclasses import replace
from typing import Any

from ...errors import SolverError
from ...models.system import System
from ...scenario import Scenario
from ..result import Solution
from .iterate import matrix_free_value_iteration

__all__ = ["solve_scenario", "solve_mdp"]


def solve_scenario(scenario: Scenario, method: str = "matrix-free", *, force: bool = False, **kw: Any) -> Solution:
    """Solve a scenario by name of method: ``"matrix-free"`` runs
    :func:`matrix_free_value_iteration` (no MDP is built); any other method builds the MDP
    after the size guard and calls :func:`wncs_lp.solvers.solve`."""
    if method == "matrix-free":
        return matrix_free_value_iteration(scenario, **kw)
    from ...models.guard import build_checked
    from .. import solve

    return solve(build_checked(scenario, force=force), method, **kw)


def solve_mdp(mdp, **kw: Any) -> Solution:
    """``solve(mdp, "matrix-free")``: the matrix-free solve of the MDP's scenario, returned on
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

