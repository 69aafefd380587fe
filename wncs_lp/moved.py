"""Public names that moved or were replaced: the old import path still works for one release,
with a :class:`DeprecationWarning` that names the new one.

* :data:`MOVED` -- a name now held by another module under the same name;
* :data:`MOVED_MODULES` -- a module whose every public name now lives in another (``wncs_lp.maps``,
  the policy maps as data, is :mod:`wncs_lp.policy_grids`, so that it is not read as the drawing of
  :mod:`wncs_lp.viz.maps`; ``wncs_lp.export`` and ``wncs_lp.interop`` are :mod:`wncs_lp.io`, one
  module a format);
* :data:`RENAMED` -- a name that said two things, now one (``Certificate`` of the joint
  relaxation's tables, beside the solutions' ``Certificate``, is ``TableCertificate``);
* :data:`REPLACED` -- an old public entry point of a solve (``wncs_lp.solvers.solve``,
  ``solve_scenario``, ``solve_constrained``, ``solve_discounted``, ``matrix_free.solve_mdp``), now
  a step of the one public :func:`wncs_lp.solve` under a name that says so; the old name gives
  that step, which behaves as the old function did, and the warning names the call that replaces
  it.

A module that lost a name ends with ``__getattr__ = moved.old_names(__name__)`` (PEP 562). The
new home is loaded by name here, and only here: it stands on a higher floor than
the old one (the workflow floor above the solvers and the policies; the files' room above the
policies), so a plain import from the old module would climb a floor and close a cycle.
"""
from __future__ import annotations

import importlib
import warnings
from typing import Any, Callable

__all__ = ["MOVED", "MOVED_MODULES", "RENAMED", "REPLACED", "old_name", "old_names"]

#: Old ``module.name`` -> the module that now holds ``name``.
MOVED = {
    "wncs_lp.policies.policy_for": "wncs_lp.workflow",
    "wncs_lp.policies.factory.policy_for": "wncs_lp.workflow",
    "wncs_lp.policies.make_policy": "wncs_lp.workflow",
    "wncs_lp.policies.factory.make_policy": "wncs_lp.workflow",
    "wncs_lp.policies.policy_from_file": "wncs_lp.io",
    "wncs_lp.policies.convert.policy_from_file": "wncs_lp.io",
}

#: Old module -> the module that now holds every public name it had.
MOVED_MODULES = {
    "wncs_lp.maps": "wncs_lp.policy_grids",
    "wncs_lp.export": "wncs_lp.io",
    "wncs_lp.interop": "wncs_lp.io",
}

#: Old ``module.name`` -> the new ``module.name``.
RENAMED = {
    "wncs_lp.bounds.joint_chains.Certificate": "wncs_lp.bounds.joint_chains.TableCertificate",
}

_SCENARIO = ("wncs_lp.workflow.route", "run_scenario", "wncs_lp.solve(scenario, method=...)")
_DISCOUNTED = ("wncs_lp.solvers.discounted", "run_discounted", "wncs_lp.solve(mdp, method=..., discount=beta)")
_MATRIX_FREE = ("wncs_lp.solvers.matrix_free.solve", "run_on_mdp", "wncs_lp.solve(mdp, method=\"matrix-free\")")
_ANY = ("wncs_lp.workflow.route", "solve", "wncs_lp.solve(problem, method=...)")

#: Old ``module.name`` -> (the module and the name of the step that now runs, the call that replaces it).
REPLACED = {
    "wncs_lp.solvers.solve": ("wncs_lp.solvers.registry", "run_average", "wncs_lp.solve(mdp, method=...)"),
    "wncs_lp.constrained.solve_constrained": ("wncs_lp.constrained.registry", "run_constrained",
                                              "wncs_lp.solve(mdp, method=..., constraints=...)"),
    "wncs_lp.solvers.solve_discounted": _DISCOUNTED,
    "wncs_lp.solvers.discounted.solve_discounted": _DISCOUNTED,
    "wncs_lp.solvers.solve_scenario": _SCENARIO,
    "wncs_lp.solvers.route.solve_scenario": _SCENARIO,
    "wncs_lp.workflow.solve_scenario": _SCENARIO,
    "wncs_lp.workflow.route.solve_scenario": _SCENARIO,
    "wncs_lp.workflow.solve_any": _ANY,
    "wncs_lp.workflow.route.solve_any": _ANY,
    "wncs_lp.solvers.matrix_free.solve_mdp": _MATRIX_FREE,
    "wncs_lp.solvers.matrix_free.solve.solve_mdp": _MATRIX_FREE,
}


def old_names(module: str) -> Callable[[str], Any]:
    """The ``__getattr__`` of a module that lost names: :func:`old_name` of that module."""
    def __getattr__(name: str) -> Any:
        return old_name(module, name)

    return __getattr__


def old_name(module: str, name: str) -> Any:
    """``name`` of ``module`` where it moved or what replaced it (with a :class:`DeprecationWarning`),
    else the :class:`AttributeError` a module without it raises."""
    home, attr, message = _new_place(module, name)
    target = importlib.import_module(home) if home else None  # the one load by name (module docstring)
    if target is None or not hasattr(target, attr):
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(message, DeprecationWarning, stacklevel=3)  # the line that asked for the old name
    return getattr(target, attr)


def _new_place(module: str, name: str) -> tuple[str, str, str]:
    """(the new module, the name there, the warning) of ``module.name``; ("", "", "") where nothing moved."""
    old = f"{module}.{name}"
    if old in REPLACED:
        home, step, call = REPLACED[old]
        return home, step, (f"{old} is deprecated: call {call} (the step it was is now {home}.{step}; the old name "
                            "goes in the next release)")
    if old in RENAMED:
        home, renamed = RENAMED[old].rsplit(".", 1)
        return home, renamed, (f"{old} is renamed {home}.{renamed}; use the new name (the old one goes in the next "
                               "release)")
    new = MOVED.get(old) or (MOVED_MODULES.get(module) if not name.startswith("_") else None)
    if new is None:
        return "", "", ""
    return new, name, f"{old} has moved to {new}.{name}; import it from there (the old path goes in the next release)"
