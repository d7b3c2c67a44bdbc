"""A PX4 mission started again on the ground (issue 31): PX4 v1.15 goes back to item 0 when
it was disarmed since the mission last ran and its current item is the last
(``checkMissionRestart``), but its MISSION_CURRENT still says the last item for a moment
after the arming. The nuisance soak's PX4 SIH plane, its mission flown to its landing and
uploaded again, was planned from that stale NAV_LAND at its second take-off (a line from
where it stood to the landing point behind it): UAS_OUT_OV 32.6 m 2.5 s into the roll, an
auto-accepted hold. ``tests/data/flown/px4_plane_restart_stale_seq.json`` holds the mission
and its positions."""

from __future__ import annotations

import itertools
import json
import math
import sys
from pathlib import Path
from typing import Any

from gcs_utm.clock import ManualClock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import Autopilot, FlightPlan, Position, SysId
from gcs_utm.services import mission_order
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import Usm

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_fixed_wing_plan as t

FLOWN: dict[str, Any] = json.loads(
    (Path(__file__).resolve().parents[1] / "data" / "flown" / "px4_plane_restart_stale_seq.json")
    .read_text()
)  # fmt: skip
HOME = Position(**FLOWN["home"])
ARMED_T_S = 2000.0


def _items() -> list[t._Item]:
    return [
        t._Item(it["command"], round(it["lat_deg"] * 1e7), round(it["lon_deg"] * 1e7),
                it["alt_amsl_m"], frame=0, param1=it["param1"], seq=it["seq"])
        for it in FLOWN["items"]
    ]  # fmt: skip


def _status(clock: ManualClock, seq: int, *, armed: bool) -> VehicleStatus:
    return VehicleStatus(
        sys_id=SysId(2), t_s=clock.now_s(), autopilot=Autopilot.PX4,
        mode=FlightMode.MISSION if armed else FlightMode.HOLD, armed=armed, landed=True,
        mission_seq=seq, mission_total=FLOWN["total"], home=HOME, position=HOME,
        gnss_fix_type=3, heading_deg=FLOWN["heading_deg"],
    )  # fmt: skip


def _off_m(plan: FlightPlan, q: dict[str, float]) -> float:
    """Horizontal distance from the recorded position ``q`` to the plan's path."""
    k = math.cos(math.radians(HOME.lat_deg))

    def en(lat: float, lon: float) -> tuple[float, float]:
        return (lon - HOME.lon_deg) * 111_320.0 * k, (lat - HOME.lat_deg) * 110_540.0

    e, n = en(q["lat_deg"], q["lon_deg"])
    best = math.inf
    for a, b in itertools.pairwise(plan.waypoints):
        (ax, ay), (bx, by) = en(a.lat_deg, a.lon_deg), en(b.lat_deg, b.lon_deg)
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        u = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((e - ax) * dx + (n - ay) * dy) / length2))
        best = min(best, math.hypot(e - ax - u * dx, n - ay - u * dy))
    return best


async def test_a_px4_mission_started_on_the_ground_runs_from_its_first_item() -> None:
    clock = ManualClock(ARMED_T_S - 20.0)
    usm = Usm(Airspace(), clock)
    usm.attach_vehicles(t._Port(_items()))
    usm.on_vehicle(t._Info(key=t._Key(2), autopilot=Autopilot.PX4))
    stale = FLOWN["stale_seq"]
    usm.on_status(_status(clock, stale, armed=False))  # parked after its first landing
    await usm.drain()
    clock.set(ARMED_T_S)
    usm.on_status(_status(clock, stale, armed=True))  # armed into MISSION: still "item 4"
    await usm.drain()
    clock.set(ARMED_T_S + 0.5)
    usm.on_status(_status(clock, stale, armed=True))  # the stale seq again: not a new item
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(2))
    assert op is not None
    # the take-off from its parked heading, not a line to the landing point
    assert len(op.plan.waypoints) > 10
    off = [_off_m(op.plan, q) for q in FLOWN["track"]]
    assert max(off) < 6.0, off  # was 32.6 m (UAS_OUT_OV) planned from the stale item
    version = op.plan.version
    clock.set(ARMED_T_S + 1.0)
    usm.on_status(_status(clock, 0, armed=True))  # PX4's MISSION_CURRENT catches up
    await usm.drain()
    op = usm.airspace.by_sys_id(SysId(2))
    assert op is not None and op.plan.version == version  # item 0 is what it was planned from


def _seq(seq: int, *, started: bool, landed: bool, autopilot: Autopilot, stale: int | None
         ) -> tuple[int | None, int | None]:  # fmt: skip
    s = VehicleStatus(sys_id=SysId(2), t_s=0.0, autopilot=autopilot, armed=True, landed=landed,
                      mission_seq=seq, mission_total=5)  # fmt: skip
    return mission_order.current_seq(s, autopilot, stale, started)


def test_only_a_px4_ground_start_at_the_last_item_restarts() -> None:
    px4, ardupilot = Autopilot.PX4, Autopilot.ARDUPILOT
    assert _seq(4, started=True, landed=True, autopilot=px4, stale=None) == (0, 4)
    assert _seq(4, started=False, landed=True, autopilot=px4, stale=4) == (0, 4)
    assert _seq(1, started=False, landed=False, autopilot=px4, stale=4) == (1, None)
    # in the air (a HOLD left for MISSION at its landing), ArduPilot, another item: as reported
    assert _seq(4, started=True, landed=False, autopilot=px4, stale=None) == (4, None)
    assert _seq(4, started=True, landed=True, autopilot=ardupilot, stale=None) == (4, None)
    assert _seq(2, started=True, landed=True, autopilot=px4, stale=None) == (2, None)
