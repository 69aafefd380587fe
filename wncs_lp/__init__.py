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


#: The solver function behind each method name (for the keyword check of :func:`solve`).
_SOLVER_FUNCTIONS = {
    "lp": ("wncs_lp.solvers.lp", "solve_lp"),
    "lp-cvxpy": ("wncs_lp.solvers.lp", "solve_lp"),
    "lp-highs": ("wncs_lp.solvers.lp", "solve_lp"),
    "rvi": ("wncs_lp.solvers.dp", "relative_value_iteration"),
    "vi": ("wncs_lp.solvers.dp", "value_iteration"),
    "pi": ("wncs_lp.solvers.dp", "policy_iteration"),
    "auto": ("wncs_lp.solvers.auto", "solve_auto"),
}


def _check_keywords(method: str, kwargs: dict) -> None:
    """One clear :class:`SolverError` for a keyword the method does not take (instead of a TypeError)."""
    target = _SOLVER_FUNCTIONS.get(method)
    if target is None or not kwargs:
        return
    import importlib
    import inspect

    fn = getattr(importlib.import_module(target[0]), target[1])
    params = inspect.signature(fn).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    taken = [p for p, v in params.items() if v.kind is inspect.Parameter.KEYWORD_ONLY and p != "backend"]
    bad = [k for k in kwargs if k not in taken]
    if bad:
        raise SolverError(f"method {method!r} takes no keyword {bad[0]!r}; it takes {', '.join(taken)}")


def solve(mdp: "MDP", method: str = DEFAULT_METHOD, **kwargs) -> "Solution":
    """Solve an MDP to average-cost optimality (see :func:`wncs_lp.solvers.solve`).

    Parameters
    ----------
    mdp : MDP
    method : {"auto", "lp", "lp-cvxpy", "vi", "rvi", "pi"}
        The vocabulary of every command and library function (:mod:`wncs_lp.methods`). The
        default ``"auto"`` is the command line's: the LP on small models, certified value
        iteration above, cross-checked when both are cheap (``stats["auto_choice"]`` says which).
    **kwargs
        The method's keywords. Every method takes ``tol`` (the accuracy asked for: the relative
        certificate width; for ``lp``/``lp-cvxpy`` the solver's tolerance, the certificate being
        checked at ``cert_rtol``) and ``progress`` (show progress on stderr); see the method's
        function for the rest. A keyword the method does not take raises a :class:`SolverError`
        naming the ones it does.

    Returns
    -------
    Solution
        With ``sigma`` (the action per state) and ``chain(mdp)`` (the induced Markov chain).
    """
    from .solvers import solve as _solve
    from .solvers.result import Solution as _Solution

    _check_keywords(method, kwargs)
    sol = _solve(mdp, method=method, **kwargs)
    if type(sol) is _Solution and sol.pair_actions is None:  # e.g. a matrix-free solve mapped onto the MDP
        import dataclasses

        sol = dataclasses.replace(sol, pair_actions=mdp.a_indices)
    return sol


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
