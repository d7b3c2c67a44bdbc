"""The Tracking module's state: one constant-velocity Kalman track per UAS and per intruder.

Role (paper §4.3, Figure 5): fuse every position source of a UAS (MAVLink telemetry, ADS-B,
MQTT) into one track, keep non-cooperative traffic as intruder tracks, find each UAS's current
waypoint and predict all tracks over a horizon. Pure: time is always passed in.

Association (:meth:`Tracker.set_operations`): a measurement's ``operation_id`` if known, else
its MAVLink ``sys_id``, else its ICAO address, mapped to the operation. Anything else with an
ICAO address is the intruder ``"icao:<hex>"``; an unassigned MAVLink vehicle is the intruder
``"sysid:<n>"``, or ``"sysid:<n>@<host:port>"`` when the measurement names the vehicle's
address (``Measurement.vehicle``: system ids are 8-bit, so a link can carry several vehicles
with the same one; an operation claims every vehicle with its system id). Intruders are
``cooperative=False`` and carry no operation id, so they are never confused with an operation.

Ingest (:meth:`Tracker.ingest`), per batch:
1. scalar checks (finite, in range, identity, capture time not after receipt + max_future_s,
   measured speed <= max_speed_mps) -> ``invalid`` / ``gate`` / ``unassociated``;
2. the batch is sorted by capture time, and split into rounds in which each track appears at
   most once; each round is one vectorised predict + update (:mod:`.kalman`). So reordering
   *within* a batch is repaired (the service drains a batch per period: that is the reorder
   window). The result is that of ingesting the measurements one by one in capture-time
   order, bit for bit (tested). Per call cost matters as much as per measurement (the
   service ingests every few milliseconds): a batch in which every track appears once is
   one round without sorting, and a round of plain updates (every measurement updates its
   track) is computed row by row -- in C (``_kalman_c.update_rows``, built with the package;
   optional) or, without it, up to ``_SMALL_ROUND`` rows in Python floats
   (:func:`.kalman.step_row`) -- the same arithmetic in the same order as the NumPy round, so
   bit for bit the same (tested), and cheaper than its ~60 NumPy calls;
3. against its track a measurement is ``out_of_order`` if older than the track's state time,
   a ``duplicate`` if a measurement of the same source with the same capture time was already
   used, ``gate`` if farther from the prediction than
   ``min(max_jump_m, gate_margin_m + max_speed_mps * dt)``. Rejections never touch the state.
   A stale track that rejected ``gate_reset_count`` measurements in a row restarts from the
   next valid one (a wrong first fix must not lock a track out forever).

Position lanes (:class:`~gcs_utm.model.PositionLane`): the MAVLink receive path hands
telemetry positions over as flat entries instead of Measurements; ``ingest(measurements,
lane, lane_sources)`` checks and converts them together (in C, or NumPy without it) and uses
each exactly as its Measurement would be used (tested against the Measurement path).

Units: positions in the airspace's local UTM grid (east_m, north_m) and alt_amsl_m; velocities
east/north/up in m/s on the same grid (measured NED velocities are rotated by the grid
convergence at the origin); times in POSIX seconds.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import repeat
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking import kalman

try:  # the common round in C (optional; see _kalman_c.c): the same results
    from gcs_utm.core.tracking import _kalman_c
except ImportError:  # pragma: no cover - built by every install with a C compiler
    _kalman_c = None  # type: ignore[assignment]
from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.core.tracking.plans import PlanTable
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    LANE_STRIDE,
    Icao24,
    LaneSource,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    PredictedTrajectories,
    SysId,
    Track,
    TrackId,
    slot_setters,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]


def round_kernel() -> str:
    """Where the common round and the lane checks run: "c" (the extension is built) or
    "python" (Python floats and NumPy: the same results)."""
    return "c" if _kalman_c is not None else "python"


_SOURCE_INDEX = {
    MeasurementSource.TELEMETRY: 0,
    MeasurementSource.ADSB: 1,
    MeasurementSource.MQTT: 2,
}
# Altitudes outside this band are not an aircraft: below the Dead Sea shore (-430 m) with
# margin, above any airspace a UTM serves (the stratosphere, 30 km) with margin.
_MIN_ALT_AMSL_M = -1_000.0
_MAX_ALT_AMSL_M = 50_000.0


@dataclass(frozen=True, slots=True, kw_only=True)
class IngestStats:
    """What one :meth:`Tracker.ingest` call did. Every measurement is counted exactly once:
    ``accepted + rejected == len(measurements)``."""

    accepted: int = 0
    out_of_order: int = 0
    duplicate: int = 0
    invalid: int = 0
    gate: int = 0
    unassociated: int = 0
    reinitialised: int = 0
    new_tracks: tuple[TrackId, ...] = ()
    new_intruders: tuple[TrackId, ...] = ()

    @property
    def rejected(self) -> int:
        return self.out_of_order + self.duplicate + self.invalid + self.gate + self.unassociated


@dataclass(slots=True)
class _Identity:
    track_id: TrackId
    cooperative: bool
    operation_id: OperationId | None
    icao24: Icao24 | None


# One record of floats per measurement that reached a track, the batch being one (N, _NCOL)
# array: capture time; longitude and latitude, replaced by east and north once projected (so
# east, north, alt are the position measurement z, contiguous); the grid velocity (east,
# north, up; zero when not measured); the position variances (east, north, up) [m^2]; the
# velocity variances [m^2/s^2] (the same on every axis, three times); the source index; 1.0
# if a velocity was measured.
_C_T = 0
_C_LON = _C_EAST = 1
_C_LAT = _C_NORTH = 2
_C_ALT = 3
_C_VE, _C_VN, _C_VU = 4, 5, 6
_C_R = 7
_C_RV = 10
_C_SRC = 13
_C_HAS_VEL = 14
_NCOL = 15
# Up to this many measurements, a round in which every measurement simply updates its track
# is computed in Python floats (kalman.step_row): ~60 NumPy calls cost more than the
# arithmetic of a few rows. Measured with 1,000 tracks: Python ~80 us per call + ~8 us per
# row, NumPy ~170 us + ~2 us per row, so the crossover is ~15 rows (see _round_small).
_SMALL_ROUND = 12


class Tracker:
    """All tracks of one airspace as arrays (struct of arrays), row ``i`` = ``ids[i]``."""

    def __init__(self, frame: LocalFrame, config: TrackingConfig) -> None:
        self.frame = frame
        self.config = config
        self._q = np.array(
            [
                config.accel_sigma_h_mps2**2,
                config.accel_sigma_h_mps2**2,
                config.accel_sigma_v_mps2**2,
            ]
        )
        self._q_col = self._q[:, None]  # kalman.step's layout
        self._q_row = (float(self._q[0]), float(self._q[1]), float(self._q[2]))  # step_row's
        # Grid convergence: true north expressed on the UTM grid at the origin, used to turn
        # measured NED velocities into grid velocities.
        d_east, d_north = frame.point_to_local(frame.origin_lat_deg + 1e-3, frame.origin_lon_deg)
        norm = math.hypot(d_east, d_north)
        self._north_dir = (d_east / norm, d_north / norm)
        self._default_sigma = {
            0: (config.telemetry_eph_m, config.telemetry_epv_m, config.telemetry_vel_sigma_mps),
            1: (config.adsb_eph_m, config.adsb_epv_m, config.adsb_vel_sigma_mps),
            2: (config.mqtt_eph_m, config.mqtt_epv_m, config.telemetry_vel_sigma_mps),
        }
        self._n = 0
        self._cap = 0
        self._x = np.zeros((0, 3, 2))
        self._p = np.zeros((0, 3, 3))
        self._t = np.zeros(0)
        self._src_t = np.zeros((0, 3))
        self._updates = np.zeros(0, dtype=np.int64)
        self._gate_fails = np.zeros(0, dtype=np.int64)
        self._coop = np.zeros(0, dtype=bool)
        self._stale = np.zeros(0, dtype=bool)
        self._plan_row = np.zeros(0, dtype=np.intp)
        self._geom_m = np.zeros(0)
        # Closest plan segment found by the last locate (-1: none): the windowed search
        # starts there (see PlanTable.locate). A cache only: never changes a result.
        self._seg_hint = np.zeros(0, dtype=np.intp)
        self._ids: list[TrackId] = []
        self._op_ids: list[OperationId | None] = []
        self._icao: list[Icao24 | None] = []
        self._row: dict[TrackId, int] = {}
        # (operation_id, sys_id, icao24, vehicle) of a measurement -> its track's row: what
        # _resolve + _row give, remembered. Emptied whenever association or rows change
        # (set_operations, _compact).
        self._row_of_key: dict[
            tuple[OperationId | None, SysId | None, Icao24 | None, str], int
        ] = {}
        # PositionLane source index -> its track's row (-1: not known yet): the same as
        # _row_of_key for the source's key, and emptied with it.
        self._lane_row: IntArray = np.full(0, -1, dtype=np.intp)
        self._dirty: set[TrackId] = set()
        self._ops: dict[OperationId, Operation] = {}
        self._by_sys: dict[SysId, OperationId] = {}
        self._by_icao: dict[Icao24, OperationId] = {}
        self._plans = PlanTable([], frame)
        self._plan_of_op: dict[OperationId, int] = {}
        self._counters: dict[str, int] = dict.fromkeys(
            (
                "accepted",
                "out_of_order",
                "duplicate",
                "invalid",
                "gate",
                "unassociated",
                "reinitialised",
                "tracks_created",
                "intruders_created",
                "intruders_dropped",
                "stale_raised",
            ),
            0,
        )

    # ---- operations and association -------------------------------------------------------
    def set_operations(self, operations: Iterable[Operation]) -> None:
        """Replace the known operations (association maps and plans). Call again whenever a
        plan or an assignment changes. Intruder tracks whose ICAO address or system id now
        belongs to an operation are removed, so one aircraft never shows up twice."""
        ops = list(operations)
        self._row_of_key.clear()
        self._lane_row.fill(-1)
        self._ops = {op.id: op for op in ops}
        self._by_sys = {op.sys_id: op.id for op in ops if op.sys_id is not None}
        self._by_icao = {op.icao24: op.id for op in ops if op.icao24 is not None}
        self._plans = PlanTable([op.plan for op in ops], self.frame)
        self._plan_of_op = {op.id: j for j, op in enumerate(ops)}
        self._seg_hint[:] = -1
        for row in range(self._n):
            op_id = self._op_ids[row]
            j = self._plan_of_op.get(op_id, -1) if op_id is not None else -1
            self._plan_row[row] = j
            self._geom_m[row] = ops[j].flight_geometry_m if j >= 0 else 0.0
        claimed = {f"icao:{icao}" for icao in self._by_icao}
        claimed |= {f"sysid:{sys_id}" for sys_id in self._by_sys}
        keep = np.array(
            [tid.partition("@")[0] not in claimed for tid in self._ids[: self._n]], dtype=bool
        )
        if not keep.all():
            self._counters["intruders_dropped"] += int((~keep).sum())
            self._compact(keep)

    def _resolve(
        self,
        operation_id: OperationId | None,
        sys_id: SysId | None,
        icao24: Icao24 | None,
        vehicle: str,
    ) -> _Identity | None:
        """The track identity of a measurement so named (module docstring: Association)."""
        op_id: OperationId | None = None
        if operation_id is not None and operation_id in self._ops:
            op_id = operation_id
        elif sys_id is not None and sys_id in self._by_sys:
            op_id = self._by_sys[sys_id]
        elif icao24 is not None and icao24 in self._by_icao:
            op_id = self._by_icao[icao24]
        if op_id is not None:
            return _Identity(TrackId(op_id), True, op_id, self._ops[op_id].icao24)
        if icao24 is not None:
            return _Identity(TrackId(f"icao:{icao24}"), False, None, icao24)
        if sys_id is not None:
            tid = f"sysid:{sys_id}@{vehicle}" if vehicle else f"sysid:{sys_id}"
            return _Identity(TrackId(tid), False, None, None)
        return None

    # ---- storage ----------------------------------------------------------------------------
    def _grow(self, need: int) -> None:
        if need <= self._cap:
            return
        cap = max(need, 2 * self._cap, 64)

        def grown(a: npt.NDArray[Any], fill: float = 0.0) -> npt.NDArray[Any]:
            out = np.full((cap, *a.shape[1:]), fill, dtype=a.dtype)
            out[: self._n] = a[: self._n]
            return out

        self._x = grown(self._x)
        self._p = grown(self._p)
        self._t = grown(self._t)
        self._src_t = grown(self._src_t, -np.inf)
        self._updates = grown(self._updates)
        self._gate_fails = grown(self._gate_fails)
        self._coop = grown(self._coop)
        self._stale = grown(self._stale)
        self._plan_row = grown(self._plan_row, -1)
        self._geom_m = grown(self._geom_m)
        self._seg_hint = grown(self._seg_hint, -1)
        self._cap = cap

    def _new_row(self, ident: _Identity) -> int:
        self._grow(self._n + 1)
        row = self._n
        self._n += 1
        self._ids.append(ident.track_id)
        self._op_ids.append(ident.operation_id)
        self._icao.append(ident.icao24)
        self._row[ident.track_id] = row
        self._coop[row] = ident.cooperative
        self._stale[row] = False
        self._src_t[row] = -np.inf
        self._updates[row] = 0
        self._gate_fails[row] = 0
        op = self._ops.get(ident.operation_id) if ident.operation_id is not None else None
        self._plan_row[row] = self._plan_of_op[op.id] if op is not None else -1
        self._geom_m[row] = op.flight_geometry_m if op is not None else 0.0
        self._seg_hint[row] = -1
        return row

    def _compact(self, keep: npt.NDArray[np.bool_]) -> None:
        idx = np.flatnonzero(keep)
        for name in (
            "_x", "_p", "_t", "_src_t", "_updates", "_gate_fails", "_coop", "_stale",
            "_plan_row", "_geom_m", "_seg_hint",
        ):  # fmt: skip
            arr = getattr(self, name)
            arr[: len(idx)] = arr[idx]
        removed = [self._ids[i] for i in np.flatnonzero(~keep)]
        self._ids = [self._ids[i] for i in idx]
        self._op_ids = [self._op_ids[i] for i in idx]
        self._icao = [self._icao[i] for i in idx]
        self._n = len(idx)
        self._row = {tid: i for i, tid in enumerate(self._ids)}
        self._row_of_key.clear()
        self._lane_row.fill(-1)
        self._dirty.difference_update(removed)

    # ---- ingest -----------------------------------------------------------------------------
    def ingest(
        self,
        measurements: Sequence[Measurement],
        lane: Sequence[float] = (),
        lane_sources: Sequence[LaneSource] = (),
    ) -> IngestStats:
        """Fuse a batch of measurements into the tracks; see the module docstring.

        ``lane``: more of the batch as :class:`~gcs_utm.model.PositionLane` entries naming
        ``lane_sources`` -- each is used exactly as its Measurement (``PositionLane.
        measurement``) would be, checked and converted in NumPy instead of one by one. In a
        batch they come after ``measurements`` (which decides only the order of equal capture
        times of one track)."""
        cfg = self.config
        invalid = 0
        gate = 0
        unassociated = 0
        new_tracks: list[TrackId] = []
        new_intruders: list[TrackId] = []
        n_before = self._n
        # What reaches a track: its row, and one record of _NCOL floats (see _C_*).
        rows: list[int] = []
        records: list[float] = []
        add_row = rows.append
        put = records.extend
        isfinite = math.isfinite
        max_future_s = cfg.max_future_s
        max_speed2 = cfg.max_speed_mps**2
        min_sigma = cfg.min_sigma_m
        nd_e, nd_n = self._north_dir
        cache = self._row_of_key
        n_vel = 0
        # The source's defaults, looked up again only when the source changes (an Enum's hash
        # is a Python call).
        last_source: MeasurementSource | None = None
        src = 0
        eph_d = epv_d = vsig2 = eph2_d = epv2_d = 0.0
        for m in measurements:
            t = m.capture_t_s
            lat = m.lat_deg
            lon = m.lon_deg
            alt = m.alt_amsl_m
            # The range checks also reject nan and inf (every comparison with nan is false).
            if not (
                isfinite(t)
                and -90.0 <= lat <= 90.0
                and -180.0 <= lon <= 180.0
                and _MIN_ALT_AMSL_M <= alt <= _MAX_ALT_AMSL_M
                and not (t - m.receipt_t_s > max_future_s and isfinite(m.receipt_t_s))
            ):
                invalid += 1
                continue
            source = m.source
            if source is not last_source:
                src = _SOURCE_INDEX[source]
                eph_d, epv_d, vsig = self._default_sigma[src]
                vsig2 = vsig * vsig
                # The defaults are valid (config ranges): their variances once per source.
                e = max(eph_d, min_sigma)
                eph2_d = e * e
                e = max(epv_d, min_sigma)
                epv2_d = e * e
                last_source = source
            eph_m = m.eph_m
            epv_m = m.epv_m
            if eph_m is None and epv_m is None:
                eph2 = eph2_d
                epv2 = epv2_d
            else:
                eph = eph_d if eph_m is None else eph_m
                epv = epv_d if epv_m is None else epv_m
                if not (isfinite(eph) and isfinite(epv) and eph >= 0.0 and epv >= 0.0):
                    invalid += 1
                    continue
                eph = max(eph, min_sigma)
                epv = max(epv, min_sigma)
                eph2 = eph * eph
                epv2 = epv * epv
            vel = m.vel_ned_mps
            if vel is not None:
                vn, ve, vd = vel
                # Any nan or inf component makes the sum nan or inf: one comparison for the
                # common case, the finer checks only when it fails.
                if not vn * vn + ve * ve + vd * vd <= max_speed2:
                    if isfinite(vn) and isfinite(ve) and isfinite(vd):
                        gate += 1
                    else:
                        invalid += 1
                    continue
            key = (m.operation_id, m.sys_id, m.icao24, m.vehicle)
            row = cache.get(key)
            if row is None:
                ident = self._resolve(*key)
                if ident is None:
                    if m.operation_id is not None:
                        unassociated += 1
                    else:
                        invalid += 1
                    continue
                row = self._row.get(ident.track_id)
                if row is None:
                    row = self._new_row(ident)
                    (new_tracks if ident.cooperative else new_intruders).append(ident.track_id)
                cache[key] = row
            add_row(row)
            if vel is None:
                put(
                    (
                        t, lon, lat, alt,
                        0.0, 0.0, 0.0,
                        eph2, eph2, epv2, vsig2, vsig2, vsig2, src, 0.0,
                    )
                )  # fmt: skip
            else:
                n_vel += 1
                # NED (true north/east) -> grid east/north: north along north_dir, east
                # 90 deg right of it.
                put(
                    (
                        t, lon, lat, alt,
                        vn * nd_e + ve * nd_n, vn * nd_n - ve * nd_e, -vd,
                        eph2, eph2, epv2, vsig2, vsig2, vsig2, src, 1.0,
                    )
                )  # fmt: skip

        rw: IntArray | None = None
        a: FloatArray | None = None
        if rows:
            rw = np.array(rows, dtype=np.intp)
            # Field j of every record is row j of ``a`` (_NCOL, N): each quantity contiguous.
            a = np.array(records, dtype=np.float64).reshape(len(rows), _NCOL).T.copy()
        if lane:
            rw_l, a_l, bad, gated_l = self._lane_records(
                lane, lane_sources, new_tracks, new_intruders
            )
            invalid += bad
            gate += gated_l
            n_vel += len(rw_l)
            if rw is None or a is None:
                rw, a = rw_l, a_l
            elif len(rw_l):
                rw = np.concatenate((rw, rw_l))
                a = np.concatenate((a, a_l), axis=1)
        c = {"invalid": invalid, "gate": gate, "unassociated": unassociated}
        accepted = 0
        reinit = 0
        if rw is not None and a is not None and len(rw):
            n = len(rw)
            with_vel = True if n_vel == n else False if n_vel == 0 else None
            accepted, reinit, ooo, dup, gated = self._apply(rw, a, n_before, with_vel)
            c["gate"] += gated
            c["out_of_order"] = ooo
            c["duplicate"] = dup
        else:
            c["out_of_order"] = 0
            c["duplicate"] = 0
        if len(cache) > 4 * self._n + 1024:
            # Keys are per vehicle and source identity, so this only happens with a churn of
            # identities (it is also emptied whenever rows move): start again.
            cache.clear()
        stats = IngestStats(
            accepted=accepted,
            reinitialised=reinit,
            new_tracks=tuple(new_tracks),
            new_intruders=tuple(new_intruders),
            **c,
        )
        counters = self._counters
        for key_, value in c.items():
            counters[key_] += value
        counters["accepted"] += accepted
        counters["reinitialised"] += reinit
        counters["tracks_created"] += len(new_tracks)
        counters["intruders_created"] += len(new_intruders)
        return stats

    def _lane_records(
        self,
        lane: Sequence[float],
        sources: Sequence[LaneSource],
        new_tracks: list[TrackId],
        new_intruders: list[TrackId],
    ) -> tuple[IntArray, FloatArray, int, int]:
        """:meth:`ingest`'s per-measurement checks and records for lane entries, as its loop
        makes them for the entries' Measurements: the same conditions in the same order (so
        the same counts), the same arithmetic (the same records, bit for bit), tracks created
        in order of first valid entry. In C (:mod:`._kalman_c`) when it is built, else in
        NumPy. Returns (rows, records (_NCOL, M), invalid, gate)."""
        fast = _kalman_c
        if fast is not None:
            cfg = self.config
            k = len(lane) // LANE_STRIDE
            a = np.empty((_NCOL, k))
            idx = np.empty(k, dtype=np.intp)
            m, invalid, gate = fast.lane_records(
                lane, a, idx,
                self._default_sigma[_SOURCE_INDEX[MeasurementSource.TELEMETRY]],
                cfg.min_sigma_m, cfg.max_future_s, cfg.max_speed_mps**2, self._north_dir,
                _MIN_ALT_AMSL_M, _MAX_ALT_AMSL_M,
            )  # fmt: skip
            if m < k:
                a = a[:, :m].copy()
                idx = idx[:m]
        else:
            idx, a, invalid, gate = self._lane_checks(lane)
        if len(self._lane_row) < len(sources):
            grown = np.full(max(len(sources), 2 * len(self._lane_row), 64), -1, dtype=np.intp)
            grown[: len(self._lane_row)] = self._lane_row
            self._lane_row = grown
        rows = self._lane_row[idx]
        if len(rows) and rows.min() < 0:
            self._lane_resolve(idx[rows < 0].tolist(), sources, new_tracks, new_intruders)
            rows = self._lane_row[idx]
        return rows, a, invalid, gate

    def _lane_checks(self, lane: Sequence[float]) -> tuple[IntArray, FloatArray, int, int]:
        """:meth:`_lane_records` in NumPy: (source indices, records, invalid, gate)."""
        cfg = self.config
        # one contiguous row per field (see LANE_STRIDE)
        v = np.array(lane, dtype=np.float64).reshape(-1, LANE_STRIDE).T.copy()
        rcv, t, lon, lat, alt, vn, ve, vd = v[1:9]
        sig = v[9:11]  # eph, epv; nan: unknown
        eph_d, epv_d, vsig = self._default_sigma[_SOURCE_INDEX[MeasurementSource.TELEMETRY]]
        max_speed2 = cfg.max_speed_mps**2
        with np.errstate(all="ignore"):  # nan and inf fail the checks, as in ingest
            speed2 = vn * vn + ve * ve + vd * vd
            # The common case first: a few reductions tell that every entry passes (a nan
            # anywhere makes its reduction nan, and the comparison false).
            lo = v[1:6].min(axis=1).tolist()
            hi = v[1:6].max(axis=1).tolist()
            sig_lo = np.fmin.reduce(sig, axis=1).tolist()  # (fmin/fmax skip nan)
            sig_hi = np.fmax.reduce(sig, axis=1).tolist()
            all_ok = (
                -math.inf < lo[1]
                and hi[1] < math.inf
                and lo[2] >= -180.0
                and hi[2] <= 180.0
                and lo[3] >= -90.0
                and hi[3] <= 90.0
                and lo[4] >= _MIN_ALT_AMSL_M
                and hi[4] <= _MAX_ALT_AMSL_M
                and not float(np.fmax.reduce(t - rcv)) > cfg.max_future_s  # (nan rcv: passes)
                and not (sig_lo[0] < 0.0 or sig_lo[1] < 0.0)
                and not (sig_hi[0] == math.inf or sig_hi[1] == math.inf)
                and float(speed2.max()) <= max_speed2
            )
            if all_ok:
                invalid = gate = 0
                sel: IntArray | slice = slice(None)
            else:
                ok = (
                    np.isfinite(t)
                    & (lat >= -90.0)
                    & (lat <= 90.0)
                    & (lon >= -180.0)
                    & (lon <= 180.0)
                    & (alt >= _MIN_ALT_AMSL_M)
                    & (alt <= _MAX_ALT_AMSL_M)
                    & ~((t - rcv > cfg.max_future_s) & np.isfinite(rcv))
                )
                eph = np.where(np.isnan(sig[0]), eph_d, sig[0])  # unknown: the default
                epv = np.where(np.isnan(sig[1]), epv_d, sig[1])
                ok_sigma = np.isfinite(eph) & np.isfinite(epv) & (eph >= 0.0) & (epv >= 0.0)
                invalid = int(np.count_nonzero(~ok)) + int(np.count_nonzero(ok & ~ok_sigma))
                ok &= ok_sigma
                fast = ~(speed2 <= max_speed2)
                finite_v = np.isfinite(vn) & np.isfinite(ve) & np.isfinite(vd)
                gate = int(np.count_nonzero(ok & fast & finite_v))
                invalid += int(np.count_nonzero(ok & fast & ~finite_v))
                ok &= ~fast
                sel = np.flatnonzero(ok)
        idx = v[0, sel].astype(np.intp)
        m = len(idx)
        a = np.empty((_NCOL, m))
        a[_C_T : _C_ALT + 1] = v[2:6, sel]  # t, lon, lat, alt: the record's order
        nd_e, nd_n = self._north_dir
        vn = vn[sel]
        ve = ve[sel]
        # NED (true north/east) -> grid east/north, as ingest computes it
        a[_C_VE] = vn * nd_e + ve * nd_n
        a[_C_VN] = vn * nd_n - ve * nd_e
        np.negative(vd[sel], out=a[_C_VU])
        min_sigma = cfg.min_sigma_m
        for k, default, first in ((0, eph_d, _C_R), (1, epv_d, _C_R + 2)):
            if math.isnan(sig_lo[k]):  # unknown throughout: the default's variance
                e2 = max(default, min_sigma)
                a[first] = e2 * e2
            else:
                e = np.where(np.isnan(sig[k, sel]), default, sig[k, sel])
                np.maximum(e, min_sigma, out=e)
                np.multiply(e, e, out=a[first])
        a[_C_R + 1] = a[_C_R]  # east and north: eph
        a[_C_RV : _C_RV + 3] = vsig * vsig
        a[_C_SRC] = 0.0
        a[_C_HAS_VEL] = 1.0
        return idx, a, invalid, gate

    def _lane_resolve(
        self,
        unknown: list[int],
        sources: Sequence[LaneSource],
        new_tracks: list[TrackId],
        new_intruders: list[TrackId],
    ) -> None:
        """Rows for the lane sources ``unknown`` (in order of first entry; repeats allowed),
        as :meth:`ingest` finds them for a Measurement of the same identity."""
        cache = self._row_of_key
        for i in dict.fromkeys(unknown):
            src = sources[i]
            key = (None, src.sys_id, None, src.vehicle)
            row = cache.get(key)
            if row is None:
                ident = self._resolve(*key)
                if ident is None:  # (a system id always names a track)
                    raise ValueError(f"lane source {i} has no identity")
                row = self._row.get(ident.track_id)
                if row is None:
                    row = self._new_row(ident)
                    (new_tracks if ident.cooperative else new_intruders).append(ident.track_id)
                cache[key] = row
            self._lane_row[i] = row

    def _apply(
        self, rw: IntArray, a: FloatArray, n_before: int, with_vel: bool | None
    ) -> tuple[int, int, int, int, int]:
        """Rounds of one vectorised predict + update of rows ``rw`` with their records ``a``
        (_NCOL, N; lon/lat become east/north here). Returns (accepted, reinitialised,
        out_of_order, duplicate, gate). ``with_vel``: every record has a velocity (True),
        none has (False), or mixed (None)."""
        n = len(rw)
        self.frame.to_local_in_place(a[_C_LON], a[_C_LAT])
        new_rows = self._n > n_before
        if len(set(rw.tolist())) == n:
            # The common case: every track at most once, so one round in any order.
            if not new_rows:
                done = self._round_plain(rw, a)
                if done is not None:
                    return done
            return self._round(rw, a, rw >= n_before if new_rows else None, with_vel)
        # Rounds: sort by capture time, then rank each measurement among those of its
        # track; round k holds every track's k-th measurement.
        order = np.argsort(a[_C_T], kind="stable")
        rs = rw[order]
        by_row = np.argsort(rs, kind="stable")
        grouped = rs[by_row]
        pos = np.arange(n)
        first = np.ones(n, dtype=bool)
        first[1:] = grouped[1:] != grouped[:-1]
        rank_grouped = pos - np.maximum.accumulate(np.where(first, pos, 0))
        rank = np.empty(n, dtype=np.intp)
        rank[by_row] = rank_grouped
        totals = [0, 0, 0, 0, 0]
        for k in range(int(rank.max()) + 1):
            sel = order[rank == k]
            r_k = rw[sel]
            # Rows created by this batch start uninitialised: their earliest measurement
            # is rank 0.
            init = r_k >= n_before if new_rows and k == 0 else None
            res = self._round(r_k, a[:, sel], init, with_vel)
            totals = [x + y for x, y in zip(totals, res, strict=True)]
        accepted, reinit, ooo, dup, gate = totals
        return accepted, reinit, ooo, dup, gate

    def _round(
        self,
        rw: IntArray,
        a: FloatArray,
        init: npt.NDArray[np.bool_] | None,
        with_vel: bool | None,
    ) -> tuple[int, int, int, int, int]:
        """One round: rows ``rw`` (each at most once) with their records ``a`` (_NCOL, M);
        ``init``: rows that start from their measurement (None: none)."""
        cfg = self.config
        t = a[_C_T]
        src = a[_C_SRC].astype(np.intp)
        # The rows' states as planes (kalman.step): (2, 3, M) and (3, 3, M).
        x = self._x.transpose(2, 1, 0)[:, :, rw]
        dt = t - self._t[rw]
        x[kalman.POS] += x[kalman.VEL] * dt  # predicted (x is a copy: written back if updated)
        d = a[_C_EAST : _C_ALT + 1] - x[kalman.POS]
        d *= d
        miss = np.sqrt(d[0] + d[1] + d[2])
        allowed = np.minimum(cfg.max_jump_m, cfg.gate_margin_m + cfg.max_speed_mps * dt)
        ooo = dt < 0.0
        dup = t == self._src_t[rw, src]
        gate = miss > allowed
        m = len(rw)
        if init is None and not (ooo | dup | gate).any():
            # The common case: every measurement updates its track.
            self._filter(rw, x, a, dt, with_vel)
            self._accept(rw, t, src)
            return m, 0, 0, 0, 0
        if init is None:
            init = np.zeros(m, dtype=bool)
        ooo &= ~init
        dup &= ~init & ~ooo
        gate &= ~(init | ooo | dup)
        # A stale track that keeps rejecting restarts from this measurement.
        restart = gate & (dt > cfg.stale_after_s) & (self._gate_fails[rw] >= cfg.gate_reset_count)
        gate &= ~restart
        init |= restart
        self._gate_fails[rw[gate]] += 1
        upd = ~(init | ooo | dup | gate)
        ok = init | upd
        if init.any():
            # New and restarted tracks: state = the measurement, velocity unknown unless
            # measured.
            ri = rw[init]
            ai = a[:, init]
            hv = ai[_C_HAS_VEL] != 0.0
            xi = np.empty((2, 3, len(ri)))
            xi[kalman.POS] = ai[_C_EAST : _C_ALT + 1]
            xi[kalman.VEL] = np.where(hv, ai[_C_VE : _C_VU + 1], 0.0)
            pi = np.empty((3, 3, len(ri)))
            pi[kalman.PP] = ai[_C_R : _C_R + 3]
            pi[kalman.PV] = 0.0
            pi[kalman.VV] = np.where(hv, ai[_C_RV : _C_RV + 3], cfg.initial_vel_sigma_mps**2)
            self._x.transpose(2, 1, 0)[:, :, ri] = xi
            self._p.transpose(2, 1, 0)[:, :, ri] = pi
            self._src_t[ri] = -np.inf
        if upd.any():
            self._filter(rw[upd], x[:, :, upd], a[:, upd], dt[upd], with_vel)
        if ok.any():
            self._accept(rw[ok], t[ok], src[ok])
        return (
            int(ok.sum()),
            int(restart.sum()),
            int(ooo.sum()),
            int(dup.sum()),
            int(gate.sum()),
        )

    def _round_plain(self, rw: IntArray, a: FloatArray) -> tuple[int, int, int, int, int] | None:
        """The round of existing rows ``rw`` (each once) when every measurement updates its
        track, as :meth:`_round_small` computes it: in C (:mod:`._kalman_c`) when it is
        built, for any number of rows, else in Python up to ``_SMALL_ROUND`` rows. None:
        nothing changed, :meth:`_round` decides."""
        fast = _kalman_c
        if fast is not None:
            cfg = self.config
            if not fast.update_rows(
                rw, a, self._x, self._p, self._t, self._src_t, self._updates,
                self._gate_fails, self._stale, self._q_row,
                cfg.max_jump_m, cfg.gate_margin_m, cfg.max_speed_mps,
            ):  # fmt: skip
                return None
            ids = self._ids
            self._dirty.update([ids[i] for i in rw.tolist()])
            return len(rw), 0, 0, 0, 0
        if len(rw) <= _SMALL_ROUND:
            return self._round_small(rw, a)
        return None

    def _round_small(self, rw: IntArray, a: FloatArray) -> tuple[int, int, int, int, int] | None:
        """:meth:`_round` without new rows, in Python floats, when every measurement updates
        its track; None (nothing changed) as soon as one does not: :meth:`_round` decides
        then. The same arithmetic in the same order (bit for bit; tests check it)."""
        cfg = self.config
        max_jump = cfg.max_jump_m
        margin = cfg.gate_margin_m
        max_speed = cfg.max_speed_mps
        q = self._q_row
        step_row = kalman.step_row
        sqrt = math.sqrt
        m = len(rw)
        # Rows flattened (x: 6, p: 9 per row); written back from flat lists (NumPy converts
        # nested lists several times slower).
        xs = self._x[rw].reshape(m, 6).tolist()
        ps = self._p[rw].reshape(m, 9).tolist()
        t_prev = self._t[rw].tolist()
        src_t = self._src_t[rw].tolist()
        out_x: list[float] = []
        out_p: list[float] = []
        try:
            for rec, x, p, t0, ts in zip(a.T.tolist(), xs, ps, t_prev, src_t, strict=True):
                t = rec[_C_T]
                dt = t - t0
                if dt < 0.0 or t == ts[int(rec[_C_SRC])]:
                    return None
                pe = x[0] + x[1] * dt
                pn = x[2] + x[3] * dt
                pu = x[4] + x[5] * dt
                de = rec[_C_EAST] - pe
                dn = rec[_C_NORTH] - pn
                du = rec[_C_ALT] - pu
                if sqrt(de * de + dn * dn + du * du) > min(max_jump, margin + max_speed * dt):
                    return None
                x[0] = pe
                x[2] = pn
                x[4] = pu
                z = rec[_C_EAST : _C_ALT + 1]
                r = rec[_C_R : _C_R + 3]
                if rec[_C_HAS_VEL]:
                    step_row(x, p, dt, q, z, r, rec[_C_VE : _C_VU + 1], rec[_C_RV])
                else:
                    step_row(x, p, dt, q, z, r)
                out_x += x
                out_p += p
        except ZeroDivisionError:
            return None  # NumPy's inf / nan (and its warning), as with a larger batch
        self._x[rw] = np.array(out_x).reshape(m, 3, 2)
        self._p[rw] = np.array(out_p).reshape(m, 3, 3)
        self._accept(rw, a[_C_T], a[_C_SRC].astype(np.intp))
        return m, 0, 0, 0, 0

    def _filter(
        self, rw: IntArray, x: FloatArray, a: FloatArray, dt: FloatArray, with_vel: bool | None
    ) -> None:
        """Predict rows ``rw`` (their states ``x`` as planes, gathered, positions already
        predicted) by ``dt`` and update them with their records ``a``; written back."""
        if with_vel is None:
            hv = a[_C_HAS_VEL] != 0.0
            for part, wv in ((~hv, False), (hv, True)):
                if part.any():
                    self._filter(rw[part], x[:, :, part], a[:, part], dt[part], wv)
            return
        p = self._p.transpose(2, 1, 0)[:, :, rw]
        z = a[_C_EAST : _C_ALT + 1]
        r = a[_C_R : _C_R + 3]
        if with_vel:
            zv = a[_C_VE : _C_VU + 1]
            rv = a[_C_RV : _C_RV + 3]
            kalman.step(x, p, dt, self._q_col, z, r, zv, rv, positions_predicted=True)
        else:
            kalman.step(x, p, dt, self._q_col, z, r, positions_predicted=True)
        self._x.transpose(2, 1, 0)[:, :, rw] = x
        self._p.transpose(2, 1, 0)[:, :, rw] = p

    def _accept(self, rw: IntArray, t: FloatArray, src: IntArray) -> None:
        """Bookkeeping of rows ``rw`` that took a measurement of time ``t`` from ``src``."""
        self._t[rw] = t
        self._src_t[rw, src] = t
        self._updates[rw] += 1
        self._gate_fails[rw] = 0
        self._stale[rw] = False
        ids = self._ids
        self._dirty.update([ids[i] for i in rw.tolist()])

    # ---- reading ----------------------------------------------------------------------------
    @property
    def counters(self) -> dict[str, int]:
        """Totals since construction (a copy)."""
        return dict(self._counters)

    def __len__(self) -> int:
        return self._n

    def covariance(self, track_id: TrackId) -> FloatArray:
        """The 6x6 covariance of a track over (east, north, up, v_east, v_north, v_up)."""
        row = self._row[track_id]
        _, cov = kalman.to_full(self._x[row : row + 1], self._p[row : row + 1])
        out: FloatArray = cov[0]
        return out

    def _plan_state(
        self, pos: FloatArray, t_s: FloatArray, sel: IntArray | None = None
    ) -> tuple[IntArray, IntArray, FloatArray, FloatArray]:
        """For tracks with a plan: (rows, current waypoint, distance to plan, plan time).
        ``pos`` and ``t_s`` are of every row, or with ``sel`` of rows ``sel`` only; the rows
        returned are then positions in ``sel``."""
        if sel is None:
            at = rows = np.flatnonzero(self._plan_row[: self._n] >= 0)
        else:
            at = np.flatnonzero(self._plan_row[sel] >= 0)
            rows = sel[at]
        if len(rows) == 0:
            empty = np.zeros(0)
            return at, np.zeros(0, dtype=np.intp), empty, empty
        cfg = self.config
        geom = self._geom_m[rows]
        wp, dist, tau, seg = self._plans.locate(
            self._plan_row[rows],
            pos[at],
            t_s[at],
            geom * cfg.plan_ambiguity_factor,
            hint=self._seg_hint[rows],
            # A window answer within this distance is exact, and it is also within the
            # plan-following distance, so predict() decides as with the full search.
            accept_m=geom * min(cfg.plan_ambiguity_factor, cfg.plan_follow_factor),
        )
        self._seg_hint[rows] = seg
        return at, wp, dist, tau

    @property
    def plan_searches(self) -> dict[str, int]:
        """How many current-waypoint searches were answered from the window around the
        previous segment and how many searched the whole plan (since the last
        :meth:`set_operations`)."""
        return dict(self._plans.searches)

    def forget_plan_hints(self) -> None:
        """Drop every track's previous segment: the next search covers whole plans (what
        the first cycle does; the benchmark times it)."""
        self._seg_hint[:] = -1

    def _make_tracks(
        self,
        t_s: float | None,
        pos: FloatArray,
        vel: FloatArray,
        pos_var: FloatArray,
        sel: IntArray | None = None,
    ) -> dict[TrackId, Track]:
        """Track objects for all rows (or rows ``sel``) at ``t_s`` (None: each at its own
        state time) with positions ``pos`` (N, 3), velocities ``vel`` (N, 3) and position
        variances ``pos_var`` (N, 3) of those rows. Every field is converted for all rows at
        once (``tolist``), then the objects are built column by column
        (:func:`build_tracks`)."""
        if sel is None:
            n = self._n
            rows_t = np.full(n, t_s) if t_s is not None else self._t[:n]
            ids = self._ids[:n]
            op_ids = self._op_ids[:n]
            icao = self._icao[:n]
            coop, stale, updates = self._coop[:n], self._stale[:n], self._updates[:n]
        else:
            n = len(sel)
            rows_t = np.full(n, t_s) if t_s is not None else self._t[sel]
            at = sel.tolist()
            ids = [self._ids[i] for i in at]
            op_ids = [self._op_ids[i] for i in at]
            icao = [self._icao[i] for i in at]
            coop, stale, updates = self._coop[sel], self._stale[sel], self._updates[sel]
        plan_rows, wp, _, _ = self._plan_state(pos, rows_t, sel)
        if len(plan_rows) == n:
            next_wp: list[int | None] = wp.tolist()
        else:
            next_wp = [None] * n
            for row, w in zip(plan_rows.tolist(), wp.tolist(), strict=True):
                next_wp[row] = w
        lat, lon = self.frame.to_wgs84(pos[:, 0], pos[:, 1])
        east, north, alt = pos.T.tolist()
        columns: dict[str, list[Any]] = {
            "id": ids,
            "t_s": [float(t_s)] * n if t_s is not None else rows_t.tolist(),
            "lat_deg": np.asarray(lat, dtype=np.float64).tolist(),
            "lon_deg": np.asarray(lon, dtype=np.float64).tolist(),
            "alt_amsl_m": alt,
            "east_m": east,
            "north_m": north,
            "vel_enu_mps": list(zip(*vel.T.tolist(), strict=True)),
            "position_sigma_m": np.sqrt(pos_var.sum(axis=1)).tolist(),
            "cooperative": coop.tolist(),
            "operation_id": op_ids,
            "icao24": icao,
            "stale": stale.tolist(),
            "updates": updates.tolist(),
            "next_waypoint": next_wp,
        }
        return dict(zip(ids, build_tracks(columns, n), strict=True))

    def tracks(self) -> dict[TrackId, Track]:
        """Every track at its own state time (the last accepted measurement)."""
        n = self._n
        return self._make_tracks(
            None,
            self._x[:n, :, kalman.POS].copy(),
            self._x[:n, :, kalman.VEL].copy(),
            self._p[:n, :, kalman.PP].copy(),
        )

    def take_updated(self, limit: int | None = None) -> list[Track]:
        """Tracks changed since the previous call (for batched store writes): all of them,
        or at most ``limit`` (the others stay for the next call)."""
        dirty = self._dirty
        if not dirty:
            return []
        if limit is None or len(dirty) <= limit:
            taken: Iterable[TrackId] = dirty
            self._dirty = set()
        else:
            taken = [dirty.pop() for _ in range(limit)]
        row = self._row
        sel = np.array(sorted(row[tid] for tid in taken if tid in row), dtype=np.intp)
        return list(
            self._make_tracks(
                None,
                self._x[sel, :, kalman.POS],
                self._x[sel, :, kalman.VEL],
                self._p[sel, :, kalman.PP],
                sel,
            ).values()
        )

    @property
    def updated_count(self) -> int:
        """How many tracks changed since the last :meth:`take_updated`."""
        return len(self._dirty)

    def predict(self, t_s: float) -> PredictedTrajectories:
        """Predicted trajectories of all tracks (cooperative and intruders) from ``t_s``.

        Points are at ``t_s + k * step_s`` for k = 0 .. horizon_s / step_s. A UAS within
        ``plan_follow_factor * flight_geometry_m`` of its plan follows the 4D plan from the
        plan time of its current position (the cross-track offset decays with
        ``plan_offset_decay_s``), its radius grows by ``plan_sigma_growth_mps``; every other
        track is extrapolated with its filtered velocity and its radius is the filter's
        position covariance propagated (root of the trace). Time is counted from each
        track's state time, so a stale track's radius keeps growing.

        Layout: (N, K) arrays per axis, stacked once at the end (much faster than writing
        through an (N, K, 4) array). Whichever kind of row is the majority is computed for
        all rows at once and the minority is written over it: scattering the majority's
        rows into the result would cost more than computing them."""
        n = self._n
        cfg = self.config
        k = cfg.n_points
        steps: FloatArray = np.arange(k, dtype=np.float64) * cfg.step_s
        times = t_s + steps
        # Time from each track's state to the first point; point k is ahead0 + steps[k]
        # (an outer sum: no (N, K) array of POSIX times is subtracted).
        ahead0 = t_s - self._t[:n]
        rows, _, dist, tau0 = self._plan_state(self._x[:n, :, kalman.POS], self._t[:n])
        follow = dist <= self._geom_m[rows] * self.config.plan_follow_factor
        fr = rows[follow]
        is_follow = np.zeros(n, dtype=bool)
        is_follow[fr] = True
        ex = np.flatnonzero(~is_follow)
        if len(fr) * 2 > n:
            # Rows that do not follow get a placeholder plan (row 0 at its start), are
            # computed along with the others and then overwritten by extrapolation.
            plan_rows = np.where(is_follow, self._plan_row[:n], 0)
            tau_all = np.full(n, self._plans.start_t_s[0])
            tau_all[fr] = tau0[follow]
            axes, sigma = self._follow_rows(np.arange(n), plan_rows, tau_all, ahead0, steps)
            if len(ex):
                ex_axes, ex_sigma = self._extrapolate_rows(ex, ahead0, steps)
                for axis in range(3):
                    axes[axis][ex] = ex_axes[axis]
                sigma[ex] = ex_sigma
        else:
            axes, sigma = self._extrapolate_rows(np.arange(n), ahead0, steps)
            if len(fr):
                f_axes, f_sigma = self._follow_rows(
                    fr, self._plan_row[fr], tau0[follow], ahead0, steps
                )
                for axis in range(3):
                    axes[axis][fr] = f_axes[axis]
                sigma[fr] = f_sigma
        points = np.stack([*axes, np.broadcast_to(times, (n, k))], axis=2)
        return PredictedTrajectories(
            t_s=t_s, track_ids=tuple(self._ids[:n]), points=points, sigma_m=sigma
        )

    def _extrapolate_rows(
        self, ex: IntArray, ahead0: FloatArray, steps: FloatArray
    ) -> tuple[list[FloatArray], FloatArray]:
        """Rows ``ex`` extrapolated with the filter's velocity; the radius is the root of the
        trace of the propagated position covariance."""
        x = self._x[ex]
        p = self._p[ex]
        tau = np.add.outer(ahead0[ex], steps)
        axes = [
            x[:, axis, kalman.POS, None] + x[:, axis, kalman.VEL, None] * tau for axis in range(3)
        ]
        pp = p[:, :, kalman.PP].sum(axis=1)[:, None]
        pv = p[:, :, kalman.PV].sum(axis=1)[:, None]
        vv = p[:, :, kalman.VV].sum(axis=1)[:, None]
        tau2 = tau * tau
        var = pp + 2.0 * pv * tau + vv * tau2 + (float(self._q.sum()) / 4.0) * (tau2 * tau2)
        return axes, np.sqrt(var)

    def _follow_rows(
        self,
        fr: IntArray,
        plan_rows: IntArray,
        tau0: FloatArray,
        ahead0: FloatArray,
        steps: FloatArray,
    ) -> tuple[list[FloatArray], FloatArray]:
        """Rows ``fr`` following plans ``plan_rows`` from plan times ``tau0``: the plan
        positions plus the current cross-track offset decaying as exp(-(a0 + k step) / T);
        the radius grows linearly with time from the state."""
        cfg = self.config
        k = len(steps)
        a0 = ahead0[fr]
        now = self._plans.follow(plan_rows, tau0, np.zeros(len(fr)), 1.0, 1)
        axes = list(self._plans.follow(plan_rows, tau0, a0, cfg.step_s, k))
        # The decay is an outer product of two vectors (no (N, K) exp), added in place.
        decay_t = cfg.plan_offset_decay_s
        decay_k = np.exp(-steps / decay_t)
        decay_0 = np.exp(-a0 / decay_t)
        # A snapshot older than the track (a0 < 0) must not amplify the offset: those
        # few rows use exp(-max(a0 + k step, 0) / T) instead.
        young = np.flatnonzero(a0 < 0.0)
        capped = np.exp(-np.maximum(np.add.outer(a0[young], steps), 0.0) / decay_t)
        for axis in range(3):
            offset = self._x[fr, axis, kalman.POS] - now[axis][:, 0]
            value = axes[axis]
            plain = value[young]
            value += np.multiply.outer(offset * decay_0, decay_k)
            value[young] = plain + offset[young, None] * capped
        # sqrt(pp + (growth * (a0 + k step))^2), in place on one (N, K) array.
        sigma = np.add.outer(a0, steps)
        sigma *= cfg.plan_sigma_growth_mps
        sigma *= sigma
        sigma += self._p[fr, :, kalman.PP].sum(axis=1)[:, None]
        np.sqrt(sigma, out=sigma)
        return axes, sigma

    def snapshot(self, t_s: float) -> tuple[dict[TrackId, Track], PredictedTrajectories]:
        """All tracks propagated to ``t_s`` (``Track.t_s == t_s``) and their prediction from
        ``t_s``: one consistent view; the filter state itself is not changed."""
        n = self._n
        dt = t_s - self._t[:n]
        x = self._x[:n]
        pos = x[:, :, kalman.POS] + x[:, :, kalman.VEL] * dt[:, None]
        pos_var = kalman.predicted_position_var(self._p[:n], dt[:, None], self._q)[:, 0, :]
        tracks = self._make_tracks(t_s, pos, x[:, :, kalman.VEL], pos_var)
        return tracks, self.predict(t_s)

    def check_stale(self, t_s: float) -> list[TrackId]:
        """Mark tracks silent for more than ``stale_after_s`` as stale and return the newly
        stale ones (each once until a new measurement revives it). Intruders silent for more
        than ``intruder_drop_after_s`` are removed."""
        n = self._n
        age = t_s - self._t[:n]
        newly = (age > self.config.stale_after_s) & ~self._stale[:n]
        self._stale[:n] |= newly
        out = [self._ids[i] for i in np.flatnonzero(newly)]
        for tid in out:
            self._dirty.add(tid)
        self._counters["stale_raised"] += len(out)
        drop = ~self._coop[:n] & (age > self.config.intruder_drop_after_s)
        if drop.any():
            self._counters["intruders_dropped"] += int(drop.sum())
            self._compact(~drop)
        return out

    def track_operation(self, track_id: TrackId) -> Operation | None:
        """The operation a cooperative track belongs to, if still known."""
        row = self._row.get(track_id)
        op_id = self._op_ids[row] if row is not None else None
        return self._ops.get(op_id) if op_id is not None else None


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
