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

import numpy as np
import numpy.typing as npt

from gcs_utm.geo import LocalFrame
from gcs_utm.model import FlightPlan

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

# A closest point this close to a segment's end (as a fraction of the segment) counts as
# having reached that end's waypoint.
_REACHED_U = 1.0 - 1e-9


class PlanTable:
    """All plans of the airspace, row j = ``plans[j]``."""

    def __init__(self, plans: Sequence[FlightPlan], frame: LocalFrame) -> None:
        self.n_plans = len(plans)
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
        start = np.array([p.start_t_s for p in plans], dtype=np.float64)
        end = np.array([p.end_t_s for p in plans], dtype=np.float64)
        self.start_t_s: FloatArray = start
        self.end_t_s: FloatArray = end
        # Sorted search keys: plan-relative time shifted by j * stride keeps each plan in its
        # own interval without the precision loss of adding large offsets to POSIX times.
        duration = end - start
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

    def locate(
        self, plan_idx: IntArray, pos_m: FloatArray, t_s: FloatArray, ambiguity_m: FloatArray
    ) -> tuple[IntArray, FloatArray, FloatArray]:
        """For N tracks on plans ``plan_idx`` at positions ``pos_m`` (N, 3) and times ``t_s``:
        (current waypoint index within the plan, distance to the plan [m], plan time at the
        closest point [s])."""
        a = self.seg_a[plan_idx]
        d = self.seg_b[plan_idx] - a
        rel = pos_m[:, None, :] - a
        len2 = np.einsum("nsk,nsk->ns", d, d)
        dot = np.einsum("nsk,nsk->ns", rel, d)
        safe = np.where(len2 > 0.0, len2, 1.0)
        u = np.clip(np.where(len2 > 0.0, dot / safe, 0.0), 0.0, 1.0)
        off = rel - u[:, :, None] * d
        dist = np.sqrt(np.einsum("nsk,nsk->ns", off, off))
        valid = self.seg_valid[plan_idx]
        dist = np.where(valid, dist, np.inf)
        ta = self.seg_ta[plan_idx]
        tau = ta + u * (self.seg_tb[plan_idx] - ta)
        dmin = dist.min(axis=1)
        cand = dist <= (dmin + ambiguity_m)[:, None]
        cost = np.where(cand, np.abs(t_s[:, None] - tau), np.inf)
        rows = np.arange(len(plan_idx))
        seg = np.argmin(cost, axis=1)
        seg_u = u[rows, seg]
        seg_tau = tau[rows, seg]
        n_wp = self.n_waypoints[plan_idx]
        # Reached the end of this segment: the UAS now flies to the following waypoint.
        reached = (seg_u >= _REACHED_U) & (seg + 2 < n_wp)
        seg = np.where(reached, seg + 1, seg)
        waypoint = np.where(n_wp >= 2, seg + 1, 0).astype(np.intp)
        return waypoint, dmin, seg_tau

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

        Why not ``searchsorted``: the grid is regular, so the waypoint index of every point
        is a count of the waypoints whose time has been crossed; each crossing is one integer
        ``ceil((t_wp - t_first) / step)``, scattered and summed along the row. That and
        ``take`` on flat per-waypoint tables are several times faster than a binary search and
        (N, K, 3) fancy indexing."""
        n = len(plan_idx)
        start = self.start_t_s[plan_idx]
        dur = self.end_t_s[plan_idx] - start
        first = (tau0_s - start) + first_ahead_s  # plan-relative time of point 0
        ks = np.arange(n_points, dtype=np.float64)
        rel = np.clip(first[:, None] + ks[None, :] * step_s, 0.0, dur[:, None])
        # Index of the first point at or after each waypoint's time; waypoint 0 (time 0) is
        # always crossed because rel >= 0.
        wp_rel = self._wp_rel_pad[plan_idx]  # (N, M), +inf padding never crossed
        cross = np.ceil((wp_rel - first[:, None]) / step_s)
        cross = np.clip(np.nan_to_num(cross, posinf=n_points), 0, n_points).astype(np.intp)
        counts = np.zeros((n, n_points + 1), dtype=np.intp)
        np.add.at(counts, (np.repeat(np.arange(n), cross.shape[1]), cross.ravel()), 1)
        # Before the plan starts no waypoint is crossed yet; the clamped time sits on wp 0.
        idx = np.maximum(np.cumsum(counts[:, :n_points], axis=1), 1)
        i0 = (self.wp_offset[plan_idx][:, None] + idx - 1).ravel()
        dt = rel.ravel() - np.take(self._wp_rel_flat, i0)
        out = []
        for axis in range(3):
            pos = np.take(self._wp_axis[axis], i0) + dt * np.take(self._seg_vel[axis], i0)
            out.append(pos.reshape(n, n_points))
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
    wp, _, _ = table.locate(
        np.zeros(1, dtype=np.intp),
        np.array([[east_m, north_m, alt_amsl_m]]),
        np.array([t_s]),
        np.array([ambiguity_m]),
    )
    return int(wp[0])
