"""Plan <-> MAVLink mission (pure): :class:`MissionItem`, :func:`plan_to_mission_items`,
:func:`same_item` (readback verification by meaning), :func:`start_item`.

Encoding of a 4D :class:`FlightPlan` (MAVLink waypoints carry no time):
- every plan waypoint k becomes a NAV_WAYPOINT (MISSION_ITEM_INT, frame MAV_FRAME_GLOBAL,
  so ``z`` is metres AMSL, ``x``/``y`` are degrees * 1e7);
- before waypoint k (k >= 1) a DO_CHANGE_SPEED sets the speed of segment k-1 -> k to
  horizontal length / duration, so the vehicle keeps the plan's timing: a ground speed
  (speed type 1) for a multirotor, an airspeed (speed type 0) for a fixed wing, never below
  its minimum airspeed (ArduPlane takes a type-1 speed as a minimum ground speed and keeps
  flying its cruise airspeed; a plane cannot fly slower than it stalls) (a multirotor flies
  the straight 3D line, its climb within its limit); a segment with no horizontal length and
  no climb but a duration becomes a hold time (NAV_WAYPOINT param1) at its start; a climb
  (descent) on the spot is flown at the vehicle's vertical speed, and only the time the plan
  gives beyond ``|dz| / climb_rate_mps`` is held, at its end (a hold before the climb made
  the vehicle late by the whole climb);
- the first item of plan waypoint ``start_index`` (its speed item, if any) has current=1:
  PX4 otherwise keeps the old index when a mission is replaced in flight;
- ArduPilot: seq 0 is home (``home`` or the first waypoint), so items shift by one;
  hold times are whole seconds (ArduCopter keeps ``param1`` as an integer).
- items without a position (DO_CHANGE_SPEED) are in MAV_FRAME_MISSION (2): PX4 refuses
  them in a global frame (MAV_MISSION_UNSUPPORTED), ArduPilot takes either;
- a plan that lands (``lands``: return home, a landing site) flown by a vehicle that hovers
  ends with a NAV_LAND at its last waypoint, the touchdown point, in place of a waypoint
  there: a waypoint at ground level is no landing on PX4 or ArduPilot (the vehicle hovers
  over it, armed). The plan's descent onto it is the landing: the items before it stay
  where the plan has them (above home at the cruise altitude), and the autopilot descends
  at its own landing speed, then disarms.

Readback (:func:`stored_form`, :func:`same_item`) compares what each autopilot is documented
to keep, not the bytes sent:
- positions to 1e-7 deg (one unit of ``x``/``y``), altitude ``z`` to 1 cm;
- frame by family: global 0/5, relative-altitude 3/6, terrain 10/11, mission 2. PX4 returns
  global items in their INT frames (0 -> 5, 3 -> 6). ArduPilot keeps no frame for an item
  without a position and returns it in frame 0;
- PX4 keeps every param as float32, NaN included;
- ArduPilot keeps a NaN param as 0.0 and no frame for a DO item (read back in frame 0),
  except DO_LAND_START, whose position it stores with its frame; NAV_WAYPOINT keeps only
  what its 15-byte command holds: ArduCopter the hold time (param1, whole seconds),
  ArduPlane the acceptance and pass-by radii (param2/param3, whole metres up to 255); the
  other params read back 0;
  NAV_LAND keeps of param4 only its sign (-1 or 1: ArduPlane's deep-stall direction);
- ArduPilot's seq 0 is its own home, not compared.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from gcs_utm.geo import haversine_m
from gcs_utm.model import Autopilot, FlightPlan, Position, VehicleKind

MAV_FRAME_GLOBAL = 0
MAV_FRAME_MISSION = 2
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LAND = 21
MAV_CMD_NAV_TAKEOFF = 22
MAV_CMD_NAV_LOITER_TO_ALT = 31
MAV_CMD_NAV_VTOL_LAND = 85
MAV_CMD_DO_LAND_START = 189
MAV_CMD_DO_CHANGE_SPEED = 178
NAV_COMMAND_MAX = 95  # MAV_CMD ids up to MAV_CMD_NAV_LAST (95) are navigation commands
LAND_COMMANDS = frozenset({MAV_CMD_NAV_LAND, MAV_CMD_NAV_VTOL_LAND})
APPROACH_COMMANDS = frozenset({MAV_CMD_NAV_WAYPOINT, MAV_CMD_NAV_LOITER_TO_ALT})
"""What may precede a landing as its approach: PX4 rejects a fixed wing's NAV_LAND after
anything else with a position ("Only ORBIT_TO_ALT or WAYPOINT allowed")."""
# Frame families: the same meaning under another number (the _INT variants of MAVLink 1).
_FRAME_FAMILY = {0: 0, 5: 0, 3: 3, 6: 3, 10: 10, 11: 10, 2: 2}
SPEED_TYPE_AIRSPEED = 0.0
SPEED_TYPE_GROUND = 1.0
_MIN_SEGMENT_M = 0.5  # below this a segment is "no horizontal motion": GNSS noise scale


@dataclass(frozen=True, slots=True, kw_only=True)
class MissionItem:
    """One MISSION_ITEM_INT. ``x``/``y`` are degrees * 1e7 for global frames; ``z`` metres."""

    seq: int
    command: int
    frame: int = MAV_FRAME_GLOBAL
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = 0

    @property
    def lat_deg(self) -> float:
        return self.x / 1e7

    @property
    def lon_deg(self) -> float:
        return self.y / 1e7


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def is_nav(command: int) -> bool:
    """True for a navigation command (it moves the vehicle; DO_* items do not)."""
    return command <= NAV_COMMAND_MAX


def _waypoint(lat: float, lon: float, alt: float) -> MissionItem:
    return MissionItem(
        seq=0,
        command=MAV_CMD_NAV_WAYPOINT,
        param4=math.nan,
        x=_e7(lat),
        y=_e7(lon),
        z=float(alt),
    )


def _landing(wp: MissionItem) -> MissionItem:
    """A NAV_LAND at waypoint ``wp``'s position (abort altitude and precision mode 0: the
    autopilot's defaults; yaw NaN: keep the heading)."""
    return replace(
        wp, command=MAV_CMD_NAV_LAND, param1=0.0, param2=0.0, param3=0.0, param4=math.nan
    )


