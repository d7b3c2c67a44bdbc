"""Flight modes, kinematics and faults, stepping a Vehicle directly (no sockets)."""

from __future__ import annotations

import math

import sitl
from sitl.vehicle import Vehicle

HOME = (47.397742, 8.545594, 488.0)


def make(**kw: object) -> Vehicle:
    spec = sitl.VehicleSpec(instance=0, **kw)  # type: ignore[arg-type]
    return Vehicle(spec, sitl.SimTime(start_utc_s=1_700_000_000.0))


def run(v: Vehicle, until_s: float, t0: float = 0.0) -> float:
    t = t0
    while t < until_s:
        t += 0.5
        v.advance(t)
    return t


def dist_m(v: Vehicle, lat: float, lon: float) -> float:
    dn = (v.lat_deg - lat) * 111_200.0
    de = (v.lon_deg - lon) * 111_200.0 * math.cos(math.radians(lat))
    return math.hypot(dn, de)


WPS = (
    sitl.MissionItemSpec(lat_deg=47.3986, lon_deg=8.5456, alt_amsl_m=510.0),
    sitl.MissionItemSpec(lat_deg=47.3986, lon_deg=8.5470, alt_amsl_m=510.0, speed_mps=4.0),
)


def test_multirotor_flies_mission_then_rtl_and_lands() -> None:
    v = make(mission=WPS, auto_start_at_s=1.0)
    t = run(v, 20.0)
    assert v.armed and not v.landed and v.mode == "MISSION"
    t = run(v, 90.0, t)
    assert dist_m(v, 47.3986, 8.5470) < 3.0 and abs(v.alt_amsl_m - 510.0) < 1.5
    assert v.mission_current_seq == 2
    # the DO_CHANGE_SPEED(4 m/s) item governed the last leg
    assert v.k.airspeed_mps < 4.5
    assert v.commands.request_mode("RTL") == 0
    t = run(v, 200.0, t)
    assert v.landed and not v.armed and dist_m(v, HOME[0], HOME[1]) < 1.5
    assert v.position_history and v.position_history[-1][0] > 1_700_000_000.0


def test_takeoff_hold_land_and_fixed_wing_loiter() -> None:
    v = make()
    assert v.arm() == 0
    v.flight.takeoff_alt_m = HOME[2] + 15.0
    assert v.commands.request_mode("TAKEOFF") == 0
    t = run(v, 15.0)
    assert v.mode == "HOLD" and abs(v.alt_amsl_m - 503.0) < 1.0
    assert v.commands.request_mode("LAND") == 0
    run(v, 40.0, t)
    assert v.landed and not v.armed

    fw = make(kind="fixed_wing", auto_start_at_s=0.0, takeoff_alt_rel_m=40.0)
    t = run(fw, 60.0)
    assert fw.mode == "HOLD" and not fw.landed
    # loiter: keeps flying (never hovers) within ~2 radii of the hold point
    speeds = []
    for _ in range(40):
        t += 0.5
        fw.advance(t)
        speeds.append(math.hypot(fw.k.vn_mps, fw.k.ve_mps))
    assert min(speeds) >= 11.0
    n, e = fw.flight.goal_ne
    assert math.hypot(fw.k.north_m - n, fw.k.east_m - e) < 2.5 * fw.lim.loiter_radius_m


def test_gnss_jamming_degrades_fix_and_drifts() -> None:
    v = make(
        faults=(
            sitl.FaultSpec(kind=sitl.FaultKind.GNSS_JAMMING, at_s=2.0, duration_s=30.0, value=3.0),
        )
    )
    run(v, 1.0)
    assert v.faults.gps_fix_type() == 3
    t = run(v, 20.0, 1.0)
    assert v.faults.gps_fix_type() < 3 and v.telemetry.health() & 32 == 0
    lat, _, _ = v.reported_position()
    assert abs(lat - v.lat_deg) * 111_000 > 10.0
    assert any("jamming" in s for _, _, s in v.statustexts)
    assert v.arm() != 0  # no arming without a 3D fix
    run(v, 40.0, t)
    assert v.faults.gps_fix_type() == 3 and any("recovered" in s for _, _, s in v.statustexts)


def test_jamming_drift_advances_per_simulated_second_not_per_message() -> None:
    """The documented drift rate (the fault's value, m/s at full jamming level) holds per
    simulated second; reports sent in between do not move it."""
    rate_mps = 1.0  # the default
    v = make(faults=(sitl.FaultSpec(kind=sitl.FaultKind.GNSS_JAMMING, at_s=0.0),))
    run(v, 12.0)  # jamming level 1 after 9 s
    before = v.faults.jam_offset
    sent: list[str] = []

    class _Sink:
        def send(self, name: str, **_fields: object) -> None:
            sent.append(name)

    for _ in range(250):  # many reports, no simulated time
        v.telemetry.send_stream(_Sink(), "GPS_RAW_INT")  # type: ignore[arg-type]
        v.telemetry.send_stream(_Sink(), "GLOBAL_POSITION_INT")  # type: ignore[arg-type]
    assert len(sent) == 500 and v.faults.jam_offset == before
    t, t_end = 12.0, 32.0
    while t < t_end:  # 20 simulated seconds in physics steps
        t += 0.05
        v.advance(t)
    moved_m = math.hypot(v.faults.jam_offset[0] - before[0], v.faults.jam_offset[1] - before[1])
    # the path is rate * 20 s; the straight-line displacement a little less (direction wanders)
    assert 0.85 * rate_mps * 20.0 < moved_m <= rate_mps * 20.0 + 1e-6


def test_spoofing_battery_and_motor_failure() -> None:
    faults = (
        sitl.FaultSpec(kind=sitl.FaultKind.SPOOFING, at_s=0.0, duration_s=10.0, value=100.0),
        sitl.FaultSpec(kind=sitl.FaultKind.BATTERY_DROP, at_s=15.0, value=6.0),
    )
    v = make(faults=faults, mission=WPS, auto_start_at_s=0.0)
    t = run(v, 5.0)
    lat, _, _ = v.reported_position()
    assert abs((lat - v.lat_deg) * 111_200 - 100.0) < 1.0
    t = run(v, 16.0, t)
    assert v.mode == "RTL"  # critical battery
    assert any("Critical battery" in s for _, _, s in v.statustexts)

    m = make(mission=WPS, auto_start_at_s=0.0)
    t = run(m, 10.0)
    m.inject_fault(sitl.FaultKind.MOTOR_FAILURE)
    assert m.mode == "LAND" and m.motor_failed
    assert m.commands.request_mode("MISSION") != 0
    assert m.telemetry.health() & 32768 == 0
    run(m, 40.0, t)
    assert m.landed


def test_link_faults_drop_and_count() -> None:
    v = make(faults=(sitl.FaultSpec(kind=sitl.FaultKind.LINK_LOSS, at_s=0.0, duration_s=5.0),))
    v.advance(1.0)
    assert v.faults.link_loss
    v.advance(6.0)
    assert not v.faults.link_loss
    v.inject_fault(sitl.FaultKind.PACKET_LOSS, value=0.5, duration_s=2.0)
    assert v.faults.packet_loss == 0.5
    v.advance(9.0)
    assert v.faults.packet_loss == 0.0
