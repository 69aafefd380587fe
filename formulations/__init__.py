"""The paper's scenarios as TOML files, installed with the package as ``wncs_lp.formulations``.

:func:`scenario_path` finds one in any installation (editable or not, from any folder); the
format of the files is described in ``docs/scenarios.md``.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

__all__ = ["scenario_names", "scenario_path"]


def scenario_names() -> list[str]:
    """The file names of the shipped scenarios (``paper_p12.toml``, ...)."""
    return sorted(p.name for p in resources.files(__name__).iterdir() if p.name.endswith(".toml"))


def scenario_path(name: str) -> Path:
    """The path of a shipped scenario file, e.g. ``scenario_path("paper_p12.toml")`` (or ``"paper_p12"``).

    Raises
    ------
    FileNotFoundError
        No shipped scenario has that name (the message lists those that exist).
    """
    if not name.endswith(".toml"):
        name += ".toml"
    path = Path(str(resources.files(__name__) / name))
    if not path.is_file():
        raise FileNotFoundError(f"no shipped scenario {name!r}; the scenarios are {', '.join(scenario_names())}")
    return path
