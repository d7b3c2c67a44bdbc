"""The simulator's structure: parts composed by the vehicle, not a class spread over files.

The import graph of ``sitl`` (every import statement, ``TYPE_CHECKING`` ones included) has no
cycle, and no class of ``sitl`` derives from more than one level of ``sitl`` classes."""

from __future__ import annotations

import ast
from pathlib import Path

import sitl

PKG = Path(sitl.__file__).resolve().parent


def _modules() -> dict[str, ast.Module]:
    return {
        "sitl" if p.stem == "__init__" else f"sitl.{p.stem}": ast.parse(p.read_text(), str(p))
        for p in sorted(PKG.glob("*.py"))
    }


def _imports(tree: ast.Module, names: set[str]) -> set[str]:
    """The ``sitl`` modules a module imports, wherever the import statement is."""
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name in names}
        elif isinstance(node, ast.ImportFrom) and node.module is not None and node.level == 0:
            # ``from sitl import mission`` imports the module sitl.mission
            submodules = {f"{node.module}.{a.name}" for a in node.names} & names
            out |= submodules or ({node.module} & names)
    return out


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (a path that returns to its start), None without one."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    path: list[str] = []

    def visit(mod: str) -> list[str] | None:
        state[mod] = 1
        path.append(mod)
        for dep in sorted(graph[mod]):
            if state.get(dep) == 1:
                return [*path[path.index(dep) :], dep]
            if dep not in state and (found := visit(dep)) is not None:
                return found
        path.pop()
        state[mod] = 2
        return None

    for mod in sorted(graph):
        if mod not in state and (found := visit(mod)) is not None:
            return found
    return None


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    names = set(mods)
    return {name: _imports(tree, names) - {name} for name, tree in mods.items()}


def test_the_sitl_import_graph_has_no_cycle() -> None:
    graph = _graph()
    assert graph.get("sitl.vehicle")  # the walk sees the imports
    assert _cycle(graph) is None, f"import cycle: {' -> '.join(_cycle(graph) or [])}"


def test_only_the_fleet_imports_the_vehicle() -> None:
    """The vehicle's parts are given what they need; none imports the vehicle back."""
    importers = {name for name, deps in _graph().items() if "sitl.vehicle" in deps}
    assert importers == {"sitl", "sitl.fleet"}


def test_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_sitl_class_derives_from_a_chain_of_sitl_classes() -> None:
    bases: dict[str, list[str]] = {}
    for tree in _modules().values():
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                bases[node.name] = [b.id for b in node.bases if isinstance(b, ast.Name)]

    def depth(name: str) -> int:
        own = [b for b in bases.get(name, []) if b in bases]
        return 1 + max((depth(b) for b in own), default=0) if own else 0

    deep = {name: depth(name) for name in bases if depth(name) > 1}
    assert not deep, f"classes deriving from a chain of sitl classes: {deep}"
    assert depth("Vehicle") == 0
