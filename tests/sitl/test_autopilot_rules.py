"""The PX4 and ArduPilot personalities refuse, store and restart missions as the real
autopilots do (measured on PX4 v1.15.2 and ArduPilot 4.6 SITL; docs/autopilots.md). Stepping
a Vehicle directly, without sockets."""

from __future__ import annotations

import math

import sitl
from sitl import mission as mp
from sitl.vehicle import Vehicle

HOME = (47.397742, 8.545594, 488.0)


def make(**kw: object) -> Vehicle:
    spec = sitl.VehicleSpec(instance=0, **kw)  # type: ignore[arg-type]
    return Vehicle(spec, sitl.SimTime(start_utc_s=1_700_000_000.0))


def wp(seq: int, dlat: float, alt: float, frame: int = mp.FRAME_GLOBAL) -> mp.RawItem:
    x, y = round((HOME[0] + dlat) * 1e7), round(HOME[1] * 1e7)
    return mp.RawItem(seq, frame, mp.CMD_WAYPOINT, 0, 1, 2.6, 3.0, 0.0, math.nan, x, y, alt)


def speed(seq: int, frame: int) -> mp.RawItem:
    return mp.RawItem(seq, frame, mp.CMD_CHANGE_SPEED, 0, 1, 1.0, 5.0, -1.0, 0.0, 0, 0, 0.0)


def test_px4_refuses_do_items_outside_the_mission_frame() -> None:
    assert mp.validate_px4_item(speed(1, mp.FRAME_GLOBAL)) == mp.UNSUPPORTED
    assert mp.validate_px4_item(speed(1, mp.FRAME_MISSION)) == mp.ACCEPTED
    assert mp.validate_item(speed(1, mp.FRAME_GLOBAL)) == mp.ACCEPTED  # ArduPilot takes it


def test_px4_stores_int_frames_and_keeps_nan() -> None:
    v = make()
    v.accept_mission([wp(0, 0.001, 500.0), speed(1, mp.FRAME_MISSION), wp(2, 0.002, 20.0, 3)], 1)
    got = v.mission_items()
    assert [it.frame for it in got] == [mp.FRAME_GLOBAL_INT, mp.FRAME_MISSION, 6]
    assert math.isnan(got[0].param4) and got[0].param1 == 2.6
    assert v.mission_current_seq == 1  # the current flag is honoured


def test_ardupilot_copter_and_plane_stored_forms() -> None:
    items = [wp(0, 0.0, 488.0), wp(1, 0.001, 500.0), speed(2, mp.FRAME_MISSION)]
    copter = make(autopilot="ardupilot")
    copter.accept_mission(items, 2)
    got = copter.mission_items()
    assert (got[1].param1, got[1].param2, got[1].param4) == (2.0, 0.0, 0.0)  # NaN -> 0
    assert got[2].frame == mp.FRAME_GLOBAL and got[2].param2 == 5.0
    assert copter.mission_current_seq == 1  # the flag is ignored: execution starts at 1
    assert got[0].x == round(copter.home[0] * 1e7)  # seq 0 reads back as its own home
    plane = make(autopilot="ardupilot", kind="fixed_wing")
    plane.accept_mission(items, None)
    got = plane.mission_items()
    assert (got[1].param1, got[1].param2, got[1].param4) == (0.0, 3.0, 0.0)


def test_ardupilot_keeps_only_the_direction_of_a_loiter_time_radius() -> None:
    """ArduPilot reads NAV_LOITER_TIME back with param3 = +1 or -1 (measured on ArduPlane
    4.6): the radius flown is WP_LOITER_RAD (gcs_utm takes a radius of 1 m as none)."""
    x, y = round(HOME[0] * 1e7), round(HOME[1] * 1e7)
    loiters = [
        mp.RawItem(k + 1, mp.FRAME_GLOBAL_REL, mp.CMD_LOITER_TIME, 0, 1, 20.0, 0.0, r, 0.0, x, y,
                   60.0)
        for k, r in enumerate((0.0, 150.0, -150.0))
    ]  # fmt: skip
    plane = make(autopilot="ardupilot", kind="fixed_wing")
    plane.accept_mission([wp(0, 0.0, 488.0), *loiters], None)
    assert [it.param3 for it in plane.mission_items()[1:]] == [1.0, 1.0, -1.0]
    px4 = make(kind="fixed_wing")
    px4.accept_mission(loiters, None)
    assert [it.param3 for it in px4.mission_items()] == [0.0, 150.0, -150.0]


def test_ardupilot_restart_on_a_do_item_fails_until_set_current() -> None:
    v = make(autopilot="ardupilot", home_lat_deg=HOME[0], home_lon_deg=HOME[1])
    v.accept_mission([wp(0, 0.0, 488.0), wp(1, 0.001, 500.0), wp(2, 0.002, 500.0)], None)
    assert v.arm(force=True) == 0
    v.flight.enter_mode("MISSION")
    t = 0.0
    while v.mission_current_seq < 2 and t < 120.0:
        t += 0.5
        v.advance(t)
    assert v.mission_current_seq == 2
    # replaced in flight: index 2 is now a DO item -> the restart fails, the copter waits
    new = [wp(0, 0.0, 488.0), wp(1, 0.003, 505.0), speed(2, mp.FRAME_MISSION), wp(3, 0.004, 505.0)]
    v.accept_mission(new, 2)
    assert any("failed to restart" in s for _, _, s in v.statustexts)
    for _ in range(10):  # it brakes to a stop
        t += 0.5
        v.advance(t)
    lat0 = v.lat_deg
    for _ in range(40):  # and hovers there
        t += 0.5
        v.advance(t)
    assert v.mission_current_seq == 2 and abs(v.lat_deg - lat0) * 111_000 < 0.5
    assert v.set_current(3)
    for _ in range(40):
        t += 0.5
        v.advance(t)
    assert (v.lat_deg - lat0) * 111_000 > 50.0  # flying to item 3


