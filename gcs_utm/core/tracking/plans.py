"""Flight plans as padded arrays: where a UAS is on its plan, and where the plan takes it.

A :class:`PlanTable` holds every plan in the airspace's local frame (east_m, north_m,
alt_amsl_m; times in POSIX seconds) so the questions below are answered for all tracks at
once:

- :meth:`PlanTable.locate`: the closest *segment* (not vertex: on a lawn-mower pattern the
  closest vertex is often the end of a neighbouring lane, and on a loop the same vertex is
  visited twice). Segments within ``min distance + ambiguity_m`` compete, and the one whose
  plan time at the closest point is nearest to the track time wins: that separates the two
  passes of a loop and the crossing of a figure-eight. The current waypoint is the end of
  that segment; a segment whose end has been reached hands over to the next one.
- :meth:`PlanTable.follow`: positions along the plan from a plan time ``tau0`` onwards, at the
  plan's own timing (4D), clamped to the plan's end (the UAS stays at its last waypoint).

Invariants: plan times never decrease (checked by :class:`gcs_utm.model.FlightPlan`);
zero-length or zero-duration segments are allowed and handled without division by zero.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

# A closest point this close to a segment's end (as a fraction of the segment) counts as
# having reached that end's waypoint.
_REACHED_U = 1.0 - 1e-9

# Windowed search of the closest segment: segments hint - WINDOW_BEHIND .. hint - WINDOW_BEHIND
# + WINDOW - 1, i.e. the previous segment, the last one and the next two.
WINDOW = 4
WINDOW_BEHIND = 1


class PlanTable:
    """All plans of the airspace, row j = ``plans[j]``."""

    def __init__(self, plans: Sequence[FlightPlan], frame: LocalFrame) -> None:
        self.n_plans = len(plans)
        # How many tracks locate() answered from their window and from the full search.
        self.searches: dict[str, int] = {"window": 0, "full": 0}
        self._init_waypoints(plans, frame)
        self._init_follow()
        self._init_segments()

    def _init_waypoints(self, plans: Sequence[FlightPlan], frame: LocalFrame) -> None:
        """The waypoint table: positions (local frame), times, offsets per plan."""
        counts = np.array([len(p.waypoints) for p in plans], dtype=np.intp)
        self.n_waypoints: IntArray = counts
        total = int(counts.sum())
        self.wp_offset: IntArray = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        lat = np.array([w.lat_deg for p in plans for w in p.waypoints], dtype=np.float64)
        lon = np.array([w.lon_deg for p in plans for w in p.waypoints], dtype=np.float64)
        alt = np.array([w.alt_amsl_m for p in plans for w in p.waypoints], dtype=np.float64)
        t = np.array([w.t_s for p in plans for w in p.waypoints], dtype=np.float64)
        east, north = frame.to_local(lat, lon) if total else (np.zeros(0), np.zeros(0))
        self.wp_pos: FloatArray = np.stack([east, north, alt], axis=1).reshape(total, 3)
        self.wp_t: FloatArray = t
        # Contiguous per-axis copies for fast gathers in follow().
        self._wp_axis = [np.ascontiguousarray(self.wp_pos[:, a]) for a in range(3)]
        self.start_t_s: FloatArray = np.array([p.start_t_s for p in plans], dtype=np.float64)
        self.end_t_s: FloatArray = np.array([p.end_t_s for p in plans], dtype=np.float64)

    def _init_follow(self) -> None:
        """Plan-relative waypoint times (search keys, padded table) and the velocity of the
        segment starting at each waypoint: what follow() reads."""
        counts, t, start = self.n_waypoints, self.wp_t, self.start_t_s
        total = len(t)
        # Sorted search keys: plan-relative time shifted by j * stride keeps each plan in its
        # own interval without the precision loss of adding large offsets to POSIX times.
        duration = self.end_t_s - start
        self._stride = float(duration.max() + 1.0) if self.n_plans else 1.0
        plan_of_wp = np.repeat(np.arange(self.n_plans), counts)
        self._keys: FloatArray = (t - start[plan_of_wp]) + plan_of_wp * self._stride
        self._wp_rel_flat: FloatArray = t - start[plan_of_wp] if total else np.zeros(0)
        m_max = int(counts.max()) if self.n_plans else 1
        self._wp_rel_pad: FloatArray = np.full((self.n_plans, m_max), np.inf)
        # Velocity of the segment that starts at each waypoint (m/s per axis); zero for the
        # last waypoint and for zero-duration segments, so interpolation clamps there.
        self._seg_vel = [np.zeros(total) for _ in range(3)]
        for j in range(self.n_plans):
            o, m = int(self.wp_offset[j]), int(counts[j])
            self._wp_rel_pad[j, :m] = self._wp_rel_flat[o : o + m]
            if m >= 2:
                dt_seg = np.diff(t[o : o + m])
                safe = np.where(dt_seg > 0.0, dt_seg, 1.0)
                for a in range(3):
                    dp = np.diff(self.wp_pos[o : o + m, a])
                    self._seg_vel[a][o : o + m - 1] = np.where(dt_seg > 0.0, dp / safe, 0.0)
        # The segment that starts at each waypoint as a line in plan-relative time:
        # position = intercept + t_rel * velocity (for follow()).
        self._intercept = [
            self._wp_axis[a] - self._wp_rel_flat * self._seg_vel[a] for a in range(3)
        ]

    def _init_segments(self) -> None:
        """The padded segment table (N plans, S segments) and its per-axis copies: what
        locate() reads."""
        counts, t = self.n_waypoints, self.wp_t
        n_seg = np.maximum(counts - 1, 1)
        s_max = int(n_seg.max()) if self.n_plans else 1
        self.seg_a: FloatArray = np.zeros((self.n_plans, s_max, 3))
        self.seg_b: FloatArray = np.zeros((self.n_plans, s_max, 3))
        self.seg_ta: FloatArray = np.zeros((self.n_plans, s_max))
        self.seg_tb: FloatArray = np.zeros((self.n_plans, s_max))
        self.seg_valid = np.zeros((self.n_plans, s_max), dtype=bool)
        for j in range(self.n_plans):
            o, m = int(self.wp_offset[j]), int(counts[j])
            if m == 1:
                # A single waypoint is a degenerate segment from the point to itself.
                self.seg_a[j, 0] = self.seg_b[j, 0] = self.wp_pos[o]
                self.seg_ta[j, 0] = self.seg_tb[j, 0] = t[o]
                self.seg_valid[j, 0] = True
                continue
            self.seg_a[j, : m - 1] = self.wp_pos[o : o + m - 1]
            self.seg_b[j, : m - 1] = self.wp_pos[o + 1 : o + m]
            self.seg_ta[j, : m - 1] = t[o : o + m - 1]
            self.seg_tb[j, : m - 1] = t[o + 1 : o + m]
            self.seg_valid[j, : m - 1] = True
        self.n_seg: IntArray = n_seg
        self._s_max = s_max
        # Per-axis segment tables for locate(): start point, direction, squared length.
        d = self.seg_b - self.seg_a
        self._seg_a_axis = [np.ascontiguousarray(self.seg_a[:, :, a]) for a in range(3)]
        self._seg_d_axis = [np.ascontiguousarray(d[:, :, a]) for a in range(3)]
        self.seg_len2: FloatArray = (d * d).sum(axis=2)
        # A zero-length segment divides 0 by 1: its closest point is its start (u = 0).
        self._seg_len2_safe: FloatArray = np.where(self.seg_len2 > 0.0, self.seg_len2, 1.0)
        # A hold (zero length, positive duration: the UAS waits there) is at every time of
        # its window at once, so a track on it is at the plan time nearest its own time.
        dt = self.seg_tb - self.seg_ta
        self._seg_hold = self.seg_valid & (self.seg_len2 == 0.0) & (dt > 0.0)
        self._seg_dt_safe: FloatArray = np.where(dt > 0.0, dt, 1.0)
        self._any_hold = bool(self._seg_hold.any())

    def locate(
        self,
        plan_idx: IntArray,
        pos_m: FloatArray,
        t_s: FloatArray,
        ambiguity_m: FloatArray,
        *,
        hint: IntArray | None = None,
        accept_m: FloatArray | None = None,
    ) -> tuple[IntArray, FloatArray, FloatArray, IntArray]:
        """For N tracks on plans ``plan_idx`` at positions ``pos_m`` (N, 3) and times ``t_s``:
        (current waypoint index within the plan, distance to the plan [m], plan time at the
        closest point [s], closest segment index within the plan).

        ``hint`` (N,): each track's closest segment from a previous call (-1: none). With a
        hint only the :data:`WINDOW` segments around it are searched, and that answer is
        kept only when it provably equals the full search's (see :meth:`_window_exact`):
        the chosen segment is within ``accept_m`` (default ``ambiguity_m``; it must not
        exceed it) and its plan time is nearer the track time than any plan time outside
        the window. Every other track -- no hint, off the plan, late or early, moved past
        the window -- falls back to the search over all segments. The returned distance is
        then the window's: at most ``accept_m``, and never below the true distance."""
        n = len(plan_idx)
        seg = np.zeros(n, dtype=np.intp)
        u = np.zeros(n)
        tau = np.zeros(n)
        dmin = np.zeros(n)
        todo = np.ones(n, dtype=bool)
        if hint is not None and self._s_max > WINDOW:
            accept = ambiguity_m if accept_m is None else np.minimum(accept_m, ambiguity_m)
            rows = np.flatnonzero(hint >= 0)
            if len(rows):
                p = plan_idx[rows]
                lo = np.clip(hint[rows] - WINDOW_BEHIND, 0, np.maximum(self.n_seg[p] - WINDOW, 0))
                cols = lo[:, None] + np.arange(WINDOW)
                s, uu, tt, dd, dc = self._closest(
                    p, cols, pos_m[rows], t_s[rows], ambiguity_m[rows]
                )
                ok = (dc <= accept[rows]) & self._window_exact(p, lo, t_s[rows], tt)
                done = rows[ok]
                seg[done], u[done], tau[done], dmin[done] = s[ok], uu[ok], tt[ok], dd[ok]
                todo[done] = False
                self.searches["window"] += len(done)
        rows = np.flatnonzero(todo)
        if len(rows):
            p = plan_idx[rows]
            s, uu, tt, dd, _ = self._closest(p, None, pos_m[rows], t_s[rows], ambiguity_m[rows])
            seg[rows], u[rows], tau[rows], dmin[rows] = s, uu, tt, dd
            self.searches["full"] += len(rows)
        n_wp = self.n_waypoints[plan_idx]
        # Reached the end of this segment: the UAS now flies to the following waypoint.
        reached = (u >= _REACHED_U) & (seg + 2 < n_wp)
        ahead = np.where(reached, seg + 1, seg)
        waypoint = np.where(n_wp >= 2, ahead + 1, 0).astype(np.intp)
        return waypoint, dmin, tau, seg

    def _closest(
        self,
        plan_idx: IntArray,
        cols: IntArray | None,
        pos_m: FloatArray,
        t_s: FloatArray,
        ambiguity_m: FloatArray,
    ) -> tuple[IntArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """Closest segment among columns ``cols`` (N, W) of each plan (None: all of them).
        Returns (segment, u on it, plan time there, min distance, distance of the chosen).
        Per axis (N, W) arrays: much faster than (N, W, 3) with einsum."""
        if cols is None:

            def take(table: npt.NDArray[Any]) -> npt.NDArray[Any]:
                return table[plan_idx]

        else:
            # Flat indices into the (P, S) tables: one 1-D take each, much faster than
            # 2-D fancy indexing with (plan, column) pairs.
            flat = plan_idx[:, None] * self._s_max + cols

            def take(table: npt.NDArray[Any]) -> npt.NDArray[Any]:
                return np.take(table.ravel(), flat)

        d = [take(self._seg_d_axis[axis]) for axis in range(3)]
        rel = [pos_m[:, axis, None] - take(self._seg_a_axis[axis]) for axis in range(3)]
        dot = rel[0] * d[0]
        dot += rel[1] * d[1]
        dot += rel[2] * d[2]
        dot /= take(self._seg_len2_safe)
        u = np.clip(dot, 0.0, 1.0, out=dot)
        dist2 = np.zeros_like(dot)
        for axis in range(3):
            o = rel[axis] - u * d[axis]
            o *= o
            dist2 += o
        dist = np.where(take(self.seg_valid), np.sqrt(dist2), np.inf)
        ta = take(self.seg_ta)
        if self._any_hold:
            hold = take(self._seg_hold)
            on_hold = np.clip((t_s[:, None] - ta) / take(self._seg_dt_safe), 0.0, 1.0)
            u = np.where(hold, on_hold, u)
        tau = ta + u * (take(self.seg_tb) - ta)
        dmin = dist.min(axis=1)
        cand = dist <= (dmin + ambiguity_m)[:, None]
        cost = np.where(cand, np.abs(t_s[:, None] - tau), np.inf)
        rows = np.arange(len(plan_idx))
        k = np.argmin(cost, axis=1)
        seg = k if cols is None else cols[rows, k]
        return seg.astype(np.intp), u[rows, k], tau[rows, k], dmin, dist[rows, k]

    def _window_exact(
        self, plan_idx: IntArray, lo: IntArray, t_s: FloatArray, tau: FloatArray
    ) -> npt.NDArray[np.bool_]:
        """True where no segment outside the window ``lo .. lo + WINDOW - 1`` can beat the
        window's choice at plan time ``tau`` in the full search.

        Outside segments have plan times <= ``t_lo`` (start of the window) or >= ``t_hi``
        (its end), so their time cost is at least ``min(t - t_lo, t_hi - t)``; a choice
        with a strictly smaller cost wins every tie-break against them. They could still
        win by distance only if the choice were farther than (their distance + ambiguity)
        from the track, which the caller rules out by accepting only choices within the
        ambiguity."""
        hi = lo + WINDOW - 1
        t_lo = np.where(lo > 0, self.seg_ta[plan_idx, lo], -np.inf)
        last = self.n_seg[plan_idx] - 1
        t_hi = np.where(hi < last, self.seg_tb[plan_idx, np.minimum(hi, last)], np.inf)
        margin = np.minimum(t_s - t_lo, t_hi - t_s)
        out: npt.NDArray[np.bool_] = np.abs(t_s - tau) < margin
        return out

    def follow(
        self,
        plan_idx: IntArray,
        tau0_s: FloatArray,
        first_ahead_s: FloatArray,
        step_s: float,
        n_points: int,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Plan positions at plan times ``tau0_s + first_ahead_s + k * step_s`` for
        k = 0 .. n_points - 1, as three (N, K) arrays (east_m, north_m, alt_amsl_m). Times
        outside the plan are clamped to its first/last waypoint.

        How: the waypoint at point 0 comes from one binary search per track (``_keys``).
        On a regular grid the later waypoints are crossed at the integer points
        ``ceil((t_wp - t_first) / step)``; only those inside the horizon are counted
        (``bincount`` over all tracks, one pass per waypoint crossed, so the cost does not
        grow with the plan's length), and a running sum gives the waypoint of every point.
        The position is then ``intercept[wp] + t * velocity[wp]`` (the segment line written
        in plan-relative time): two gathers, one multiply, one add per axis."""
        n = len(plan_idx)
        if n == 0:
            empty = np.zeros((0, n_points))
            return empty, empty.copy(), empty.copy()
        start = self.start_t_s[plan_idx]
        dur = self.end_t_s[plan_idx] - start
        first = (tau0_s - start) + first_ahead_s  # plan-relative time of point 0
        offset = self.wp_offset[plan_idx]
        last = offset + self.n_waypoints[plan_idx] - 1
        # Waypoint of point 0: the last one whose time is <= first (a repeated time: the later
        # one, as np.interp); before the plan starts, the first waypoint.
        key = np.minimum(first, dur) + plan_idx * self._stride
        i_start = np.clip(np.searchsorted(self._keys, key, side="right") - 1, offset, last)
        i_start = np.where(first < 0.0, offset, i_start).astype(np.intp)
        row_base = np.arange(n, dtype=np.intp) * (n_points + 1)
        parts: list[IntArray] = []
        nxt = i_start + 1
        active = np.flatnonzero(nxt <= last)
        while len(active):
            crossing = np.ceil((self._wp_rel_flat[nxt[active]] - first[active]) / step_s)
            inside = crossing < n_points
            active = active[inside]
            k = np.maximum(crossing[inside], 0.0).astype(np.intp)
            parts.append(row_base[active] + k)
            nxt[active] += 1
            active = active[nxt[active] <= last[active]]
        if parts:
            counts = np.bincount(np.concatenate(parts), minlength=n * (n_points + 1))
            counts = counts.reshape(n, n_points + 1)[:, :n_points]
            idx = np.cumsum(counts, axis=1)
            idx += i_start[:, None]
        else:
            idx = np.repeat(i_start[:, None], n_points, axis=1)
        rel = np.add.outer(first, np.arange(n_points) * step_s)
        # Clamp to the plan only the rows that leave it (before its start or after its end).
        leave = np.flatnonzero((first < 0.0) | (rel[:, -1] > dur))
        if len(leave):
            rel[leave] = np.clip(rel[leave], 0.0, dur[leave, None])
        out = []
        for axis in range(3):
            pos = np.take(self._seg_vel[axis], idx)
            pos *= rel
            pos += np.take(self._intercept[axis], idx)
            out.append(pos)
        return out[0], out[1], out[2]


def current_waypoint(
    plan: FlightPlan,
    frame: LocalFrame,
    *,
    east_m: float,
    north_m: float,
    alt_amsl_m: float,
    t_s: float,
    ambiguity_m: float,
) -> int:
    """Index in ``plan.waypoints`` of the waypoint a UAS at this position and time is flying
    to (see the module docstring). ``ambiguity_m`` is typically the flight geometry."""
    table = PlanTable([plan], frame)
    wp, _, _, _ = table.locate(
        np.zeros(1, dtype=np.intp),
        np.array([[east_m, north_m, alt_amsl_m]]),
        np.array([t_s]),
        np.array([ambiguity_m]),
    )
    return int(wp[0])
