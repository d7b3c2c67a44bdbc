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
1. checks of each measurement (finite, in range, capture time not after receipt +
   max_future_s, measured speed <= max_speed_mps: :func:`.kernel.check_entries`), then its
   identity -> ``invalid`` / ``gate`` / ``unassociated``;
2. the batch is sorted by capture time, and split into rounds in which each track appears at
   most once; each round is one vectorised predict + update (:mod:`.kalman`). So reordering
   *within* a batch is repaired (the service drains a batch per period: that is the reorder
   window). The result is that of ingesting the measurements one by one in capture-time
   order, bit for bit (tested). Per call cost matters as much as per measurement (the
   service ingests every few milliseconds): a batch in which every track appears once is
   one round without sorting, and a round of plain updates (every measurement updates its
   track) runs in the optional C kernel when it is built (:func:`.kernel.update_rows`: the
   same arithmetic in the same order as the NumPy round, so bit for bit the same, tested);
3. against its track a measurement is ``out_of_order`` if older than the track's state time,
   a ``duplicate`` if a measurement of the same source with the same capture time was already
   used, ``gate`` if farther from the prediction than
   ``min(max_jump_m, gate_margin_m + max_speed_mps * dt)``. Rejections never touch the state.
   A stale track that rejected ``gate_reset_count`` measurements in a row restarts from the
   next valid one (a wrong first fix must not lock a track out forever); a track silent for
   more than ``stale_after_s`` restarts from its next one that passes the gate (a link drop).

Position lanes (:class:`~gcs_utm.model.PositionLane`): the MAVLink receive path hands
telemetry positions over as flat entries instead of Measurements; ``ingest(measurements,
lane, lane_sources)`` checks and converts them together (:func:`.kernel.entry_records`) and
uses each exactly as its Measurement would be used (tested against the Measurement path).
The record layout both paths produce is defined once in :mod:`.layout`.

Units: positions in the airspace's local UTM grid (east_m, north_m) and alt_amsl_m; velocities
east/north/up in m/s on the same grid (measured NED velocities are rotated by the grid
convergence at the origin); times in POSIX seconds.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.core.tracking import kalman, kernel, loiter, offsets, prediction
from gcs_utm.core.tracking.config import TrackingConfig
from gcs_utm.core.tracking.intake import Identity, Intake
from gcs_utm.core.tracking.layout import (
    REC_ALT,
    REC_EAST,
    REC_HAS_VEL,
    REC_LAT,
    REC_LON,
    REC_R,
    REC_RV,
    REC_SRC,
    REC_T,
    REC_VE,
    REC_VU,
)
from gcs_utm.core.tracking.plans import PlanTable
from gcs_utm.core.tracking.tracks import TrackColumns, TrackMap
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    Icao24,
    LaneSource,
    Measurement,
    Operation,
    OperationId,
    PredictedTrajectories,
    Track,
    TrackId,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

Counts = tuple[int, int, int, int, int, int]
"""A round's (accepted, reinitialised, restarted, out_of_order, duplicate, gate)."""

