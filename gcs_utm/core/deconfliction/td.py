"""Tactical Deconfliction: alternatives, each with cost and riskiness, for EM to choose from.

Two families (paper §4.5):

- multi-UAS loss of separation (this module): charged cords (:mod:`.cords`) in several
  scenarios: a joint vertical and a joint lateral repulsion where every mobile UAS moves in
  inverse proportion to its priority (neighbours that the deformation pushes into are part of
  the problem, which resolves chains), and per involved UAS a single-mover go up / go down /
  go left / go right; plus a delay (only for a vehicle that can hover) and a speed change
  found by search (:mod:`.timing`), and keep-plan (cost 0) for every UAS;
- single UAS (:mod:`.single`, routes in :mod:`.router`): A* on a visibility graph of
  inflated geofences: reroute around a crossing, escape from inside, direct to goal, back to
  plan, next waypoint, return home, nearest reachable landing site; intruders
  (:mod:`.intruder`): vertical or lateral avoidance.

Every new plan starts at the *start time* EM passes in (when the vehicle will have the plan:
decision + expected answer + upload + margin), at the position the UAS will have then on its
plan as flown: ahead along its path, never a point it has passed. Its times come from the
vehicle's performance envelope (``Operation.performance()``: climb and descent rates, speed
range, hover or not; :mod:`.deform`). Before it is returned it is checked against that
envelope and the safety floor (:mod:`.safety`) and verified by the Monitoring core
(``plan_vs_geofences`` and ``plan_vs_plans`` against every operation outside the problem);
dropped candidates are listed in :attr:`TacticalDeconfliction.dropped` with the reason.
Compatibility between alternatives of UAS in the same problem is checked with the same
Monitoring function by :meth:`TacticalDeconfliction.compatible` during EM's joint selection.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace

import numpy as np

from gcs_utm.core.deconfliction import cords as cd
from gcs_utm.core.deconfliction import loitering as lt
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.deform import deformed
from gcs_utm.core.deconfliction.geometry import (
    LocalFence,
    LocalPlan,
    fence_to_local,
    local_to_plans,
    max_speeds,
    plan_to_local,
    separation_screen,
)
from gcs_utm.core.deconfliction.intruder import intruder_plan, resolve_intruder
from gcs_utm.core.deconfliction.lead_times import lead_times, needs_lead_in
from gcs_utm.core.deconfliction.overshoot import overshoot_flags
from gcs_utm.core.deconfliction.safety import envelope_flags, floor_flags, turn_flags
from gcs_utm.core.deconfliction.scoring import (
    Neighbour,
    Reference,
    Score,
    alternative_terms,
    reference,
    score_many,
)
from gcs_utm.core.deconfliction.single import resolve_single
from gcs_utm.core.deconfliction.timing import timing_candidates
from gcs_utm.core.deconfliction.tolerance import pair_buffers
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences, plan_vs_plans
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FlightPlan,
    FloatArray,
    Geofence,
    Maneuver,
    Operation,
    OperationId,
    OperationState,
    Threat,
)

_INACTIVE = (OperationState.LANDED, OperationState.ENDED)
LEAD_IN_STEP_S = 5.0
"""Spacing of a new plan's lead-in points: the untimed first leg a vehicle flies after it
gets the plan is at most this long."""
_ABANDON = (Maneuver.RETURN_HOME, Maneuver.LANDING_SITE)


@dataclass(frozen=True, slots=True, kw_only=True)
class Dropped:
    """A candidate that was generated but not offered, and why."""

    operation_id: OperationId
    maneuver: Maneuver
    reason: str


@dataclass(slots=True, kw_only=True, eq=False)
class _Candidate:
    """A new plan waiting for Monitoring's verification and for its score (see
    :meth:`TacticalDeconfliction.flush`); ``keep`` marks the filed plan itself (no
    conversion, verified against every geofence, cost 0). The alternative, if any, is
    appended to ``dest``."""

    op: Operation
    maneuver: Maneuver
    new: LocalPlan
    old: LocalPlan
    geofences: Sequence[Geofence]
    fences: Sequence[LocalFence]
    outsiders: Sequence[Operation]
    lowest_priority: int
    detail: str
    dest: list[Alternative]
    verify_from: int = 0
    keep: bool = False
    lead: LocalPlan | None = None
    """Timed points of the plan as flown before ``new`` starts (see :meth:`.lead_in`):
    part of the plan the vehicle gets, not of what is scored or envelope-checked."""

    def full(self) -> LocalPlan:
        if self.lead is None or len(self.lead) == 0:
            return self.new
        b = self.new
        a = self.lead
        keep = a.t < b.t[0] - 1e-6  # a plan already over starts before the start time
        if not keep.all():
            a = LocalPlan(a.e[keep], a.n[keep], a.z[keep], a.t[keep])
        return LocalPlan(
            np.concatenate([a.e, b.e]),
            np.concatenate([a.n, b.n]),
            np.concatenate([a.z, b.z]),
            np.concatenate([a.t, b.t]),
        )


@dataclass(slots=True, kw_only=True, eq=False)
class Problem:
    """One charged-cord problem: the members (involved UAS and the neighbours drawn in),
    their plans from the start time on, the common grid and minima, what lies outside the
    problem, and the alternatives collected per member."""

    members: list[Operation]
    involved: set[OperationId]
    local: dict[OperationId, LocalPlan]
    grid: FloatArray
    minima: FloatArray
    outsiders: list[Operation]
    geofences: Sequence[Geofence]
    fences: list[LocalFence]
    lowest: int
    out: dict[OperationId, list[Alternative]]
    prepared: cd.Problem


class TacticalDeconfliction:
    """Generates verified alternatives; pure apart from the :attr:`dropped` diagnostics of
    the last call."""

    def __init__(
        self, frame: LocalFrame, config: DeconflictionConfig, monitoring: MonitoringConfig
    ) -> None:
        self.frame = frame
        self.config = config
        self.monitoring = monitoring
        self.dropped: list[Dropped] = []
        # Lead-in of the current call: (from_t_s, start_t_s) and per-UAS offsets.
        self._lead_window: tuple[float, float] | None = None
        self._lead_off: dict[OperationId, FloatArray] = {}
        # Candidates and drops of the current call, in the order they were made (_flush).
        self._queue: list[_Candidate | Dropped] = []
        # Local conversions of the plans in the current snapshot, keyed by object identity
        # (the plan is kept in the value so its id cannot be reused while cached).
        self._local: dict[int, tuple[FlightPlan, LocalPlan]] = {}
        self._speeds: dict[int, tuple[FlightPlan, tuple[float, float]]] = {}
        self._pair_configs: dict[tuple[float, float, float], MonitoringConfig] = {}
        self._loitering: set[OperationId] = set()  # involved fixed wings on their circle
        self._air = lt.Airborne(config.horizon_s)  # airborne UAS hover after their plan
        self.tracking_buffers = True
        """Keep the vehicles' tracking tolerances free around new plans (:meth:`pair_minima`);
        EM switches them off for a second search when no combination keeps them."""

    def local_plan(self, plan: FlightPlan) -> LocalPlan:
        hit = self._local.get(id(plan))
        if hit is None or hit[0] is not plan:
            if len(self._local) > 4096:
                self._local.clear()
            hit = (plan, plan_to_local(plan, self.frame))
            self._local[id(plan)] = hit
        return hit[1]

    def _max_speeds(self, plan: FlightPlan) -> tuple[float, float]:
        hit = self._speeds.get(id(plan))
        if hit is None or hit[0] is not plan:
            if len(self._speeds) > 4096:
                self._speeds.clear()
            hit = (plan, max_speeds(self.local_plan(plan)))
            self._speeds[id(plan)] = hit
        return hit[1]

    # ---- helpers on the snapshot -------------------------------------------------------------
    def others(
        self, snapshot: AirspaceSnapshot, exclude: Collection[OperationId]
    ) -> list[Operation]:
        """The traffic other than ``exclude``, airborne UAS after their plan (loitering.py)."""
        return lt.traffic(snapshot, exclude, self.frame, self._air.until(snapshot), _INACTIVE)

    def current_xyz(self, op: Operation, snapshot: AirspaceSnapshot) -> FloatArray:
        """Where the UAS is now: its track if tracked, else its plan at the snapshot time."""
        for tr in snapshot.tracks.values():
            if tr.operation_id == op.id and not tr.stale:
                e, n = self.frame.point_to_local(tr.lat_deg, tr.lon_deg)
                return np.array([e, n, tr.alt_amsl_m])
        return self.local_plan(op.plan).position_at(snapshot.t_s)

    def start_time(self, snapshot: AirspaceSnapshot, start_t_s: float | None) -> float:
        """When a new plan starts: ``start_t_s`` (the decision time plus the expected answer,
        upload and margin, from EM), never before the snapshot."""
        return snapshot.t_s if start_t_s is None else max(snapshot.t_s, start_t_s)

    def set_lead_in(self, from_t_s: float | None, start_t_s: float) -> None:
        """Give every new plan of this call timed lead-in points from ``from_t_s`` (the
        earliest the vehicle can have the plan) up to ``start_t_s``: see :meth:`lead_in`."""
        self._lead_off = {}
        ok = needs_lead_in(from_t_s, start_t_s)  # see .lead_times
        self._lead_window = (from_t_s, start_t_s) if ok and from_t_s is not None else None

    def lead_in(self, op: Operation) -> LocalPlan | None:
        """Points of the UAS's plan as flown every LEAD_IN_STEP_S before the start time,
        back to the earliest time the vehicle can have the plan. Missions carry no time: the
        vehicle flies to the first waypoint still ahead when it gets the plan, untimed.
        Without these points that is the start point, up to the whole answer window away
        (a pilot may answer at once): the vehicle arrives early, holds and manoeuvres early.
        With them the untimed leg is at most one step and every later leg keeps its time."""
        if self._lead_window is None:
            return None
        t_from, t0 = self._lead_window
        times: FloatArray = lead_times(t_from, t0, LEAD_IN_STEP_S)
        e, n, z = self.local_plan(op.plan).coords(times)
        off = self._lead_off.get(op.id)
        if off is not None:
            e, n, z = e + off[0], n + off[1], z + off[2]
        return LocalPlan(e, n, z, times)

    def start_xyz(self, op: Operation, snapshot: AirspaceSnapshot, t0: float) -> FloatArray:
        """Where the UAS will be at ``t0``: on its plan (as flown) at ``t0``, offset by how far
        it is off the plan now. For a fixed wing that is ahead along its path, never a point
        it has passed by the time it gets the new plan."""
        lp = self.local_plan(op.plan)
        ahead = lp.position_at(t0)
        if t0 <= snapshot.t_s:
            return self.current_xyz(op, snapshot)
        off = self.current_xyz(op, snapshot) - lp.position_at(snapshot.t_s)
        self._lead_off[op.id] = off
        return np.asarray(ahead + off, dtype=np.float64)

    def floor_amsl(self, op: Operation) -> float:
        """The safety floor: home altitude (else the airspace's ground elevation) plus the
        configured minimum height above home."""
        home = op.home.alt_amsl_m if op.home is not None else self.frame.ground_elevation_amsl_m
        return home + self.config.min_height_above_home_m

    def alt_limits(self, op: Operation) -> tuple[float, float]:
        """Altitude band a deformation stays in: the operation's band (else the airspace's),
        never below the safety floor."""
        lo = op.min_alt_amsl_m if op.min_alt_amsl_m is not None else self.config.min_alt_amsl_m
        hi = op.max_alt_amsl_m if op.max_alt_amsl_m is not None else self.config.max_alt_amsl_m
        return max(lo, self.floor_amsl(op)), hi

    def vertical_slope(self, op: Operation) -> float:
        """Metres per cord step of a vertical deformation: a share of the climb rate. The
        cord only shapes the deformation; the new plan's timing keeps it inside the envelope
        (:func:`.deform.deformed` re-times climbs and descents at their own rates) and that
        re-timed plan is what Monitoring verifies."""
        rate = op.performance().climb_rate_mps
        return rate * self.config.climb_fraction * self.config.cord_dt_s

    def deform(  # noqa: PLR0917 - positional like the cord's description
        self, op: Operation, lp: LocalPlan, grid: FloatArray, d: FloatArray, axis: str, sign: int
    ) -> LocalPlan:
        """The plan through a displaced cord, re-timed inside the vehicle's envelope."""
        return deformed(
            lp,
            grid,
            d,
            axis,
            sign,
            cruise_speed_mps=op.cruise_speed_mps,
            envelope=op.performance(),
            max_speed_factor=self.config.max_speed_factor,
        )

    def reset_queue(self) -> None:
        self._queue = []

    def _mobility(self, op: Operation) -> float:
        if op.priority >= self.config.immovable_priority or op.id in self._loitering:
            return 0.0
        return 1.0 / max(op.priority, 1)

    def pair_minima(self, a: Operation, b: Operation) -> tuple[float, float]:
        """(horizontal, vertical) minima TD keeps between the plans of ``a`` and ``b``: the
        pair's effective minima (one definition of loss, :mod:`..monitoring.loss`) plus the
        two vehicles' tracking tolerances, horizontal and vertical (sphere mode: horizontal
        on the 3D distance). A plan is flown with a lag at its corners and an altitude error;
        a candidate keeping only the bare minima is flown into a loss by a few metres."""
        h, v = self.monitoring.effective_minima(a.operational_volume_m, b.operational_volume_m)
        if not self.tracking_buffers:
            return h, v
        return pair_buffers(a.performance(), b.performance(), h, v, self.monitoring.spherical)

    def _pair_config(self, a: Operation, b: Operation) -> MonitoringConfig:
        """Monitoring's configuration with :meth:`pair_minima` as the pair's minima (the
        buffered minima are never below the operational-volume floor, so they are the
        effective minima Monitoring's checks use)."""
        h, v = self.pair_minima(a, b)
        key = (h, v, a.operational_volume_m + b.operational_volume_m)
        cfg = self._pair_configs.get(key)
        if cfg is None:
            if self.monitoring.spherical:
                cfg = replace(self.monitoring, safety_distance_m=h)
            else:
                cfg = replace(self.monitoring, separation_horizontal_m=h, separation_vertical_m=v)
            self._pair_configs[key] = cfg
        return cfg

    def verify(
        self,
        plan: FlightPlan,
        op: Operation,
        others: Sequence[Operation],
        geofences: Sequence[Geofence],
    ) -> list[str]:
        """What Monitoring would flag on ``plan`` (empty list = clean), hovering after its end
        when the UAS is airborne. With nothing to check against, Monitoring is not asked."""
        flags: list[str] = []
        plan = self._air.extend(op, plan)
        if geofences:
            flags += [
                f"geofence {c.geofence_id} at t={c.entry_t_s:.1f}"
                for c in plan_vs_geofences(plan, op, geofences, self.frame, self.monitoring)
            ]
        # one Monitoring call per group of others with the same buffered minima
        groups: dict[int, tuple[MonitoringConfig, list[Operation]]] = {}
        for o in others:
            if o.id != op.id:
                cfg = self._pair_config(op, o)
                groups.setdefault(id(cfg), (cfg, []))[1].append(o)
        for cfg, group in groups.values():
            flags += [
                f"separation with {c.b} at t={c.first_loss_t_s:.1f} ({c.min_distance_m:.1f} m)"
                for c in plan_vs_plans(plan, op, group, self.frame, cfg)
            ]
        return flags

    def compatible(self, a: Alternative, b: Alternative, snapshot: AirspaceSnapshot) -> bool:
        """True when the plans of two alternatives (of different UAS) keep separation, as
        Monitoring checks it. An alternative without a plan (a command) is compatible."""
        if a.plan is None or b.plan is None:
            return True
        op_a = snapshot.operations[a.operation_id]
        op_b = snapshot.operations[b.operation_id]
        # Sound shortcuts either way (see separation_screen); only an undecided pair goes to
        # Monitoring's exact closest-approach check. An airborne UAS hovers after its plan.
        pa, pb = self._air.extend(op_a, a.plan, snapshot), self._air.extend(op_b, b.plan, snapshot)
        h, v = self.pair_minima(op_a, op_b)
        broken, clear = separation_screen(
            self.local_plan(pa),
            self.local_plan(pb),
            h,
            v,
            spherical=self.monitoring.spherical,
            speeds_a=self._max_speeds(pa),
            speeds_b=self._max_speeds(pb),
        )
        if broken or clear:
            return not broken
        cfg = self._pair_config(op_a, op_b)
        return not plan_vs_plans(pa, op_a, [replace(op_b, plan=pb)], self.frame, cfg)

    def _reference(
        self, op: Operation, old: LocalPlan, neighbours: Sequence[Operation]
    ) -> Reference:
        nbs = []
        for o in neighbours:
            h, v = self.monitoring.effective_minima(op.operational_volume_m, o.operational_volume_m)
            nbs.append(Neighbour(plan=self.local_plan(o.plan), h_min_m=h, v_min_m=v, name=o.id))
        return reference(old, self.local_plan(op.plan), op.operational_volume_m, nbs)

    def finish(
        self,
        op: Operation,
        maneuver: Maneuver,
        new: LocalPlan,
        old: LocalPlan,
        *,
        geofences: Sequence[Geofence],
        fences: Sequence[LocalFence],
        outsiders: Sequence[Operation],
        lowest_priority: int,
        detail: str,
        dest: list[Alternative],
        verify_from: int = 0,
    ) -> None:
        """Queue ``new`` for verification by Monitoring and scoring (:meth:`flush`), its
        alternative for ``dest``. ``verify_from`` skips leading waypoints (an escape leg that
        starts inside a fence)."""
        self._queue.append(
            _Candidate(
                op=op,
                maneuver=maneuver,
                new=new,
                old=old,
                geofences=geofences,
                fences=fences,
                outsiders=outsiders,
                lowest_priority=lowest_priority,
                detail=detail,
                dest=dest,
                verify_from=verify_from,
                lead=self.lead_in(op),
            )
        )

    def drop(self, op_id: OperationId, maneuver: Maneuver, reason: str) -> None:
        self._queue.append(Dropped(operation_id=op_id, maneuver=maneuver, reason=reason))

    def flush(self, now: float) -> None:
        """Turn the queued candidates into alternatives: all new plans converted to WGS84 at
        once, each verified by Monitoring (in queue order, so :attr:`dropped` lists drops in
        the order the candidates were made), the survivors of one UAS scored together against
        one prepared reference (:func:`score_many`), then appended to their lists in queue
        order."""
        queue, self._queue = self._queue, []
        moved = [c for c in queue if isinstance(c, _Candidate) and not c.keep]
        converted = local_to_plans(
            [c.full() for c in moved],
            [c.op.plan for c in moved],
            self.frame,
            created_t_s=now,
            reasons=[f"TD {c.maneuver.value}" for c in moved],
        )
        plans = {id(c): p for c, p in zip(moved, converted, strict=True)}
        passed: list[tuple[_Candidate, FlightPlan, list[bool]]] = []
        for c in queue:
            if isinstance(c, Dropped):
                self.dropped.append(c)
                continue
            flags, plan, applies = self._check(c, plans.get(id(c)))
            if flags:
                self.dropped.append(
                    Dropped(operation_id=c.op.id, maneuver=c.maneuver, reason="; ".join(flags))
                )
            else:
                passed.append((c, plan, applies))
        # Candidates of one UAS against the same remaining plan, neighbours, priority floor
        # and fence list share a reference and are scored in one pass.
        groups: dict[tuple[object, ...], list[int]] = {}
        for k, (c, _, _) in enumerate(passed):
            key = (
                c.op.id,
                id(c.old),
                id(c.fences),
                c.lowest_priority,
                *(o.id for o in c.outsiders),
            )
            groups.setdefault(key, []).append(k)
        scores: list[Score | None] = [None] * len(passed)
        cfg = self.config
        for idx in groups.values():
            c0 = passed[idx[0]][0]
            op = c0.op
            levels = max(0, op.priority - c0.lowest_priority)
            got = score_many(
                [passed[k][0].new for k in idx],
                self._reference(op, c0.old, c0.outsiders),
                fences=c0.fences,
                applies=[np.array(passed[k][2], dtype=bool) for k in idx],
                priority_weight=1.0 + cfg.priority_cost_weight * levels,
                priority_levels=levels,
                abandons=[passed[k][0].maneuver in _ABANDON for k in idx],
                spherical=self.monitoring.spherical,
                config=cfg,
            )
            for k, sc in zip(idx, got, strict=True):
                scores[k] = sc
        for (c, plan, _), got_sc in zip(passed, scores, strict=True):
            assert got_sc is not None
            sc = got_sc
            terms = ", ".join(f"{k}={v}" for k, v in sc.as_dict().items())
            c.dest.append(
                Alternative(
                    operation_id=c.op.id,
                    maneuver=c.maneuver,
                    plan=plan,
                    cost=0.0 if c.keep else sc.cost,
                    risk=sc.risk,
                    detail=f"{c.detail}; {terms}",
                    **alternative_terms(sc),
                )
            )

    def _check(
        self, c: _Candidate, plan: FlightPlan | None
    ) -> tuple[list[str], FlightPlan, list[bool]]:
        """Monitoring's flags on a candidate's plan, the plan, and which of its fences the
        score counts."""
        op = c.op
        if c.keep:
            flags = self.verify(op.plan, op, c.outsiders, c.geofences)
            return flags, op.plan, [True] * len(c.fences)
        assert plan is not None
        self._local[id(plan)] = (plan, c.full())  # its local form, without a second conversion
        env = op.performance()
        unsafe = envelope_flags(c.new, c.old, env) + turn_flags(c.new, c.old, env.turn_radius_m)
        unsafe += floor_flags(c.new, c.old, self.floor_amsl(op), lands=c.maneuver in _ABANDON)
        filed, first_t = self.local_plan(op.plan), c.new.t[min(c.verify_from, len(c.new) - 1)]
        unsafe += overshoot_flags(c.full(), first_t, filed, c.fences, c.geofences, op)
        if unsafe:
            return unsafe, plan, []
        checked = plan
        skip = c.verify_from + len(c.full()) - len(c.new)
        if c.verify_from > 0:
            checked = replace(plan, waypoints=plan.waypoints[skip:])
        # Monitoring's check is exact but costs a buffer per fence: hand it only the fences
        # whose box comes within the OV radius of the new plan's box (the others cannot be
        # crossed), and score only those within the proximity range.
        ov = op.operational_volume_m
        near_g = [
            g
            for g, near in zip(c.geofences, _near(c.fences, c.full(), ov + 1.0), strict=True)
            if near and g.applies_to(op.id)
        ]
        flags = self.verify(checked, op, c.outsiders, near_g)
        if flags:
            return flags, plan, []
        reach = ov * self.config.risk_proximity_factor + 1.0
        applies = [
            near and g.applies_to(op.id)
            for g, near in zip(c.geofences, _near(c.fences, c.new, reach), strict=True)
        ]
        return flags, plan, applies

    def local_fences(self, geofences: Sequence[Geofence]) -> list[LocalFence]:
        return [fence_to_local(g, self.frame) for g in geofences]

    # ---- multi-UAS --------------------------------------------------------------------------
    def resolve_loss_of_separation(
        self,
        threat: Threat,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
    ) -> dict[OperationId, list[Alternative]]:
        """Alternatives per UAS of the conflict and of the neighbours drawn into it. Every UAS
        gets ``KEEP_PLAN`` (if Monitoring does not flag its plan against outsiders) so that
        EM's joint selection can leave the higher-priority UAS alone. New plans start at
        ``start_t_s`` (:meth:`start_time`): where each UAS will be when it gets the plan."""
        self.dropped = []
        self._queue = []
        t0 = self.start_time(snapshot, start_t_s)
        self.set_lead_in(lead_in_from_t_s, t0)
        cfg = self.config
        self._air.at(snapshot)
        involved = [
            lt.involved(op, snapshot, self.frame, t0 + cfg.horizon_s)
            for op in (snapshot.operations[i] for i in threat.uas_ids if i in snapshot.operations)
        ]
        self._loitering = {op.id for op in involved if op is not snapshot.operations[op.id]}
        if not involved:
            return {}
        local = {op.id: self.local_plan(op.plan).after(t0) for op in involved}
        end = min(t0 + cfg.horizon_s, max(float(lp.t[-1]) for lp in local.values()))
        steps = max(2, math.ceil((end - t0) / cfg.cord_dt_s) + 1)
        grid: FloatArray = t0 + np.arange(steps, dtype=np.float64) * cfg.cord_dt_s
        members = list(involved) + self._neighbours(involved, snapshot, grid)
        for op in members:
            local.setdefault(op.id, self.local_plan(op.plan).after(t0))
        u = len(members)
        minima = np.zeros((u, u, 2))
        for i, a in enumerate(members):
            for j, b in enumerate(members):
                minima[i, j] = self.pair_minima(a, b)
        pb = Problem(
            members=members,
            involved={op.id for op in involved},
            local=local,
            grid=grid,
            minima=minima,
            outsiders=self.others(snapshot, {op.id for op in members}),
            geofences=snapshot.geofences,
            fences=self.local_fences(snapshot.geofences),
            lowest=min(op.priority for op in members),
            out={op.id: [] for op in members},
            # Axes, signs and mobility aside, every scenario works on the same cords.
            prepared=cd.prepare(
                [local[op.id] for op in members],
                grid,
                minima,
                spherical=self.monitoring.spherical,
                margin_fraction=cfg.separation_margin_fraction,
            ),
        )
        for op in members:
            # Keeping the plan moves nothing: no priority price (the score's cost is then 0).
            self._queue.append(
                _Candidate(
                    op=op,
                    maneuver=Maneuver.KEEP_PLAN,
                    new=local[op.id],
                    old=local[op.id],
                    geofences=pb.geofences,
                    fences=pb.fences,
                    outsiders=pb.outsiders,
                    lowest_priority=op.priority,
                    detail="keep the current plan",
                    dest=pb.out[op.id],
                    keep=True,
                )
            )
        mobile_all = [self._mobility(op) > 0 for op in members]
        self._run(pb, [cd.AXIS_VERTICAL] * u, [0] * u, mobile_all, "joint vertical repulsion")
        self._run(pb, [cd.AXIS_LATERAL] * u, [0] * u, mobile_all, "joint lateral repulsion")
        for k, op in enumerate(members):
            if op.id in pb.involved and mobile_all[k]:
                self._alone(pb, k, snapshot)
        self.flush(snapshot.t_s)
        return {k: _dedupe(v) for k, v in pb.out.items() if v or k in threat.uas_ids}

    def _alone(self, pb: Problem, k: int, snapshot: AirspaceSnapshot) -> None:
        """Single-mover scenarios of member ``k``: up, down, left, right, then timing."""
        u = len(pb.members)
        op = pb.members[k]
        only = [j == k for j in range(u)]
        for axis, sign in (
            (cd.AXIS_VERTICAL, 1),
            (cd.AXIS_VERTICAL, -1),
            (cd.AXIS_LATERAL, 1),
            (cd.AXIS_LATERAL, -1),
        ):
            signs = [sign if j == k else 0 for j in range(u)]
            self._run(pb, [axis] * u, signs, only, f"{op.id} alone")
        rigid = [o for o in pb.members if o.id != op.id]
        timing_candidates(self, op, pb, rigid)

    def _cord(self, op: Operation, plan: LocalPlan, axis: str, sign: int, mobile: bool) -> cd.Cord:
        cfg = self.config
        lo, hi = self.alt_limits(op)
        vertical = axis == cd.AXIS_VERTICAL
        slope = (
            self.vertical_slope(op)
            if vertical
            else cd.lateral_slope(op.cruise_speed_mps, cfg.cord_dt_s, cfg.max_lateral_angle_deg)
        )
        return cd.Cord(
            plan=plan,
            axis=axis if mobile else cd.AXIS_NONE,
            sign=sign,
            mobility=self._mobility(op) if mobile else 0.0,
            slope_m_per_step=slope,
            max_offset_m=cfg.max_vertical_offset_m if vertical else cfg.max_lateral_offset_m,
            min_alt_amsl_m=lo,
            max_alt_amsl_m=hi,
        )

    def _run(
        self, pb: Problem, axes: list[str], signs: list[int], mobile: list[bool], label: str
    ) -> None:
        """One charged-cord scenario; every deformed member's plan is queued."""
        cfg = self.config
        cords = [
            self._cord(op, pb.local[op.id], axes[k], signs[k], mobile[k])
            for k, op in enumerate(pb.members)
        ]
        res = cd.resolve(
            cords,
            pb.grid,
            pb.minima,
            spherical=self.monitoring.spherical,
            margin_fraction=cfg.separation_margin_fraction,
            max_iterations=cfg.max_iterations,
            problem=pb.prepared,
        )
        if res is None:
            for k, op in enumerate(pb.members):
                if mobile[k] and op.id in pb.involved:
                    self.drop(op.id, Maneuver.KEEP_PLAN, f"{label}: no convergence")
            return
        for k, op in enumerate(pb.members):
            dk = res.displacement_m[k]
            if cords[k].axis == cd.AXIS_NONE or float(dk.max()) < 0.5:
                continue
            sign = res.signs[k]
            man = _maneuver(cords[k].axis, sign)
            self.finish(
                op,
                man,
                self.deform(op, pb.local[op.id], pb.grid, dk, cords[k].axis, sign),
                pb.local[op.id],
                geofences=pb.geofences,
                fences=pb.fences,
                outsiders=pb.outsiders,
                lowest_priority=pb.lowest,
                detail=f"{label}: {man.value} up to {float(dk.max()):.0f} m",
                dest=pb.out[op.id],
            )

    def _neighbours(
        self, involved: Sequence[Operation], snapshot: AirspaceSnapshot, grid: FloatArray
    ) -> list[Operation]:
        """Operations whose plans come within 3x the minima of an involved plan inside the
        horizon: the ones a deformation can push into (nearest first, at most
        ``max_neighbours``)."""
        ids = {op.id for op in involved}
        pos = [self.local_plan(op.plan).sample(grid) for op in involved]
        found: list[tuple[float, Operation]] = []
        for other in self.others(snapshot, ids):
            p, ok = self.local_plan(other.plan).sample(grid)
            best = math.inf
            for op, (q, ok2) in zip(involved, pos, strict=True):
                m = ok & ok2
                if not m.any():
                    continue
                h, v = self.monitoring.effective_minima(
                    op.operational_volume_m, other.operational_volume_m
                )
                dh = np.hypot(p[m, 0] - q[m, 0], p[m, 1] - q[m, 1]) / h
                dv = np.abs(p[m, 2] - q[m, 2]) / v
                best = min(best, float(np.maximum(dh, dv).min()))
            if best < 3.0:
                found.append((best, other))
        found.sort(key=lambda x: x[0])
        return [op for _, op in found[: self.config.max_neighbours]]

    # ---- intruder ---------------------------------------------------------------------------
    def intruder_plan(self, threat: Threat, snapshot: AirspaceSnapshot) -> LocalPlan | None:
        """The intruder's predicted path (see :func:`.intruder.intruder_plan`)."""
        return intruder_plan(threat, snapshot, self.config.horizon_s)

    def resolve_intruder(
        self,
        threat: Threat,
        operation_id: OperationId,
        snapshot: AirspaceSnapshot,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
    ) -> list[Alternative]:
        """Vertical or lateral avoidance of a non-cooperative intruder (:mod:`.intruder`)."""
        self.set_lead_in(lead_in_from_t_s, self.start_time(snapshot, start_t_s))
        return resolve_intruder(self, threat, operation_id, snapshot, start_t_s)

    # ---- single UAS -------------------------------------------------------------------------
    def resolve_single(
        self,
        threat: Threat,
        operation_id: OperationId,
        snapshot: AirspaceSnapshot,
        maneuvers: Collection[Maneuver] | None = None,
        extra_geofences: Sequence[Geofence] = (),
        *,
        start_t_s: float | None = None,
        lead_in_from_t_s: float | None = None,
    ) -> list[Alternative]:
        """Single-UAS alternatives (A*), verified (:func:`.single.resolve_single`)."""
        self.set_lead_in(lead_in_from_t_s, self.start_time(snapshot, start_t_s))
        return resolve_single(
            self, threat, operation_id, snapshot, maneuvers, extra_geofences, start_t_s
        )


