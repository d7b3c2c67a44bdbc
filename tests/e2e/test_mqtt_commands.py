"""Operator commands over MQTT, end to end: the project's pilot station (``PilotStation``, as
``gcs-utm pilot`` runs it) sends ``hold`` on alice's ``commands`` topic of a real mosquitto
(password file + the gcs-utm ACL), the gateway hands it to the USM, the USM sends it to a
``sitl`` PX4 over the real MAVLink hub, and the outcome (``confirmed``, the mode read back
from HEARTBEAT) comes back on alice's ``status`` topic. bob, who does not fly the UAS, is
refused with the reason; the broker drops bob's publish on alice's topic (ACL)."""

from __future__ import annotations

import asyncio
import contextlib
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mqtt"))

from mqtt_helpers import make_broker, peer

import sitl
from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.mqtt.codec import Topics
from adapters.mqtt.station import PilotStation
from gcs_utm.clock import ScaledClock
from gcs_utm.messages import FlightMode
from gcs_utm.model import (
    AuditEntry,
    FlightPlan,
    Operation,
    OperationId,
    SysId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm

pytestmark = [pytest.mark.network, pytest.mark.timeout(90)]

HOME = (47.397742, 8.545594, 488.0)
T = Topics("gcs_utm")


def _op(t0_s: float) -> Operation:
    """alice's operation, flown by system id 1."""
    wps = tuple(
        Waypoint4D(
            lat_deg=HOME[0] + 0.001 * k,
            lon_deg=HOME[1],
            alt_amsl_m=HOME[2] + 15.0,
            t_s=t0_s + 30.0 * k,
        )
        for k in (1, 2, 3)
    )
    return Operation(
        id=OperationId("UAS1"),
        icao24=None,
        sys_id=SysId(1),
        priority=1,
        plan=FlightPlan(operation_id=OperationId("UAS1"), version=1, waypoints=wps),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
        operator="alice",
    )


async def test_a_station_holds_its_uas_over_mqtt_and_another_operator_is_refused(
    tmp_path: Path,
) -> None:
    broker = make_broker(tmp_path)
    clock = ScaledClock(5.0)
    sim = sitl.SimTime(5.0, start_utc_s=clock.start_utc_s, start_mono_s=clock.start_mono_s)
    records: list[object] = []
    airspace = Airspace()
    airspace.load([_op(clock.now_s())], ())
    usm = Usm(airspace, clock, record=records.append)
    gateway = MqttGateway(usm, broker.config())
    gateway.attach()
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    spec_mission = tuple(
        sitl.MissionItemSpec(lat_deg=w.lat_deg, lon_deg=w.lon_deg, alt_amsl_m=w.alt_amsl_m)
        for w in airspace.operation(OperationId("UAS1")).plan.waypoints
    )
    try:
        async with MavlinkHub(cfg, clock, usm) as hub:
            usm.attach_vehicles(hub)
            spec = sitl.VehicleSpec(
                instance=0,
                home_lat_deg=HOME[0],
                home_lon_deg=HOME[1],
                home_alt_amsl_m=HOME[2],
                mission=spec_mission,
                auto_start_at_s=1.0,
                gcs_port=hub.local_port(next(iter(hub._links))),
                bind_port=0,
            )
            gw_task = asyncio.create_task(gateway.run())
            try:
                async with (
                    sitl.Fleet([spec], sim) as fleet,
                    PilotStation(broker.config("alice"), "alice", clock) as alice,
                    PilotStation(broker.config("bob"), "bob", clock) as bob,
                    peer(broker, "bob", (T.status("bob"),)) as bob_raw,
                ):
                    await gateway.bridge.wait_connected(5.0)
                    end = time.monotonic() + 30.0
                    while not (
                        (s := usm.statuses_by_sys_id().get(SysId(1))) is not None
                        and s.mode is FlightMode.MISSION
                        and any(f.airborne for f in usm.flight.values())
                    ):
                        assert time.monotonic() < end, "the vehicle never flew its mission"
                        await asyncio.sleep(0.05)
                    # bob cannot reach alice's topic at all (the broker's ACL drops it) ...
                    await bob_raw.send(
                        T.commands("alice"),
                        {
                            "schema_version": 1,
                            "type": "operator_command",
                            "uas": "UAS1",
                            "command": "land",
                            "id": "bob-1",
                        },
                    )
                    # ... and on his own topic gcs-utm refuses: he does not fly UAS1
                    refused = await bob.command("UAS1", "land", timeout_s=10.0)
                    assert refused.outcome == "refused"
                    assert refused.reason == "operator 'bob' does not fly UAS1"
                    ack = await alice.command("UAS1", "hold", request_id="a-1", timeout_s=20.0)
                    mode = usm.statuses_by_sys_id()[SysId(1)].mode
                    vehicle_mode = fleet.vehicles[0].mode
                    # the same id again (a station re-sending): not sent twice
                    again = await alice.command("UAS1", "hold", request_id="a-1", timeout_s=10.0)
            finally:
                gw_task.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await gw_task
            await usm.drain()
    finally:
        broker.stop()
    assert (ack.outcome, ack.uas, ack.command, ack.mode) == ("confirmed", "UAS1", "hold", "hold")
    assert mode is FlightMode.HOLD and vehicle_mode == "HOLD"
    assert again == ack
    audit = [r for r in records if isinstance(r, AuditEntry)]
    mine = [(a.actor, a.action, a.detail["outcome"]) for a in audit if a.action.startswith("op")]
    assert mine == [
        ("operator:bob", "operator_land", "refused"),
        ("operator:alice", "operator_hold", "confirmed"),
    ]
    sent = [a for a in audit if a.action.startswith("command_")]
    assert [(a.action, a.detail["reason"]) for a in sent] == [
        ("command_hold", "operator alice (mqtt)")
    ]
