"""Every product module runs (issue 36): each is reachable in the import graph from an entry
point, so no product module is imported only by the tests.

Entry points: ``[project.scripts]`` of pyproject.toml and every ``__main__`` module. The graph
is test_import_cycles' (``ast``: imports inside functions and under ``TYPE_CHECKING`` count),
plus what Python does by name: importing ``a.b.c`` imports ``a`` and ``a.b``; a package that
walks its own ``__path__`` (``pkgutil.iter_modules``: the CLI's commands, the benchmarks)
imports all its modules; a string literal that is a product module's name is an
``importlib.import_module`` of it (the CLI's configuration sections)."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

from tests.foundation.test_import_cycles import ROOT, _modules, import_graph


def _by_name(root: Path) -> dict[str, set[str]]:
    """Imports Python makes by name, not by an import statement."""
    mods = _modules(root)
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                if node.value in mods and node.value != name:
                    edges[name].add(node.value)
            elif (
                path.name == "__init__.py"
                and isinstance(node, ast.Attribute)
                and node.attr == "iter_modules"
            ):
                edges[name].update(m for m in mods if m.rpartition(".")[0] == name)
        parent = name.rpartition(".")[0]
        if parent:
            edges[name].add(parent)
    return edges


def entry_points(root: Path) -> set[str]:
    project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    scripts = {target.partition(":")[0] for target in project.get("scripts", {}).values()}
    return scripts | {m for m in _modules(root) if m.rpartition(".")[2] == "__main__"}


def unreachable(root: Path) -> set[str]:
    graph = import_graph(root)
    for name, more in _by_name(root).items():
        graph[name] |= more
    seen: set[str] = set()
    todo = [m for m in entry_points(root) if m in graph]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(graph[m] - seen)
    return set(graph) - seen


def test_every_product_module_is_reachable_from_an_entry_point() -> None:
    assert entry_points(ROOT) >= {"gcs_utm.cli", "gcs_utm.__main__", "sitl.__main__"}
    orphans = sorted(unreachable(ROOT))
    assert not orphans, f"product modules no entry point imports (tests only?): {orphans}"


def test_a_module_only_a_test_imports_is_found(tmp_path: Path) -> None:
    for pkg in ("gcs_utm", "adapters", "sitl"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "pyproject.toml").write_text(
        '[project]\nname = "x"\n[project.scripts]\nx = "gcs_utm.cli:main"\n'
    )
    (tmp_path / "gcs_utm" / "cli.py").write_text("from gcs_utm import used\n")
    (tmp_path / "gcs_utm" / "used.py").write_text("")
    (tmp_path / "gcs_utm" / "orphan.py").write_text("from gcs_utm import used\n")
    assert unreachable(tmp_path) == {"gcs_utm.orphan", "adapters", "sitl"}
