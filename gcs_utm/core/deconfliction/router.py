"""Single-UAS routes for Tactical Deconfliction: A* paths on the visibility graph turned into
4D local plans (reroute, escape, direct to a point, back to plan, next waypoint, land at a
site). Pure: positions in the airspace's local frame (metres), times in POSIX seconds."""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
from shapely.geometry import LineString, Point

from gcs_utm.core.deconfliction.astar import VisibilityPlanner
from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.model import FloatArray, Operation


class Router:
    """Builds 4D local plans for one UAS from A* paths: horizontal path at the cruise speed,
    altitude blended linearly along it, then the rest of the plan shifted to the arrival.

    ``now`` is when the new plan starts (the vehicle has it by then) and ``cur`` where the
    UAS is expected to be at that time; vertical legs take the envelope's climb or descent
    rate. From inside an obstacle every route first leaves it by the closest border point,
    ``escape_m`` beyond it (see :meth:`exit_xyz`)."""

    def __init__(  # noqa: PLR0917 - the planner's context, positional as before
        self,
        op: Operation,
        planner: VisibilityPlanner,
        now: float,
        cur: FloatArray,
        lp: LocalPlan,
        escape_m: float = 0.0,
    ) -> None:
        self.op = op
        self.planner = planner
        self.now = now
        self.cur = cur
        self.lp = lp
        self.escape_m = escape_m

    def inside(self) -> bool:
        """Is the UAS (at the start time) inside an inflated geofence?"""
        return not self.planner.free(self.cur[:2])

    def exit_xyz(self) -> FloatArray:
        """The closest point outside every obstacle, ``escape_m`` beyond the border, at the
        current altitude (the current position when outside)."""
        out2 = self.planner.exit_point(self.cur[:2], self.escape_m)
        return np.array([out2[0], out2[1], self.cur[2]])

    def _fly(self, pts: Sequence[FloatArray], t0: float) -> LocalPlan:
        xyz = np.array([np.asarray(p, dtype=np.float64) for p in pts])
        d = np.diff(xyz, axis=0)
        env = self.op.performance()
        rate = np.where(d[:, 2] > 0.0, env.climb_rate_mps, env.descent_rate_mps)
        need = np.maximum(
            np.hypot(d[:, 0], d[:, 1]) / self.op.cruise_speed_mps, np.abs(d[:, 2]) / rate
        )
        t = np.concatenate([[t0], t0 + np.cumsum(need)])
        return LocalPlan(xyz[:, 0], xyz[:, 1], xyz[:, 2], t)

    def _path3d(self, a: FloatArray, b: FloatArray) -> list[FloatArray] | None:
        path = self.planner.path(a[:2], b[:2])
        if path is None:
            return None
        lengths = np.concatenate(
            [
                [0.0],
                np.cumsum([np.hypot(*(q - p)) for p, q in itertools.pairwise(path)]),
            ]
        )
        total = lengths[-1] if lengths[-1] > 0 else 1.0
        return [
            np.array([p[0], p[1], a[2] + (b[2] - a[2]) * s / total])
            for p, s in zip(path, lengths, strict=True)
        ]

    def _join(self, head: LocalPlan, rest_from: int) -> LocalPlan:
        """``head`` then the plan's waypoints from ``rest_from`` on, shifted in time so that
        the first of them is reached when ``head`` ends."""
        if rest_from >= len(self.lp):
            return head
        shift = float(head.t[-1]) - float(self.lp.t[rest_from])
        # ``head`` ends at waypoint rest_from, so the rest starts after it.
        sl = slice(rest_from + 1, None)
        return LocalPlan(
            np.concatenate([head.e, self.lp.e[sl]]),
            np.concatenate([head.n, self.lp.n[sl]]),
            np.concatenate([head.z, self.lp.z[sl]]),
            np.concatenate([head.t, self.lp.t[sl] + shift]),
        )

    def _route_via(
        self, start: FloatArray, t0: float, prefix: list[FloatArray], first: int
    ) -> LocalPlan | None:
        """From ``start`` through the plan's waypoints from index ``first``, replacing every
        blocked stretch by an A* path from the last free waypoint before it to the first free
        one after it."""
        pts: list[FloatArray] = [*prefix, start]
        wps = self.lp.xyz()
        free = [self.planner.free(w[:2]) for w in wps]
        i = first
        last = start
        while i < len(wps):
            if not free[i]:
                i += 1
                continue
            if self.planner.segment_free(last[:2], wps[i][:2]):
                pts.append(wps[i])
            else:
                seg = self._path3d(last, wps[i])
                if seg is None:
                    return None
                pts.extend(seg[1:])
            last = wps[i]
            i += 1
        if not free[-1]:
            return None  # the destination itself is blocked
        return self._fly(pts, t0)

    def reroute(self) -> tuple[LocalPlan, int] | None:
        plan = self._route_via(self.cur, self.now, [], 1)
        return None if plan is None else (plan, 0)

    def escape(self) -> tuple[LocalPlan, int] | None:
        out = self.exit_xyz()
        # Rejoin at the first plan waypoint ahead that is outside every obstacle.
        plan = self._route_via(out, self.now, [self.cur], 1)
        if plan is None:
            return None
        t1 = self._fly([self.cur, out], self.now).t[-1]
        shifted = LocalPlan(
            plan.e, plan.n, plan.z, plan.t + (t1 - self.now) - (plan.t[1] - plan.t[0])
        )
        return shifted, 1

    def to_point(self, target: FloatArray) -> tuple[LocalPlan, int] | None:
        path = self._path3d(self.cur, target)
        if path is None:
            return None
        return self._fly(path, self.now), 0

    def distance_to_plan(self) -> float:
        if len(self.lp) < 2:
            return float(np.hypot(*(self.cur[:2] - self.lp.xyz()[0, :2])))
        return float(LineString(self.lp.xyz()[:, :2]).distance(Point(self.cur[0], self.cur[1])))

    def back_to_plan(self) -> tuple[LocalPlan, int] | None:
        """To the closest point of the remaining plan, then on along the plan."""
        if len(self.lp) < 2:
            return self.to_point(self.lp.xyz()[0])
        line = LineString(self.lp.xyz()[:, :2])
        s = line.project(Point(self.cur[0], self.cur[1]))
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(self.lp.e), np.diff(self.lp.n)))])
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(self.lp) - 2))
        frac = 0.0 if cum[k + 1] == cum[k] else (s - cum[k]) / (cum[k + 1] - cum[k])
        xyz = self.lp.xyz()
        q = xyz[k] + frac * (xyz[k + 1] - xyz[k])
        path = self._path3d(self.cur, q)
        if path is None:
            return None
        head = self._fly(path, self.now)
        tq = float(self.lp.t[k] + frac * (self.lp.t[k + 1] - self.lp.t[k]))
        shift = float(head.t[-1]) - tq
        sl = slice(k + 1, None)
        return (
            LocalPlan(
                np.concatenate([head.e, self.lp.e[sl]]),
                np.concatenate([head.n, self.lp.n[sl]]),
                np.concatenate([head.z, self.lp.z[sl]]),
                np.concatenate([head.t, self.lp.t[sl] + shift]),
            ),
            0,
        )

    def next_waypoint(self) -> tuple[LocalPlan, int] | None:
        target = self.lp.xyz()[1]
        path = self._path3d(self.cur, target)
        if path is None:
            return None
        return self._join(self._fly(path, self.now), 1), 0

    def land_at(self, site: FloatArray) -> tuple[LocalPlan, int] | None:
        """Cruise at the current altitude to above ``site``, then descend onto it. A vehicle
        that cannot hover cannot descend vertically: its plan ends above the site, where it
        circles (the autopilot's RTL loiter) until it lands on its own landing sequence.
        From inside an obstacle, leave it first (:meth:`exit_xyz`); the plan is then
        verified from the exit point on (the leg out is unavoidable)."""
        head, start = ([self.cur], self.exit_xyz()) if self.inside() else ([], self.cur)
        above = np.array([site[0], site[1], self.cur[2]])
        path = self._path3d(start, above)
        if path is None:
            return None
        end = [site] if self.op.performance().can_hover else []
        return self._fly([*head, *path, *end], self.now), len(head)

    def hold_outside(self, hold_s: float) -> tuple[LocalPlan, int]:
        """Leave the obstacle by the closest border point (:meth:`exit_xyz`) and hold there
        for ``hold_s`` (a vehicle that cannot hover ends its plan there and circles it);
        verified from the exit point on."""
        out = self.exit_xyz()
        plan = self._fly([self.cur, out], self.now)
        if not self.op.performance().can_hover:
            return plan, 1
        t_end = float(plan.t[-1]) + hold_s
        return (
            LocalPlan(
                np.append(plan.e, out[0]),
                np.append(plan.n, out[1]),
                np.append(plan.z, out[2]),
                np.append(plan.t, t_end),
            ),
            1,
        )
