"""wncs_lp: exact scheduling of multi-process WNCS with edge computing as average-cost MDPs.

Data flows one way::

    load_scenario (TOML) -> build (MDP) -> solve (Solution) -> policies / checks / plots

>>> import wncs_lp
>>> sc = wncs_lp.load_scenario("formulations/paper_p12.toml", ["tau_cap=6"])  # doctest: +SKIP
>>> sol = wncs_lp.solve(wncs_lp.build(sc))                                     # doctest: +SKIP

``solve`` is the one public solve (:func:`wncs_lp.workflow.route.solve`): an MDP, a scenario,
its file or a shipped scenario's name; ``method=``; ``criterion=`` ``"average"`` (default),
``"constrained"`` (``constraints=``, or a scenario's ``[[constraint]]`` tables) or
``"discounted"`` (``discount=beta``).

The names below are imported on first use (PEP 562), so ``import wncs_lp`` (and the command
line's start-up) loads numpy, scipy and the solvers only when something needs them.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .errors import ModelError, PolicyError, ScenarioError, SolverError, WncsError
from .methods import DEFAULT_METHOD, METHODS

if TYPE_CHECKING:  # pragma: no cover
    from .formulations import scenario_names, scenario_path
    from .mdp import MDP
    from .models import build
    from .scenario import Scenario, load_scenario, scenario_from_dict
    from .solvers.result import Solution
    from .workflow import solve

#: Lazily imported public names: name -> module.
_LAZY = {
    "MDP": ".mdp",
    "build": ".models",
    "Scenario": ".scenario",
    "load_scenario": ".scenario",
    "scenario_from_dict": ".scenario",
    "Solution": ".solvers.result",
    "scenario_names": ".formulations",
    "scenario_path": ".formulations",
    "solve": ".workflow",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'wncs_lp' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


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
    "METHODS",
    "DEFAULT_METHOD",
    "WncsError",
    "ScenarioError",
    "ModelError",
    "SolverError",
    "PolicyError",
    "__version__",
]
