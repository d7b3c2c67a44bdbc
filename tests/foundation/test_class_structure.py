"""Inheritance only for a real is-a (issue 36): no product class has more than two levels of
project-defined base classes, and no method is a ``raise NotImplementedError`` hook for a
subclass or a sibling part to fill in (a class spread over files by base classes).

Protocols and exceptions are aside: a Protocol is an interface, not a base; exception
hierarchies are how callers catch. The classes are read from the source (``ast``); a base is
resolved through the module's imports."""

from __future__ import annotations

import ast
import builtins
import functools
from pathlib import Path

from tests.foundation.test_import_cycles import ROOT, _modules

MAX_PROJECT_BASES = 2

ClassKey = tuple[str, str]  # (module, class name)


class _Module:
    def __init__(self, name: str, path: Path, is_pkg: bool) -> None:
        self.name = name
        self.tree = ast.parse(path.read_text(encoding="utf-8"))
        self.classes = {n.name: n for n in self.tree.body if isinstance(n, ast.ClassDef)}
        self.imported: dict[str, str] = {}  # local name -> "module.name" or "module"
        for node in ast.walk(self.tree):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = name.split(".") if is_pkg else name.split(".")[:-1]
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join([*parts, *([node.module] if node.module else [])])
                for a in node.names:
                    self.imported[a.asname or a.name] = f"{base}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    top = a.name.split(".")[0]
                    self.imported[a.asname or top] = a.name if a.asname else top


def _dotted(expr: ast.expr) -> str | None:
    if isinstance(expr, ast.Subscript):  # Generic[T], Protocol[T]
        return _dotted(expr.value)
    if isinstance(expr, ast.Name):
        return expr.id
    if isinstance(expr, ast.Attribute):
        head = _dotted(expr.value)
        return None if head is None else f"{head}.{expr.attr}"
    return None


class Classes:
    """Every product class with its bases resolved: project classes, or external names."""

    def __init__(self, root: Path) -> None:
        self.modules = {
            name: _Module(name, path, path.name == "__init__.py")
            for name, path in _modules(root).items()
        }
        self.paths = {name: path.relative_to(root) for name, path in _modules(root).items()}

    def _resolve(self, module: str, dotted: str, seen: int = 0) -> ClassKey | str:
        """A project class, or the external (or unknown) name as written."""
        mod = self.modules[module]
        head, _, rest = dotted.partition(".")
        if not rest and head in mod.classes:
            return (module, head)
        target = mod.imported.get(head)
        if target is None or seen > 10:
            return dotted
        full = f"{target}.{rest}" if rest else target
        owner, _, cls = full.rpartition(".")
        if owner in self.modules:
            return self._resolve(owner, cls, seen + 1)
        return full

    def bases(self, key: ClassKey) -> list[ClassKey | str]:
        node = self.modules[key[0]].classes[key[1]]
        out: list[ClassKey | str] = []
        for b in node.bases:
            d = _dotted(b)
            if d is not None:
                out.append(self._resolve(key[0], d))
        return out

    def all(self) -> list[ClassKey]:
        return [(m, c) for m, mod in self.modules.items() for c in mod.classes]

    def _ancestors_external(
        self, key: ClassKey, seen: frozenset[ClassKey] = frozenset()
    ) -> set[str]:
        out: set[str] = set()
        for b in self.bases(key):
            if isinstance(b, str):
                out.add(b.rpartition(".")[2])
            elif b not in seen:
                out |= self._ancestors_external(b, seen | {key})
        return out

    def is_protocol(self, key: ClassKey) -> bool:
        return "Protocol" in {b.rpartition(".")[2] for b in self.bases(key) if isinstance(b, str)}

    def is_exception(self, key: ClassKey) -> bool:
        names = self._ancestors_external(key)
        return any(
            isinstance(getattr(builtins, n, None), type)
            and issubclass(getattr(builtins, n), BaseException)
            for n in names
        )

    def depth(self, key: ClassKey, seen: frozenset[ClassKey] = frozenset()) -> int:
        """Levels of project-defined base classes above ``key`` (Protocols not counted)."""
        levels = [
            1 + self.depth(b, seen | {key})
            for b in self.bases(key)
            if not isinstance(b, str) and b not in seen and not self.is_protocol(b)
        ]
        return max(levels, default=0)


@functools.cache
def _product() -> Classes:
    return Classes(ROOT)


def _hooks(tree: ast.Module) -> list[int]:
    """Lines of ``raise NotImplementedError`` in the module."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and node.exc is not None:
            exc = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
            if isinstance(exc, ast.Name) and exc.id == "NotImplementedError":
                out.append(node.lineno)
    return out


def test_no_class_has_more_than_two_levels_of_project_bases() -> None:
    classes = _product()
    depths = {key: classes.depth(key) for key in classes.all()}
    deep = [
        f"{m}.{c}: {d} levels"
        for (m, c), d in depths.items()
        if d > MAX_PROJECT_BASES and not classes.is_exception((m, c))
    ]
    assert not deep, f"inheritance deeper than {MAX_PROJECT_BASES} project bases: {deep}"


def test_no_not_implemented_hooks() -> None:
    classes = _product()
    found = [
        f"{classes.paths[m]}:{line}"
        for m, mod in classes.modules.items()
        for line in _hooks(mod.tree)
    ]
    assert not found, f"raise NotImplementedError hooks: {found}"


def test_the_check_sees_depth_through_imports_and_leaves_protocols_and_exceptions(
    tmp_path: Path,
) -> None:
    for pkg in ("gcs_utm", "adapters", "sitl"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "gcs_utm" / "a.py").write_text(
        "from typing import Protocol\n"
        "class P(Protocol): ...\n"
        "class A(P): ...\n"
        "class E(ValueError): ...\n"
    )
    (tmp_path / "gcs_utm" / "b.py").write_text(
        "from gcs_utm.a import A, E\nfrom gcs_utm import a\n"
        "class B(A): ...\nclass C(B): ...\nclass D(a.A, C): ...\n"
        "class E2(E): ...\nclass E3(E2): ...\nclass E4(E3): ...\n"
        "def f() -> None:\n    raise NotImplementedError\n"
    )
    classes = Classes(tmp_path)
    assert classes.depth(("gcs_utm.a", "A")) == 0  # its Protocol is not a level
    assert classes.depth(("gcs_utm.b", "D")) == 3  # D -> C -> B -> A
    assert classes.is_exception(("gcs_utm.b", "E4"))
    assert not classes.is_exception(("gcs_utm.b", "D"))
    assert _hooks(classes.modules["gcs_utm.b"].tree) == [10]
