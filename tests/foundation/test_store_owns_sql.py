"""The store owns the SQL of its tables (issue 36): the cluster reads and writes leases,
regions and recommendation versions through :mod:`gcs_utm.store.leases` and
:mod:`gcs_utm.store.versions`, never with statements of its own or the store's private
helpers, so a schema change is made and tested in one package."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_SQL = re.compile(r"\b(SELECT|INSERT|UPDATE|DELETE)\b")
_PRIVATE = re.compile(r"\.(_rows|_load|_conn)\b")


def sql_in(package: Path) -> list[str]:
    """``file:line: text`` of each line of ``package`` that writes SQL or reaches into the
    store's private helpers."""
    out: list[str] = []
    for f in sorted(package.rglob("*.py")):
        for n, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            if _SQL.search(line) or _PRIVATE.search(line):
                out.append(f"{f.relative_to(ROOT)}:{n}: {line.strip()}")
    return out


def test_the_cluster_has_no_sql() -> None:
    assert sql_in(ROOT / "gcs_utm" / "cluster") == []


def test_no_sql_outside_the_store() -> None:
    """Nor does any other product package (``gcs-utm bench soak`` counts the store's rows
    through gcs_utm.store.sqlite.table_row_counts). Only statements here: other packages
    have attributes called ``_rows`` of their own."""
    found = [
        line
        for package in ("gcs_utm", "adapters", "sitl")
        for line in sql_in(ROOT / package)
        if not line.startswith("gcs_utm/store/") and _SQL.search(line.split(": ", 1)[1])
    ]
    assert found == []


def test_the_check_finds_sql() -> None:
    # the check itself reads the store, which does have statements
    assert any("INSERT INTO region_leases" in line for line in sql_in(ROOT / "gcs_utm" / "store"))


def test_the_store_has_no_not_implemented_hooks() -> None:
    """A backend is a whole class of its own over StoreBase (issue 36): no base method that
    only raises for a subclass to fill in."""
    hooks = [
        f"{f.relative_to(ROOT)}"
        for f in sorted((ROOT / "gcs_utm" / "store").rglob("*.py"))
        if "raise NotImplementedError" in f.read_text(encoding="utf-8")
    ]
    assert hooks == []
