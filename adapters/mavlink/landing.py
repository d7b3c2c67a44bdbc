"""A plan uploaded to a vehicle with a landing sequence keeps that sequence as the autopilot
flies it (pure; docs/autopilots.md, "Landing sequences").

The plan filed from a vehicle's mission models its landing as waypoints (the approach, the
landing point on the ground); a plan derived from it (back_to_plan, a re-plan, a detour that
rejoins it) ends with them. Sent as NAV_WAYPOINTs they are not a landing: a PX4 plane given
a waypoint at its landing point circled it 0-4 m above the ground. So :func:`cut_landing`
takes the plan's last waypoints that lie on the landing (within :data:`CORRIDOR_M`
horizontally of the track through the sequence's positions, and no higher than its highest
position plus :data:`ABOVE_M`: a plan that passes above the landing is not it)
off the plan; the upload sends the rest, then the sequence itself (DO_LAND_START, approach,
NAV_LAND / NAV_VTOL_LAND with their own frames and positions). A plan that starts on the
landing (the vehicle was already on its approach) starts at the landing item it joins: the
first sequence position at or after the point of the landing it flies to first.

A plan that does not reach the landing is followed by the sequence when the sequence starts
at DO_LAND_START or the vehicle cannot hover (a fixed wing circles at a plan's end, at the
plan's altitude, until its landing is flown); a multirotor's plan that ends elsewhere (a hold,
a landing site) ends there, as planned.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

from adapters.mavlink.mission import (
    MAV_CMD_DO_LAND_START,
    MissionItem,
    frame_family,
    is_nav,
    with_landing,
)
from gcs_utm.model import FlightPlan, VehicleKind, Waypoint4D

CORRIDOR_M = 5.0
"""A plan waypoint this close (horizontally) to the landing's track is on it: the filed plan
holds the items' own positions (1e-7 deg) and back_to_plan points on the segments between
them; a flat-earth projection differs from the planner's by far less over a landing's km."""
ABOVE_M = 5.0
"""A plan waypoint more than this above the landing's highest position is not its landing
(a plan that crosses it at cruise height): it is flown, then the whole sequence."""
_M_PER_DEG_LAT = 110_540.0
_M_PER_DEG_LON = 111_320.0
_RELATIVE = 3  # frame family of MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT)
_GLOBAL = 0


@dataclass(frozen=True, slots=True)
class LandingCut:
    """The plan to send before the landing sequence, where it starts, and how it meets the
    landing."""

    plan: FlightPlan  # the plan without its landing (at least its first waypoint)
    start_index: int  # the waypoint of ``plan`` to start at (when ``join`` is None)
    join: int | None  # the index in the sequence to start at: the plan started on the landing
    reaches: bool  # the plan went on to the landing (its last waypoints were on it)


@dataclass(frozen=True, slots=True)
class _Fix:
    """A sequence position: its index in the sequence, east/north metres, AMSL (None: its
    frame cannot be resolved here)."""

    index: int
    east_m: float
    north_m: float
    alt_amsl_m: float | None


def follows_plan(landing: list[MissionItem], kind: VehicleKind | None) -> bool:
    """Whether ``landing`` goes after a plan that does not reach it (module docstring)."""
    if not landing:
        return False
    return landing[0].command == MAV_CMD_DO_LAND_START or kind is VehicleKind.FIXED_WING


def plan_mission(
    plan: FlightPlan,
    landing: list[MissionItem],
    build: Callable[[FlightPlan, int], list[MissionItem]],
    *,
    start_index: int = 0,
    kind: VehicleKind | None = None,
    home_alt_m: float | None = None,
) -> list[MissionItem]:
    """The mission that flies ``plan`` and then ``landing`` as the autopilot flies it:
    ``build(plan, start_index)`` encodes the plan's part before the landing
    (:func:`~adapters.mavlink.mission.plan_to_mission_items`), the sequence follows it when
    the plan reached it or :func:`follows_plan` (module docstring)."""
    cut = cut_landing(plan, landing, start_index, home_alt_m)
    items = build(cut.plan, cut.start_index)
    if cut.reaches or follows_plan(landing, kind):
        items = with_landing(items, landing, current=cut.join)
    return items


def cut_landing(
    plan: FlightPlan,
    landing: list[MissionItem],
    start_index: int,
    home_alt_m: float | None = None,
) -> LandingCut:
    """``plan`` without the waypoints that model ``landing`` (module docstring).
    ``home_alt_m`` resolves items in a relative-altitude frame (None: compared horizontally
    only). ``start_index`` is where the plan would start."""
    wps = plan.waypoints
    lat0 = wps[0].lat_deg
    fixes = _fixes(landing, lat0, home_alt_m)
    if not fixes or not 0 <= start_index < len(wps):  # (plan_to_mission_items says why)
        return LandingCut(plan, start_index, None, False)
    m = len(wps)
    while m > 0 and _on_landing(wps[m - 1], fixes, lat0) is not None:
        m -= 1
    if m == len(wps):
        return LandingCut(plan, start_index, None, False)
    kept = FlightPlan(
        operation_id=plan.operation_id,
        version=plan.version,
        waypoints=wps[: max(m, 1)],
        created_t_s=plan.created_t_s,
        reason=plan.reason,
    )
    join = _on_landing(wps[start_index], fixes, lat0) if start_index >= m else None
    return LandingCut(kept, min(start_index, len(kept.waypoints) - 1), join, True)


def _fixes(landing: list[MissionItem], lat0: float, home_alt_m: float | None) -> list[_Fix]:
    k = math.cos(math.radians(lat0))
    out: list[_Fix] = []
    for i, it in enumerate(landing):
        if not is_nav(it.command) or (it.x, it.y) == (0, 0):
            continue  # DO items, and a landing "here" (no position of its own)
        family = frame_family(it.frame)
        alt: float | None = None
        if family == _GLOBAL:
            alt = it.z
        elif family == _RELATIVE and home_alt_m is not None:
            alt = it.z + home_alt_m
        east = it.lon_deg * _M_PER_DEG_LON * k
        out.append(_Fix(i, east, it.lat_deg * _M_PER_DEG_LAT, alt))
    return out


def _on_landing(w: Waypoint4D, fixes: list[_Fix], lat0: float) -> int | None:
    """The sequence index ``w`` joins when it lies on the landing (the first position at or
    after its point of the track), else None."""
    alts = [f.alt_amsl_m for f in fixes if f.alt_amsl_m is not None]
    if alts and w.alt_amsl_m > max(alts) + ABOVE_M:
        return None
    k = math.cos(math.radians(lat0))
    e, n = w.lon_deg * _M_PER_DEG_LON * k, w.lat_deg * _M_PER_DEG_LAT
    if math.hypot(e - fixes[0].east_m, n - fixes[0].north_m) <= CORRIDOR_M:
        return fixes[0].index
    for a, b in itertools.pairwise(fixes):
        de, dn = b.east_m - a.east_m, b.north_m - a.north_m
        length2 = de * de + dn * dn
        t = 0.0 if length2 == 0.0 else ((e - a.east_m) * de + (n - a.north_m) * dn) / length2
        t = min(1.0, max(0.0, t))
        if math.hypot(e - (a.east_m + t * de), n - (a.north_m + t * dn)) <= CORRIDOR_M:
            return b.index
    return None