def plan_to_mission_items(
    plan: FlightPlan,
    autopilot: Autopilot = Autopilot.PX4,
    home: Position | None = None,
    *,
    start_index: int = 0,
    max_speed_mps: float = 25.0,
    climb_rate_mps: float | None = None,
    descent_rate_mps: float | None = None,
    kind: VehicleKind | None = None,
    min_speed_mps: float = 0.0,
    lands: bool = False,
) -> list[MissionItem]:
    """The MAVLink mission that flies ``plan`` (see the module docstring for the encoding).

    Speeds are clamped to ``max_speed_mps`` (a zero-duration segment would ask for infinity).
    ``climb_rate_mps``/``descent_rate_mps`` are the vehicle's vertical speeds (None: assume
    the plan timed its climbs at them, no wait is added to a climb on the spot). A
    ``kind`` FIXED_WING gets airspeeds, raised to ``min_speed_mps`` (its minimum airspeed).
    ``lands``: the plan ends on the ground (its last waypoint the touchdown point), flown as
    a NAV_LAND there by a vehicle that is not a fixed wing (a fixed wing's landing plan ends
    above the site: it circles there until its own landing sequence is flown).
    """
    fixed_wing = kind is VehicleKind.FIXED_WING
    speed_type = SPEED_TYPE_AIRSPEED if fixed_wing else SPEED_TYPE_GROUND
    floor_mps = min(min_speed_mps, max_speed_mps) if fixed_wing else 0.0
    wps = plan.waypoints
    if not 0 <= start_index < len(wps):
        raise ValueError(f"start_index {start_index} outside the plan's {len(wps)} waypoints")
    items: list[MissionItem] = []
    if autopilot is Autopilot.ARDUPILOT:
        h = home or wps[0].position
        items.append(_waypoint(h.lat_deg, h.lon_deg, h.alt_amsl_m))
    current = -1
    last_wp = -1  # index in items of the last NAV_WAYPOINT
    vertical_hold = 0.0
    for k, wp in enumerate(wps):
        first_of_wp = len(items)
        if k >= 1:
            prev = wps[k - 1]
            dt = wp.t_s - prev.t_s
            dist = haversine_m(prev.lat_deg, prev.lon_deg, wp.lat_deg, wp.lon_deg)
            if dist < _MIN_SEGMENT_M:
                dz = wp.alt_amsl_m - prev.alt_amsl_m
                if abs(dz) < 0.01:
                    if dt > 0.0:  # a wait at the previous point: hold there
                        held = items[last_wp]
                        items[last_wp] = replace(held, param1=round(held.param1 + dt, 3))
                    if k == start_index:
                        current = last_wp
                    continue
                # A climb or descent on the spot: the vehicle flies it at its own vertical
                # speed (PX4 MPC_Z_V_AUTO_UP/DN, no mission item sets it), so only the time
                # the plan leaves beyond that is a wait, held at the top (bottom), after it.
                rate = climb_rate_mps if dz > 0.0 else descent_rate_mps
                vertical_hold = max(0.0, dt - abs(dz) / rate) if rate else 0.0
            else:
                speed = dist / dt if dt > 0.0 else max_speed_mps
                items.append(
                    MissionItem(
                        seq=0,
                        command=MAV_CMD_DO_CHANGE_SPEED,
                        frame=MAV_FRAME_MISSION,
                        param1=speed_type,
                        param2=round(max(floor_mps, min(speed, max_speed_mps)), 3),
                        param3=-1.0,
                    )
                )
        last_wp = len(items)
        items.append(_waypoint(wp.lat_deg, wp.lon_deg, wp.alt_amsl_m))
        if vertical_hold >= 0.05:
            items[last_wp] = replace(items[last_wp], param1=round(vertical_hold, 3))
        vertical_hold = 0.0
        if k == start_index:
            current = first_of_wp
    land = lands and not fixed_wing and len(wps) > 1
    items[last_wp] = _landing(items[last_wp]) if land else items[last_wp]
    if autopilot is Autopilot.ARDUPILOT:
        # ArduCopter stores the hold time as whole seconds: send what it keeps
        items = [
            replace(it, param1=float(round(it.param1)))
            if it.command == MAV_CMD_NAV_WAYPOINT
            else it
            for it in items
        ]
    out = [replace(it, seq=i, current=int(i == current)) for i, it in enumerate(items)]
    return out


