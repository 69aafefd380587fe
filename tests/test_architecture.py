"""The rules of the house (docs/architecture.md), checked on the source with the ``ast`` module.

* every package folder is listed in pyproject.toml, and the scenarios install as package data;
* no import cycle between the package's modules (runtime imports, function-level ones included);
* no private name (leading underscore) imported from another module;
* only ``models/`` (and ``scenario.py``, which validates it) tests a model kind;
* nothing of the package loaded by a name in a string (importlib, ``__import__``,
  ``"module:function"``), but the lazy public names of ``wncs_lp/__init__.py`` and the old paths
  of ``moved.py`` (which warn and give the object of the new path);
* no import, function-level ones included, climbs a floor: the rooms (a top-level folder of the
  package, or a top-level module) and their imports form no cycle;
* method names are compared only in ``methods.py`` and the command line's parser;
* one public solve (``wncs_lp.solve`` is ``workflow.route.solve``);
* every moved, renamed or replaced public name is found at its old path, once, with a warning.
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


def _cycle(graph: dict) -> list[str] | None:
    """The first cycle of a directed graph (node -> its successors), closed on its first node; None without one."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if t not in state and (found := visit(t)) is not None:
                return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m)) is not None:
            return found
    return None


def test_no_import_cycle():
    # a package's __init__ importing its own submodules is how a package exposes them, not a cycle
    graph = {m: {t for t, _, _ in edges if not (MODS[m].name == "__init__.py" and t.startswith(m + "."))
                 and not (t == m.rsplit(".", 1)[0])}
             for m, edges in IMPORTS.items()}
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


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


# ----------------------------------------------------------------------------- loaded by name
#: Where the package may load a module by a name in a string: the lazy public names (start-up time),
#: the old paths of moved names, optional third-party packages, third-party versions in a report.
LOADS_BY_NAME = {"wncs_lp/__init__.py", "wncs_lp/moved.py", "wncs_lp/io/toolkits.py", "wncs_lp/reproduce/__init__.py"}
TARGET_STRING = re.compile(r"^wncs_lp(\.\w+)+:\w+$")


def _loads_by_name(tree: ast.AST) -> list[int]:
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import) and any(a.name == "importlib" for a in node.names):
            lines.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and node.module == "importlib" and any(
                a.name == "import_module" for a in node.names):
            lines.append(node.lineno)
        elif isinstance(node, ast.Name) and node.id == "__import__":
            lines.append(node.lineno)
    return lines


def test_nothing_of_the_package_is_loaded_by_name():
    bad = []
    for path in MODS.values():
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text())
        if rel not in LOADS_BY_NAME:
            bad += [f"{rel}:{line}: loads a module by name" for line in _loads_by_name(tree)]
        bad += [f"{rel}:{n.lineno}: {n.value!r} names a function by a string" for n in ast.walk(tree)
                if isinstance(n, ast.Constant) and isinstance(n.value, str) and TARGET_STRING.match(n.value)]
    assert not bad, bad
    # third-party only: no name of the package in what interop and the report's versions load
    for rel in ("wncs_lp/io/toolkits.py", "wncs_lp/reproduce/__init__.py"):
        assert "import_module(f\"wncs_lp" not in (ROOT / rel).read_text() and "__import__(\"wncs_lp" not in (
            ROOT / rel).read_text()


def test_every_moved_name_is_found_at_its_old_path_with_a_warning():
    import importlib

    from wncs_lp import moved

    for old, new in moved.MOVED.items():
        module, name = old.rsplit(".", 1)
        with pytest.warns(DeprecationWarning, match=f"{old} has moved to {new}.{name}"):
            found = getattr(importlib.import_module(module), name)
        assert found is getattr(importlib.import_module(new), name)
        assert name not in vars(importlib.import_module(module))  # nothing left behind at the old place
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        importlib.import_module("wncs_lp.solvers").nothing


def test_every_replaced_entry_point_still_runs_its_step_with_a_warning_naming_wncs_lp_solve():
    """The old public solves (``solvers.solve``, ``solve_scenario``, ``solve_constrained``,
    ``solve_discounted``, ``matrix_free.solve_mdp``, ``workflow.solve_any``) give the step that now
    runs, for one release, with a DeprecationWarning naming the call that replaces them."""
    import importlib

    from wncs_lp import moved

    assert {old.rsplit(".", 1)[1] for old in moved.REPLACED} == {
        "solve", "solve_scenario", "solve_constrained", "solve_discounted", "solve_mdp", "solve_any"}
    for old, (home, step, call) in moved.REPLACED.items():
        module, name = old.rsplit(".", 1)
        assert call.startswith("wncs_lp.solve(")
        with pytest.warns(DeprecationWarning, match=re.escape(f"{old} is deprecated: call {call}")):
            found = getattr(importlib.import_module(module), name)
        assert found is getattr(importlib.import_module(home), step)
        assert name not in vars(importlib.import_module(module))  # nothing left behind at the old place


