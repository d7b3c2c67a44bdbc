"""Verification and scoring of TD's candidates: the vehicle's envelope, the safety floor and
overshoot (:mod:`.safety`, :mod:`.overshoot`), then Monitoring's ``plan_vs_geofences`` and
``plan_vs_plans`` against every operation outside the problem; the survivors are scored
(:mod:`.scoring`) and become alternatives. Also the compatibility of two alternatives for
EM's joint selection. Pure apart from the caches it shares with TD."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from gcs_utm.core.deconfliction import loitering as lt
from gcs_utm.core.deconfliction.config import DeconflictionConfig
from gcs_utm.core.deconfliction.context import (
    Candidate,
    Dropped,
    Queued,
    floor_amsl,
    pair_minima,
)
from gcs_utm.core.deconfliction.corner_lag import lagged
from gcs_utm.core.deconfliction.geometry import (
    LocalFence,
    LocalPlan,
    local_to_plan,
    local_to_plans,
    separation_screen,
)
from gcs_utm.core.deconfliction.overshoot import overshoot_flags
from gcs_utm.core.deconfliction.plan_cache import PlanCache
from gcs_utm.core.deconfliction.safety import envelope_flags, floor_flags, turn_flags
from gcs_utm.core.deconfliction.scoring import (
    Neighbour,
    Reference,
    Score,
    alternative_terms,
    reference,
    score_many,
)
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences, plan_vs_plans
from gcs_utm.envelope import MULTIROTOR_HORIZONTAL_ACCEL_MPS2
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    FlightPlan,
    Geofence,
    Maneuver,
    Operation,
)

ABANDON = (Maneuver.RETURN_HOME, Maneuver.LANDING_SITE)
"""The manoeuvres that give the mission up (they land: no safety floor at their end)."""


class Verifier:
    """Monitoring's checks and the scores of candidates, with the pair configurations they
    need cached."""

    def __init__(
        self,
        frame: LocalFrame,
        config: DeconflictionConfig,
        monitoring: MonitoringConfig,
        plans: PlanCache,
        air: lt.Airborne,
    ) -> None:
        self.frame = frame
        self.config = config
        self.monitoring = monitoring
        self.plans = plans
        self.air = air
        self._pair_configs: dict[tuple[float, float, float], MonitoringConfig] = {}

    def _pair_config(self, a: Operation, b: Operation, *, buffered: bool) -> MonitoringConfig:
        """Monitoring's configuration with :func:`.context.pair_minima` as the pair's minima
        (the buffered minima are never below the operational-volume floor, so they are the
        effective minima Monitoring's checks use)."""
        h, v = pair_minima(self.monitoring, a, b, buffered=buffered)
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
        *,
        buffered: bool,
        flown: bool = True,
    ) -> list[str]:
        """What Monitoring would flag on ``plan`` (empty list = clean), hovering after its end
        when the UAS is airborne. With nothing to check against, Monitoring is not asked.
        With ``flown`` (a new plan), also as it is flown: a multirotor late by its corners
        (:mod:`.corner_lag`)."""
        flags: list[str] = []
        plan = self.air.extend(op, plan)
        if geofences:
            flags += [
                f"geofence {c.geofence_id} at t={c.entry_t_s:.1f}"
                for c in plan_vs_geofences(plan, op, geofences, self.frame, self.monitoring)
            ]
        flags += self._separation(plan, op, others, buffered=buffered)
        if flown and not flags and others:
            flags += self._as_flown(plan, op, others, buffered=buffered)
        return flags

    def _separation(
        self, plan: FlightPlan, op: Operation, others: Sequence[Operation], *, buffered: bool
    ) -> list[str]:
        """Monitoring's plan-against-plans flags of ``plan`` against ``others``."""
        flags: list[str] = []
        # one Monitoring call per group of others with the same buffered minima
        groups: dict[int, tuple[MonitoringConfig, list[Operation]]] = {}
        for o in others:
            if o.id != op.id:
                cfg = self._pair_config(op, o, buffered=buffered)
                groups.setdefault(id(cfg), (cfg, []))[1].append(o)
        for cfg, group in groups.values():
            flags += [
                f"separation with {c.b} at t={c.first_loss_t_s:.1f} ({c.min_distance_m:.1f} m)"
                for c in plan_vs_plans(plan, op, group, self.frame, cfg)
            ]
        return flags

    def _as_flown(
        self, plan: FlightPlan, op: Operation, others: Sequence[Operation], *, buffered: bool
    ) -> list[str]:
        """The flags of ``plan`` as it is flown: a multirotor late by its corners. (A check of
        a fixed wing's circle after its plan against the other plans, as a disk of its loiter
        radius, was tried and withdrawn: it refused the plans through the circle, held the
        fixed wing instead, and flew losses and fence conflicts elsewhere, docs/evaluation.md.)"""
        lp = self.plans.local(plan)
        env = op.performance()
        if env.can_hover:
            late = lagged(lp, env.horizontal_accel_mps2 or MULTIROTOR_HORIZONTAL_ACCEL_MPS2)
            if late is not None:
                late_plan = local_to_plan(
                    late, plan, self.frame, created_t_s=plan.created_t_s, reason="as flown"
                )
                flags = self._separation(late_plan, op, others, buffered=buffered)
                if flags:
                    return [f"as flown late at its corners: {f}" for f in flags]
        return []

    def compatible(
        self, a: Alternative, b: Alternative, snapshot: AirspaceSnapshot, *, buffered: bool
    ) -> bool:
        """True when the plans of two alternatives (of different UAS) keep separation, as
        Monitoring checks it. An alternative without a plan (a command) is compatible."""
        if a.plan is None or b.plan is None:
            return True
        op_a = snapshot.operations[a.operation_id]
        op_b = snapshot.operations[b.operation_id]
        # Sound shortcuts either way (see separation_screen); only an undecided pair goes to
        # Monitoring's exact closest-approach check. An airborne UAS hovers after its plan.
        pa, pb = self.air.extend(op_a, a.plan, snapshot), self.air.extend(op_b, b.plan, snapshot)
        h, v = pair_minima(self.monitoring, op_a, op_b, buffered=buffered)
        broken, clear = separation_screen(
            self.plans.local(pa),
            self.plans.local(pb),
            h,
            v,
            spherical=self.monitoring.spherical,
            speeds_a=self.plans.max_speeds(pa),
            speeds_b=self.plans.max_speeds(pb),
        )
        if broken or clear:
            return not broken
        cfg = self._pair_config(op_a, op_b, buffered=buffered)
        return not plan_vs_plans(pa, op_a, [replace(op_b, plan=pb)], self.frame, cfg)

    def flush(self, queue: Sequence[Queued], now: float, *, buffered: bool) -> list[Dropped]:
        """Turn the queued candidates into alternatives: all new plans converted to WGS84 at
        once, each verified by Monitoring (in queue order, so the drops returned are in the
        order the candidates were made), the survivors of one UAS scored together against
        one prepared reference (:func:`score_many`), then appended to their lists in queue
        order."""
        if not queue:
            return []
        moved = [c for c in queue if isinstance(c, Candidate) and not c.keep]
        converted = local_to_plans(
            [c.full() for c in moved],
            [c.op.plan for c in moved],
            self.frame,
            created_t_s=now,
            reasons=[f"TD {c.maneuver.value}" for c in moved],
        )
        plans = {id(c): p for c, p in zip(moved, converted, strict=True)}
        dropped: list[Dropped] = []
        passed: list[tuple[Candidate, FlightPlan, list[bool]]] = []
        for c in queue:
            if isinstance(c, Dropped):
                dropped.append(c)
                continue
            flags, plan, applies = self._check(c, plans.get(id(c)), buffered=buffered)
            if flags:
                dropped.append(
                    Dropped(operation_id=c.op.id, maneuver=c.maneuver, reason="; ".join(flags))
                )
            else:
                passed.append((c, plan, applies))
        for (c, plan, _), sc in zip(passed, self._scores(passed), strict=True):
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
        return dropped

    def _scores(self, passed: Sequence[tuple[Candidate, FlightPlan, list[bool]]]) -> list[Score]:
        """The score of every verified candidate. Candidates of one UAS against the same
        remaining plan, neighbours, priority floor and fence list share a reference and are
        scored in one pass."""
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
                abandons=[passed[k][0].maneuver in ABANDON for k in idx],
                spherical=self.monitoring.spherical,
                config=cfg,
            )
            for k, sc in zip(idx, got, strict=True):
                scores[k] = sc
        out: list[Score] = []
        for sc_or_none in scores:
            assert sc_or_none is not None
            out.append(sc_or_none)
        return out

    def _check(
        self, c: Candidate, plan: FlightPlan | None, *, buffered: bool
    ) -> tuple[list[str], FlightPlan, list[bool]]:
        """Monitoring's flags on a candidate's plan, the plan, and which of its fences the
        score counts."""
        op = c.op
        if c.keep:
            flags = self.verify(
                op.plan, op, c.outsiders, c.geofences, buffered=buffered, flown=False
            )
            return flags, op.plan, [True] * len(c.fences)
        assert plan is not None
        self.plans.remember(plan, c.full())  # its local form, without a second conversion
        env = op.performance()
        unsafe = envelope_flags(c.new, c.old, env) + turn_flags(c.new, c.old, env.turn_radius_m)
        floor = floor_amsl(op, self.frame, self.config)
        unsafe += floor_flags(c.new, c.old, floor, lands=c.maneuver in ABANDON)
        filed, first_t = self.plans.local(op.plan), c.new.t[min(c.verify_from, len(c.new) - 1)]
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
        flags = self.verify(checked, op, c.outsiders, near_g, buffered=buffered)
        if flags:
            return flags, plan, []
        reach = ov * self.config.risk_proximity_factor + 1.0
        applies = [
            near and g.applies_to(op.id)
            for g, near in zip(c.geofences, _near(c.fences, c.new, reach), strict=True)
        ]
        return flags, plan, applies

    def _reference(
        self, op: Operation, old: LocalPlan, neighbours: Sequence[Operation]
    ) -> Reference:
        nbs = []
        for o in neighbours:
            h, v = self.monitoring.effective_minima(op.operational_volume_m, o.operational_volume_m)
            nbs.append(Neighbour(plan=self.plans.local(o.plan), h_min_m=h, v_min_m=v, name=o.id))
        return reference(old, self.plans.local(op.plan), op.operational_volume_m, nbs)


def _near(fences: Sequence[LocalFence], lp: LocalPlan, margin_m: float) -> list[bool]:
    """Per fence: does its bounding box come within ``margin_m`` of the plan's bounding box."""
    e0, e1 = float(lp.e.min()) - margin_m, float(lp.e.max()) + margin_m
    n0, n1 = float(lp.n.min()) - margin_m, float(lp.n.max()) + margin_m
    out = []
    for f in fences:
        b0, b1, b2, b3 = f.shape.bounds
        out.append(b0 <= e1 and b2 >= e0 and b1 <= n1 and b3 >= n0)
    return out
