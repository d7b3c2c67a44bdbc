"""Operations from vehicles (paper: operations come from the pilots' ground stations): a vehicle
that flies a mission is an operation, filed from the mission it has, kept in step with it.

- Filed when a vehicle with no operation has a mission, and re-filed (a new plan version)
  whenever its mission changes: a change shows as a new item count or opaque mission id in
  MISSION_CURRENT, or on arming; the mission is then downloaded again and compared with the
  plan by position (a mission that is the plan, e.g. one the UTM uploaded, changes nothing).
  A mission present before the first position fix waits for the home it needs.
- Home from HOME_POSITION (ArduPilot: else mission item 0) once the vehicle has had a 3D fix
  since its boot (PX4 sends HOME_POSITION 0.4 s after boot, before its fix), never from the
  first reported altitude (a vehicle that connects airborne would put every waypoint that
  much too high); waypoints in a relative-altitude frame are resolved against it; the
  operation is re-filed when its home moves more than ``home_tolerance_m`` vertically (2 m
  horizontally), and its home is set to the vehicle's at arming (the floor of its flight).
- A mission present before the first 3D fix is filed, whole, when the fix comes. A disarmed
  vehicle's plan is its whole mission from where it stands (the current item counts only in
  the air); it is re-timed from the vehicle's progress when it starts the mission. A vehicle
  found flying (a restarted service) has its stored plan re-timed from its position at once
  (:mod:`.found_flying`); without one it is filed at its first MISSION_CURRENT, not before.
- A reboot forgets the home: a new pre-flight.
- Timed from the vehicle's progress, not from the download: the plan starts at the vehicle's
  position (at that position's time), flies to the current item (MISSION_CURRENT) and on at
  the mission's speeds (DO_CHANGE_SPEED, else the cruise speed); it is re-timed when the
  vehicle starts the mission and when, at a new current item, it is more than a
  flight-geometry's worth of time off.
- A warning, once per vehicle, when its home is far from the airspace's ground elevation
  (AGL inputs would then be converted with the wrong ground).

A cluster member (``owns`` set, :mod:`gcs_utm.cluster.node`) hears every vehicle behind a
MAVLink router: it files only a vehicle whose mission departs in a region it holds, and
re-files, re-times or re-homes only the operations it owns (another instance's are that
instance's to change).

Only operations this module filed (``conops`` = :data:`CONOPS`) are re-timed or follow home
moves; an operation filed elsewhere (scenario, MQTT) is re-filed only when the vehicle's
mission changes after discovery to something other than its plan.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field

from gcs_utm.clock import Clock
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import (
    Autopilot,
    FlightPlan,
    Operation,
    OperationId,
    Position,
    SysId,
    VehicleKind,
    Waypoint4D,
    default_envelope,
)
from gcs_utm.services import fixed_wing_plan as fw
from gcs_utm.services import found_flying, mission_order
from gcs_utm.services.airspace import Airspace, AirspaceError
from gcs_utm.services.flight_state import FlightState
from gcs_utm.services.mission_points import (
    ABSOLUTE_FRAMES,
    MATCH_H_M,
    NavPoint,
    dist_m,
    mission_is_plan,
    mission_points,
    plan_from_points,
)
from gcs_utm.services.takeoff_roll import RollWatch

_log = logging.getLogger(__name__)

CONOPS = "from vehicle mission"
"""``Operation.conops`` of an operation filed from a vehicle's mission."""

_RETRY_FIRST_S = 2.0  # a failed mission download is tried again after this, doubling
_RETRY_MAX_S = 30.0
_FAILURES_CAP = 1000
"""Failed downloads in a row are counted up to this (the back-off reached its cap long
before): a counter a sender drives cannot grow without bound."""
_BACKOFF_STEPS_MAX = 16  # 2 s * 2**16 is past any cap: no exponent past it (no overflow)
_HOME_MOVE_M = 2.0
"""A home that moved less than this is the same home: PX4's HOME_POSITION wanders by about a
metre while its estimator converges (measured on SIH), which would re-file every few seconds."""
_FLYING_MODES = frozenset({FlightMode.MISSION, FlightMode.TAKEOFF})
_TURN_FROM_M = 80.0
"""A fixed wing this close to the waypoint it just reached is turning round it (ArduPlane
accepts a waypoint WP_RADIUS, 50 m, before it): its re-timed plan starts there."""
_CLIMB_RATE_MPS = 3.0
"""The climb rate of an operation filed here (``Operation.max_climb_rate_mps``'s default): a
fixed wing's take-off climb-out and loiter-to-alt circles are timed at it."""


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleOpsSettings:
    """The operation defaults (from ``[usm]``) and the airspace ground for the warning."""

    priority: int
    flight_geometry_m: float
    operational_volume_m: float
    cruise_speed_mps: float
    ground_warning_m: float
    fixed_wing_cruise_speed_mps: float = 22.0
    ground_elevation_amsl_m: float | None = None
    home_tolerance_m: float = 1.0


