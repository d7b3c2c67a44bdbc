"""The Monitoring cycle (paper §4.4, Figures 6-8) and the threat life cycle.

``Monitor.cycle(snapshot)`` reads one consistent :class:`AirspaceSnapshot` and returns the
threats OPENED, UPDATED or CLOSED in this cycle; ``active()`` lists the open ones.

Conditions, each keyed so a persisting one stays ONE threat with a stable id:
- conformance per operation (UAS_IN_CV / UAS_OUT_OV; the kind follows the worst state),
  gated during take-off and landing near home (config); a fixed wing's plan re-timed to the
  progress its envelope allows (along_track.py);
- geofence per (operation, fence) (GEOFENCE_CONFLICT with the predicted entry time, or
  GEOFENCE_INTRUSION when inside now; the kind follows);
- loss of separation per pair of operations (first loss, closest approach);
- INTRUDER per (operation, non-cooperative track) with the intruder minima.

Hysteresis: a condition opens after ``open_cycles`` consecutive fresh cycles; an open threat
closes only after ``close_cycles`` consecutive fresh cycles in which it is clear by a margin.
Stale or missing data (stale track, row absent from the prediction, no prediction) changes
nothing: silence is not evidence. An operation that is LANDED/ENDED or gone from the snapshot
closes its threats (the plan is over). A vehicle on the ground by its own messages
(``AirspaceSnapshot.grounded``: disarmed, or armed and landed) is not traffic: its track is
no evidence of any condition (its filed plan, whose start time may have passed, is not
predicted as if it flew) and its threats close at once; once it takes off it is checked
like any other. UPDATED is emitted when the kind, the predicted event
time (by more than one period) or the closest distance (by more than the separation margin)
changes; ``active()`` always holds the latest figures.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass, field, replace
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from gcs_utm.core.monitoring.along_track import plan_time_window, progress_ratios
from gcs_utm.core.monitoring.checks import (
    PlanTable,
    check_geofences,
    pack_plans,
    plan_distance,
)
from gcs_utm.core.monitoring.closing import clear_reason, closed_message, over_reason
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.end_circle import EndRings, end_circle_hits
from gcs_utm.core.monitoring.fences import LocalFence, localise
from gcs_utm.core.monitoring.fixed_wing_band import band_distance, band_parameters
from gcs_utm.core.monitoring.geometry import FloatArray, Windows, window_extents
from gcs_utm.core.monitoring.separation import detect_los, detect_pairs_between, window_steps
from gcs_utm.core.monitoring.strategic import plan_local
from gcs_utm.core.tracking.tracks import TrackColumns, track_columns
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Geofence,
    GeofenceId,
    Operation,
    OperationId,
    PredictedTrajectories,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
    TrackId,
)

Key = tuple[str, ...]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]
# flight geometry m, operational volume m, plan start s, plan end s, slowest and fastest
# progress along the plan (along_track.py); per operation
_Limits = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]
_Band = tuple[FloatArray, FloatArray, FloatArray]


@dataclass(slots=True)
class _Observation:
    kind: ThreatKind
    uas_ids: tuple[OperationId, ...]
    event_t_s: float | None = None
    geofence_id: GeofenceId | None = None
    intruder_id: TrackId | None = None
    closest_t_s: float | None = None
    closest_m: float | None = None
    horizontal_m: float | None = None
    vertical_m: float | None = None
    message: str = ""


@dataclass(slots=True)
class _State:
    present: int = 0
    clear: int = 0
    threat: Threat | None = None
    # The latest figures (observation, prediction, time) when they changed nothing material:
    # the Threat object is built from them only when it is read (active(), closing).
    pending: tuple[_Observation, PredictedTrajectories | None, float] | None = None


@dataclass(slots=True)
class _Evaluation:
    seen: dict[Key, _Observation] = field(default_factory=dict)
    # Keys whose condition is not met but not clear by the margin either (no close count).
    marginal: set[Key] = field(default_factory=set)
    # Operations with a fresh track (conformance evidence) this cycle, and operations and
    # intruder track ids with a fresh prediction row (predictive evidence): as collected,
    # turned into sets only if a condition not seen this cycle asks (fresh_sets()).
    fresh_parts: list[Sequence[str]] = field(default_factory=list)
    pred_parts: list[Sequence[str]] = field(default_factory=list)
    _sets: tuple[set[str], set[str]] | None = None

    def fresh_sets(self) -> tuple[set[str], set[str]]:
        """(operations with conformance evidence, ids with predictive evidence)."""
        if self._sets is None:
            fresh: set[str] = set()
            pred: set[str] = set()
            for part in self.fresh_parts:
                fresh.update(part)
            for part in self.pred_parts:
                pred.update(part)
            self._sets = (fresh, pred)
        return self._sets


class Monitor:
    """Stateful threat detector over successive snapshots (pure: no clock, no I/O).

    Threat ids are ``<id_prefix>T<n>-<KIND>`` with ``n`` counted from 1 in each Monitor; the
    service passes its store life's prefix (``E<epoch>-``) so ids stay unique across
    restarts."""

    def __init__(self, frame: LocalFrame, config: MonitoringConfig, *, id_prefix: str = "") -> None:
        self.frame = frame
        self.config = config
        self.id_prefix = id_prefix
        self._states: dict[Key, _State] = {}
        self._seq = 0
        self._fence_cache: dict[GeofenceId, tuple[Geofence, LocalFence]] = {}
        self._plan_cache: dict[OperationId, tuple[FlightPlan, FloatArray]] = {}
        self._end_rings = EndRings()  # fixed wings' end circles, by plan
        # Operations (frozen objects) of the last conformance table, the table, the anchors.
        self._conf_cache: tuple[list[Operation], PlanTable, FloatArray, _Limits, _Band] | None = (
            None
        )

    # ---- public -------------------------------------------------------------------------
    def active(self) -> list[Threat]:
        return [self._current(s) for s in self._states.values() if s.threat is not None]

    def open_count(self) -> int:
        """How many threats are open (without building them: see :meth:`active`)."""
        return sum(1 for s in self._states.values() if s.threat is not None)

    def _current(self, st: _State) -> Threat:
        """The open threat of ``st`` with its latest figures."""
        assert st.threat is not None
        if st.pending is not None:
            obs, pred, t = st.pending
            old = st.threat
            st.threat = self._make(
                old.id, obs, old.detected_at_s, pred, updated=t, status=old.status
            )
            st.pending = None
        return st.threat

    def cycle(self, snapshot: AirspaceSnapshot) -> list[Threat]:
        ev = self._evaluate(snapshot)
        _prune(self._plan_cache, snapshot.operations)
        self._end_rings.prune(snapshot.operations)
        _prune(self._fence_cache, {g.id for g in snapshot.geofences})
        return self._update(snapshot, ev)

    # ---- evaluation ---------------------------------------------------------------------
    def _fence(self, g: Geofence) -> LocalFence:
        hit = self._fence_cache.get(g.id)
        if hit is None or hit[0] is not g:
            hit = (g, localise(g, self.frame))
            self._fence_cache[g.id] = hit
        return hit[1]

    def _plan(self, op: Operation) -> FloatArray:
        op_id = op.id
        hit = self._plan_cache.get(op_id)
        # Keyed on the plan object (frozen): a replaced plan is re-projected even if a caller
        # reuses a version number.
        if hit is None or hit[0] is not op.plan:
            hit = (op.plan, plan_local(op.plan, self.frame))
            self._plan_cache[op_id] = hit
        return hit[1]

    def _evaluate(self, snapshot: AirspaceSnapshot) -> _Evaluation:
        ev = _Evaluation()
        ops = snapshot.operations
        cols = track_columns(snapshot.tracks, self.frame)
        op_ids = cols.operation_ids
        # Rows of cooperative tracks whose operation is in the snapshot (evidence about it),
        # less the vehicles on the ground: not traffic, whatever their filed plan says.
        ground = snapshot.grounded
        known = np.fromiter((o in ops and o not in ground for o in op_ids), bool, len(op_ids))
        usable = known & cols.cooperative
        # Conformance only from a track measured recently: a silent track's dead-reckoned
        # position is a prediction, no evidence (past the staleness limit the link-loss
        # threat is raised instead). Prediction keeps the silent track as traffic.
        measured = (cols.t_s - cols.measured_t_s) <= self.config.conformance_max_track_age_s
        fresh = np.flatnonzero(usable & ~cols.stale & measured)
        self._conformance(snapshot, cols, fresh, ev)
        pred = snapshot.prediction
        if pred is None or len(pred.track_ids) == 0:
            return ev  # predictive conditions have no evidence this cycle
        self._predictive(snapshot, pred, cols, usable, ev)
        return ev

    def _prediction_rows(
        self, pred: PredictedTrajectories, cols: TrackColumns, usable: BoolArray
    ) -> tuple[IntArray, IntArray, IntArray]:
        """(prediction rows of fresh cooperative tracks with an operation, prediction rows of
        fresh intruders, the column row of each prediction row); a row without a fresh
        track is neither."""
        if pred.track_ids == cols.ids:
            col = np.arange(len(cols.ids), dtype=np.intp)  # the tracker's own snapshot
        else:
            where = {tid: i for i, tid in enumerate(cols.ids)}
            col = np.fromiter(
                (where.get(t, -1) for t in pred.track_ids), np.intp, len(pred.track_ids)
            )
        if not len(cols.ids):
            none = np.zeros(0, np.intp)
            return none, none, col
        c = np.where(col >= 0, col, 0)
        ok = (col >= 0) & ~cols.stale[c]
        return np.flatnonzero(ok & usable[c]), np.flatnonzero(ok & ~cols.cooperative[c]), col

    def _predictive(
        self,
        snapshot: AirspaceSnapshot,
        pred: PredictedTrajectories,
        cols: TrackColumns,
        usable: BoolArray,
        ev: _Evaluation,
    ) -> None:
        """Geofences, loss of separation and intruders on the prediction."""
        cfg = self.config
        ops = snapshot.operations
        rows_coop, rows_intr, col = self._prediction_rows(pred, cols, usable)
        if snapshot.grounded_tracks:  # an unfiled vehicle on the ground is no intruder
            ground = snapshot.grounded_tracks
            keep = [pred.track_ids[i] not in ground for i in rows_intr.tolist()]
            rows_intr = rows_intr[np.array(keep, dtype=bool)]
        # The operation of each cooperative prediction row, by position in rows_coop.
        op_of: list[OperationId] = [cols.operation_ids[i] for i in col[rows_coop].tolist()]
        ev.pred_parts.append(op_of)
        ev.pred_parts.append([pred.track_ids[i] for i in rows_intr.tolist()])
        if len(rows_coop) == len(pred.track_ids):
            pts = pred.points  # every row: no copy
        else:
            pts = pred.points[rows_coop] if len(rows_coop) else np.empty((0, 1, 4))
        ov = np.fromiter((ops[o].operational_volume_m for o in op_of), np.float64, len(op_of))
        # Window bounds shared by the geofence prefilter and the separation grid.
        windows = (
            window_extents(pts, window_steps(pts, cfg)) if len(pts) and pts.shape[1] >= 2 else None
        )
        self._geofences(snapshot, pts, windows, op_of, ev)
        # Loss of separation (grid or all-pairs by size), and the margin set for closing.
        if len(rows_coop) >= 2:
            for x in detect_los(pts, ov, cfg, windows):
                a, b = sorted((op_of[x.a], op_of[x.b]))
                ev.seen[("LOS", a, b)] = _Observation(
                    kind=ThreatKind.LOSS_OF_SEPARATION,
                    uas_ids=(OperationId(a), OperationId(b)),
                    event_t_s=x.first_loss_t_s,
                    closest_t_s=x.closest_t_s,
                    closest_m=x.min_distance_m,
                    horizontal_m=x.min_horizontal_m,
                    vertical_m=x.min_vertical_m,
                )
            self._separation_margin(pts, ov, op_of, ev)
        # Intruders: every cooperative row against every non-cooperative row.
        if len(rows_coop) and len(rows_intr):
            self._intruders(pts, pred, rows_intr, op_of, ev)

    def _geofences(
        self,
        snapshot: AirspaceSnapshot,
        pts: FloatArray,
        windows: Windows | None,
        op_of: list[OperationId],
        ev: _Evaluation,
    ) -> None:
        """Geofences (4D, points and segments) of the cooperative prediction rows."""
        fences = [self._fence(g) for g in snapshot.geofences]
        exempt = {g.id: g.exempt for g in snapshot.geofences if g.exempt}
        for h in check_geofences(pts, fences, windows):
            op_id = op_of[h.row]
            if op_id in exempt.get(h.geofence_id, ()):
                continue
            kind = ThreatKind.GEOFENCE_INTRUSION if h.inside_now else ThreatKind.GEOFENCE_CONFLICT
            ev.seen[("GEO", op_id, h.geofence_id)] = _Observation(
                kind=kind, uas_ids=(op_id,), event_t_s=h.entry_t_s, geofence_id=h.geofence_id
            )
        # A fixed wing's circle after its plan, while the plan still runs (end_circle.py).
        t_s, by_id = snapshot.t_s, snapshot.operations
        rows = [
            r
            for r, o in enumerate(op_of)
            if o in by_id and t_s < by_id[o].plan.end_t_s <= pts[r, -1, 3]
        ]
        ops = [by_id[op_of[r]] for r in rows]
        plans = [self._plan(o) for o in ops]
        for i, f, t in end_circle_hits(
            ops=ops,
            plans=plans,
            predicted=pts[rows],
            fences=fences,
            t_s=t_s,
            rings=self._end_rings,
        ):
            key = ("GEO", ops[i].id, f.id)
            if key not in ev.seen and ops[i].id not in exempt.get(f.id, ()):
                ev.seen[key] = _Observation(
                    kind=ThreatKind.GEOFENCE_CONFLICT,
                    uas_ids=(ops[i].id,),
                    event_t_s=t,
                    geofence_id=f.id,
                )

    def _intruders(
        self,
        pts: FloatArray,
        pred: PredictedTrajectories,
        rows_intr: IntArray,
        op_of: list[OperationId],
        ev: _Evaluation,
    ) -> None:
        cfg = self.config
        ipts = pred.points[rows_intr]
        for i, j, st in detect_pairs_between(
            pts,
            ipts,
            cfg.intruder_horizontal_m,
            cfg.intruder_vertical_m,
            spherical=False,
        ):
            op_id = op_of[i]
            tid = pred.track_ids[int(rows_intr[j])]
            ev.seen[("INTR", op_id, str(tid))] = _Observation(
                kind=ThreatKind.INTRUDER,
                uas_ids=(op_id,),
                intruder_id=tid,
                event_t_s=float(st[0]),
                closest_t_s=float(st[1]),
                closest_m=float(st[2]),
                horizontal_m=float(st[3]),
                vertical_m=float(st[4]),
            )

    def _separation_margin(
        self,
        pts: FloatArray,
        ov: FloatArray,
        op_of: list[OperationId],
        ev: _Evaluation,
    ) -> None:
        """Open separation threats not seen this cycle: still within minima + margin?"""
        keys = [
            key
            for key, st in self._states.items()
            if key[0] == "LOS" and st.threat is not None and key not in ev.seen
        ]
        if not keys:
            return
        idx = {op: k for k, op in enumerate(op_of)}
        m = self.config.separation_close_margin_m
        for key in keys:
            ka = idx.get(OperationId(key[1]))
            kb = idx.get(OperationId(key[2]))
            if ka is None or kb is None:
                continue
            mh, mv = self.config.effective_minima(float(ov[ka]), float(ov[kb]))
            if detect_pairs_between(
                pts[ka : ka + 1],
                pts[kb : kb + 1],
                mh + m,
                mv + m,
                spherical=self.config.spherical,
            ):
                ev.marginal.add(key)

    def _conformance(
        self, snapshot: AirspaceSnapshot, cols: TrackColumns, rows: IntArray, ev: _Evaluation
    ) -> None:
        cfg = self.config
        if not len(rows):
            return
        fresh_ids = [cols.operation_ids[i] for i in rows.tolist()]
        ev.fresh_parts.append(fresh_ids)
        ops = [snapshot.operations[o] for o in fresh_ids]
        table, anchors, (fg, ovol, start, end, slow, fast), band = self._conformance_table(ops)
        pos = cols.pos[rows]  # m
        ts = cols.t_s[rows]  # s
        # a fixed wing flying its own cruise is re-timed along its track (along_track.py)
        window = plan_time_window(ts, start, slow, fast, cfg.conformance_time_tolerance_s)
        dist = plan_distance(table, pos, ts, cfg.conformance_time_tolerance_s, window)  # m
        # ...and flies its turns on its radius and its climbs first (fixed_wing_band.py)
        dist = np.minimum(dist, band_distance(table, pos, window, band))
        gated = np.zeros(len(ops), bool)
        if cfg.gate_takeoff_landing:
            # Near the first or last waypoint or home (NaN when none), horizontally within
            # the radius and not higher than the height above it.
            horiz = np.hypot(pos[:, None, 0] - anchors[:, :, 0], pos[:, None, 1] - anchors[:, :, 1])
            near = (horiz <= cfg.takeoff_landing_radius_m) & (
                pos[:, None, 2] - anchors[:, :, 2] <= cfg.takeoff_landing_height_m
            )
            gated |= near.any(axis=1)
        if cfg.gate_outside_plan_time:
            gated |= ~((start <= ts) & (ts <= end))
        out_ov = dist > ovol
        in_cv = ~out_ov & (dist > fg)
        marginal = ~(out_ov | in_cv) & (dist > fg - cfg.conformance_close_margin_m)
        for k in np.nonzero(~gated & marginal)[0]:
            ev.marginal.add(("CONF", ops[k].id))
        for k in np.nonzero(~gated & (out_ov | in_cv))[0]:
            d = float(dist[k])
            ev.seen[("CONF", ops[k].id)] = _Observation(
                kind=ThreatKind.UAS_OUT_OV if out_ov[k] else ThreatKind.UAS_IN_CV,
                uas_ids=(ops[k].id,),
                event_t_s=float(ts[k]),
                closest_m=d,
                message=f"{d:.1f} m from plan",
            )

    def _conformance_table(
        self, ops: list[Operation]
    ) -> tuple[PlanTable, FloatArray, _Limits, _Band]:
        """Packed local plans, the take-off/landing anchors (N, 3, 3), the limits and the
        fixed-wing band parameters of these operations, rebuilt only when an operation object
        changed (cached)."""
        prev = self._conf_cache
        if (
            prev is not None
            and len(prev[0]) == len(ops)
            and all(a is b for a, b in zip(prev[0], ops, strict=True))
        ):
            return prev[1], prev[2], prev[3], prev[4]
        plans = [self._plan(o) for o in ops]
        anchors = np.full((len(ops), 3, 3), np.nan)
        for k, (o, p) in enumerate(zip(ops, plans, strict=True)):
            anchors[k, 0] = p[0, :3]
            anchors[k, 1] = p[-1, :3]
            if o.home is not None:
                he, hn = self.frame.point_to_local(o.home.lat_deg, o.home.lon_deg)
                anchors[k, 2] = (he, hn, o.home.alt_amsl_m)
        table = pack_plans(plans)
        limits = (
            np.array([o.flight_geometry_m for o in ops]),  # m
            np.array([o.operational_volume_m for o in ops]),  # m
            np.array([o.plan.start_t_s for o in ops]),  # s
            np.array([o.plan.end_t_s for o in ops]),  # s
            *progress_ratios(ops),
        )
        band = band_parameters(ops)
        self._conf_cache = (ops, table, anchors, limits, band)
        return table, anchors, limits, band

    # ---- life cycle ---------------------------------------------------------------------
    def _fresh(self, key: Key, ev: _Evaluation) -> bool:
        fresh, pred_fresh = ev.fresh_sets()
        if key[0] == "CONF":
            return key[1] in fresh
        if key[0] in ("INTR", "LOS"):
            return key[1] in pred_fresh and key[2] in pred_fresh
        return key[1] in pred_fresh

    def _update(self, snapshot: AirspaceSnapshot, ev: _Evaluation) -> list[Threat]:
        out = self._update_seen(snapshot, ev)
        out.extend(self._update_unseen(snapshot, ev))
        return out

    def _update_seen(self, snapshot: AirspaceSnapshot, ev: _Evaluation) -> list[Threat]:
        """Conditions met this cycle: open after ``open_cycles``, else the latest figures
        (UPDATED when they changed materially)."""
        cfg = self.config
        t = snapshot.t_s
        pred: PredictedTrajectories | None = snapshot.prediction
        out: list[Threat] = []
        for key, obs in ev.seen.items():
            st = self._states.setdefault(key, _State())
            st.present += 1
            st.clear = 0
            old = st.threat
            if old is None:
                if st.present >= cfg.open_cycles:
                    self._seq += 1
                    tid = ThreatId(f"{self.id_prefix}T{self._seq}-{key[0]}")
                    st.threat = self._make(tid, obs, t, pred)
                    out.append(st.threat)
                continue
            if self._material_change(st, obs):
                status = ThreatStatus.UPDATED
                st.threat = self._make(
                    old.id, obs, old.detected_at_s, pred, updated=t, status=status
                )
                st.pending = None
                out.append(st.threat)
            else:
                st.pending = (obs, pred, t)
        return out

    def _update_unseen(self, snapshot: AirspaceSnapshot, ev: _Evaluation) -> list[Threat]:
        """Conditions not met this cycle: count clear cycles (fresh evidence, clear by the
        margin) and close after ``close_cycles``, or at once when the plan is over or the
        intruder gone (tracking drops an intruder silent for ``intruder_drop_after_s``: with no
        track left, nothing would ever be fresh evidence of its threat again)."""
        cfg = self.config
        t = snapshot.t_s
        out: list[Threat] = []
        for key in list(self._states):
            if key in ev.seen:
                continue
            st = self._states[key]
            over = over_reason(self._op_ids(key), key[2] if key[0] == "INTR" else None, snapshot)
            ended = over is not None
            if not ended and (key in ev.marginal or not self._fresh(key, ev)):
                st.clear = 0 if key in ev.marginal else st.clear
                st.present = 0 if key in ev.marginal else st.present
                continue  # no evidence either way (stale) or not clear by the margin
            st.present = 0
            st.clear += 1
            if st.threat is None:
                del self._states[key]
            elif ended or st.clear >= cfg.close_cycles:
                closed = self._current(st)
                why = closed_message(closed, over or clear_reason(cfg.close_cycles))
                out.append(replace(closed, status=ThreatStatus.CLOSED, updated_at_s=t, message=why))
                del self._states[key]
        return out

    @staticmethod
    def _op_ids(key: Key) -> tuple[str, ...]:
        return (key[1], key[2]) if key[0] == "LOS" else (key[1],)

    def _material_change(self, st: _State, new: _Observation) -> bool:
        """Whether ``new`` differs materially from the open threat's latest figures."""
        assert st.threat is not None
        if st.pending is not None:
            kind, event, closest = (
                st.pending[0].kind,
                st.pending[0].event_t_s,
                st.pending[0].closest_m,
            )
        else:
            old = st.threat
            kind, event, closest = old.kind, old.predicted_event_at_s, old.closest_approach_m
        if kind is not new.kind:
            return True
        if (event is None) != (new.event_t_s is None):
            return True
        if (
            event is not None
            and new.event_t_s is not None
            and abs(event - new.event_t_s) > self.config.period_s
            and kind not in (ThreatKind.UAS_IN_CV, ThreatKind.UAS_OUT_OV)
        ):
            return True
        return (
            closest is not None
            and new.closest_m is not None
            and abs(closest - new.closest_m) > self.config.separation_close_margin_m
        )

    @staticmethod
    def _make(
        tid: ThreatId,
        obs: _Observation,
        detected: float,
        pred: PredictedTrajectories | None,
        *,
        updated: float | None = None,
        status: ThreatStatus = ThreatStatus.OPEN,
    ) -> Threat:
        return Threat(
            id=tid,
            kind=obs.kind,
            uas_ids=obs.uas_ids,
            detected_at_s=detected,
            predicted_event_at_s=obs.event_t_s,
            geofence_id=obs.geofence_id,
            intruder_id=obs.intruder_id,
            closest_approach_t_s=obs.closest_t_s,
            closest_approach_m=obs.closest_m,
            horizontal_m=obs.horizontal_m,
            vertical_m=obs.vertical_m,
            message=obs.message,
            snapshot=pred,
            updated_at_s=updated if updated is not None else detected,
            status=status,
        )


K = TypeVar("K")
V = TypeVar("V")


def _prune(cache: dict[K, V], current: Collection[K]) -> None:
    """Drop the cached projections of operations and geofences no longer in the airspace (a
    day of traffic came and went), once the cache holds twice what is current."""
    if len(cache) > 2 * len(current) + 16:
        for key in [k for k in cache if k not in current]:
            del cache[key]
