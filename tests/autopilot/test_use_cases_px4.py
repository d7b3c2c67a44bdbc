"""Use cases 1 and 2 with ``gcs-utm run --external --fly`` on real PX4 v1.15.2 SIH vehicles
(issues 18 and 30).

``config/scenarios/use_case_1_px4.toml`` is use case 1 matched to the SIH plane's speed
(14 m/s instead of 30 m/s; the same line, cut so that the plane reaches the crossing 100 s after its
first waypoint as in use case 1) and shifted by 110 s for boot and take-off; the multirotor's
plan and its 3 s late start are use case 1's. A SIH quadrotor flies UAS1 (sys_id 1) and a SIH
plane UAS2 (sys_id 2, with ``PX4_SIH_PLANE_PARAMS``). Checked on the report and on PX4's own
GLOBAL_POSITION_INT (recorded by the run, ``--record``):
- both missions uploaded, verified, armed and started; UAS1's 3 s late start flown;
- LOSS_OF_SEPARATION between UAS1 and UAS2 predicted at least 30 s before it would happen;
- recommendations for the low-priority UAS1 only (never the plane), accepted, uploaded and
  verified by readback, and flown: PX4's positions pass each waypoint of UAS1's last plan;
- the flown separation (PX4's positions, time-matched) never under 50 m horizontally while
  under 15 m vertically, and no loss of separation in the report.

``config/scenarios/use_case_2_px4.toml`` is use case 2 at PX4 SIH's origin, shifted by 110 s for
take-off, flown by two SIH quadrotors. PX4 v1.15.2 SIH's GNSS takes no jamming, so the run
reports the scenario's jamming to the USM as the RPA would (docs/autopilots.md, "Use cases 1
and 2 on PX4"). Checked as an outsider, on PX4's own positions from take-off to the run's end:
- JAMMING_ATTACK on UAS1 at the scenario's time; UAS1 held (or landed) by command, a geofence
  around it, UAS2 re-planned around it (accepted, uploaded, verified);
- UAS1 stopped its climb (held); UAS2 never inside that geofence (its filed leg passes 41 m
  from its centre) and past it at the end;
- no moment inside the pair's effective minima (50 m horizontally and 30 m vertically at once:
  the minima are at least the sum of the two 15 m operational volumes).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, PX4_SIH_PLANE_PARAMS, REPO, SitlProcess
from tests.autopilot.fly import run_fly
from tests.autopilot.pilot import PilotLink, local_m, offset_deg

SPEED = 5.0  # PX4_SIM_SPEED_FACTOR; run --speed matches it
LAT0, LON0, GROUND_M = PX4_DEFAULT_HOME
SCENARIO = REPO / "config" / "scenarios" / "use_case_1_px4.toml"
HOMES = {1: ("quad", (240.0, -40.0)), 2: ("plane", (1717.8, -137.4))}  # the scenario's homes
SCENARIO_2 = REPO / "config" / "scenarios" / "use_case_2_px4.toml"
HOMES_2 = {1: (190.0, 60.0), 2: (315.4, 57.0)}  # use case 2's homes, two quads
JAMMED_AT_S = 122.0  # the scenario's jamming of UAS1
UAS1_TOP_AGL_M = 90.0  # the top of UAS1's filed climb
MIN_V_2_M = 30.0  # use case 2's pair: max(15 m, 15 m + 15 m operational volumes)
# the plane waits for its start in a loiter around its first waypoint: within its 30 m
# operational volume (PX4's default NAV_LOITER_RAD is 80 m), as its operator would set it
PLANE_PARAMS = {**PX4_SIH_PLANE_PARAMS, "NAV_LOITER_RAD": 25.0}
MIN_H_M, MIN_V_M = 50.0, 15.0  # the monitoring minima (cylinder mode)
WAYPOINT_TOLERANCE_M = 12.0  # horizontal, quadrotor; PX4's acceptance radius, 0.5 s samples
ALTITUDE_TOLERANCE_M = 5.0
PAIR_DT_S = 0.05  # record-time s: two positions compared (PX4 streams them at ~50 Hz)
RUN_END_S = 320.0  # the scenario's duration
PREDICTED_AHEAD_S = 30.0  # the loss is predicted at least this long before it would happen


def _px4_positions(record_dir: Path) -> dict[int, list[tuple[float, float, float, float]]]:
    """PX4's own GLOBAL_POSITION_INT per sys_id, from the run's recorded links: (record time
    s, east m, north m, alt AMSL m)."""
    out: dict[int, list[tuple[float, float, float, float]]] = {1: [], 2: []}
    for path in sorted(record_dir.glob("*.tlog")):
        log = mavutil.mavlink_connection(str(path), dialect="common")
        try:  # closed here: left to the garbage collector, a later test fails on its warning
            while (m := log.recv_match(type="GLOBAL_POSITION_INT")) is not None:
                if m.get_srcSystem() in out and m.lat != 0:
                    e, n = local_m(LAT0, LON0, m.lat / 1e7, m.lon / 1e7)
                    out[m.get_srcSystem()].append((m._timestamp, e, n, m.alt / 1000.0))
        finally:
            log.close()
    for samples in out.values():
        samples.sort()
    return out


def _closest_pair(
    a: list[tuple[float, float, float, float]],
    b: list[tuple[float, float, float, float]],
    min_v_m: float = MIN_V_M,
) -> tuple[float, float, int, tuple[float, float]]:
    """(horizontal m, vertical m) of the time-matched pair of positions that comes closest to
    the minima: the smallest horizontal distance among the pairs less than ``min_v_m`` apart
    vertically (or the smallest vertical distance when none is); how many pairs; and the
    closest horizontal pass with its vertical distance (for the record)."""
    times = [q[0] for q in b]
    best_h, best_v, pairs = math.inf, math.inf, 0
    closest = (math.inf, math.inf)
    for t, e, n, alt in a:
        i = bisect.bisect_left(times, t)
        near = [b[j] for j in (i - 1, i) if 0 <= j < len(b)]
        q = min(near, key=lambda q: abs(q[0] - t), default=None)
        if q is None or abs(q[0] - t) > PAIR_DT_S:
            continue
        pairs += 1
        h, v = math.hypot(e - q[1], n - q[2]), abs(alt - q[3])
        closest = min(closest, (h, v))
        if v < min_v_m and h < best_h:
            best_h, best_v = h, v
        elif best_h == math.inf and v < best_v:
            best_v = v
    return best_h, best_v, pairs, closest


def _passed_m(
    samples: list[tuple[float, float, float, float]], east_m: float, north_m: float, alt_m: float
) -> float:
    """Horizontal distance of the closest pass within ALTITUDE_TOLERANCE_M of ``alt_m``."""
    return min(
        (
            math.hypot(e - east_m, n - north_m)
            for _t, e, n, alt in samples
            if abs(alt - alt_m) < ALTITUDE_TOLERANCE_M
        ),
        default=math.inf,
    )


@pytest.mark.timeout(300)
def test_use_case_1_on_px4_sih_plane_and_quad(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    for sys_id, (airframe, home) in HOMES.items():
        lat, lon = offset_deg(LAT0, LON0, *home)
        px4(instance=sys_id - 1, airframe=airframe, home=(lat, lon), speed=SPEED)
    pilot = PilotLink(1)
    try:  # closed before the run: parsing PX4's onboard stream costs CPU the run needs
        pilot.wait_ready(90.0)
        pilot.set_params(PLANE_PARAMS)
    finally:
        pilot.close()
    record = ("--record", str(tmp_path / "rec"))
    report, log = run_fly(SCENARIO, tmp_path / "runs", SPEED, extra_args=record)
    fly = {f["uas"]: f for f in report["fly"]}
    # the scenario's 3 s late start of UAS1 is flown (mission mode 3 s after its time)
    print("mission started late by:", {u: f["late_s"] for u, f in fly.items()})
    assert fly["UAS1"]["late_s"] >= 3.0
    _check_resolution(report, log)
    _check_flown(report, _px4_positions(tmp_path / "rec"))


def _check_resolution(report: dict[str, Any], log: str) -> None:
    """The loss predicted well ahead; the low-priority UAS1 moved, accepted, verified."""
    los = [t for t in report["threats"] if t["kind"] == "LOSS_OF_SEPARATION"]
    print("threats:", [(t["kind"], t["uas"], t["detected_at_s"]) for t in report["threats"]])
    assert los, f"no loss of separation predicted\n{log}"
    first = min(los, key=lambda t: t["detected_at_s"])
    assert sorted(first["uas"]) == ["UAS1", "UAS2"]
    ahead_s = first["predicted_event_at_s"] - first["detected_at_s"]
    print(f"first loss predicted at t = {first['detected_at_s']:.1f} s, {ahead_s:.1f} s ahead")
    assert ahead_s >= PREDICTED_AHEAD_S
    recs = [r for r in report["recommendations"] if r["threat_kind"] == "LOSS_OF_SEPARATION"]
    print("recommendations:", [(r["uas"], r["maneuver"], r["decision"], r["state"]) for r in recs])
    applied = [r for r in recs if r["decision"] == "accepted" and r["verified"]]
    assert applied and all(r["uas"] == "UAS1" and r["uploaded"] for r in applied), recs
    assert not [r for r in recs if r["uas"] == "UAS2"], "the high-priority plane was moved"


def _check_flown(
    report: dict[str, Any], px4: dict[int, list[tuple[float, float, float, float]]]
) -> None:
    """UAS1 flew its last plan version; PX4's own positions kept the minima."""
    assert len(px4[1]) > 1000 and len(px4[2]) > 1000, {k: len(v) for k, v in px4.items()}
    uas1 = next(o for o in report["operations"] if o["id"] == "UAS1")
    last = uas1["plans"][-1]
    assert last["version"] > 1, "UAS1 still has its filed plan"
    accepted_s = max(r["history"][-1][0] for r in report["recommendations"] if r["uas"] == "UAS1")
    checked = 0
    for lat, lon, alt, t_s in last["waypoints"]:
        if not accepted_s <= t_s <= RUN_END_S - 15.0:
            continue  # before the plan was uploaded, or after the run's end
        e, n = local_m(LAT0, LON0, lat, lon)
        miss = _passed_m(px4[1], e, n, alt)
        print(f"UAS1 v{last['version']} waypoint ({e:.0f}, {n:.0f}, {alt:.1f}) at {miss:.1f} m")
        assert miss < WAYPOINT_TOLERANCE_M
        checked += 1
    assert checked >= 2, last
    h_m, v_m, pairs, (close_h_m, close_v_m) = _closest_pair(px4[1], px4[2])
    print(f"flown (PX4's positions, {pairs} pairs): closest {h_m:.1f} m horizontally "
          f"within {MIN_V_M:.0f} m vertically (vertical {v_m:.1f} m); closest horizontal "
          f"pass {close_h_m:.1f} m at {close_v_m:.1f} m vertically")  # fmt: skip
    assert pairs > 1000
    assert h_m >= MIN_H_M, (h_m, v_m)
    assert not any(p["loss_of_separation"] for p in report["separation"]), report["separation"]