def _moved(a: Position | None, b: Position | None, vertical_m: float = _HOME_MOVE_M) -> bool:
    if a is None or b is None:
        return a is not b
    horizontal = dist_m(a, Position(lat_deg=b.lat_deg, lon_deg=b.lon_deg, alt_amsl_m=a.alt_amsl_m))
    return horizontal > _HOME_MOVE_M or abs(a.alt_amsl_m - b.alt_amsl_m) > vertical_m


@dataclass(slots=True)
class _Vehicle:
    sys_id: SysId
    autopilot: Autopilot
    kind: VehicleKind
    items: Sequence[object] | None = None  # the last downloaded mission
    # MISSION_CURRENT's item count and mission id: as last reported, and as they were when
    # the last download started (a difference is a mission change)
    total: int | None = None
    mission_id: int | None = None
    items_total: int | None = None
    items_mission_id: int | None = None
    home: Position | None = None  # HOME_POSITION, else ArduPilot's item 0
    home_from_status: bool = False
    seq: int | None = None
    stale_seq: int | None = None  # a stale MISSION_CURRENT after PX4 restarted (mission_order)
    position: Position | None = None
    position_t_s: float | None = None  # when it was taken (None: not reported, take it as now)
    takeoff_heading_deg: float | None = None  # its heading when it armed (a fixed wing's run)
    heading_deg: float | None = None  # its last (GLOBAL_POSITION_INT hdg)
    landed: bool | None = None  # its last landed state (None: not reported)
    armed: bool = False
    flying: bool = False  # armed in a mission mode
    downloading: bool = False
    again: bool = False  # the mission changed during a download: download once more
    change_waiting: bool = False  # the mission changed (or it armed) during a back-off
    changes: int = 0  # downloads triggered by a change after discovery
    start_pending: bool = False  # the mission started during a download: re-time after it
    waiting_logged: bool = False
    ground_warned: bool = False
    failures: int = 0  # mission downloads failed in a row
    retry_at_s: float | None = None  # when a failed download is tried again
    uploading: FlightPlan | None = None  # the plan the USM is uploading (see expect_upload)
    fixed: bool = True  # a 3D fix since its boot (False while a FlightState says none yet)
    roll: RollWatch = field(default_factory=RollWatch)  # a fixed wing's take-off run
    # first heard in the air (None: not heard yet), until it is on the ground: its take-off
    # run was not seen (no take-off heading) and its stored plan was timed by another life
    found_flying: bool | None = None
    timed_here: bool = False  # its operation's plan was timed (filed, re-timed) by this life