def _near(fences: Sequence[LocalFence], lp: LocalPlan, margin_m: float) -> list[bool]:
    """Per fence: does its bounding box come within ``margin_m`` of the plan's bounding box."""
    e0, e1 = float(lp.e.min()) - margin_m, float(lp.e.max()) + margin_m
    n0, n1 = float(lp.n.min()) - margin_m, float(lp.n.max()) + margin_m
    out = []
    for f in fences:
        b0, b1, b2, b3 = f.shape.bounds
        out.append(b0 <= e1 and b2 >= e0 and b1 <= n1 and b3 >= n0)
    return out


def _dedupe(alts: list[Alternative]) -> list[Alternative]:
    """Drop alternatives that repeat a maneuver with the same cost and risk (two scenarios
    that deformed one UAS the same way)."""
    seen: set[tuple[Maneuver, float, float]] = set()
    out = []
    for a in alts:
        key = (a.maneuver, round(a.cost, 6), round(a.risk, 6))
        if key not in seen:
            seen.add(key)
            out.append(a)
    return out


def _maneuver(axis: str, sign: int) -> Maneuver:
    if axis == cd.AXIS_VERTICAL:
        return Maneuver.GO_UP if sign > 0 else Maneuver.GO_DOWN
    return Maneuver.GO_LEFT if sign > 0 else Maneuver.GO_RIGHT
