"""Tracks as columns (:class:`TrackColumns`, what Monitoring reads each cycle), a mapping that
builds :class:`~gcs_utm.model.Track` objects only for the rows read (:class:`TrackMap`), and
many Track objects at once from one list per field (:func:`build_tracks`): what a snapshot of
10,000 tracks spent most of its time on when built one constructor call each."""

from __future__ import annotations

from collections import deque
from collections.abc import ItemsView, Iterator, Mapping, Sequence, ValuesView
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.geo import LocalFrame
from gcs_utm.model import Icao24, OperationId, Track, TrackId, slot_setters

# ---- building many Track objects -----------------------------------------------------------
# ``Track``'s generated __init__ costs about 4 us per track here (40 ms for 10,000, most of a
# snapshot). Its slots are written by their member descriptors instead (see
# ``model.slot_setters``), one field at a time over all rows with ``map`` (the loop runs in
# C); while ``Track`` is exactly what this was written for, otherwise the plain constructor.
_TRACK_FIELDS = (
    "id", "t_s", "lat_deg", "lon_deg", "alt_amsl_m", "east_m", "north_m", "vel_enu_mps",
    "position_sigma_m", "cooperative", "operation_id", "icao24", "stale", "updates",
    "next_waypoint", "measured_t_s",
)  # fmt: skip
# the tracker has no Remote ID: the field is set to None (adapters/remoteid/tracks.py fills it)
_SETTERS = slot_setters(Track, (*_TRACK_FIELDS, "remote_id"))


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
    for name, setter in zip(_TRACK_FIELDS, _SETTERS, strict=False):
        deque(map(setter, out, columns[name]), maxlen=0)
    deque(map(_SETTERS[-1], out, repeat(None, n)), maxlen=0)
    return out


# ---- the tracks of one snapshot as columns ---------------------------------------------------
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class TrackColumns:
    """Tracks as columns, row ``i`` = ``ids[i]``: what the monitoring cycle reads, without one
    Python object per track. Copies, not views of the tracker: a later ingest changes nothing
    here. ``t_s`` (N,) each row's time (the snapshot time when propagated); ``pos`` (N, 3)
    east_m, north_m, alt_amsl_m; ``vel`` (N, 3) east, north, up m/s; ``position_sigma_m``
    (N,); ``next_waypoint`` (N,) -1 where none; ``measured_t_s`` (N,) each row's last accepted
    measurement (its state time: ``t_s - measured_t_s`` is how long it was dead-reckoned)."""

    frame: LocalFrame
    ids: tuple[TrackId, ...]
    t_s: FloatArray
    pos: FloatArray
    vel: FloatArray
    position_sigma_m: FloatArray
    cooperative: BoolArray
    stale: BoolArray
    updates: npt.NDArray[np.int64]
    operation_ids: tuple[OperationId | None, ...]
    icao24: tuple[Icao24 | None, ...]
    next_waypoint: IntArray
    measured_t_s: FloatArray

    def __len__(self) -> int:
        return len(self.ids)

    def build(self, rows: IntArray | None = None) -> list[Track]:
        """The :class:`Track` objects of all rows, or of ``rows``; every field converted for
        all of them at once, then the objects built column by column (:func:`build_tracks`)."""
        if rows is None:
            n = len(self.ids)
            ids: Sequence[TrackId] = self.ids
            op_ids: Sequence[OperationId | None] = self.operation_ids
            icao: Sequence[Icao24 | None] = self.icao24
            t, pos, vel = self.t_s, self.pos, self.vel
            sigma, coop, stale = self.position_sigma_m, self.cooperative, self.stale
            updates, wp, measured = self.updates, self.next_waypoint, self.measured_t_s
        else:
            n = len(rows)
            at = rows.tolist()
            ids = [self.ids[i] for i in at]
            op_ids = [self.operation_ids[i] for i in at]
            icao = [self.icao24[i] for i in at]
            t, pos, vel = self.t_s[rows], self.pos[rows], self.vel[rows]
            sigma, coop, stale = (
                self.position_sigma_m[rows],
                self.cooperative[rows],
                self.stale[rows],
            )
            updates, wp = self.updates[rows], self.next_waypoint[rows]
            measured = self.measured_t_s[rows]
        lat, lon = self.frame.to_wgs84(pos[:, 0], pos[:, 1])
        east, north, alt = pos.T.tolist()
        columns: dict[str, list[Any]] = {
            "id": list(ids),
            "t_s": t.tolist(),
            "lat_deg": np.asarray(lat, dtype=np.float64).tolist(),
            "lon_deg": np.asarray(lon, dtype=np.float64).tolist(),
            "alt_amsl_m": alt,
            "east_m": east,
            "north_m": north,
            "vel_enu_mps": list(zip(*vel.T.tolist(), strict=True)),
            "position_sigma_m": sigma.tolist(),
            "cooperative": coop.tolist(),
            "operation_id": list(op_ids),
            "icao24": list(icao),
            "stale": stale.tolist(),
            "updates": updates.tolist(),
            "next_waypoint": [None if w < 0 else w for w in wp.tolist()],
            "measured_t_s": [
                None if m == r else m for m, r in zip(measured.tolist(), t.tolist(), strict=True)
            ],
        }
        return build_tracks(columns, n)

    @staticmethod
    def of_tracks(tracks: Mapping[TrackId, Track], frame: LocalFrame) -> TrackColumns:
        """Columns of Track objects (a snapshot assembled from objects: tests, replays)."""
        rows = list(tracks.values())
        n = len(rows)

        def col(name: str) -> FloatArray:
            return np.fromiter((getattr(r, name) for r in rows), np.float64, n)

        return TrackColumns(
            frame=frame,
            ids=tuple(tracks),
            t_s=col("t_s"),
            pos=np.column_stack([col("east_m"), col("north_m"), col("alt_amsl_m")]).reshape(n, 3),
            vel=np.array([r.vel_enu_mps for r in rows], np.float64).reshape(n, 3),
            position_sigma_m=col("position_sigma_m"),
            cooperative=np.fromiter((r.cooperative for r in rows), bool, n),
            stale=np.fromiter((r.stale for r in rows), bool, n),
            updates=np.fromiter((r.updates for r in rows), np.int64, n),
            operation_ids=tuple(r.operation_id for r in rows),
            icao24=tuple(r.icao24 for r in rows),
            next_waypoint=np.fromiter(
                (-1 if r.next_waypoint is None else r.next_waypoint for r in rows), np.intp, n
            ),
            measured_t_s=np.fromiter(
                (r.t_s if r.measured_t_s is None else r.measured_t_s for r in rows), np.float64, n
            ),
        )


