"""The plain install (``pip install .``, no extras) computes every section of the reproduction:
numba is a core dependency, and the matrix-free solver runs on the installed dependencies."""
from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: The import name of each distribution the package declares (where the two differ).
IMPORT_NAME = {"tomli": "tomli"}


def _core_dependencies() -> dict[str, str]:
    """{distribution name: requirement} of pyproject.toml's ``[project] dependencies``."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    return {re.match(r"[A-Za-z0-9_.-]+", d).group(0).lower(): d for d in deps}


def test_numba_is_a_core_dependency_and_every_core_dependency_is_installed():
    deps = _core_dependencies()
    assert "numba" in deps and ";" not in deps["numba"]  # unconditional, not behind an extra
    for name, req in deps.items():
        if ";" in req and "python_version < '3.11'" in req and sys.version_info >= (3, 11):
            continue  # tomli: only below Python 3.11
        assert importlib.util.find_spec(IMPORT_NAME.get(name, name)) is not None, f"{req} is not installed"


def test_the_matrix_free_solver_runs_on_the_installed_dependencies(monkeypatch):
    """No importorskip: without numba this fails, as ``wncs-lp reproduce`` would (section B2)."""
    monkeypatch.delenv("WNCS_LP_NO_NUMBA", raising=False)
    from wncs_lp import build, load_scenario
    from wncs_lp.formulations import scenario_path
    from wncs_lp import solve
    from wncs_lp.solvers.matrix_free import matrix_free_value_iteration

    sc = load_scenario(scenario_path("paper_p12.toml"), ["tau_cap=7", "p=0.9"])
    sol = matrix_free_value_iteration(sc, tol=1e-10)
    ref = solve(build(sc), "pi")  # policy iteration on the stored matrix: exact evaluation
    assert sol.status == "optimal" and ref.status == "optimal"
    assert sol.gain_lower - 1e-9 * ref.gain <= ref.gain <= sol.gain_upper + 1e-9 * ref.gain
    assert sol.gain == pytest.approx(ref.gain, rel=1e-9)
