"""Configuration: TOML read once into frozen, validated dataclasses.

Each area defines its own settings dataclass next to its code, with every field declared by
:func:`setting` (default, one-line doc, optional range). This module turns a TOML mapping into
such a dataclass, and renders the defaults back to a commented TOML file
(``config/default.toml`` is generated from the dataclasses, so code and file cannot drift).

Errors are :class:`ConfigError` naming the file, the key (dotted path) and what was expected.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import math
import re
import tomllib
import types
import typing
from collections.abc import Mapping
from dataclasses import MISSING, field
from pathlib import Path
from typing import Any, TypeVar

from gcs_utm.validation import nesting_problem, too_deep

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


# The physical limit of a numeric setting that declares no bound of its own, by its unit:
# beyond it a value means nothing physical and only overflows or silently disables something
# downstream (1e300 m/s as a speed gate overflows the first squared distance).
UNIT_LIMITS: dict[str, float] = {
    "s": 1e6,  # 11.6 days
    "ms": 1e9,
    "m": 1e7,  # a quarter of the Earth's circumference
    "m/s": 1e3,  # about Mach 3
    "m/s^2": 1e3,  # about 100 g
    "deg": 360.0,
    "%": 100.0,
    "Hz": 1e4,
    "MB": 1e6,  # a terabyte
    "bytes": 2**31 - 1,  # a C int: what setsockopt takes
}
COUNT_LIMIT = 1e9  # an integer without a unit (a count, a size)
FACTOR_LIMIT = 1e6  # a number without a unit (a weight, a factor)


def limits(meta: Mapping[str, Any], *, integer: bool) -> tuple[float, float, str]:
    """The inclusive range a numeric setting accepts: its declared ``min``/``max``, else
    -/+ the physical limit of its unit (:data:`UNIT_LIMITS`); and what the limit is, for a
    message ("" for a declared bound)."""
    unit = str(meta.get("unit") or "")
    if unit in UNIT_LIMITS:
        cap, why = UNIT_LIMITS[unit], f" (the physical limit for {unit})"
    elif integer:
        cap, why = COUNT_LIMIT, " (the limit for a count)"
    else:
        cap, why = FACTOR_LIMIT, " (the limit for a factor)"
    lo, hi = meta.get("min"), meta.get("max")
    return (
        -cap if lo is None else float(lo),
        cap if hi is None else float(hi),
        why if lo is None or hi is None else "",
    )


def check_range(source: str, key: str, value: float, meta: dict[str, Any]) -> None:
    """Raise :class:`ConfigError` if ``value`` is NaN/inf or outside ``meta``'s range (its
    declared one, else the physical limit of its unit: :func:`limits`)."""
    if isinstance(value, float) and not math.isfinite(value):
        raise ConfigError(source, key, f"expected a finite number, got {value!r}")
    lo, hi, why = limits(meta, integer=isinstance(value, int))
    declared_lo, declared_hi = meta.get("min"), meta.get("max")
    if value < lo:
        shown = declared_lo if declared_lo is not None else _number(lo)
        note = "" if declared_lo is not None else why
        raise ConfigError(source, key, f"expected a value >= {shown}{note}, got {value!r}")
    if value > hi:
        shown = declared_hi if declared_hi is not None else _number(hi)
        note = "" if declared_hi is not None else why
        raise ConfigError(source, key, f"expected a value <= {shown}{note}, got {value!r}")


def _number(x: float) -> str:
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e16 else repr(x)


def has_default(f: dataclasses.Field[Any]) -> bool:
    return f.default is not MISSING or f.default_factory is not MISSING


# --------------------------------------------------------------------------------------------
# Loading: TOML file -> mapping -> frozen settings dataclass

_TOML_POS = re.compile(r"\(at line (\d+), column (\d+)\)")


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file. A missing, unreadable, malformed or absurdly nested file raises
    :class:`ConfigError` naming the file and, for syntax errors, the line (tomllib only
    reports it inside its message). Never a traceback: tomllib recurses once per nesting
    level, so a few thousand levels would end in RecursionError."""
    source = str(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError as exc:
        raise ConfigError(source, "(file)", "the file does not exist") from exc
    except IsADirectoryError as exc:
        raise ConfigError(source, "(file)", "is a directory, not a file") from exc
    except OSError as exc:
        raise ConfigError(source, "(file)", f"cannot be read: {exc.strerror}") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(source, "(file)", f"is not UTF-8 text: {exc.reason}") from exc
    except tomllib.TOMLDecodeError as exc:
        text = str(exc)
        m = _TOML_POS.search(text)
        where = f"line {m.group(1)}" if m else "(syntax)"
        raise ConfigError(source, where, f"malformed TOML: {text}") from exc
    except RecursionError:
        raise ConfigError(source, "(file)", f"malformed TOML: {too_deep()}") from None
    problem = nesting_problem(doc)
    if problem is not None:
        raise ConfigError(source, "(file)", problem)
    return doc


def _type_name(tp: Any) -> str:
    if isinstance(tp, type):
        return _class_name(tp)
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (types.UnionType, typing.Union):
        return " or ".join(_type_name(a) for a in args if a is not type(None))
    if origin in (tuple, list):
        inner = args[0] if args else Any
        return f"an array of {_type_name(inner)}"
    if origin is dict:
        return f"a table of {_type_name(args[1])}"
    return str(tp)


def _class_name(tp: type) -> str:
    if issubclass(tp, enum.Enum):
        return "one of " + ", ".join(repr(m.value) for m in tp)
    if dataclasses.is_dataclass(tp):
        return "a table"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}.get(
        tp, tp.__name__
    )