def landing_sequence(
    items: list[MissionItem] | None, autopilot: Autopilot | None = None
) -> list[MissionItem]:
    """The landing sequence of a vehicle's mission, a pilot's landing that no UTM plan
    removes (docs/autopilots.md, "Landing sequences"): the items from its first DO_LAND_START
    to the end (what ArduPlane's RTL_AUTOLAND and DO_LAND_START and PX4's mission landing
    jump to); without one, from its first NAV_LAND / NAV_VTOL_LAND (PX4's land start then)
    to the end, with the approach before it: the navigation item before the landing when it
    is a NAV_WAYPOINT or NAV_LOITER_TO_ALT with a position (PX4's fixed-wing approach
    entrance, the start of ArduPlane's glide). Empty without a landing. ArduPilot's seq 0 is
    its home, never an approach."""
    seq = list(items or ())
    for i, it in enumerate(seq):
        if it.command == MAV_CMD_DO_LAND_START:
            return seq[i:]
    first = 1 if autopilot is Autopilot.ARDUPILOT else 0
    land = next((i for i in range(first, len(seq)) if seq[i].command in LAND_COMMANDS), None)
    if land is None:
        return []
    j = land - 1
    while j >= first and not is_nav(seq[j].command):
        j -= 1
    if j >= first and seq[j].command in APPROACH_COMMANDS and (seq[j].x, seq[j].y) != (0, 0):
        return seq[j:]
    return seq[land:]


def with_landing(
    items: list[MissionItem], landing: list[MissionItem], *, current: int | None = None
) -> list[MissionItem]:
    """``items`` followed by ``landing`` (renumbered) unless ``items`` already has a landing
    sequence of its own: a plan uploaded to a vehicle whose mission ended in a landing
    sequence keeps it at its end. ``current``: the index in ``landing`` of the item to start
    at (the plan starts inside the landing), else the item flagged in ``items``."""
    if not landing or landing_sequence(items):
        return items
    n = len(items)
    head = items if current is None else [replace(it, current=0) for it in items]
    tail = [replace(it, seq=n + k, current=int(k == current)) for k, it in enumerate(landing)]
    return [*head, *tail]


def current_seq(items: list[MissionItem]) -> int:
    """The seq flagged current=1 (0 if none)."""
    for it in items:
        if it.current:
            return it.seq
    return 0


