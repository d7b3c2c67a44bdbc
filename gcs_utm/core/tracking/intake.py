"""What a batch brings to the tracks: each measurement and lane entry checked
(:mod:`.kernel`), its identity resolved to a track (paper §4.3, association) and its record
(:mod:`.layout`) made, in batch order; tracks are found or made through the tracker's
``row_for``. See :mod:`.tracker` for the rules.

Association: a measurement's ``operation_id`` if known, else its MAVLink ``sys_id``, else its
ICAO address, mapped to the operation. Anything else with an ICAO address is the intruder
``"icao:<hex>"``; an unassigned MAVLink vehicle is the intruder ``"sysid:<n>"``, or
``"sysid:<n>@<host:port>"`` when the measurement names the vehicle's address; an aircraft
known only by its Remote ID broadcast (``vehicle`` ``"rid:<id>"``) is the intruder ``"rid:<id>"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking import kernel
from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.core.tracking.layout import SOURCE_INDEX
from gcs_utm.model import (
    Icao24,
    LaneSource,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    SysId,
    TrackId,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
Key = tuple[OperationId | None, SysId | None, Icao24 | None, str]


@dataclass(slots=True)
class Identity:
    """The track a measurement belongs to."""

    track_id: TrackId
    cooperative: bool
    operation_id: OperationId | None
    icao24: Icao24 | None


# The tracker's function from an identity to its track's row (made if new).
RowFor = Callable[[Identity], int]


class Intake:
    """Association maps and caches, and the batch's records (see the module docstring)."""

    def __init__(self, config: TrackingConfig, north_dir: tuple[float, float]) -> None:
        self._config = config
        # true north on the UTM grid at the origin: measured NED velocities -> grid velocities
        self._north_dir = north_dir
        # (eph, epv, velocity sigma) per source index (layout.SOURCE_INDEX)
        self._defaults = (
            (config.telemetry_eph_m, config.telemetry_epv_m, config.telemetry_vel_sigma_mps),
            (config.adsb_eph_m, config.adsb_epv_m, config.adsb_vel_sigma_mps),
            (config.mqtt_eph_m, config.mqtt_epv_m, config.telemetry_vel_sigma_mps),
        )
        self.ops: dict[OperationId, Operation] = {}
        self._by_sys: dict[SysId, OperationId] = {}
        self._by_icao: dict[Icao24, OperationId] = {}
        # (operation_id, sys_id, icao24, vehicle) of a measurement -> its track's row: what
        # resolve + row_for give, remembered. Emptied whenever association or rows change.
        self._row_of_key: dict[Key, int] = {}
        # PositionLane source index -> its track's row (-1: not known yet): the same as
        # _row_of_key for the source's key, and emptied with it.
        self._lane_row: IntArray = np.full(0, -1, dtype=np.intp)

    def set_operations(self, ops: Iterable[Operation]) -> set[str]:
        """Replace the operations; returns the intruder track ids (without a vehicle
        address) that now belong to an operation."""
        ops = list(ops)
        self.forget_rows()
        self.ops = {op.id: op for op in ops}
        self._by_sys = {op.sys_id: op.id for op in ops if op.sys_id is not None}
        self._by_icao = {op.icao24: op.id for op in ops if op.icao24 is not None}
        claimed = {f"icao:{icao}" for icao in self._by_icao}
        claimed |= {f"sysid:{sys_id}" for sys_id in self._by_sys}
        return claimed

    def forget_rows(self) -> None:
        """Empty the row caches (rows moved or association changed)."""
        self._row_of_key.clear()
        self._lane_row.fill(-1)

    def trim(self, n_tracks: int) -> None:
        """Keys are per vehicle and source identity, so the cache only outgrows the tracks
        with a churn of identities: then it starts again."""
        if len(self._row_of_key) > 4 * n_tracks + 1024:
            self._row_of_key.clear()

    def resolve(
        self,
        operation_id: OperationId | None,
        sys_id: SysId | None,
        icao24: Icao24 | None,
        vehicle: str,
    ) -> Identity | None:
        """The track identity of a measurement so named (module docstring: Association)."""
        op_id: OperationId | None = None
        if operation_id is not None and operation_id in self.ops:
            op_id = operation_id
        elif sys_id is not None and sys_id in self._by_sys:
            op_id = self._by_sys[sys_id]
        elif icao24 is not None and icao24 in self._by_icao:
            op_id = self._by_icao[icao24]
        if op_id is not None:
            return Identity(TrackId(op_id), True, op_id, self.ops[op_id].icao24)
        if icao24 is not None:
            return Identity(TrackId(f"icao:{icao24}"), False, None, icao24)
        if sys_id is not None:
            tid = f"sysid:{sys_id}@{vehicle}" if vehicle else f"sysid:{sys_id}"
            return Identity(TrackId(tid), False, None, None)
        if vehicle.startswith("rid:"):  # an aircraft known only by its Remote ID broadcast
            return Identity(TrackId(vehicle), False, None, None)
        return None

    def measurement_records(
        self,
        measurements: Sequence[Measurement],
        counts: dict[str, int],
        row_for: RowFor,
    ) -> tuple[IntArray, FloatArray]:
        """Rows and records (NCOL, M) of the measurements that reach a track: each is
        written as an entry (:mod:`.layout`) and checked with the lane entries' checks
        (:func:`.kernel.entry_records`); then the identity of those that passed finds or
        makes their track, in batch order. Rejections are added to ``counts``."""
        values, kinds, has_vel, rows, misses = self._entries(measurements)
        cfg = self._config
        idx, a, invalid, gate = kernel.entry_records(
            values,
            self._defaults,
            # (None: all telemetry, all with a velocity, as lane entries)
            np.array(kinds, dtype=np.intp) if any(kinds) else None,
            None if all(has_vel) else np.array(has_vel, dtype=bool),
            cfg.min_sigma_m,
            cfg.max_future_s,
            cfg.max_speed_mps,
            self._north_dir,
        )
        counts["invalid"] += invalid
        counts["gate"] += gate
        rw = np.array(rows, dtype=np.intp)[idx]
        if not misses or not len(rw) or rw.min() >= 0:
            return rw, a
        keep = self._resolve_misses(rw, idx, misses, counts, row_for)
        if keep.all():
            return rw, a
        return rw[keep], a[:, keep]

    def _entries(
        self, measurements: Sequence[Measurement]
    ) -> tuple[list[float], list[int], list[bool], list[int], dict[int, Key]]:
        """(entry values, source index, has a velocity, cached row or -1, identity key of
        each measurement whose row is not cached) of the measurements, in batch order."""
        cache = self._row_of_key
        values: list[float] = []
        put = values.extend
        kinds: list[int] = []
        has_vel: list[bool] = []
        rows: list[int] = []
        misses: dict[int, Key] = {}
        nan = math.nan
        inf = math.inf
        isnan = math.isnan
        # The source index, looked up again only when the source changes (an Enum's hash is
        # a Python call).
        last_source: MeasurementSource | None = None
        src = 0
        for k, m in enumerate(measurements):
            source = m.source
            if source is not last_source:
                src = SOURCE_INDEX[source]
                last_source = source
            kinds.append(src)
            # None: unknown (nan in an entry); a nan given as a value is invalid (inf)
            eph = m.eph_m
            eph = nan if eph is None else inf if isnan(eph) else eph
            epv = m.epv_m
            epv = nan if epv is None else inf if isnan(epv) else epv
            vel = m.vel_ned_mps
            if vel is None:
                has_vel.append(False)
                vel = (0.0, 0.0, 0.0)
            else:
                has_vel.append(True)
            put((k, m.receipt_t_s, m.capture_t_s, m.lon_deg, m.lat_deg, m.alt_amsl_m, *vel))
            put((eph, epv))
            key = (m.operation_id, m.sys_id, m.icao24, m.vehicle)
            row = cache.get(key)
            if row is None:
                misses[k] = key
                row = -1
            rows.append(row)
        return values, kinds, has_vel, rows, misses

    def _resolve_misses(
        self,
        rw: IntArray,
        idx: IntArray,
        misses: dict[int, Key],
        counts: dict[str, int],
        row_for: RowFor,
    ) -> npt.NDArray[np.bool_]:
        """Rows (written into ``rw``) of the passing entries whose identity was not cached,
        in batch order (finding or making their track); False where no track is theirs."""
        cache = self._row_of_key
        keep = np.ones(len(rw), dtype=bool)
        for j in np.flatnonzero(rw < 0).tolist():
            key = misses[int(idx[j])]
            row = cache.get(key)
            if row is None:
                ident = self.resolve(*key)
                if ident is None:
                    counts["unassociated" if key[0] is not None else "invalid"] += 1
                    keep[j] = False
                    continue
                row = cache[key] = row_for(ident)
            rw[j] = row
        return keep

    def lane_records(
        self,
        lane: Sequence[float],
        sources: Sequence[LaneSource],
        counts: dict[str, int],
        row_for: RowFor,
    ) -> tuple[IntArray, FloatArray]:
        """Rows and records of the lane entries that reach a track, as
        :meth:`measurement_records` gives them for the entries' Measurements (the same
        checks, bit for bit the same records, tracks created in order of first valid entry);
        checked by :func:`.kernel.entry_records`."""
        cfg = self._config
        idx, a, invalid, gate = kernel.entry_records(
            lane,
            self._defaults,
            None,  # telemetry
            None,  # with a velocity
            cfg.min_sigma_m,
            cfg.max_future_s,
            cfg.max_speed_mps,
            self._north_dir,
        )
        counts["invalid"] += invalid
        counts["gate"] += gate
        if len(self._lane_row) < len(sources):
            grown = np.full(max(len(sources), 2 * len(self._lane_row), 64), -1, dtype=np.intp)
            grown[: len(self._lane_row)] = self._lane_row
            self._lane_row = grown
        rows = self._lane_row[idx]
        if len(rows) and rows.min() < 0:
            self._lane_resolve(idx[rows < 0].tolist(), sources, row_for)
            rows = self._lane_row[idx]
        return rows, a

    def _lane_resolve(
        self, unknown: list[int], sources: Sequence[LaneSource], row_for: RowFor
    ) -> None:
        """Rows for the lane sources ``unknown`` (in order of first entry; repeats allowed),
        as :meth:`ingest` finds them for a Measurement of the same identity."""
        cache = self._row_of_key
        for i in dict.fromkeys(unknown):
            src = sources[i]
            key = (None, src.sys_id, None, src.vehicle)
            row = cache.get(key)
            if row is None:
                ident = self.resolve(*key)
                if ident is None:  # (a system id always names a track)
                    raise ValueError(f"lane source {i} has no identity")
                row = cache[key] = row_for(ident)
            self._lane_row[i] = row