def test_renamed_names_and_moved_modules_are_found_at_their_old_paths_with_a_warning():
    """``bounds.joint_chains.Certificate`` (now ``TableCertificate``, distinct from the solutions'
    ``Certificate``), every public name of ``wncs_lp.maps`` (now ``policy_grids``, the data beside
    ``viz.maps``, the drawing) and of ``export`` and ``interop`` (now the ``io`` package, one module a
    format) are found at the old path for one release, with a warning."""
    import importlib

    from wncs_lp import moved, policy_grids

    for old, new in moved.RENAMED.items():
        module, name = old.rsplit(".", 1)
        home, renamed = new.rsplit(".", 1)
        assert renamed != name
        with pytest.warns(DeprecationWarning, match=re.escape(f"{old} is renamed {new}")):
            found = getattr(importlib.import_module(module), name)
        assert found is getattr(importlib.import_module(home), renamed)
        assert name not in vars(importlib.import_module(module))
    assert moved.MOVED_MODULES == {"wncs_lp.maps": "wncs_lp.policy_grids", "wncs_lp.export": "wncs_lp.io",
                                   "wncs_lp.interop": "wncs_lp.io"}
    assert {"policy_grid", "slice_grid", "region_stats", "matrix_free_grid", "action_name"} <= set(policy_grids.__all__)
    for old, new in moved.MOVED_MODULES.items():
        home = importlib.import_module(new)
        for name in home.__all__:
            with pytest.warns(DeprecationWarning, match=f"{old}.{name} has moved to {new}.{name}"):
                assert getattr(importlib.import_module(old), name) is getattr(home, name)
    with pytest.raises(AttributeError, match="has no attribute '_policy_array'"):
        importlib.import_module("wncs_lp.maps")._policy_array  # private names did not move as public ones


def test_one_public_solve():
    """``wncs_lp.solve`` is the workflow floor's function, the one public solve; the steps it runs are
    not exported by the top-level package."""
    import wncs_lp
    from wncs_lp.workflow import route

    assert wncs_lp.solve is route.solve
    assert [n for n in wncs_lp.__all__ if n.startswith("solve") or n.startswith("run_")] == ["solve"]


# ----------------------------------------------------------------------------- floors
def _room(module: str) -> str:
    """``wncs_lp.solvers.lp`` -> ``wncs_lp.solvers`` (a folder is one room); a top-level module is its own."""
    return ".".join(module.split(".")[:2])


def test_no_import_climbs_a_floor():
    """Rooms as the house is drawn (a top-level folder of the package, or a top-level module): with
    every import counted, function-level ones included, they form no cycle, so every import goes
    down to a lower floor."""
    edges: dict[str, dict[str, str]] = {}
    for m, found in IMPORTS.items():
        for t, name, line in found:
            a, b = _room(m), _room(t)
            if a != b:
                edges.setdefault(a, {}).setdefault(b, f"{MODS[m].relative_to(ROOT).as_posix()}:{line} imports {t}")
    ring = _cycle(edges)
    assert ring is None, "rooms in a circle: " + "; ".join(edges[x][y] for x, y in zip(ring, ring[1:]))


# ----------------------------------------------------------------------------- method names
#: Where method names may be compared: the registry and the command line's parser.
COMPARES_METHOD_NAMES = ("wncs_lp/methods.py", "wncs_lp/cli/common.py")


def _identifier(node: ast.AST) -> str:
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant) and isinstance(node.slice.value, str):
        return node.slice.value
    return ""


def _strings(node: ast.AST) -> set[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return {node.value}
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return {e.value for e in node.elts if isinstance(e, ast.Constant) and isinstance(e.value, str)}
    return set()


def test_method_names_are_compared_in_one_place():
    """A value called ``method`` (or ``*_method``) is never compared with a method's name outside
    the registry and the parser: the rest asks the name's row. ``auto`` is left out: several
    parameters of other vocabularies (a stationary solver's, a bundle's) call their default so."""
    from wncs_lp import methods

    names = (set(methods.TABLE) | set(methods.CONSTRAINED) | set(methods.DISCOUNTED)) - {"auto"}
    bad = []
    for path in MODS.values():
        rel = path.relative_to(ROOT).as_posix()
        if rel in COMPARES_METHOD_NAMES:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if not (isinstance(node, ast.Compare) and len(node.ops) == 1
                    and isinstance(node.ops[0], (ast.Eq, ast.NotEq, ast.In, ast.NotIn))):
                continue
            a, b = node.left, node.comparators[0]
            if any("method" in _identifier(x).lower() and _strings(y) & names for x, y in ((a, b), (b, a))):
                bad.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not bad, bad