@pytest.mark.timeout(300)
def test_use_case_2_on_px4_sih_quads(px4: Callable[..., SitlProcess], tmp_path: Path) -> None:
    for sys_id, home in HOMES_2.items():
        px4(instance=sys_id - 1, airframe="quad", home=offset_deg(LAT0, LON0, *home), speed=SPEED)
    for instance in (0, 1):
        pilot = PilotLink(instance)
        try:  # closed before the run: parsing PX4's onboard stream costs CPU the run needs
            pilot.wait_ready(90.0)
        finally:
            pilot.close()
    record = ("--record", str(tmp_path / "rec"))
    report, log = run_fly(SCENARIO_2, tmp_path / "runs", SPEED, timeout_s=200.0, extra_args=record)
    px4_positions = _px4_positions(tmp_path / "rec")
    fence = _check_jamming_response(report, log)
    _check_flown_2(report, px4_positions, fence)


def _check_jamming_response(report: dict[str, Any], log: str) -> dict[str, Any]:
    """The jamming reported at its time: UAS1 suspended by command, a geofence around it,
    UAS2 re-planned around the geofence; returns that geofence."""
    jams = [t for t in report["threats"] if t["kind"] == "JAMMING_ATTACK"]
    assert jams and jams[0]["uas"] == ["UAS1"], f"{report['threats']}\n{log}"
    assert JAMMED_AT_S <= jams[0]["detected_at_s"] <= JAMMED_AT_S + 3.0, jams
    recs = report["recommendations"]
    print("recommendations:", [(r["uas"], r["threat_kind"], r["maneuver"], r["decision"],
                                r["verified"], r["history"][0][0]) for r in recs])  # fmt: skip
    suspend = [r for r in recs if r["uas"] == "UAS1" and r["threat_kind"] == "JAMMING_ATTACK"]
    assert suspend and suspend[0]["maneuver"] in {"hold", "land"}, recs
    assert (suspend[0]["decision"], suspend[0]["verified"]) == ("accepted", True), suspend
    fences = [g for g in report["geofences"] if g["reason"].startswith("JAMMING_ATTACK")]
    assert len(fences) == 1 and fences[0]["exempt"] == ["UAS1"], report["geofences"]
    reroute = [r for r in recs if r["uas"] == "UAS2"]
    assert reroute, recs
    assert (reroute[0]["decision"], reroute[0]["uploaded"], reroute[0]["verified"]) == (
        "accepted",
        True,
        True,
    ), reroute
    return fences[0]