PREDICT_BLOCK_ROWS = 2048
"""Rows predicted together (:meth:`Tracker.predict`): a block's (rows, 61) temporaries are
1 MB each, so the few a block needs fit in a core's L2 cache (2 MB on the project's machine)."""


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
    reinitialised: int = 0  # restarted after gate_reset_count gate rejections
    restarted: int = 0  # restarted after a gap longer than stale_after_s
    new_tracks: tuple[TrackId, ...] = ()
    new_intruders: tuple[TrackId, ...] = ()

    @property
    def rejected(self) -> int:
        return self.out_of_order + self.duplicate + self.invalid + self.gate + self.unassociated


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
        self._q_row = (float(self._q[0]), float(self._q[1]), float(self._q[2]))  # the C kernel's
        # Grid convergence: true north expressed on the UTM grid at the origin, used to turn
        # measured NED velocities into grid velocities.
        d_east, d_north = frame.point_to_local(frame.origin_lat_deg + 1e-3, frame.origin_lon_deg)
        norm = math.hypot(d_east, d_north)
        self._north_dir = (d_east / norm, d_north / norm)
        self._intake = Intake(config, self._north_dir)
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
        self._loiter_m = np.zeros(0)  # loiter radius of a fixed wing's operation, else 0
        # Closest plan segment found by the last locate (-1: none): the windowed search
        # starts there (see PlanTable.locate). A cache only: never changes a result.
        self._seg_hint = np.zeros(0, dtype=np.intp)
        self._alt_offsets = offsets.AltitudeOffsets(config.plan_offset_persist_s)  # rows: _x's
        self._ids: list[TrackId] = []
        self._op_ids: list[OperationId | None] = []
        self._icao: list[Icao24 | None] = []
        self._row: dict[TrackId, int] = {}
        self._dirty: set[TrackId] = set()
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
                "restarted",
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
        belongs to an operation are removed, so one aircraft never shows up twice, and so are
        the tracks of operations no longer given (the airspace forgot them)."""
        ops = list(operations)
        claimed = self._intake.set_operations(ops)
        self._plans = PlanTable([op.plan for op in ops], self.frame)
        self._plan_of_op = {op.id: j for j, op in enumerate(ops)}
        self._seg_hint[:] = -1
        for row in range(self._n):
            op_id = self._op_ids[row]
            j = self._plan_of_op.get(op_id, -1) if op_id is not None else -1
            self._plan_row[row] = j
            self._geom_m[row] = ops[j].flight_geometry_m if j >= 0 else 0.0
            self._loiter_m[row] = loiter.loiter_radius_m(ops[j]) if j >= 0 else 0.0
        n, known = self._n, self._plan_of_op
        gone = np.array([o is not None and o not in known for o in self._op_ids[:n]], bool)
        taken = np.array([tid.partition("@")[0] in claimed for tid in self._ids[:n]], bool)
        if gone.any() or taken.any():
            self._counters["intruders_dropped"] += int(taken.sum())
            self._compact(~(gone | taken))

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
        self._loiter_m = grown(self._loiter_m)
        self._seg_hint = grown(self._seg_hint, -1)
        self._alt_offsets.grow(cap, self._n)
        self._cap = cap

    def _row_for(self, ident: Identity, new: tuple[list[TrackId], list[TrackId]]) -> int:
        """The row of ``ident``'s track, made (and listed in ``new``: tracks, intruders) if
        it has none."""
        row = self._row.get(ident.track_id)
        if row is None:
            row = self._new_row(ident)
            new[0 if ident.cooperative else 1].append(ident.track_id)
        return row

    def _new_row(self, ident: Identity) -> int:
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
        op = self._intake.ops.get(ident.operation_id) if ident.operation_id is not None else None
        self._plan_row[row] = self._plan_of_op[op.id] if op is not None else -1
        self._geom_m[row] = op.flight_geometry_m if op is not None else 0.0
        self._loiter_m[row] = loiter.loiter_radius_m(op) if op is not None else 0.0
        self._seg_hint[row] = -1
        self._alt_offsets.reset(np.array([row], dtype=np.intp))
        return row

    def _compact(self, keep: npt.NDArray[np.bool_]) -> None:
        idx = np.flatnonzero(keep)
        for name in (
            "_x", "_p", "_t", "_src_t", "_updates", "_gate_fails", "_coop", "_stale",
            "_plan_row", "_geom_m", "_loiter_m", "_seg_hint",
        ):  # fmt: skip
            arr = getattr(self, name)
            arr[: len(idx)] = arr[idx]
        self._alt_offsets.compact(idx)
        removed = [self._ids[i] for i in np.flatnonzero(~keep)]
        self._ids = [self._ids[i] for i in idx]
        self._op_ids = [self._op_ids[i] for i in idx]
        self._icao = [self._icao[i] for i in idx]
        self._n = len(idx)
        self._row = {tid: i for i, tid in enumerate(self._ids)}
        self._intake.forget_rows()
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
        measurement``) would be, without building it. In a batch they come after
        ``measurements`` (which decides only the order of equal capture times of one track)."""
        new_tracks: list[TrackId] = []
        new_intruders: list[TrackId] = []
        n_before = self._n
        c = {"invalid": 0, "gate": 0, "unassociated": 0, "out_of_order": 0, "duplicate": 0}
        parts: list[tuple[IntArray, FloatArray]] = []
        intake = self._intake
        row_for = functools.partial(self._row_for, new=(new_tracks, new_intruders))
        if measurements:
            parts.append(intake.measurement_records(measurements, c, row_for))
        if lane:
            parts.append(intake.lane_records(lane, lane_sources, c, row_for))
        accepted = reinit = restarted = 0
        if len(parts) == 2:
            rw = np.concatenate((parts[0][0], parts[1][0]))
            a = np.concatenate((parts[0][1], parts[1][1]), axis=1)
        elif parts:
            rw, a = parts[0]
        if parts and len(rw):
            n = len(rw)
            n_vel = int(np.count_nonzero(a[REC_HAS_VEL]))
            with_vel = True if n_vel == n else False if n_vel == 0 else None
            accepted, reinit, restarted, ooo, dup, gated = self._apply(rw, a, n_before, with_vel)
            c["gate"] += gated
            c["out_of_order"] = ooo
            c["duplicate"] = dup
        intake.trim(self._n)
        stats = IngestStats(
            accepted=accepted,
            reinitialised=reinit,
            restarted=restarted,
            new_tracks=tuple(new_tracks),
            new_intruders=tuple(new_intruders),
            **c,
        )
        counters = self._counters
        for key_, value in c.items():
            counters[key_] += value
        counters["accepted"] += accepted
        counters["reinitialised"] += reinit
        counters["restarted"] += restarted
        counters["tracks_created"] += len(new_tracks)
        counters["intruders_created"] += len(new_intruders)
        return stats

    def _apply(self, rw: IntArray, a: FloatArray, n_before: int, with_vel: bool | None) -> Counts:
        """Rounds of one vectorised predict + update of rows ``rw`` with their records ``a``
        (NCOL, N; lon/lat become east/north here). Returns :data:`Counts`. ``with_vel``: every
        record has a velocity (True), none has (False), or mixed (None)."""
        n = len(rw)
        self.frame.to_local_in_place(a[REC_LON], a[REC_LAT])
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
        order = np.argsort(a[REC_T], kind="stable")
        rs = rw[order]
        by_row = np.argsort(rs, kind="stable")
        grouped = rs[by_row]
        pos = np.arange(n)
        first = np.ones(n, dtype=bool)
        first[1:] = grouped[1:] != grouped[:-1]
        rank_grouped = pos - np.maximum.accumulate(np.where(first, pos, 0))
        rank = np.empty(n, dtype=np.intp)
        rank[by_row] = rank_grouped
        totals = [0, 0, 0, 0, 0, 0]
        for k in range(int(rank.max()) + 1):
            sel = order[rank == k]
            r_k = rw[sel]
            # Rows created by this batch start uninitialised: their earliest measurement
            # is rank 0.
            init = r_k >= n_before if new_rows and k == 0 else None
            res = self._round(r_k, a[:, sel], init, with_vel)
            totals = [x + y for x, y in zip(totals, res, strict=True)]
        accepted, reinit, restarted, ooo, dup, gate = totals
        return accepted, reinit, restarted, ooo, dup, gate

    def _round(
        self,
        rw: IntArray,
        a: FloatArray,
        init: npt.NDArray[np.bool_] | None,
        with_vel: bool | None,
    ) -> Counts:
        """One round: rows ``rw`` (each at most once) with their records ``a`` (NCOL, M);
        ``init``: rows that start from their measurement (None: none)."""
        cfg = self.config
        t = a[REC_T]
        src = a[REC_SRC].astype(np.intp)
        # The rows' states as planes (kalman.step): (2, 3, M) and (3, 3, M).
        x = self._x.transpose(2, 1, 0)[:, :, rw]
        dt = t - self._t[rw]
        x[kalman.POS] += x[kalman.VEL] * dt  # predicted (x is a copy: written back if updated)
        d = a[REC_EAST : REC_ALT + 1] - x[kalman.POS]
        d *= d
        miss = np.sqrt(d[0] + d[1] + d[2])
        allowed = np.minimum(cfg.max_jump_m, cfg.gate_margin_m + cfg.max_speed_mps * dt)
        ooo = dt < 0.0
        dup = t == self._src_t[rw, src]
        gate = miss > allowed
        # Silent for longer than stale_after_s (a link drop): the state is too old to filter
        # (its velocity and the position-velocity correlation grown over the gap would pull
        # the position off the measurement), so the track restarts from it.
        lapsed = dt > cfg.stale_after_s
        m = len(rw)
        if init is None and not (ooo | dup | gate | lapsed).any():
            # The common case: every measurement updates its track.
            self._filter(rw, x, a, dt, with_vel)
            self._accept(rw, t, src)
            return m, 0, 0, 0, 0, 0
        if init is None:
            init = np.zeros(m, dtype=bool)
        ooo &= ~init
        dup &= ~init & ~ooo
        gate &= ~(init | ooo | dup)
        # A stale track that keeps rejecting restarts from this measurement.
        restart = gate & lapsed & (self._gate_fails[rw] >= cfg.gate_reset_count)
        gate &= ~restart
        # A track back after a gap restarts from its first measurement that passes the gate
        # (identity, plan association and history kept: same row).
        resumed = lapsed & ~(init | gate | restart)
        init |= restart | resumed
        self._gate_fails[rw[gate]] += 1
        upd = ~(init | ooo | dup | gate)
        ok = init | upd
        if init.any():  # new and restarted tracks
            ri = rw[init]
            ai = a[:, init]
            xi, pi = kalman.start(
                ai[REC_EAST : REC_ALT + 1],
                ai[REC_R : REC_R + 3],
                ai[REC_VE : REC_VU + 1],
                ai[REC_RV : REC_RV + 3],
                ai[REC_HAS_VEL] != 0.0,
                cfg.initial_vel_sigma_mps**2,
            )
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
            int(resumed.sum()),
            int(ooo.sum()),
            int(dup.sum()),
            int(gate.sum()),
        )

    def _round_plain(self, rw: IntArray, a: FloatArray) -> Counts | None:
        """The round of existing rows ``rw`` (each once) when every measurement updates its
        track, in the C kernel (:func:`.kernel.update_rows`). None: nothing changed (no C
        kernel, or not that case), :meth:`_round` decides."""
        cfg = self.config
        if not kernel.update_rows(
            rw,
            a,
            (self._x, self._p, self._t, self._src_t),
            (self._updates, self._gate_fails, self._stale),
            self._q_row,
            cfg.max_jump_m,
            cfg.gate_margin_m,
            cfg.max_speed_mps,
            cfg.stale_after_s,
        ):
            return None
        ids = self._ids
        self._dirty.update([ids[i] for i in rw.tolist()])
        return len(rw), 0, 0, 0, 0, 0

    def _filter(
        self, rw: IntArray, x: FloatArray, a: FloatArray, dt: FloatArray, with_vel: bool | None
    ) -> None:
        """Predict rows ``rw`` (their states ``x`` as planes, gathered, positions already
        predicted) by ``dt`` and update them with their records ``a``; written back."""
        if with_vel is None:
            hv = a[REC_HAS_VEL] != 0.0
            for part, wv in ((~hv, False), (hv, True)):
                if part.any():
                    self._filter(rw[part], x[:, :, part], a[:, part], dt[part], wv)
            return
        p = self._p.transpose(2, 1, 0)[:, :, rw]
        z = a[REC_EAST : REC_ALT + 1]
        r = a[REC_R : REC_R + 3]
        if with_vel:
            zv = a[REC_VE : REC_VU + 1]
            rv = a[REC_RV : REC_RV + 3]
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

    def last_accepted_t_s(self, track_id: TrackId) -> float | None:
        """When the track last accepted a measurement (capture time); None: no such track."""
        row = self._row.get(track_id)
        return None if row is None else float(self._t[row])

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

    def _columns(
        self,
        t_s: float | None,
        pos: FloatArray,
        vel: FloatArray,
        pos_var: FloatArray,
        sel: IntArray | None = None,
    ) -> TrackColumns:
        """The columns of all rows (or rows ``sel``) at ``t_s`` (None: each at its own state
        time) with positions ``pos`` (N, 3), velocities ``vel`` (N, 3) and position variances
        ``pos_var`` (N, 3) of those rows; the current waypoint of each row with a plan.
        Every column is a copy (the tracker's arrays change with the next ingest)."""
        if sel is None:
            n = self._n
            rows_t = np.full(n, t_s) if t_s is not None else self._t[:n].copy()
            ids = tuple(self._ids[:n])
            op_ids = tuple(self._op_ids[:n])
            icao = tuple(self._icao[:n])
            coop, stale = self._coop[:n].copy(), self._stale[:n].copy()
            updates, measured = self._updates[:n].copy(), self._t[:n].copy()
        else:
            n = len(sel)
            rows_t = np.full(n, t_s) if t_s is not None else self._t[sel]
            at = sel.tolist()
            ids = tuple(self._ids[i] for i in at)
            op_ids = tuple(self._op_ids[i] for i in at)
            icao = tuple(self._icao[i] for i in at)
            coop, stale, updates = self._coop[sel], self._stale[sel], self._updates[sel]
            measured = self._t[sel]
        plan_rows, wp, _, _ = self._plan_state(pos, rows_t, sel)
        next_wp = np.full(n, -1, np.intp)
        next_wp[plan_rows] = wp
        return TrackColumns(
            frame=self.frame,
            ids=ids,
            t_s=rows_t,
            pos=np.array(pos, np.float64),
            vel=np.array(vel, np.float64),
            position_sigma_m=np.sqrt(pos_var.sum(axis=1)),
            cooperative=coop,
            stale=stale,
            updates=updates,
            operation_ids=op_ids,
            icao24=icao,
            next_waypoint=next_wp,
            measured_t_s=measured,
        )

    def tracks(self) -> dict[TrackId, Track]:
        """Every track at its own state time (the last accepted measurement)."""
        n = self._n
        return TrackMap(
            self._columns(
                None,
                self._x[:n, :, kalman.POS],
                self._x[:n, :, kalman.VEL],
                self._p[:n, :, kalman.PP],
            )
        ).materialise()

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
        return self._columns(
            None,
            self._x[sel, :, kalman.POS],
            self._x[sel, :, kalman.VEL],
            self._p[sel, :, kalman.PP],
            sel,
        ).build()

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
        track's state time, so a stale track's radius keeps growing. A fixed wing whose plan
        has ended and that circles its last waypoint is predicted on that loiter circle
        (:mod:`.loiter`), not on its tangent.

        Layout: the rows are predicted in blocks of ``PREDICT_BLOCK_ROWS`` (each row's
        figures do not depend on the others), each block as (K, ) arrays per axis written
        into the one (N, K, 4) result: a block's temporaries stay in the CPU cache, so the
        cost per row does not rise once N's (N, K) planes outgrow it. In a block, whichever
        kind of row is the majority is computed for all its rows at once and the minority is
        written over it: scattering the majority's rows would cost more than computing
        them."""
        n = self._n
        cfg = self.config
        k = cfg.n_points
        steps: FloatArray = np.arange(k, dtype=np.float64) * cfg.step_s
        # Time from each track's state to the first point; point k is ahead0 + steps[k]
        # (an outer sum: no (N, K) array of POSIX times is subtracted).
        ahead0 = t_s - self._t[:n]
        rows, _, dist, tau0 = self._plan_state(self._x[:n, :, kalman.POS], self._t[:n])
        follow = dist <= self._geom_m[rows] * self.config.plan_follow_factor
        is_follow = np.zeros(n, dtype=bool)
        is_follow[rows[follow]] = True
        tau = np.zeros(n)  # plan time of each following row's state
        tau[rows[follow]] = tau0[follow]
        points = np.empty((n, k, 4))
        points[:, :, 3] = t_s + steps
        sigma = np.empty((n, k))
        for lo in range(0, n, PREDICT_BLOCK_ROWS):
            block = slice(lo, min(lo + PREDICT_BLOCK_ROWS, n))
            axes, block_sigma = self._predict_block(block, is_follow[block], tau, ahead0, steps)
            sigma[block] = block_sigma
            for axis in range(3):
                points[block, :, axis] = axes[axis]
        self._keep_persistent_alt(rows[follow], tau0[follow], points[:, :, 2], ahead0, steps)
        # Loitering fixed wings onto their circle (few rows, written through the result).
        loiter.overlay(
            [points[:, :, axis] for axis in range(3)],
            plans=self._plans,
            plan_row=self._plan_row[:n],
            loiter_m=self._loiter_m[:n],
            t_state_s=self._t[:n],
            x=self._x[:n],
            ahead0_s=ahead0,
            steps_s=steps,
            decay_s=cfg.plan_offset_decay_s,
        )
        return PredictedTrajectories(
            t_s=t_s, track_ids=tuple(self._ids[:n]), points=points, sigma_m=sigma
        )

    def _predict_block(
        self,
        block: slice,
        is_follow: npt.NDArray[np.bool_],
        tau: FloatArray,
        ahead0: FloatArray,
        steps: FloatArray,
    ) -> tuple[list[FloatArray], FloatArray]:
        """Axes and radii of rows ``block`` (see :meth:`predict`); ``is_follow`` is of the
        block's rows, ``tau`` (plan time) and ``ahead0`` of all rows."""
        cfg = self.config
        x, p, a0 = self._x[block], self._p[block], ahead0[block]
        plan_row, tau = self._plan_row[block], tau[block]
        fr = np.flatnonzero(is_follow)
        ex = np.flatnonzero(~is_follow)
        if len(fr) * 2 > len(is_follow):
            # Rows that do not follow get a placeholder plan (row 0 at its start), are
            # computed along with the others and then overwritten by extrapolation.
            plan_rows = np.where(is_follow, plan_row, 0)
            tau_all = np.where(is_follow, tau, self._plans.start_t_s[0])
            axes, sigma = prediction.follow(self._plans, cfg, x, p, plan_rows, tau_all, a0, steps)
            if len(ex):
                ex_axes, ex_sigma = prediction.extrapolate(x[ex], p[ex], self._q, a0[ex], steps)
                for axis in range(3):
                    axes[axis][ex] = ex_axes[axis]
                sigma[ex] = ex_sigma
        else:
            axes, sigma = prediction.extrapolate(x, p, self._q, a0, steps)
            if len(fr):
                f_axes, f_sigma = prediction.follow(
                    self._plans, cfg, x[fr], p[fr], plan_row[fr], tau[fr], a0[fr], steps
                )
                for axis in range(3):
                    axes[axis][fr] = f_axes[axis]
                sigma[fr] = f_sigma
        return axes, sigma

    def _keep_persistent_alt(
        self, fr: IntArray, tau0: FloatArray, alt: FloatArray, ahead0: FloatArray, steps: FloatArray
    ) -> None:
        """Rows ``fr`` follow their plans from plan times ``tau0``: sample their altitude
        offsets from the plan and keep the persistent part in ``alt`` (:mod:`.offsets`)."""
        if len(fr):
            now = self._plans.follow(self._plan_row[fr], tau0, np.zeros(len(fr)), 1.0, 1)
            self._alt_offsets.observe(fr, self._t[fr], self._x[fr, 2, kalman.POS] - now[2][:, 0])
            bias = self._alt_offsets.persistent(fr)
            decay_s = self.config.plan_offset_decay_s
            offsets.keep_persistent(alt, fr, bias, ahead0, steps, decay_s=decay_s)

    def tracks_at(self, t_s: float) -> TrackMap:
        """All tracks propagated to ``t_s`` (``Track.t_s == t_s``; the filter state itself is
        not changed), as columns (``TrackMap.columns``, what Monitoring reads); a ``Track``
        object is built only for a row that is read."""
        n = self._n
        dt = t_s - self._t[:n]
        x = self._x[:n]
        pos = x[:, :, kalman.POS] + x[:, :, kalman.VEL] * dt[:, None]
        pos_var = kalman.predicted_position_var(self._p[:n], dt[:, None], self._q)[:, 0, :]
        return TrackMap(self._columns(t_s, pos, x[:, :, kalman.VEL], pos_var))

    def snapshot(self, t_s: float) -> tuple[TrackMap, PredictedTrajectories]:
        """:meth:`tracks_at` ``t_s`` and their prediction from ``t_s``: one consistent view."""
        return self.tracks_at(t_s), self.predict(t_s)

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
        return self._intake.ops.get(op_id) if op_id is not None else None