def test_ardupilot_copter_modes_brake_holds_loiter_descends() -> None:
    v = make(autopilot="ardupilot")
    assert v.telemetry.custom_mode()[1] == 0  # boots in STABILIZE
    assert v.arm(force=True) == 0
    assert v.commands.request_mode("TAKEOFF") == 0
    t = 0.0
    while v.alt_amsl_m < v.ground_alt_m + 9.0 and t < 60.0:
        t += 0.5
        v.advance(t)
    assert v.commands.set_mode_numbers(1, 17) == 0 and v.telemetry.custom_mode()[1] == 17  # BRAKE
    a0 = v.alt_amsl_m
    for _ in range(20):
        t += 0.5
        v.advance(t)
    assert abs(v.alt_amsl_m - a0) < 0.5
    assert v.commands.set_mode_numbers(1, 5) == 0 and v.telemetry.custom_mode()[1] == 5  # LOITER
    for _ in range(20):
        t += 0.5
        v.advance(t)
    assert v.alt_amsl_m < a0 - 5.0  # no RC throttle: it descends


def test_land_start_fails_without_a_landing_sequence() -> None:
    v = make(autopilot="ardupilot", kind="fixed_wing")
    v.accept_mission([wp(0, 0.0, 488.0), wp(1, 0.01, 550.0)], None)
    assert v.commands._cmd_land_start(None, None, [0.0] * 7) == 4  # type: ignore[arg-type]
    assert any("Unable to start landing" in s for _, _, s in v.statustexts)
    assert v.commands._cmd_land(None, None, [0.0] * 7) == 3  # type: ignore[arg-type]
    land_start = mp.RawItem(2, mp.FRAME_MISSION, mp.CMD_LAND_START, 0, 1, 0, 0, 0, 0, 0, 0, 0)
    v.accept_mission([wp(0, 0.0, 488.0), wp(1, 0.01, 550.0), land_start], None)
    assert v.commands._cmd_land_start(None, None, [0.0] * 7) == 0  # type: ignore[arg-type]
    assert v.mode == "MISSION" and v.mission_current_seq == 2


def test_ardupilot_refuses_uploads_until_its_storage_is_up() -> None:
    from sitl._mav import Inbound
    from tests.sitl.conftest import mav

    sent: list[tuple[str, dict[str, object]]] = []
    count = mav.MAVLink_mission_count_message(1, 1, 2, 0)
    msg = Inbound("MISSION_COUNT", 255, 190, count.get_msgId(), count)
    for autopilot, refused in (("ardupilot", True), ("px4", False)):
        v = make(autopilot=autopilot)
        v.send = lambda _peer, name, **f: sent.append((name, f))  # type: ignore[method-assign]
        v.advance(1.0)  # 1 simulated s after boot
        sent.clear()
        v.mission_server.handle(None, msg, 0.0)
        refusal = ("MISSION_ACK", sent[0][1]["type"]) if sent[0][0] == "MISSION_ACK" else None
        assert (refusal == ("MISSION_ACK", mp.NO_SPACE)) is refused, sent
    v = make(autopilot="ardupilot")
    v.advance(2.0)
    assert v.storage_ready()


def test_arduplane_refuses_to_arm_with_do_land_start_unless_rtl_autoland() -> None:
    """Measured on ArduPlane 4.6: "Arm: DO_LAND_START set and RTL_AUTOLAND disabled",
    COMMAND_ACK 4, until RTL_AUTOLAND is set (issue 31.4)."""
    land_start = mp.RawItem(2, mp.FRAME_MISSION, mp.CMD_LAND_START, 0, 1, 0, 0, 0, 0, 0, 0, 0)
    mission = [wp(0, 0.0, 488.0), wp(1, 0.01, 550.0), land_start]
    for autopilot, kind, refused in (
        ("ardupilot", "fixed_wing", True),
        ("ardupilot", "multirotor", False),
        ("px4", "fixed_wing", False),
    ):
        v = make(autopilot=autopilot, kind=kind)
        v.advance(30.0)  # a fix
        v.accept_mission(mission, None)
        assert (v.arm() == 4) is refused, (autopilot, kind)
        if refused:
            assert any("RTL_AUTOLAND disabled" in s for _, _, s in v.statustexts)
            v.flight.params["RTL_AUTOLAND"] = 2.0
            assert v.arm() == 0


def test_a_plane_flies_airspeeds_not_below_its_minimum() -> None:
    """ArduPlane takes a ground-speed item (type 1) as a minimum ground speed and keeps its
    airspeed; an airspeed item (type 0) below the minimum airspeed is flown at the minimum."""
    plane = make(autopilot="ardupilot", kind="fixed_wing")
    ground = speed(1, mp.FRAME_MISSION)  # type 1, 5 m/s
    assert plane.speed_item(ground) is None
    air = mp.RawItem(1, mp.FRAME_MISSION, mp.CMD_CHANGE_SPEED, 0, 1, 0.0, 5.0, -1.0, 0, 0, 0, 0)
    assert plane.speed_item(air) == plane.lim.min_airspeed_mps > 5.0
    quad = make(autopilot="ardupilot", kind="multirotor")
    assert quad.speed_item(ground) == 5.0