def _describe(value: Any) -> str:
    kind = {bool: "boolean", int: "integer", float: "number", str: "string"}.get(
        type(value), "array" if isinstance(value, list) else "table"
    )
    text = repr(value)
    return f"{kind} {text if len(text) <= 40 else text[:37] + '...'}"


def _convert(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    """Check ``value`` (as parsed from TOML) against the annotation ``tp`` and convert it."""
    if tp is Any:
        return value
    if typing.get_origin(tp) is not None:
        return _convert_generic(tp, value, source, key, meta)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise _bad(tp, value, source, key)
        return build(tp, value, source=source, section=key)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return _convert_enum(tp, value, source, key)
    return _convert_scalar(tp, value, source, key, meta)


def _convert_generic(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    """``value`` for a union, array or table annotation."""
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        return _convert_union(tp, value, source, key, meta)
    if origin in (tuple, list):
        return _convert_sequence(tp, value, source, key, meta)
    if origin is dict:
        return _convert_dict(tp, value, source, key, meta)
    return _convert_scalar(tp, value, source, key, meta)  # refuses it, naming the type


def _convert_dict(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    if not isinstance(value, dict):
        raise _bad(tp, value, source, key)
    inner = typing.get_args(tp)[1]
    return {str(k): _convert(inner, v, source, f"{key}.{k}", meta) for k, v in value.items()}


def _convert_enum(tp: type[enum.Enum], value: Any, source: str, key: str) -> enum.Enum:
    for member in tp:
        if member.value == value and type(member.value) is type(value):
            return member
    raise _bad(tp, value, source, key)


def _bad(tp: Any, value: Any, source: str, key: str) -> ConfigError:
    return ConfigError(source, key, f"expected {_type_name(tp)}, got {_describe(value)}")


def _convert_union(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    # TOML has no null: a present value must match one of the non-None members.
    errors: list[ConfigError] = []
    for member in typing.get_args(tp):
        if member is type(None):
            continue
        try:
            return _convert(member, value, source, key, meta)
        except ConfigError as exc:
            errors.append(exc)
    if len(errors) == 1:
        raise errors[0]
    raise _bad(tp, value, source, key)


def _convert_sequence(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    origin = typing.get_origin(tp)
    if not isinstance(value, list):
        raise _bad(tp, value, source, key)
    args = typing.get_args(tp)
    if origin is tuple and args and (len(args) != 2 or args[1] is not Ellipsis):
        if len(value) != len(args):
            raise ConfigError(
                source, key, f"expected an array of {len(args)} items, got {len(value)}"
            )
        items = [
            _convert(a, v, source, f"{key}[{i}]", meta)
            for i, (a, v) in enumerate(zip(args, value, strict=True))
        ]
    else:
        inner = args[0] if args else Any
        items = [_convert(inner, v, source, f"{key}[{i}]", meta) for i, v in enumerate(value)]
    return tuple(items) if origin is tuple else items


def _convert_scalar(tp: Any, value: Any, source: str, key: str, meta: Mapping[str, Any]) -> Any:
    if tp is bool or tp is str:
        if not isinstance(value, tp):
            raise _bad(tp, value, source, key)
        return value
    if tp is int or tp is float:
        allowed = int if tp is int else int | float
        if isinstance(value, bool) or not isinstance(value, allowed):
            raise _bad(tp, value, source, key)
        converted = tp(value)
        check_range(source, key, converted, dict(meta))
        return converted
    raise ConfigError(source, key, f"unsupported setting type {tp!r} (a bug in the settings)")


def build(cls: type[T], mapping: Mapping[str, Any], *, source: str, section: str) -> T:
    """Turn a TOML table into the frozen settings dataclass ``cls``.

    Absent keys take their declared default; unknown keys, wrong types and out-of-range values
    raise :class:`ConfigError` naming ``source``, the dotted key (``section.key``) and what was
    expected. Nested settings dataclasses are nested tables.
    """
    if not dataclasses.is_dataclass(cls):
        raise TypeError(f"{cls!r} is not a dataclass")
    if not isinstance(mapping, Mapping):
        raise ConfigError(source, section, f"expected a table, got {_describe(mapping)}")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    unknown = sorted(set(mapping) - set(fields))
    if unknown:
        prefix = f"{section}." if section else ""
        raise ConfigError(
            source,
            prefix + unknown[0],
            "unknown key; valid keys are: " + ", ".join(sorted(fields)),
        )
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        key = f"{section}.{name}" if section else name
        if name in mapping:
            kwargs[name] = _convert(hints[name], mapping[name], source, key, f.metadata)
        elif not has_default(f):
            raise ConfigError(source, key, f"missing; expected {_type_name(hints[name])}")
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:
        # The dataclass's own cross-field checks (e.g. min < max) name no file: add it.
        raise ConfigError(source, section or cls.__name__, str(exc)) from exc


# --------------------------------------------------------------------------------------------
# Rendering: settings dataclasses -> commented default TOML


def _toml_value(value: Any) -> str:
    if isinstance(value, enum.Enum):
        return _toml_value(value.value)
    if isinstance(value, bool | int | float):
        return _toml_number(value)
    if isinstance(value, str):
        # JSON string escapes are a subset of TOML basic-string escapes.
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot render {value!r} as TOML")


def _toml_number(value: bool | float) -> str:
    """A boolean, integer or float as TOML writes it (nan, inf, -inf included)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) or not math.isfinite(value):
        return str(value)  # str(nan) = "nan", str(inf) = "inf", str(-inf) = "-inf"
    return repr(value)


def _default_of(f: dataclasses.Field[Any]) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:
        return f.default_factory()
    return MISSING


def _comment(f: dataclasses.Field[Any], tp: Any) -> str:
    doc = str(f.metadata.get("doc", "")) or f.name
    extras: list[str] = []
    if f.metadata.get("unit"):
        extras.append(str(f.metadata["unit"]))
    lo, hi = f.metadata.get("min"), f.metadata.get("max")
    if lo is not None or hi is not None:
        extras.append(f"{'' if lo is None else lo}..{'' if hi is None else hi}")
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        extras.append("|".join(str(m.value) for m in tp))
    return f"# {doc}" + (f" ({', '.join(extras)})" if extras else "")


def _render_table(cls: type[Any], name: str, lines: list[str]) -> None:
    hints = typing.get_type_hints(cls)
    doc = (cls.__doc__ or "").strip().splitlines()
    if lines:
        lines.append("")
    if doc and not doc[0].startswith(cls.__name__ + "("):
        lines.append(f"# {doc[0]}")
    lines.append(f"[{name}]")
    nested: list[tuple[str, type[Any]]] = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        tp = hints[f.name]
        if isinstance(tp, type) and dataclasses.is_dataclass(tp):
            nested.append((f.name, tp))
            continue
        lines.append(_comment(f, tp))
        default = _default_of(f)
        if default is MISSING or default is None:
            # TOML has no null: leave the key commented out; uncomment to set it.
            lines.append(f"# {f.name} = (unset; {_type_name(tp)})")
        else:
            lines.append(f"{f.name} = {_toml_value(default)}")
    for sub_name, sub_cls in nested:
        _render_table(sub_cls, f"{name}.{sub_name}", lines)


def render_toml(sections: Mapping[str, type[Any]]) -> str:
    """A commented TOML document of every section's defaults: a ``# doc (unit, range)`` line
    above every key. Loading it back with :func:`build` yields the defaults."""
    lines: list[str] = [
        "# gcs-utm configuration: every key with its default.",
        "# Generated by `gcs-utm config default`; do not edit by hand.",
    ]
    for name, cls in sections.items():
        _render_table(cls, name, lines)
    return "\n".join(lines) + "\n"