class TrackMap(Mapping[TrackId, Track]):
    """The tracks of a snapshot by id, as a read-only mapping over :class:`TrackColumns`: a
    :class:`Track` object is built only when it is read (one by ``get``/``[]``, all at once
    by ``values``/``items``), so a consumer that reads the columns (Monitoring) or a few
    rows (the dashboard's rows on screen) does not pay for one object per track."""

    __slots__ = ("_all", "_one", "_row", "columns")

    def __init__(self, columns: TrackColumns) -> None:
        self.columns = columns
        self._row: dict[TrackId, int] | None = None
        self._one: dict[TrackId, Track] = {}
        self._all: dict[TrackId, Track] | None = None

    def _rows(self) -> dict[TrackId, int]:
        if self._row is None:
            self._row = {tid: i for i, tid in enumerate(self.columns.ids)}
        return self._row

    def __getitem__(self, key: TrackId) -> Track:
        if self._all is not None:
            return self._all[key]
        hit = self._one.get(key)
        if hit is None:
            row = self._rows()[key]  # KeyError for an unknown id, as a dict
            (hit,) = self.columns.build(np.array([row], np.intp))
            self._one[key] = hit
        return hit

    def __contains__(self, key: object) -> bool:
        return key in self._rows()

    def __iter__(self) -> Iterator[TrackId]:
        return iter(self.columns.ids)

    def __len__(self) -> int:
        return len(self.columns.ids)

    def materialise(self) -> dict[TrackId, Track]:
        """Every track as an object (built once)."""
        if self._all is None:
            self._all = dict(zip(self.columns.ids, self.columns.build(), strict=True))
        return self._all

    def values(self) -> ValuesView[Track]:
        return self.materialise().values()

    def items(self) -> ItemsView[TrackId, Track]:
        return self.materialise().items()


def track_columns(tracks: Mapping[TrackId, Track], frame: LocalFrame) -> TrackColumns:
    """The columns of a snapshot's tracks: read directly from a :class:`TrackMap`, converted
    once from Track objects otherwise."""
    if isinstance(tracks, TrackMap):
        return tracks.columns
    return TrackColumns.of_tracks(tracks, frame)
