"""Issue 31, threat lifecycle on real ArduCopter: a threat closes when its cause is gone, with
the reason in the audit (a link loss that ends: test_links.py).

- The fix is back: a copter hovering in GUIDED loses its GPS (SITL's ``SIM_GPS_DISABLE``);
  GNSS_DEGRADATION opens, and closes once the fix is back while it still flies.
- The vehicle landed: the same copter's battery falls below the reserve (a smaller
  ``BATT_CAPACITY`` than it has used); LACK_OF_BATTERY, which nothing the vehicle reports in
  the air ends, closes when the pilot has landed it and it disarmed.

``gcs-utm serve`` runs in this process (``OperatorMode.NONE``: nobody answers, nothing is
commanded) on SERIAL0; the pilot flies on SERIAL1 (pilot.py).
"""

from __future__ import annotations

import asyncio
import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from adapters.mavlink import MavlinkConfig
from gcs_utm.app import Runtime
from gcs_utm.model import (
    Operation,
    OperationId,
    SysId,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)
from gcs_utm.settings import AirspaceConfig, Settings
from gcs_utm.store import Store
from tests.autopilot.autopilots import ARDUPILOT_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import file_operations, serve_while, until
from tests.autopilot.pilot import PilotLink, offset_deg
from tests.autopilot.test_links import _operation

SPEED = 5.0
HOVER_AGL_M = 12.0
APART_M = 30.0  # the two copters' homes: inside the 50 m horizontal minimum
LAND = 9  # ArduCopter's LAND mode
# Without GPS the EKF's position variance grows and its failsafe lands the copter (FS_EKF_*):
# kept off here, so that the fix comes back while the copter is still in the air.
NO_EKF_FAILSAFE = "FS_EKF_THRESH 0\n"


def _settings(links: tuple[str, ...]) -> Settings:
    lat, lon, ground_m, _ = ARDUPILOT_DEFAULT_HOME
    return dataclasses.replace(
        Settings(),
        airspace=AirspaceConfig(
            origin_lat_deg=lat, origin_lon_deg=lon, ground_elevation_amsl_m=ground_m
        ),
        mavlink=MavlinkConfig(links=links, reconnect_min_s=0.2, reconnect_max_s=1.0),
    )


def _open(rt: Runtime, kind: ThreatKind, op_id: OperationId) -> bool:
    return any(t.kind is kind and op_id in t.uas_ids for t in rt.usm.threats.values())


async def _hover(pilot: PilotLink) -> None:
    """Once ready, the copter takes off in GUIDED and hovers ``HOVER_AGL_M`` above its home
    (in the air: on the ground these hazards are pre-flight findings)."""
    await asyncio.to_thread(pilot.wait_ready)
    await asyncio.to_thread(pilot.arm_and_start, 60.0, HOVER_AGL_M, auto=False)


def _battery_used_mah(pilot: PilotLink) -> float:
    """The charge the copter has drawn so far (BATTERY_STATUS.current_consumed)."""
    m = pilot.wait("BATTERY_STATUS", 10.0, lambda m: m.current_consumed > 0)
    return float(m.current_consumed)