def start_item(items: list[MissionItem], autopilot: Autopilot) -> tuple[int, MissionItem | None]:
    """(seq to make current, speed item skipped by it or None). PX4 starts at the flagged
    item (a DO_CHANGE_SPEED runs, then its waypoint). ArduPilot cannot restart a DO item
    when a mission is replaced in flight ("failed to restart command"): it starts at the
    next navigation item, and the skipped speed item is returned so that the caller can
    send it as a command."""
    seq = current_seq(items)
    if autopilot is not Autopilot.ARDUPILOT or not items:
        return seq, None
    seq = max(seq, 1)  # seq 0 is home
    skipped: MissionItem | None = None
    while seq < len(items) and not is_nav(items[seq].command):
        if items[seq].command == MAV_CMD_DO_CHANGE_SPEED:
            skipped = items[seq]
        seq += 1
    return min(seq, len(items) - 1), skipped


def frame_family(frame: int) -> int:
    """Frames that mean the same thing map to one number (0/5 global, 3/6 relative, ...)."""
    return _FRAME_FAMILY.get(frame, frame)


def _positional(it: MissionItem) -> bool:
    return is_nav(it.command) and frame_family(it.frame) != MAV_FRAME_MISSION


def _ap_param(v: float) -> float:
    return 0.0 if math.isnan(v) else v


def stored_form(
    sent: MissionItem, autopilot: Autopilot, kind: VehicleKind | None = None
) -> MissionItem:
    """What the autopilot keeps of ``sent`` and reports back (see the module docstring)."""
    if autopilot is not Autopilot.ARDUPILOT:
        return sent  # PX4 keeps floats and NaN; frames compared by family
    it = replace(
        sent,
        param1=_ap_param(sent.param1),
        param2=_ap_param(sent.param2),
        param3=_ap_param(sent.param3),
        param4=_ap_param(sent.param4),
    )
    if not _positional(it) and it.command != MAV_CMD_DO_LAND_START:
        it = replace(it, frame=MAV_FRAME_GLOBAL)  # no frame kept for a DO item
    if it.command == MAV_CMD_NAV_LAND:  # param4 keeps only a direction: -1 or 1
        it = replace(it, param4=-1.0 if it.param4 < 0.0 else 1.0)
    if it.command == MAV_CMD_NAV_WAYPOINT:
        if kind is VehicleKind.FIXED_WING:
            acc = float(min(255, max(0, int(it.param2))))
            passby = float(min(255, max(0, int(it.param3))))
            it = replace(it, param1=0.0, param2=acc, param3=passby, param4=0.0)
        else:
            hold = float(min(65535, max(0, int(it.param1))))
            it = replace(it, param1=hold, param2=0.0, param3=0.0, param4=0.0)
    return it


def _same_float(a: float, b: float, tol: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return abs(a - b) <= tol


def same_item(
    sent: MissionItem,
    got: MissionItem,
    autopilot: Autopilot = Autopilot.PX4,
    kind: VehicleKind | None = None,
) -> str:
    """'' when the vehicle's copy ``got`` means what ``sent`` meant on ``autopilot``, else
    what differs. The current flag is not compared (vehicles report their own); params to
    their float32 precision."""
    want = stored_form(sent, autopilot, kind)
    diffs: list[str] = []
    for name in ("seq", "command", "autocontinue", "mission_type"):
        if getattr(want, name) != getattr(got, name):
            diffs.append(f"{name} {getattr(want, name)} != {getattr(got, name)}")
    if frame_family(want.frame) != frame_family(got.frame):
        diffs.append(f"frame {want.frame} != {got.frame}")
    for name in ("x", "y"):  # degrees * 1e7: one unit is 1e-7 deg
        if abs(getattr(want, name) - getattr(got, name)) > 1:
            diffs.append(f"{name} {getattr(want, name)} != {getattr(got, name)}")
    for name in ("param1", "param2", "param3", "param4"):
        a, b = getattr(want, name), getattr(got, name)
        if not _same_float(a, b, 1e-3 * max(1.0, abs(a))):
            diffs.append(f"{name} {getattr(sent, name)} != {b}")
    if not _same_float(want.z, got.z, 0.01):
        diffs.append(f"z {sent.z} != {got.z}")
    return "; ".join(diffs)
