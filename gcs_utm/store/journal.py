"""The local journal of writes the store could not commit before the service stopped.

A must-keep write (decision, answer, audit, plan, geofence) is a store method name and its
arguments (an :data:`Op`), so it can outlive the process: when the database is unreachable as
the writer stops, the batches it still holds are appended here (one JSON line per batch:
the life that made it, the batch number and its ops), and the next start replays them before
anything else is written. A batch carries its life's batch number, which the same
transaction records in ``lives.committed_batch``: replaying a batch that did commit before
the connection broke finds that number and is skipped, so nothing is applied twice.

Track history is not journalled (it is droppable everywhere, see :mod:`.writer`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from gcs_utm.messages import PilotAnswer
from gcs_utm.model import AuditEntry, FlightPlan, Geofence, Operation, Recommendation, Threat
from gcs_utm.store.base import StoreBase, StoreError
from gcs_utm.store.codec import CodecError, decode, encode

Op = tuple[str, tuple[Any, ...]]
"""A store write as data: the :class:`StoreBase` method's name and its arguments."""

# The argument types of each journalled method, to decode an op read back.
_ARG_TYPES: dict[str, tuple[Any, ...]] = {
    "save_operation": (Operation,),
    "save_plan": (FlightPlan,),
    "save_geofence": (Geofence, bool),
    "deactivate_geofence": (str,),
    "save_threat": (Threat,),
    "save_recommendation": (Recommendation,),
    "record_answer": (PilotAnswer,),
    "audit": (AuditEntry,),
}
# Methods whose arguments are not all positional.
_CALLS: dict[str, Callable[[StoreBase, tuple[Any, ...]], Any]] = {
    "save_geofence": lambda s, a: s.save_geofence(a[0], active=a[1]),
}


def apply(store: StoreBase, op: Op) -> Any:
    """Run ``op`` on ``store`` (inside the caller's transaction)."""
    name, args = op
    call = _CALLS.get(name)
    if call is not None:
        return call(store, args)
    return getattr(store, name)(*args)


@dataclass(frozen=True, slots=True)
class JournalBatch:
    """One batch that was not committed: the store it was for (as :func:`describe` names
    it, without a password), the life that made it, its number, its ops."""

    store: str
    epoch: int
    batch: int
    ops: tuple[Op, ...]


def _encode_op(op: Op) -> list[Any]:
    name, args = op
    if name not in _ARG_TYPES:
        raise StoreError(f"store write {name!r} cannot be journalled")
    return [name, [encode(a) for a in args]]


def _decode_op(data: Any) -> Op:
    name, args = data
    types = _ARG_TYPES.get(name)
    if types is None or len(args) != len(types):
        raise CodecError(f"unknown journalled write {name!r}")
    return name, tuple(decode(t, a) for t, a in zip(types, args, strict=True))


def append(path: Path, batches: Sequence[JournalBatch]) -> None:
    """Append ``batches`` to the journal at ``path`` and flush them to disk."""
    lines = [
        json.dumps(
            {
                "store": b.store,
                "epoch": b.epoch,
                "batch": b.batch,
                "ops": [_encode_op(op) for op in b.ops],
            },
            separators=(",", ":"),
            allow_nan=True,
        )
        + "\n"
        for b in batches
    ]
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.writelines(lines)
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        raise StoreError(f"{path}: cannot write the store journal: {exc}") from exc


def read(path: Path) -> list[JournalBatch]:
    """The batches in the journal at ``path`` (none when it does not exist). A last line
    without its newline is a write the process did not finish (it was killed while
    spilling): it is ignored. Any other bad line is a :class:`StoreError` naming it."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return []
    except (OSError, UnicodeDecodeError) as exc:
        raise StoreError(f"{path}: cannot read the store journal: {exc}") from exc
    lines = text.split("\n")
    out: list[JournalBatch] = []
    for number, line in enumerate(lines[:-1], start=1):  # lines[-1]: after the last newline
        if not line.strip():
            continue
        try:
            data = json.loads(line)
            ops = tuple(_decode_op(op) for op in data["ops"])
            out.append(
                JournalBatch(str(data["store"]), int(data["epoch"]), int(data["batch"]), ops)
            )
        except (ValueError, TypeError, KeyError, CodecError) as exc:
            raise StoreError(
                f"{path}:{number}: not a store journal entry ({exc}); move the file away "
                "to start without it"
            ) from exc
    return out


__all__ = ["JournalBatch", "Op", "append", "apply", "read"]
