"""No import cycles among the product modules (issue 36): a class spread over modules that
import each other back is one class, whatever the line counts say.

The graph is read from the source (``ast``), so imports under ``TYPE_CHECKING`` and inside
functions count. ``from pkg import name`` is an edge to ``pkg.name`` when that is a module,
else to ``pkg`` (as import-linter reads it); the compiled extensions setup.py declares are
modules too (leaves: they import nothing of ours)."""

from __future__ import annotations

import ast
import re
from collections.abc import Container
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("gcs_utm", "adapters", "sitl")
STILL_CYCLIC: tuple[str, ...] = ()
"""Packages whose cycles are still being split into parts (issue 36); a cycle anywhere else
fails. Remove a package from here once its cycle is gone."""


def _modules(root: Path) -> dict[str, Path]:
    out: dict[str, Path] = {}
    for pkg in PACKAGES:
        for f in (root / pkg).rglob("*.py"):
            parts = list(f.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = f
    return out


def _extensions(root: Path) -> set[str]:
    """The compiled extension modules: setup.py's ``Extension("pkg.name", ...)``."""
    setup = root / "setup.py"
    text = setup.read_text(encoding="utf-8") if setup.exists() else ""
    return set(re.findall(r'Extension\(\s*"([\w.]+)"', text))


def _imported(node: ast.AST, name: str, is_pkg: bool, mods: Container[str]) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name in mods]
    if not isinstance(node, ast.ImportFrom):
        return []
    if node.level:
        base = name.split(".") if is_pkg else name.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        mod = ".".join([*base, *([node.module] if node.module else [])])
    else:
        mod = node.module or ""
    subs = [f"{mod}.{a.name}" for a in node.names]
    found = [s for s in subs if s in mods]
    if len(found) < len(subs) and mod in mods:
        found.append(mod)  # a name defined in (or re-exported by) ``mod`` itself
    return found


def import_graph(root: Path) -> dict[str, set[str]]:
    mods = _modules(root)
    known = set(mods) | _extensions(root)
    graph: dict[str, set[str]] = {m: set() for m in known}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            graph[name].update(m for m in _imported(node, name, is_pkg, known) if m != name)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp: list[str] = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _allowed(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in STILL_CYCLIC)


def test_no_import_cycle_outside_the_packages_still_being_split() -> None:
    bad = [c for c in cycles(import_graph(ROOT)) if not all(_allowed(m) for m in c)]
    assert not bad, f"import cycles: {bad}"


def test_the_graph_sees_a_cycle_through_a_type_checking_import(tmp_path: Path) -> None:
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "gcs_utm" / "a.py").write_text("from gcs_utm.b import B\n")
    (tmp_path / "gcs_utm" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from gcs_utm import a\n"
    )
    assert cycles(import_graph(tmp_path)) == [["gcs_utm.a", "gcs_utm.b"]]


def test_an_imported_compiled_extension_is_a_module_not_its_package(tmp_path: Path) -> None:
    for pkg in PACKAGES:
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "gcs_utm" / "p").mkdir()
    (tmp_path / "gcs_utm" / "p" / "__init__.py").write_text("from gcs_utm.p.a import A\n")
    (tmp_path / "gcs_utm" / "p" / "a.py").write_text("from gcs_utm.p import _ext\n")
    assert cycles(import_graph(tmp_path)) == [["gcs_utm.p", "gcs_utm.p.a"]]  # _ext unknown
    (tmp_path / "setup.py").write_text('setup(ext_modules=[Extension("gcs_utm.p._ext", [])])\n')
    assert cycles(import_graph(tmp_path)) == []
