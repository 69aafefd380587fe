"""wncs_lp: exact scheduling of multi-process WNCS with edge computing as average-cost MDPs.

Data flows one way::

    load_scenario (TOML) -> build (MDP) -> solve (Solution) -> policies / checks / plots

>>> import wncs_lp
>>> sc = wncs_lp.load_scenario("formulations/paper_p12.toml", ["tau_cap=6"])  # doctest: +SKIP
>>> sol = wncs_lp.solve(wncs_lp.build(sc))                                     # doctest: +SKIP

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


def solve(problem: "MDP | Scenario | str", method: str = DEFAULT_METHOD, **kwargs) -> "Solution":
    """Solve an MDP, or a scenario, to average-cost optimality.

    Parameters
    ----------
    problem : MDP, Scenario, path or str
        An MDP (:func:`wncs_lp.solvers.solve`), or a scenario, its TOML file or a shipped
        scenario's name (``"paper_p12"``), solved by the one route of the command line
        (:func:`wncs_lp.workflow.solve_scenario`: size guard, build, solve; ``auto``
        solves without a stored matrix when that matrix would not fit; a scenario's
        ``[[constraint]]`` tables are solved, as ``wncs-lp solve`` does).
    method : str
        A name of the registry (:mod:`wncs_lp.methods`), default ``"auto"``: the LP on small
        models, certified value iteration above, cross-checked when both are cheap
        (``stats["auto_choice"]`` says which).
    **kwargs
        The method's keywords (and, for a scenario, the route's: ``force``, ``threads``,
        ``constrained``). Every method takes ``tol`` (the accuracy asked for: the relative
        certificate width; for ``lp``/``lp-cvxpy`` the solver's tolerance, the certificate being
        checked at ``cert_rtol``) and ``progress`` (show progress on stderr); see the method's
        function for the rest. A keyword the method does not take raises a
        :class:`SolverError` naming the ones it does.

    Returns
    -------
    Solution
        With ``sigma`` (the action per state) and ``chain(mdp)`` (the induced Markov chain); for
        a scenario solved without a stored matrix a ``MatrixFreeSolution``, for a constrained
        one a ``ConstrainedSolution``.

    Raises
    ------
    SolverError
        ``problem`` is none of the above (the message names its type), an unknown method or
        keyword, or a solver failure.
    """
    from .workflow.route import solve_any

    return solve_any(problem, method=method, **kwargs)


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
