"""The PX4 and ArduPilot personalities run DO_JUMP loops, reboot, move their home and take it
at arming as PX4 v1.15 (Commander, MissionBase) and ArduPilot 4.6 (AP_Mission, GCS_MAVLINK)
do, and refuse what they refuse. Stepping a Vehicle directly, without sockets."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

import sitl
from sitl import mission as mp
from sitl.vehicle import REBOOT_DELAY_S, REBOOT_DOWN_S, Vehicle

HOME = (47.397742, 8.545594, 488.0)
DLAT = 0.0004  # ~44 m
DLON = 0.0006  # ~45 m
A, B, C = (DLAT, 0.0), (DLAT, DLON), (0.0, DLON)
SET_HOME, REBOOT = 179, 246
DENIED, FAILED, TEMPORARILY_REJECTED, ACCEPTED = 2, 4, 1, 0


def make(autopilot: str = "px4", **kw: object) -> Vehicle:
    spec = sitl.VehicleSpec(
        instance=0,
        autopilot=autopilot,
        home_lat_deg=HOME[0],
        home_lon_deg=HOME[1],
        home_alt_amsl_m=HOME[2],
        cruise_speed_mps=12.0,
        **kw,  # type: ignore[arg-type]
    )
    return Vehicle(spec, sitl.SimTime(start_utc_s=1_700_000_000.0))


def wp(seq: int, at: tuple[float, float], rel_alt_m: float = 20.0) -> mp.RawItem:
    x, y = round((HOME[0] + at[0]) * 1e7), round((HOME[1] + at[1]) * 1e7)
    return mp.RawItem(seq, mp.FRAME_GLOBAL_REL_INT, mp.CMD_WAYPOINT, 0, 1, 0, 0, 0, 0, x, y,
                      rel_alt_m)  # fmt: skip


def jump(seq: int, target: int, repeats: float) -> mp.RawItem:
    return mp.RawItem(seq, mp.FRAME_MISSION, mp.CMD_DO_JUMP, 0, 1, float(target), repeats,
                      0.0, 0.0, 0, 0, 0.0)  # fmt: skip


def loop_mission(ardupilot: bool, repeats: float) -> list[mp.RawItem]:
    """(ArduPilot: home at 0) A, B, DO_JUMP back to A ``repeats`` times, C."""
    first = 1 if ardupilot else 0
    items = [wp(0, (0.0, 0.0), 0.0)] if ardupilot else []
    items += [wp(first, A), wp(first + 1, B), jump(first + 2, first, repeats), wp(first + 3, C)]
    return items


def command(v: Vehicle, cmd: int, *p: float) -> int:
    params = [*p, *([0.0] * (7 - len(p)))]
    result = v.commands._command_table()[cmd](None, None, params)  # type: ignore[arg-type]
    assert result is not None
    return result


def run(v: Vehicle, t0: float, until_s: float, step_s: float = 0.5) -> float:
    t = t0
    while t < until_s:
        t += step_s
        v.advance(t)
    return t


def fly_loop(autopilot: str, repeats: float, sim_s: float) -> list[str]:
    """The points (A, B, C) the vehicle reaches, in order."""
    ap = autopilot == "ardupilot"
    v = make(autopilot)
    v.advance(1.0)
    v.accept_mission(loop_mission(ap, repeats), None)
    reached: list[int] = []
    v.broadcast = lambda name, **f: (  # type: ignore[method-assign]
        reached.append(int(f["seq"])) if name == "MISSION_ITEM_REACHED" else None
    )
    assert v.arm() == ACCEPTED
    assert v.commands.request_mode("MISSION") == ACCEPTED
    run(v, 1.0, sim_s)
    first = 1 if ap else 0
    names = {first: "A", first + 1: "B", first + 3: "C"}
    return [names[s] for s in reached]


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_do_jump_loop_is_flown_its_repeat_count_more_times(autopilot: str) -> None:
    """Repeat count 2: the loop A-B is flown three times, then C (PX4: jump while
    do_jump_current_count < repeat count; ArduPilot: while jump_times_run < num_times)."""
    assert fly_loop(autopilot, 2.0, 150.0) == ["A", "B"] * 3 + ["C"]
    assert fly_loop(autopilot, 0.0, 60.0) == ["A", "B", "C"]  # no repeat: no jump


def test_an_ardupilot_do_jump_with_a_negative_count_repeats_for_ever() -> None:
    seen = fly_loop("ardupilot", -1.0, 150.0)
    assert "C" not in seen and seen.count("A") >= 4


def test_do_jump_is_stored_as_each_autopilot_keeps_it() -> None:
    """PX4 takes a DO_JUMP in the mission frame only; ArduPilot keeps its target and repeat
    count (whole numbers) and nothing else, in frame 0."""
    assert mp.validate_px4_item(jump(2, 0, 2.0)) == mp.ACCEPTED
    assert mp.validate_px4_item(replace(jump(2, 0, 2.0), frame=mp.FRAME_GLOBAL)) == mp.UNSUPPORTED
    sent = replace(jump(2, 0, 2.0), frame=mp.FRAME_GLOBAL_INT, param1=1.7, param3=5.0)
    got = mp.ardupilot_stored(sent, fixed_wing=False)
    assert (got.frame, got.param1, got.param2, got.param3, got.param4) == (0, 1.0, 2.0, 0.0, 0.0)


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_a_reboot_is_refused_armed_and_starts_a_new_boot(autopilot: str) -> None:
    ap = autopilot == "ardupilot"
    v = make(autopilot, gnss_fix_after_s=4.0)
    t = run(v, 0.0, 10.0)
    v.accept_mission(loop_mission(ap, 1.0), None)
    assert v.arm() == ACCEPTED
    # armed: PX4 denies, ArduPilot fails unless forced with param4 = 20190226
    assert command(v, REBOOT, 1.0) == (FAILED if ap else DENIED)
    v.flight.disarm()
    boot_ms = v.time.time_boot_ms()
    assert boot_ms >= 9000
    assert command(v, REBOOT, 1.0) == ACCEPTED
    t = run(v, t, t + REBOOT_DELAY_S + 0.1, 0.1)
    assert v.reboots == 1 and not v.time.booted
    t = run(v, t, t + REBOOT_DOWN_S, 0.1)
    assert v.time.booted and v.time.time_boot_ms() < 1000  # a new boot: its clock from 0
    assert v.faults.gps_fix_type() == 0  # acquiring GNSS again
    assert v.arm() != ACCEPTED
    t = run(v, t, t + 4.5)
    assert v.faults.gps_fix_type() == 3 and v.arm() == ACCEPTED
    assert len(v.mission) == len(loop_mission(ap, 1.0))  # the stored mission is kept
    assert v.mission_current_seq == (1 if ap else 0)


def test_an_ardupilot_reboot_forced_while_armed() -> None:
    v = make("ardupilot")
    run(v, 0.0, 5.0)
    assert v.arm() == ACCEPTED
    assert command(v, REBOOT, 1.0, 0.0, 0.0, 20190226.0) == ACCEPTED
    run(v, 5.0, 6.0, 0.1)
    assert v.reboots == 1 and not v.armed


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_do_set_home_moves_home_and_a_set_home_is_kept_at_arming(autopilot: str) -> None:
    ap = autopilot == "ardupilot"
    v = make(autopilot, gnss_fix_after_s=3.0)
    v.advance(1.0)
    # without a fix: PX4 TEMPORARILY_REJECTED, ArduPilot FAILED
    assert command(v, SET_HOME, 0.0, 0, 0, 0, HOME[0] + DLAT, HOME[1], HOME[2] + 5.0) == (
        FAILED if ap else TEMPORARILY_REJECTED
    )
    run(v, 1.0, 4.0)
    assert command(v, SET_HOME, 0.0, 0, 0, 0, math.nan, HOME[1], HOME[2]) == DENIED
    assert command(v, SET_HOME, 0.0, 0, 0, 0, HOME[0] + DLAT, HOME[1], HOME[2] + 5.0) == ACCEPTED
    assert v.home == pytest.approx((HOME[0] + DLAT, HOME[1], HOME[2] + 5.0))
    assert v.arm() == ACCEPTED
    assert v.home[2] == pytest.approx(HOME[2] + 5.0)  # a set home is kept at arming
    # RTL flies to the home that was set
    assert v.commands.request_mode("TAKEOFF") == ACCEPTED
    t = run(v, 4.0, 20.0)
    assert v.commands.request_mode("RTL") == ACCEPTED
    run(v, t, t + 40.0)
    assert (v.lat_deg - HOME[0]) * 111_320 == pytest.approx(DLAT * 111_320, abs=2.0)


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_home_is_taken_again_at_arming_unless_set(autopilot: str) -> None:
    """Both take home where they arm (PX4 setHomePosition on arming, ArduCopter unless its
    home is locked): a home taken elsewhere (here: at the current position before the
    vehicle was put down 30 m away) moves to the vehicle at arming."""
    v = make(autopilot)
    run(v, 0.0, 3.0)
    v.flight.set_home(HOME[0] + DLAT, HOME[1], HOME[2] + 3.0)  # an automatic home elsewhere
    assert v.arm() == ACCEPTED
    assert v.home == pytest.approx(HOME)


@pytest.mark.parametrize("autopilot", ["px4", "ardupilot"])
def test_nav_takeoff_while_disarmed(autopilot: str) -> None:
    """PX4 takes NAV_TAKEOFF disarmed (AUTO.TAKEOFF: it climbs once armed); ArduCopter
    answers FAILED (do_user_takeoff needs the motors armed)."""
    v = make(autopilot)
    t = run(v, 0.0, 2.0)
    alt = 15.0 if autopilot == "ardupilot" else HOME[2] + 15.0
    result = command(v, 22, 0.0, 0.0, 0.0, math.nan, math.nan, math.nan, alt)
    assert result == (FAILED if autopilot == "ardupilot" else ACCEPTED)
    assert v.arm() == ACCEPTED
    run(v, t, t + 12.0)
    assert (v.alt_amsl_m > HOME[2] + 10.0) is (autopilot == "px4")
