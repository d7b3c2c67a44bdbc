"""Many :class:`~gcs_utm.model.Track` objects at once, from one list per field: what a
snapshot of 10,000 tracks spends most of its time on when built one constructor call each."""

from __future__ import annotations

from collections import deque
from itertools import repeat
from typing import Any

from gcs_utm.model import Track, slot_setters

# ---- building many Track objects -----------------------------------------------------------
# ``Track``'s generated __init__ costs about 4 us per track here (40 ms for 10,000, most of a
# snapshot). Its slots are written by their member descriptors instead (see
# ``model.slot_setters``), one field at a time over all rows with ``map`` (the loop runs in
# C); while ``Track`` is exactly what this was written for, otherwise the plain constructor.
_TRACK_FIELDS = (
    "id", "t_s", "lat_deg", "lon_deg", "alt_amsl_m", "east_m", "north_m", "vel_enu_mps",
    "position_sigma_m", "cooperative", "operation_id", "icao24", "stale", "updates",
    "next_waypoint",
)  # fmt: skip
_SETTERS = slot_setters(Track, _TRACK_FIELDS)


def build_tracks(columns: dict[str, list[Any]], n: int, *, fast: bool = True) -> list[Track]:
    """``n`` :class:`Track` objects from one list per field (``columns[name][i]`` is row
    i's value); equal to ``Track(**{name: columns[name][i]})`` for every row, which is what
    ``fast=False`` (or a changed ``Track``) does."""
    if set(columns) != set(_TRACK_FIELDS):
        raise ValueError(f"build_tracks: columns must be the Track fields, got {sorted(columns)}")
    for name, col in columns.items():
        if len(col) != n:
            raise ValueError(f"build_tracks: column {name!r} has {len(col)} rows, expected {n}")
    if _SETTERS is None or not fast:
        cols = [columns[name] for name in _TRACK_FIELDS]
        return [
            Track(**dict(zip(_TRACK_FIELDS, row, strict=True))) for row in zip(*cols, strict=True)
        ]
    new = object.__new__
    out: list[Track] = list(map(new, repeat(Track, n)))
    for name, setter in zip(_TRACK_FIELDS, _SETTERS, strict=True):
        deque(map(setter, out, columns[name]), maxlen=0)
    return out