@pytest.mark.timeout(240)
async def test_gnss_and_battery_threats_close_when_the_fix_is_back_and_it_landed(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    db = tmp_path / "utm.sqlite"
    op = _operation()
    file_operations(db, op)
    parm = tmp_path / "no-ekf-failsafe.parm"
    parm.write_text(NO_EKF_FAILSAFE)

    async def scenario(rt: Runtime) -> None:
        ardupilot(instance=0, vehicle="copter", speed=SPEED, defaults=(parm,))
        await until(lambda: op.id in rt.tracks(), 90.0, "no track of the operation")
        pilot = await asyncio.to_thread(PilotLink, 0, "ardupilot", 5762)
        try:
            await _hover(pilot)
            await until(lambda: rt.airspace.airborne(op.id), 30.0, "not airborne")
            # 1. the fix goes and comes back
            await asyncio.to_thread(pilot.set_params, {"SIM_GPS_DISABLE": 1.0})
            gnss = ThreatKind.GNSS_DEGRADATION
            await until(lambda: _open(rt, gnss, op.id), 30.0, "no GNSS_DEGRADATION")
            await asyncio.to_thread(pilot.set_params, {"SIM_GPS_DISABLE": 0.0})
            await until(lambda: not _open(rt, gnss, op.id), 30.0, "GNSS threat stayed open")
            assert rt.airspace.airborne(op.id), "closed by a landing, not by the fix"
            # 2. the battery runs low; the pilot lands
            used = await asyncio.to_thread(_battery_used_mah, pilot)
            capacity = float(max(1, round(used * 1.1)))  # about 9 % left
            await asyncio.to_thread(pilot.set_params, {"BATT_CAPACITY": capacity})
            low = ThreatKind.LACK_OF_BATTERY
            await until(lambda: _open(rt, low, op.id), 30.0, "no LACK_OF_BATTERY")
            await asyncio.to_thread(pilot.set_mode, LAND)
            await until(lambda: not _open(rt, low, op.id), 60.0, "battery threat stayed open")
        finally:
            pilot.close()

    t0 = time.monotonic()
    await serve_while(_settings(("tcp:127.0.0.1:5760",)), db, scenario, SPEED)
    print(f"threats closed in {time.monotonic() - t0:.1f} s wall")
    with Store(db) as s:
        threats = {t.id: t for t in s.load_threats()}
        reasons = {
            threats[a.subject].kind: str(a.detail["reason"])
            for a in s.load_audit()
            if a.actor == "usm" and a.action == "threat_closed" and a.subject in threats
        }
    closed = {t.kind for t in threats.values() if t.status is ThreatStatus.CLOSED}
    assert {ThreatKind.GNSS_DEGRADATION, ThreatKind.LACK_OF_BATTERY} <= closed, threats
    assert reasons[ThreatKind.GNSS_DEGRADATION].startswith("GNSS fix back"), reasons
    assert (
        "on the ground" in reasons[ThreatKind.LACK_OF_BATTERY]
        or "landed" in reasons[ThreatKind.LACK_OF_BATTERY]
    ), reasons


def _second(op: Operation, east_m: float) -> Operation:
    """``op`` flown by sysid 2 as AP2, its plan ``east_m`` east."""
    op_id = OperationId("AP2")
    wps = tuple(
        dataclasses.replace(w, lon_deg=offset_deg(w.lat_deg, w.lon_deg, east_m, 0.0)[1])
        for w in op.plan.waypoints
    )
    plan = dataclasses.replace(op.plan, operation_id=op_id, waypoints=wps)
    return dataclasses.replace(op, id=op_id, sys_id=SysId(2), plan=plan)


@pytest.mark.timeout(240)
async def test_a_loss_of_separation_closes_when_the_other_copter_lands(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """Two copters hover ``APART_M`` apart at the same height: a loss of separation, open
    while both fly; it closes once the other one has landed, the reason in the audit."""
    db = tmp_path / "utm.sqlite"
    ops = [_operation(), _second(_operation(), APART_M)]
    file_operations(db, *ops)
    lat, lon, ground_m, heading = ARDUPILOT_DEFAULT_HOME
    homes = [
        ARDUPILOT_DEFAULT_HOME,
        (lat, offset_deg(lat, lon, APART_M, 0.0)[1], ground_m, heading),
    ]

    def los(rt: Runtime) -> list[Threat]:
        return [t for t in rt.usm.threats.values() if t.kind is ThreatKind.LOSS_OF_SEPARATION]

    async def scenario(rt: Runtime) -> ThreatId:
        for i, home in enumerate(homes):
            ardupilot(instance=i, vehicle="copter", speed=SPEED, home=home)
        await until(lambda: all(o.id in rt.tracks() for o in ops), 90.0, "no tracks")
        pilots = [await asyncio.to_thread(PilotLink, i, "ardupilot", 5762 + 10 * i) for i in (0, 1)]
        try:
            for p in pilots:
                await asyncio.to_thread(p.wait_ready)
            for p in pilots:
                await asyncio.to_thread(p.arm_and_start, 60.0, HOVER_AGL_M, auto=False)
            await until(lambda: bool(los(rt)), 30.0, "no loss of separation")
            threat_id = los(rt)[0].id
            await asyncio.to_thread(pilots[1].set_mode, LAND)
            await until(lambda: not los(rt), 60.0, "the loss of separation stayed open")
            # EM audits the closing from its queue: serve must not stop before it has
            await until(lambda: rt.emergency.em.case(threat_id) is None, 10.0, "EM's case open")
            assert rt.airspace.airborne(ops[0].id), "the first copter came down too"
        finally:
            for p in pilots:
                p.close()
        return threat_id

    links = ("tcp:127.0.0.1:5760", "tcp:127.0.0.1:5770")
    threat_id = await serve_while(_settings(links), db, scenario, SPEED)
    with Store(db) as s:
        threat = next(t for t in s.load_threats() if t.id == threat_id)
        audit = [a for a in s.load_audit() if a.subject == threat.id]
    assert threat.status is ThreatStatus.CLOSED, threat
    reasons = [str(a.detail.get("reason", "")) for a in audit if a.action == "threat_closed"]
    # landed by its own messages: the operation LANDED, or its vehicle on the ground
    why = ("closed: operation AP2 landed", "closed: AP2 is on the ground")
    assert any(w in r for r in reasons for w in why), (reasons, threat.message)


# ArduPilot's simulated ADS-B receiver (test_adsb_relay.py) on a second copter that only relays:
# aircraft within RELAY_RADIUS_M of home at the hovering copter's altitude (SIM_ADSB_ALT is
# reported as the aircraft's altitude), inside the intruder minima (150 m, 50 m).
RELAY_RADIUS_M = 300.0
RELAY_PARAMS = f"""SERIAL5_PROTOCOL 2
ADSB_TYPE 1
SIM_ADSB_COUNT 3
SIM_ADSB_RADIUS {RELAY_RADIUS_M:g}
SIM_ADSB_ALT {ARDUPILOT_DEFAULT_HOME[2] + HOVER_AGL_M:g}
"""


@pytest.mark.timeout(240)
async def test_an_intruder_threat_closes_when_the_intruder_is_no_longer_heard(
    ardupilot: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    """A copter hovers; ADS-B aircraft relayed by a second autopilot (disarmed on the ground
    below it: no intruder) come inside the intruder minima (INTRUDER threats). The relay
    stops (its process killed): the aircraft are no longer heard, tracking drops them after
    ``[tracking] intruder_drop_after_s`` and their threats close, the reason in the audit."""
    db = tmp_path / "utm.sqlite"
    op = _operation()
    file_operations(db, op)
    parm = tmp_path / "relay.parm"
    parm.write_text(RELAY_PARAMS)

    def intruder_threats(rt: Runtime) -> set[ThreatId]:
        return {t.id for t in rt.usm.threats.values() if t.kind is ThreatKind.INTRUDER}

    async def scenario(rt: Runtime) -> set[ThreatId]:
        ardupilot(instance=0, vehicle="copter", speed=SPEED)
        await until(lambda: op.id in rt.tracks(), 90.0, "no track of the operation")
        pilot = await asyncio.to_thread(PilotLink, 0, "ardupilot", 5762)
        try:
            await _hover(pilot)
        finally:
            pilot.close()
        relay = ardupilot(
            instance=1,
            vehicle="copter",
            speed=SPEED,
            defaults=(parm,),
            extra_args=("--serial5=sim:adsb",),
        )
        await until(lambda: bool(intruder_threats(rt)), 90.0, "no INTRUDER threat")
        relay.stop()  # the aircraft are no longer heard
        opened = intruder_threats(rt)
        await until(lambda: not intruder_threats(rt), 60.0, "an INTRUDER threat stayed open")
        # EM audits each closing from its queue: serve must not stop before it has
        await until(
            lambda: all(rt.emergency.em.case(t) is None for t in opened), 10.0, "EM's case open"
        )
        return opened

    links = ("tcp:127.0.0.1:5760", "tcp:127.0.0.1:5770")
    opened = await serve_while(_settings(links), db, scenario, SPEED)
    with Store(db) as s:
        reasons = {
            a.subject: str(a.detail.get("reason", ""))
            for a in s.load_audit()
            if a.action == "threat_closed" and a.subject in opened
        }
        intruders = {t.intruder_id for t in s.load_threats() if t.kind is ThreatKind.INTRUDER}
    # the relay itself, disarmed on the ground below the copter, is no intruder
    assert all(str(i).startswith("icao:") for i in intruders), intruders
    print(f"intruder threats closed: {reasons}")
    assert set(reasons) == opened, (reasons, opened)
    # each closed once its aircraft was dropped (or, in the seconds before its track went
    # stale, flew clear of the copter): at least one closed because it was no longer heard
    assert any("is no longer tracked" in r for r in reasons.values()), reasons
