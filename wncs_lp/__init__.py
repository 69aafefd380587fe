"""wncs_lp: exact scheduling of multi-process WNCS with edge computing as average-cost MDPs.

Data flows one way::

    load_scenario (TOML) -> build (MDP) -> solve (Solution) -> policies / checks / plots

>>> import wncs_lp
>>> sc = wncs_lp.load_scenario("formulations/paper_p12.toml", ["tau_cap=6"])  # doctest: +SKIP
>>> sol = wncs_lp.solve(wncs_lp.build(sc))                                     # doctest: +SKIP
"""
from __future__ import annotations

from .errors import ModelError, PolicyError, ScenarioError, SolverError, WncsError
from .formulations import scenario_names, scenario_path
from .mdp import MDP
from .models import build
from .scenario import Scenario, load_scenario, scenario_from_dict
from .solvers.result import Solution


def solve(mdp: MDP, method: str = "auto", **kwargs) -> Solution:
    """Solve an MDP to average-cost optimality (see :func:`wncs_lp.solvers.solve`).

    The default ``"auto"`` is the command line's: the LP on small models, certified value
    iteration above, cross-checked when both are cheap (``stats["auto_choice"]`` says which).
    """
    from .solvers import solve as _solve

    return _solve(mdp, method=method, **kwargs)


__version__ = "0.1.0"
__all__ = [
    "MDP",
    "Scenario",
    "Solution",
    "build",
    "load_scenario",
    "scenario_from_dict",
    "scenario_names",
    "scenario_path",
    "solve",
    "WncsError",
    "ScenarioError",
    "ModelError",
    "SolverError",
    "PolicyError",
    "__version__",
]
