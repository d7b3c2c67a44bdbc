"""Faithful JSON (de)serialisation of the model's frozen dataclasses for the store.

Driven by the type annotations, so a field added to the model is stored without touching this
module: dataclasses become objects keyed by field name, Enums their value, tuples arrays,
``NewType`` ids their base type, NumPy arrays ``{"__ndarray__": nested lists, "dtype": ...}``.
Decoding rebuilds the exact types (so ``decode(T, encode(x)) == x``) and runs the model's own
validation in ``__post_init__``. Floats round-trip exactly through Python's ``repr``.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import types
import typing
from functools import cache
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


class CodecError(ValueError):
    """A stored document that does not decode into the expected type."""


def encode(obj: Any) -> Any:
    """A JSON-able value for ``obj``."""
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, np.ndarray):
        return {"__ndarray__": obj.tolist(), "dtype": str(obj.dtype)}
    if isinstance(obj, np.generic):
        return obj.item()
    return _encode_composite(obj)


def _encode_composite(obj: Any) -> Any:
    """A dataclass instance, list, tuple or dict, its members encoded."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: encode(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, list | tuple):
        return [encode(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): encode(v) for k, v in obj.items()}
    raise CodecError(f"cannot encode {type(obj).__name__}")


def dumps(obj: Any) -> str:
    # allow_nan: a NaN never reaches here from the model, but a diagnostic detail dict may
    # hold one; JSON text with NaN round-trips through Python's json module.
    return json.dumps(encode(obj), separators=(",", ":"), allow_nan=True)


def loads(cls: type[T], text: str) -> T:
    return typing.cast(T, decode(cls, json.loads(text)))


@cache
def _hints(cls: type[Any]) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def decode(tp: Any, data: Any) -> Any:
    """Rebuild a value of annotation ``tp`` from its :func:`encode` form."""
    supertype = getattr(tp, "__supertype__", None)
    if supertype is not None:  # NewType
        return decode(supertype, data)
    if tp is Any or tp is object:
        return data
    origin = typing.get_origin(tp)
    if origin in (types.UnionType, typing.Union):
        return _decode_union(tp, data)
    if origin in (tuple, list, dict):
        return _decode_container(tp, origin, data)
    if isinstance(tp, type):
        return _decode_class(tp, data)
    if origin is not None and isinstance(data, dict) and "__ndarray__" in data:
        # numpy.typing.NDArray[...] annotations are generic aliases of ndarray.
        return np.asarray(data["__ndarray__"], dtype=data.get("dtype", "float64"))
    raise CodecError(f"cannot decode into {tp!r}")


def _decode_union(tp: Any, data: Any) -> Any:
    args = typing.get_args(tp)
    if data is None and type(None) in args:
        return None
    last: Exception | None = None
    for member in args:
        if member is type(None):
            continue
        try:
            return decode(member, data)
        except (CodecError, TypeError, ValueError, KeyError) as exc:
            last = exc
    raise CodecError(f"{data!r} matches none of {tp}") from last


def _decode_container(tp: Any, origin: Any, data: Any) -> Any:
    args = typing.get_args(tp)
    if origin is list:
        return [decode(args[0] if args else Any, v) for v in data]
    if origin is dict:
        return {k: decode(args[1] if args else Any, v) for k, v in data.items()}
    if not isinstance(data, list):
        raise CodecError(f"expected an array for {tp}, got {data!r}")
    if len(args) == 2 and args[1] is Ellipsis:
        return tuple(decode(args[0], v) for v in data)
    return tuple(decode(a, v) for a, v in zip(args, data, strict=True))


def _decode_class(tp: type, data: Any) -> Any:
    if issubclass(tp, enum.Enum):
        return tp(data)
    if issubclass(tp, np.ndarray) or tp.__name__ == "ndarray":
        return np.asarray(data["__ndarray__"], dtype=data.get("dtype", "float64"))
    if dataclasses.is_dataclass(tp):
        if not isinstance(data, dict):
            raise CodecError(f"expected an object for {tp.__name__}, got {data!r}")
        hints = _hints(tp)
        kwargs = {
            f.name: decode(hints[f.name], data[f.name])
            for f in dataclasses.fields(tp)
            if f.init and f.name in data
        }
        return tp(**kwargs)
    if tp is float:
        if isinstance(data, bool) or not isinstance(data, int | float):
            raise CodecError(f"expected a number, got {data!r}")
        return float(data)
    if tp in (int, str, bool):
        if not isinstance(data, tp) or (tp is int and isinstance(data, bool)):
            raise CodecError(f"expected {tp.__name__}, got {data!r}")
        return data
    raise CodecError(f"cannot decode into {tp!r}")