def _check_flown_2(
    report: dict[str, Any],
    px4: dict[int, list[tuple[float, float, float, float]]],
    fence: dict[str, Any],
) -> None:
    """From PX4's own positions: UAS2 never inside the geofence; the pair never inside its
    effective minima, from take-off to the run's end."""
    assert len(px4[1]) > 1000 and len(px4[2]) > 1000, {k: len(v) for k, v in px4.items()}
    (sep,) = report["separation"]
    assert (sep["minimum_horizontal_m"], sep["minimum_vertical_m"]) == (MIN_H_M, MIN_V_2_M), sep
    ce, cn = local_m(LAT0, LON0, fence["center"]["lat_deg"], fence["center"]["lon_deg"])
    to_fence_m = min(math.hypot(e - ce, n - cn) for _t, e, n, _alt in px4[2])
    print(f"geofence centre ({ce:.0f}, {cn:.0f}) radius {fence['radius_m']} m: UAS2 came "
          f"{to_fence_m:.1f} m close")  # fmt: skip
    assert to_fence_m > fence["radius_m"]
    # the hold flown: UAS1 stopped its climb to 90 m AGL where the jamming caught it
    top_m = max(alt for _t, _e, _n, alt in px4[1]) - GROUND_M
    # the re-plan flown: UAS2 went on around the geofence and is past it (west) at the end
    end_e, end_n = px4[2][-1][1:3]
    print(f"UAS1 highest {top_m:.1f} m AGL; UAS2 ends at ({end_e:.0f}, {end_n:.0f})")
    assert top_m < UAS1_TOP_AGL_M - 5.0
    assert end_e < ce - fence["radius_m"]
    airborne = [[q for q in px4[i] if q[3] > GROUND_M + 1.0] for i in (1, 2)]
    h_m, v_m, pairs, (close_h_m, close_v_m) = _closest_pair(*airborne, min_v_m=MIN_V_2_M)
    print(f"flown (PX4's positions, {pairs} airborne pairs): closest {h_m:.1f} m horizontally "
          f"within {MIN_V_2_M:.0f} m vertically (vertical {v_m:.1f} m); closest horizontal "
          f"pass {close_h_m:.1f} m at {close_v_m:.1f} m vertically")  # fmt: skip
    assert pairs > 1000
    assert h_m >= MIN_H_M, (h_m, v_m)
    assert not any(p["loss_of_separation"] for p in report["separation"]), report["separation"]
