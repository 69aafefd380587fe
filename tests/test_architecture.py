"""The rules of the house (docs/architecture.md), checked on the source with the ``ast`` module.

* every package folder is listed in pyproject.toml, and the scenarios install as package data;
* no import cycle between the package's modules (runtime imports, function-level ones included);
* no private name (leading underscore) imported from another module;
* only ``models/`` (and ``scenario.py``, which validates it) tests a model kind.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "wncs_lp"

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


def _modules() -> dict[str, Path]:
    out = {}
    for f in sorted(PKG.rglob("*.py")):
        parts = list(f.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _resolve(module: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".") if is_pkg else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(mods: dict[str, Path]) -> dict[str, list[tuple[str, str, int]]]:
    """module -> [(imported module, imported name, line)] for imports of wncs_lp modules."""
    out: dict[str, list[tuple[str, str, int]]] = {}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        is_pkg = path.name == "__init__.py"
        edges = []
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(mod, is_pkg, node)
                for alias in node.names:
                    sub = f"{target}.{alias.name}"
                    edges.append((sub if sub in mods else target, alias.name, node.lineno))
            elif isinstance(node, ast.Import):
                edges += [(a.name, a.name, node.lineno) for a in node.names]
        out[mod] = [e for e in edges if e[0] in mods and e[0] != mod]
    return out


MODS = _modules()
IMPORTS = _imports(MODS)


def test_every_package_folder_is_installed():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(cfg["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts) for p in PKG.rglob("__init__.py")}
    assert folders | {"wncs_lp.formulations"} == listed
    assert cfg["package-dir"]["wncs_lp.formulations"] == "formulations"
    shipped = {p.name for p in (ROOT / "formulations").glob("*.toml")}
    from wncs_lp import scenario_names

    assert shipped and set(scenario_names()) == shipped


def test_no_import_cycle():
    # a package's __init__ importing its own submodules is how a package exposes them, not a cycle
    graph = {m: {t for t, _, _ in edges if not (MODS[m].name == "__init__.py" and t.startswith(m + "."))
                 and not (t == m.rsplit(".", 1)[0])}
             for m, edges in IMPORTS.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                cycle = stack[stack.index(t):] + [t]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_no_private_name_imported_from_another_module():
    bad = [f"{m}:{line} imports {name} from {t}" for m, edges in IMPORTS.items() for t, name, line in edges
           if name.startswith("_") and t.rsplit(".", 1)[0] != m.rsplit(".", 1)[0]]
    assert not bad, bad


KIND_TEST = re.compile(r"""kind\s*(==|!=)\s*["']|kind\s+(not\s+)?in\s*\(\s*["']""")


def test_only_models_test_a_model_kind():
    allowed = ("wncs_lp/models/", "wncs_lp/scenario.py")
    bad = []
    for path in MODS.values():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(allowed):
            continue
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if KIND_TEST.search(line) and "executor" not in line and '"process"' not in line and '"dask"' not in line:
                bad.append(f"{rel}:{i}: {line.strip()}")
    assert not bad, bad
