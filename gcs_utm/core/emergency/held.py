"""Where a UAS told to hold will be: what the re-check before an upload takes it as.

EM may decide two threats in one cycle: a hold for one UAS (its new plan failed its own
re-check) and a new plan for another. The plan was verified against the held UAS's plan,
which moves on, while the vehicle stops where it was told to hold; a plan accepted that way
was flown past the held multirotor at 47.5 m / 17 m (``enc_3_0219_endpoint_near_threshold``,
UAS5 past UAS2). So :mod:`.recheck` takes a UAS whose newest live recommendation is a HOLD
command as holding: from its track, braking along its velocity to a stop (its stopping
distance at its speed, :meth:`~gcs_utm.envelope.PerformanceEnvelope.stopping_distance_m`),
then at that point up to ``until_t_s``. So is a fixed wing in the air whose plan has ended
away from its end point (:func:`circling_elsewhere`: held, or sent on, by a command; TD's
traffic takes it at its last waypoint): it is taken at the point where it stops, the centre
of the circle it flies there. Pure.
"""

from __future__ import annotations

import math
from dataclasses import replace

from gcs_utm.geo import LocalFrame
from gcs_utm.model import AirspaceSnapshot, FlightPlan, Operation, Waypoint4D

BRAKE_ACCEL_MPS2 = 2.5
"""Deceleration for the time braking takes (the envelope's default horizontal acceleration:
the stop point comes from the envelope itself)."""


def held_plan(
    op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame, until_t_s: float
) -> FlightPlan | None:
    """``op``'s plan replaced by a hold where its fresh track stops (see the module doc), or
    None when it has no fresh track."""
    tr = next(
        (t for t in snapshot.tracks.values() if t.operation_id == op.id and not t.stale), None
    )
    if tr is None:
        return None
    now = max(snapshot.t_s, tr.t_s)
    speed = math.hypot(tr.vel_enu_mps[0], tr.vel_enu_mps[1])
    e, n = frame.point_to_local(tr.lat_deg, tr.lon_deg)
    stop_m = op.performance().stopping_distance_m(speed)
    if speed > 0.1:
        e += tr.vel_enu_mps[0] / speed * stop_m
        n += tr.vel_enu_mps[1] / speed * stop_m
    lat, lon = frame.point_to_wgs84(e, n)
    here = Waypoint4D(lat_deg=tr.lat_deg, lon_deg=tr.lon_deg, alt_amsl_m=tr.alt_amsl_m, t_s=now)
    if stop_m <= 0.0:  # a fixed wing (or a vehicle at rest): it stays round here
        return replace(op.plan, waypoints=(here, replace(here, t_s=max(until_t_s, now + 1.0))))
    stop_t = now + speed / BRAKE_ACCEL_MPS2
    stop = Waypoint4D(lat_deg=lat, lon_deg=lon, alt_amsl_m=tr.alt_amsl_m, t_s=stop_t)
    return replace(op.plan, waypoints=(here, stop, replace(stop, t_s=max(until_t_s, stop_t + 1.0))))


def circling_elsewhere(op: Operation, snapshot: AirspaceSnapshot, frame: LocalFrame) -> bool:
    """Is ``op`` a fixed wing in the air whose plan has ended, with a fresh track more than
    two loiter radii from its last waypoint (it circles a commanded point, not its end)?"""
    env = op.performance()
    if env.can_hover or op.id not in snapshot.airborne or op.plan.end_t_s > snapshot.t_s:
        return False
    tr = next(
        (t for t in snapshot.tracks.values() if t.operation_id == op.id and not t.stale), None
    )
    if tr is None:
        return False
    last = op.plan.waypoints[-1]
    e0, n0 = frame.point_to_local(last.lat_deg, last.lon_deg)
    e1, n1 = frame.point_to_local(tr.lat_deg, tr.lon_deg)
    return math.hypot(e1 - e0, n1 - n0) > 2.0 * env.turn_radius_m