class VehicleOps:
    """See the module docstring. ``log_event`` and ``spawn`` are the USM's."""

    def __init__(
        self,
        airspace: Airspace,
        clock: Clock,
        settings: VehicleOpsSettings,
        *,
        log_event: Callable[[str, str], None],
        spawn: Callable[[Awaitable[None]], None],
    ) -> None:
        self.airspace = airspace
        self.clock = clock
        self.settings = settings
        self._log_event = log_event
        self._spawn = spawn
        self._port: Callable[[SysId], Awaitable[Sequence[object]]] | None = None
        self._vehicles: dict[SysId, _Vehicle] = {}
        # cluster: may this instance file (plan: a new operation's) or change this operation
        self.owns: Callable[[OperationId, FlightPlan | None], bool] | None = None
        self.counters: dict[str, int] = {
            "filed": 0,
            "refiled": 0,
            "retimed": 0,
            "downloads": 0,
            "download_failures": 0,
            "not_ours": 0,
        }

    def _ours(self, op_id: OperationId, plan: FlightPlan | None = None) -> bool:
        return self.owns is None or self.owns(op_id, plan)

    def attach(self, port: object) -> None:
        """The MAVLink side; without ``download_mission`` no operation is filed."""
        self._port = getattr(port, "download_mission", None)

    def expect_upload(self, sys_id: SysId, plan: FlightPlan | None) -> None:
        """The USM uploads ``plan`` (None: that upload is over and failed). The vehicle's
        mission changes with the upload, which starts a download; a download that returns
        that plan before the USM installs it (after the readback) is the upload's own echo,
        not a new mission of the pilot's: it is not filed as a plan of its own."""
        v = self._vehicles.get(sys_id)
        if v is not None:
            v.uploading = plan

    # ---- events -------------------------------------------------------------------------
    def on_vehicle(self, v: object) -> None:
        """A newly heard vehicle: download its mission (and file it when it has one)."""
        key = getattr(v, "key", None)
        raw = getattr(key, "sys_id", None)
        if raw is None:
            return
        sys_id = SysId(int(raw))
        if sys_id in self._vehicles:
            return  # heard again (a moved address): the same vehicle
        self._vehicles[sys_id] = _Vehicle(
            sys_id=sys_id,
            autopilot=getattr(v, "autopilot", Autopilot.UNKNOWN),
            kind=getattr(v, "vehicle_kind", None) or VehicleKind.MULTIROTOR,
        )
        self._download(sys_id)

    def on_status(
        self, s: VehicleStatus, flight: FlightState | None = None, changes: Sequence[str] = ()
    ) -> None:
        """One status; ``flight`` is the vehicle's state (:mod:`.flight_state`) and
        ``changes`` its transitions at this status (without one, HOME_POSITION is taken as
        it comes)."""
        v = self._vehicles.get(s.sys_id)
        if v is None:
            return
        if s.position is not None:
            v.position, v.position_t_s = s.position, s.position_t_s
        v.heading_deg, v.landed = s.heading_deg, s.landed
        v.found_flying = (
            (s.armed and s.landed is not True)
            if v.found_flying is None
            else (v.found_flying and s.armed and s.landed is not True)
        )
        if (not v.armed and not v.found_flying) or s.landed is True:  # its take-off run's
            v.takeoff_heading_deg = v.roll.parked_heading_deg(s.heading_deg)
        v.total = s.mission_total
        v.mission_id = s.mission_id
        if "rebooted" in changes:
            v.home, v.home_from_status = None, False  # a new pre-flight: a new home
            v.roll = RollWatch()
        home = s.home
        if flight is not None:
            v.fixed, home = flight.had_fix, flight.home
        arming = "armed" in changes
        tolerance_m = self.settings.home_tolerance_m
        if home is not None and (_moved(v.home, home, tolerance_m) or (arming and home != v.home)):
            self._home(v, home, from_status=True, arming=arming)
        elif "fix" in changes and v.items is not None:
            self._file(v, changed=False)  # a mission that waited for the first fix
        if arming and v.home is not None:
            self._home_at_arming(v)
        self._maybe_download(v, self._mission_changed(v, s) or (s.armed and not v.armed))
        v.roll.update(s.armed, v.armed, s.position)
        v.armed = s.armed
        flying = s.armed and s.mode in _FLYING_MODES
        if flying and v.found_flying and not v.timed_here:
            self._retime_stored(v)
        started = flying and not v.flying
        seq, v.stale_seq = mission_order.current_seq(s, v.autopilot, v.stale_seq, started)
        advanced = seq is not None and seq != v.seq
        v.flying, v.seq = flying, v.seq if seq is None else seq
        # a fixed wing's plan is timed from its take-off run too (takeoff_roll.py)
        rolled = flying and v.kind is VehicleKind.FIXED_WING and v.roll.rolled(s.position)
        if flying and (started or advanced or rolled):
            self._retime(v, started=started or rolled)

    def _maybe_download(self, v: _Vehicle, changed: bool) -> None:
        """Download on a mission change or an arming, and retry a failed download when its
        back-off is over. A change during a back-off waits for it: a sender toggling armed
        would otherwise start a download (and fail it) on every frame."""
        if v.retry_at_s is not None and self.clock.now_s() < v.retry_at_s:
            v.change_waiting = v.change_waiting or changed
            return
        if not changed and v.retry_at_s is None:
            return
        if changed or v.change_waiting:
            v.changes += 1
        v.retry_at_s, v.change_waiting = None, False
        self._download(v.sys_id)

    @staticmethod
    def _mission_changed(v: _Vehicle, s: VehicleStatus) -> bool:
        """MISSION_CURRENT's count or id differ from what they were when the last download
        started (while a download runs, the check waits for its end). Compared with itself,
        not with the downloaded count: ArduPilot's count leaves out its home item."""
        if v.downloading:
            return False
        if s.mission_total is not None and s.mission_total != v.items_total:
            return True
        return s.mission_id is not None and s.mission_id != v.items_mission_id

    # ---- mission download -----------------------------------------------------------------
    def _download(self, sys_id: SysId) -> None:
        v = self._vehicles[sys_id]
        if self._port is None:
            return
        if v.downloading:
            v.again = True
            return
        v.downloading = True
        self._spawn(self._download_task(v))

    async def _download_task(self, v: _Vehicle) -> None:
        download = self._port
        assert download is not None
        try:
            while True:
                v.again = False
                v.items_total, v.items_mission_id = v.total, v.mission_id
                self.counters["downloads"] += 1
                try:
                    items = list(await download(v.sys_id))
                except Exception as exc:  # the link's own error types; it may not answer
                    self._download_failed(v, exc)
                    return
                v.failures, v.retry_at_s = 0, None
                v.items = items
                if not v.again:
                    break
        finally:
            v.downloading = False
        self._item0_home(v)
        self._file(v, changed=v.changes > 0)
        if v.start_pending:
            v.start_pending = False
            if v.flying:
                self._retime(v, started=True)

    def _download_failed(self, v: _Vehicle, exc: Exception) -> None:
        """A failed download is tried again after a backoff (2, 4, 8 ... at most 30 s), checked
        on the vehicle's next status: without it a vehicle whose first download timed out would
        stay without an operation until its mission changed. Mission changes and armings
        wait for the back-off too (see _maybe_download)."""
        self.counters["download_failures"] += 1
        v.failures = min(v.failures + 1, _FAILURES_CAP)
        steps = min(v.failures - 1, _BACKOFF_STEPS_MAX)
        delay_s = min(_RETRY_MAX_S, _RETRY_FIRST_S * 2.0**steps)
        v.retry_at_s = self.clock.now_s() + delay_s
        self._log_event(
            "vehicle",
            f"sysid {v.sys_id}: mission download failed ({v.failures} in a row): {exc}; "
            f"retry in {delay_s:.0f} s",
        )

    def _item0_home(self, v: _Vehicle) -> None:
        """ArduPilot keeps its home in mission item 0 (absolute altitude): the home until
        HOME_POSITION gives one (after the first fix: before it, item 0 is not a home)."""
        if v.home_from_status or v.autopilot is not Autopilot.ARDUPILOT or not v.items:
            return
        if not v.fixed:
            return
        it = v.items[0]
        lat, lon = float(getattr(it, "x", 0)) / 1e7, float(getattr(it, "y", 0)) / 1e7
        if (lat, lon) == (0.0, 0.0) or int(getattr(it, "frame", 0)) not in ABSOLUTE_FRAMES:
            return
        home = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=float(getattr(it, "z", 0.0)))
        if _moved(v.home, home):
            self._home(v, home, from_status=False)

    # ---- home ---------------------------------------------------------------------------
    def _home(
        self, v: _Vehicle, home: Position, *, from_status: bool, arming: bool = False
    ) -> None:
        first = v.home is None
        v.home = home
        v.home_from_status = v.home_from_status or from_status
        where = "HOME_POSITION" if from_status else "mission item 0"
        self._log_event(
            "vehicle",
            f"sysid {v.sys_id}: home {home.lat_deg:.7f}, {home.lon_deg:.7f}, "
            f"{home.alt_amsl_m:.2f} m AMSL (from {where})",
        )
        self._warn_ground(v, home)
        if v.items is None:
            return
        op = self.airspace.by_sys_id(v.sys_id)
        if op is None:
            self._file(v, changed=False)  # a mission that waited for its home
        elif op.conops == CONOPS:
            why = "the vehicle reported its home" if first else "the vehicle's home moved"
            why = "the vehicle armed (its home at arming)" if arming else why
            self._file(v, changed=True, reason=why, new_home=arming)

    def _home_at_arming(self, v: _Vehicle) -> None:
        """Any operation the vehicle flies takes its home at arming (TD's floor is that home
        plus the minimum height): one filed elsewhere (scenario, MQTT) too."""
        op = self.airspace.by_sys_id(v.sys_id)
        if op is None or v.home is None or op.home == v.home or op.conops == CONOPS:
            return
        if self._ours(op.id):
            self.airspace.set_home(op.id, v.home)

    def _warn_ground(self, v: _Vehicle, home: Position) -> None:
        ground = self.settings.ground_elevation_amsl_m
        if ground is None or v.ground_warned:
            return
        gap = home.alt_amsl_m - ground
        if abs(gap) <= self.settings.ground_warning_m:
            return
        v.ground_warned = True
        self._log_event(
            "warning",
            f"sysid {v.sys_id}: home altitude {home.alt_amsl_m:.2f} m AMSL is {gap:+.1f} m from "
            f"the airspace ground elevation {ground:.2f} m AMSL: set "
            "[airspace] ground_elevation_amsl_m (and the origin) to the vehicles' home, or AGL "
            "heights are converted with the wrong ground",
        )

    # ---- filing ---------------------------------------------------------------------------
    def _points(self, v: _Vehicle) -> list[NavPoint] | None:
        """The vehicle's last mission as points; None (logged once) while a relative altitude
        waits for the home."""
        points = mission_points(
            v.items or (),
            home=v.home,
            cruise_speed_mps=self._cruise_mps(v),
            skip_first=v.autopilot is Autopilot.ARDUPILOT,
        )
        if points is not None and v.kind is VehicleKind.FIXED_WING:
            env = default_envelope(v.kind, self._cruise_mps(v), _CLIMB_RATE_MPS)
            points = fw.fixed_wing_points(
                points,
                ground_alt_m=v.home.alt_amsl_m if v.home is not None else None,
                climb_rate_mps=env.climb_rate_mps,
                descent_rate_mps=env.descent_rate_mps,
                loiter_radius_m=env.turn_radius_m,
                home_deg=(v.home.lat_deg, v.home.lon_deg) if v.home is not None else None,
                loiter_landing=v.autopilot is Autopilot.PX4,
                takeoff_heading_deg=v.takeoff_heading_deg,
                heads_for_takeoff_position=v.autopilot is not Autopilot.ARDUPILOT,
                turn_after_takeoff=v.autopilot is Autopilot.ARDUPILOT,
                loiter_exit_on_goal=v.autopilot is Autopilot.PX4,
            )
        if points is None and not v.waiting_logged:
            v.waiting_logged = True
            self._log_event(
                "vehicle",
                f"sysid {v.sys_id}: mission altitudes are relative to a home the vehicle has "
                "not reported yet: the operation is filed when it does",
            )
        return points

    def _position_t_s(self, v: _Vehicle) -> float:
        """The time the vehicle's last position was taken, which a plan from it starts at: a
        plan made at the end of a download starts from a position up to a status period old
        (a plane at 23 m/s found flying by a restarted service, its position 1.3 s old and its
        plan timed from now: UAS_IN_CV 12.3 m), and under load positions are read seconds
        after they were taken (the PX4 plane's loiter exit re-timed from a position 3 s old
        by its capture time: UAS_IN_CV 19.4 m)."""
        now_s = self.clock.now_s()
        t_s = v.position_t_s
        return now_s if t_s is None or v.position is None else min(t_s, now_s)

    def _cruise_mps(self, v: _Vehicle) -> float:
        """The speed a mission without speed items is flown at: a fixed wing's cruise
        airspeed, else the multirotor default."""
        if v.kind is VehicleKind.FIXED_WING:
            return self.settings.fixed_wing_cruise_speed_mps
        return self.settings.cruise_speed_mps

    def _plan(
        self, v: _Vehicle, points: list[NavPoint], op_id: OperationId, version: int, reason: str
    ) -> FlightPlan | None:
        """The plan of ``points``, timed from the vehicle's current item and position now; None
        for one found in the air before its first MISSION_CURRENT (a restarted service)."""
        if v.armed and v.seq is None and v.landed is not True:
            return None
        # a multirotor's autopilot limits its vertical speed: steep legs at the envelope's
        # rates (a fixed wing's climbs are modelled by fixed_wing_points)
        rates = self._vertical_rates(v) if v.kind is VehicleKind.MULTIROTOR else (None, None)
        try:
            return plan_from_points(
                points,
                op_id,
                t_s=self._position_t_s(v),
                current_seq=v.seq if v.armed else None,  # on the ground: the whole mission
                position=v.position,
                version=version,
                reason=reason,
                turn_from_m=_TURN_FROM_M if v.kind is VehicleKind.FIXED_WING else 0.0,
                course_deg=v.heading_deg if v.autopilot is Autopilot.PX4 else None,
                climb_rate_mps=rates[0],
                descent_rate_mps=rates[1],
            )
        except ValueError as exc:  # a plan the model refuses (malformed positions)
            self._log_event("vehicle", f"sysid {v.sys_id}: mission not usable: {exc}")
            return None

    def _vertical_rates(self, v: _Vehicle) -> tuple[float, float]:
        """Climb and descent rates of the vehicle's operation's envelope (before it has one:
        of the operation it gets)."""
        op = self.airspace.by_sys_id(v.sys_id)
        env = (
            op.performance()
            if op is not None
            else default_envelope(v.kind, self._cruise_mps(v), _CLIMB_RATE_MPS)
        )
        return env.climb_rate_mps, env.descent_rate_mps

    def _file(
        self, v: _Vehicle, *, changed: bool, reason: str = "", new_home: bool = False
    ) -> None:
        """File the vehicle's mission as an operation, or as a new plan version of its
        operation when ``changed`` (or it filed that operation) and the mission is not already
        its plan (or the home moved; ``new_home``: changed at all). Not before the vehicle's
        first 3D fix (its home and position are not known yet)."""
        if v.items is None or not v.fixed:
            return
        op = self.airspace.by_sys_id(v.sys_id)
        if op is not None and (
            (not changed and op.conops != CONOPS)  # filed elsewhere: its plan stands
            or not self._ours(op.id)  # another cluster member's operation
        ):
            return
        points = self._points(v)
        if points is None:
            return  # waits for the home
        if not points:
            if op is None and v.items:
                self._log_event(
                    "vehicle", f"sysid {v.sys_id}: no waypoints in its mission: no operation"
                )
            return
        if op is None:
            plan = self._plan(
                v, points, OperationId(f"sys{v.sys_id}"), 1, "from the vehicle's mission"
            )
            if plan is not None and self._ours(plan.operation_id, plan):
                self._add(v, plan)
            elif plan is not None:
                self.counters["not_ours"] += 1  # departs in another member's region
            return
        home_moved = (
            op.conops == CONOPS
            and v.home is not None
            and (_moved(op.home, v.home, self.settings.home_tolerance_m) or new_home)
            and op.home != v.home
        )
        echo = v.uploading is not None and _flies_plan(v, points, v.uploading)
        if (echo or _flies_plan(v, points, op.plan)) and not home_moved:
            return
        why = reason or "the vehicle's mission changed"
        plan = self._plan(
            v, points, op.id, op.plan.version + 1, f"from the vehicle's mission ({why})"
        )
        if plan is not None:
            self._replace(v, op, plan, why, counter="refiled")

    def _add(self, v: _Vehicle, plan: FlightPlan) -> None:
        s = self.settings
        op = Operation(
            id=plan.operation_id,
            icao24=None,
            sys_id=v.sys_id,
            priority=s.priority,
            plan=plan,
            vehicle_kind=v.kind,
            cruise_speed_mps=self._cruise_mps(v),
            flight_geometry_m=s.flight_geometry_m,
            operational_volume_m=s.operational_volume_m,
            conops=CONOPS,
            home=v.home,
            autopilot=v.autopilot,
        )
        try:
            self.airspace.add_operation(op)
        except AirspaceError as exc:
            self._log_event("vehicle", f"sysid {v.sys_id}: {exc}")
            return
        self.counters["filed"] += 1
        v.timed_here = True
        self._log_event(
            "operation",
            f"{op.id} filed from sysid {v.sys_id}'s mission ({len(plan.waypoints)} wp)",
        )

    def _replace(
        self, v: _Vehicle, op: Operation, plan: FlightPlan, why: str, counter: str
    ) -> None:
        try:
            self.airspace.replace_plan(plan, home=v.home if op.conops == CONOPS else None)
        except AirspaceError as exc:
            self._log_event("vehicle", f"sysid {v.sys_id}: plan not installed: {exc}")
            return
        self.counters[counter] += 1
        v.timed_here = True
        self._log_event(
            "operation",
            f"{op.id} plan v{plan.version} from sysid {v.sys_id}'s mission: {why} "
            f"({len(plan.waypoints)} wp)",
        )

    # ---- timing -------------------------------------------------------------------------
    def _retime(self, v: _Vehicle, *, started: bool) -> None:
        """Re-time a vehicle-filed plan from the vehicle's progress: when it starts the
        mission, and at a new current item when the plan is more than flight_geometry_m /
        cruise speed off at that item."""
        op = self.airspace.by_sys_id(v.sys_id)
        # found flying on a plan re-timed here from its position: it did not start here
        started = started and not (v.found_flying and v.timed_here)
        if v.downloading:
            v.start_pending = v.start_pending or started
            return  # (the arming that started it also downloads the mission: after that)
        if op is None and v.items:  # found flying: filed at its first current item (_plan)
            self._file(v, changed=False)
        if op is None or op.conops != CONOPS or v.items is None or not self._ours(op.id):
            return
        points = self._points(v)
        if not points or not _flies_plan(v, points, op.plan):
            return  # a mission that is not the plan (yet): the mission check re-files it
        plan = self._plan(
            v, points, op.id, op.plan.version + 1, "re-timed from the vehicle's progress"
        )
        if plan is None:
            return
        if not started:
            # the first waypoint of the new plan that the old one has (the position the
            # plan starts from is not one of them): how far off in time the old plan is there
            pairs = ((w, o) for w in plan.waypoints for o in op.plan.waypoints)
            gap = next((w.t_s - o.t_s for w, o in pairs if _same_wp(w, o)), None)
            if gap is None:
                return  # no item of it is in the plan: the mission check re-files it
            tolerance_s = op.flight_geometry_m / max(op.cruise_speed_mps, 0.1)
            if abs(gap) <= tolerance_s:
                return
        why = "the vehicle started the mission" if started else "re-timed at a new current item"
        self._replace(v, op, plan, why, counter="retimed")

    def _retime_stored(self, v: _Vehicle) -> None:
        """A vehicle found flying with a plan this life did not time (the store's, an earlier
        life's clock): re-timed from its position at once (:mod:`.found_flying`)."""
        op = self.airspace.by_sys_id(v.sys_id)
        if op is None or v.position is None:
            return  # filed from its mission at its first MISSION_CURRENT (_plan)
        if op.conops != CONOPS or not self._ours(op.id):
            v.timed_here = True  # not this module's to re-time
            return
        plan = found_flying.retimed_at(
            op.plan,
            v.position,
            self._position_t_s(v),
            version=op.plan.version + 1,
            reason="re-timed from the vehicle's position (a stored plan, another life's clock)",
            max_off_m=op.flight_geometry_m,
        )
        if plan is None:
            v.found_flying = False  # off its stored plan: re-planned from its mission
            return
        self._replace(v, op, plan, "found flying on a stored plan", counter="retimed")


def _flies_plan(v: _Vehicle, points: Sequence[NavPoint], plan: FlightPlan) -> bool:
    """The mission's points from the current item on are the plan's (a plan filed or re-timed
    at an earlier item has them all; the items already flown are not compared)."""
    rest = [p for p in points if v.seq is None or p.seq >= v.seq]
    return mission_is_plan(rest, plan)


def _same_wp(a: Waypoint4D, b: Waypoint4D) -> bool:
    return dist_m(a, b) <= MATCH_H_M
