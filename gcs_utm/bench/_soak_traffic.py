"""The traffic of the soak (``gcs-utm bench soak``): operations filed, flown and ended as an
operator's MQTT client would, one position report a second per flying vehicle."""

from __future__ import annotations

import asyncio
import itertools
import math
import random
from typing import TYPE_CHECKING

from gcs_utm.model import (
    FlightPlan,
    Measurement,
    MeasurementSource,
    Operation,
    OperationId,
    OperationState,
    VehicleKind,
    Waypoint4D,
)

if TYPE_CHECKING:
    from gcs_utm.app.wiring import Runtime

BOX_M = 8_000.0  # side of the square the legs cross
SPEED_MPS = 12.0
LEAD_S = 30.0  # filed this long before it starts


def _plan(
    rt: Runtime, op_id: OperationId, start_t_s: float, flight_s: float, leg: tuple[float, ...]
) -> FlightPlan:
    e0, n0, e1, n1, alt_agl_m = leg
    frame = rt.frame
    alt = frame.ground_elevation_amsl_m + alt_agl_m
    lat0, lon0 = frame.point_to_wgs84(e0, n0)
    lat1, lon1 = frame.point_to_wgs84(e1, n1)
    return FlightPlan(
        operation_id=op_id,
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=lat0, lon_deg=lon0, alt_amsl_m=alt, t_s=start_t_s),
            Waypoint4D(lat_deg=lat1, lon_deg=lon1, alt_amsl_m=alt, t_s=start_t_s + flight_s),
        ),
        created_t_s=rt.clock.now_s(),
    )


def _leg(
    rng: random.Random, flight_s: float, head_on: tuple[float, ...] | None
) -> tuple[float, ...]:
    """(east0, north0, east1, north1, alt_agl) of a straight level leg; ``head_on``: the
    reverse of that leg (same height), so the two meet half way."""
    if head_on is not None:
        e0, n0, e1, n1, alt = head_on
        return (e1, n1, e0, n0, alt)
    length_m = SPEED_MPS * flight_s
    heading = rng.uniform(0.0, 2.0 * math.pi)
    ce, cn = rng.uniform(-BOX_M / 4, BOX_M / 4), rng.uniform(-BOX_M / 4, BOX_M / 4)
    de, dn = 0.5 * length_m * math.sin(heading), 0.5 * length_m * math.cos(heading)
    return (ce - de, cn - dn, ce + de, cn + dn, rng.choice((40.0, 60.0, 80.0, 100.0)))


def _position(plan: FlightPlan, t_s: float) -> tuple[float, float, float]:
    """(lat, lon, alt) on the plan at ``t_s`` (linear between waypoints)."""
    wps = plan.waypoints
    if t_s <= wps[0].t_s:
        w = wps[0]
        return w.lat_deg, w.lon_deg, w.alt_amsl_m
    for a, b in itertools.pairwise(wps):
        if t_s <= b.t_s:
            f = (t_s - a.t_s) / (b.t_s - a.t_s) if b.t_s > a.t_s else 1.0
            return (
                a.lat_deg + f * (b.lat_deg - a.lat_deg),
                a.lon_deg + f * (b.lon_deg - a.lon_deg),
                a.alt_amsl_m + f * (b.alt_amsl_m - a.alt_amsl_m),
            )
    w = wps[-1]
    return w.lat_deg, w.lon_deg, w.alt_amsl_m


async def _fly(rt: Runtime, op_id: OperationId) -> None:
    """Start the operation at its plan's start, report once a second along its current plan
    (a resolution the operator accepted is flown), end it at the plan's end."""
    clock = rt.clock
    airspace = rt.airspace
    await clock.sleep(airspace.operation(op_id).plan.start_t_s - clock.now_s())
    airspace.set_state(op_id, OperationState.ACTIVE)
    while True:
        op = airspace.operation(op_id)
        t_s = clock.now_s()
        if t_s >= op.plan.end_t_s or op.state is not OperationState.ACTIVE:
            break
        lat, lon, alt = _position(op.plan, t_s)
        rt.usm.on_measurement(
            Measurement(
                source=MeasurementSource.MQTT,
                capture_t_s=t_s,
                receipt_t_s=t_s,
                lat_deg=lat,
                lon_deg=lon,
                alt_amsl_m=alt,
                eph_m=2.0,
                epv_m=3.0,
                operation_id=op_id,
            )
        )
        await clock.sleep(1.0)
    if airspace.operation(op_id).state is not OperationState.ENDED:
        airspace.set_state(op_id, OperationState.ENDED)
    rt.usm.log_event("operation", f"{op_id} ended by soak")


async def play_traffic(
    rt: Runtime, *, every_s: float, flight_s: float, conflict_every: int
) -> None:
    """File an operation every ``every_s`` (each flying ``flight_s``, every
    ``conflict_every``-th head-on into the one before it; 0: none), each flown by a task of
    its own."""
    rng = random.Random(7)
    flights: set[asyncio.Task[None]] = set()
    last_leg: tuple[float, ...] | None = None
    n = 0
    while True:
        n += 1
        op_id = OperationId(f"soak-{n}")
        head_on = last_leg if conflict_every and n % conflict_every == 0 else None
        leg = _leg(rng, flight_s, head_on)
        last_leg = leg
        plan = _plan(rt, op_id, rt.clock.now_s() + LEAD_S, flight_s, leg)
        rt.airspace.add_operation(
            Operation(
                id=op_id,
                icao24=None,
                sys_id=None,
                priority=rng.randint(1, 3),
                plan=plan,
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=SPEED_MPS,
                flight_geometry_m=20.0,
                operational_volume_m=40.0,
            )
        )
        rt.usm.log_event("operation", f"{op_id} filed by soak")
        task = asyncio.create_task(_fly(rt, op_id), name=f"soak-{op_id}")
        flights.add(task)
        task.add_done_callback(flights.discard)
        await rt.clock.sleep(every_s)
