"""Configuration: TOML read once into frozen, validated dataclasses.

Each area defines its own settings dataclass next to its code, with every field declared by
:func:`setting` (default, one-line doc, optional range). This module turns a TOML mapping into
such a dataclass, and renders the defaults back to a commented TOML file
(``config/default.toml`` is generated from the dataclasses, so code and file cannot drift).

Errors are :class:`ConfigError` naming the file, the key (dotted path) and what was expected.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import MISSING, field
from typing import Any, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A bad configuration value. ``source`` is the file, ``key`` the dotted key."""

    def __init__(self, source: str, key: str, expected: str) -> None:
        super().__init__(f"{source}: {key}: {expected}")
        self.source = source
        self.key = key
        self.expected = expected


def setting(
    default: Any,
    doc: str,
    *,
    min: float | None = None,
    max: float | None = None,
    unit: str = "",
) -> Any:
    """Declare one configuration field: its default, a one-line comment for default.toml,
    and an optional inclusive numeric range checked on load."""
    meta = {"doc": doc, "min": min, "max": max, "unit": unit}
    if isinstance(default, list | dict | set):
        value = default
        return field(default_factory=lambda: type(value)(value), metadata=meta)
    return field(default=default, metadata=meta)


def check_range(source: str, key: str, value: float, meta: dict[str, Any]) -> None:
    """Raise :class:`ConfigError` if ``value`` is NaN/inf or outside ``meta``'s range."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(source, key, f"expected a finite number, got {value!r}")
    lo = meta.get("min")
    hi = meta.get("max")
    if lo is not None and value < lo:
        raise ConfigError(source, key, f"expected a value >= {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise ConfigError(source, key, f"expected a value <= {hi}, got {value!r}")


def field_docs(cls: type[Any]) -> dict[str, str]:
    """Field name -> doc of a settings dataclass."""
    return {f.name: str(f.metadata.get("doc", "")) for f in dataclasses.fields(cls)}


def has_default(f: dataclasses.Field[Any]) -> bool:
    return f.default is not MISSING or f.default_factory is not MISSING
