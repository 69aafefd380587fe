"""Public names that moved to another module: the old import path still works for one release,
with a :class:`DeprecationWarning` that names the new one.

A module that lost a name ends with ``def __getattr__(name): return moved.old_name(__name__, name)``
(PEP 562). The new home is loaded by name here, and only here: it stands on a higher floor than
the old one (the workflow floor above the solvers and the policies; the files' room above the
policies), so a plain import from the old module would climb a floor and close a cycle.
"""
from __future__ import annotations

import importlib
import warnings
from typing import Any

__all__ = ["MOVED", "old_name"]

#: Old ``module.name`` -> the module that now holds ``name``.
MOVED = {
    "wncs_lp.solvers.solve_scenario": "wncs_lp.workflow",
    "wncs_lp.solvers.route.solve_scenario": "wncs_lp.workflow",
    "wncs_lp.policies.policy_for": "wncs_lp.workflow",
    "wncs_lp.policies.factory.policy_for": "wncs_lp.workflow",
    "wncs_lp.policies.make_policy": "wncs_lp.workflow",
    "wncs_lp.policies.factory.make_policy": "wncs_lp.workflow",
    "wncs_lp.policies.policy_from_file": "wncs_lp.export",
    "wncs_lp.policies.convert.policy_from_file": "wncs_lp.export",
}


def old_name(module: str, name: str) -> Any:
    """``name`` of ``module`` where it moved (with a :class:`DeprecationWarning`), else the
    :class:`AttributeError` a module without it raises."""
    new = MOVED.get(f"{module}.{name}")
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    warnings.warn(f"{module}.{name} has moved to {new}.{name}; import it from there (the old path goes in the "
                  "next release)", DeprecationWarning, stacklevel=3)
    return getattr(importlib.import_module(new), name)
