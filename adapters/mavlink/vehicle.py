"""Per-vehicle telemetry state (sans-IO): decoded messages in, typed events out.

One :class:`VehicleState` per :class:`VehicleKey` (link, source address, sysid, compid). It
keeps link statistics (sequence-number loss, duplicates, reboots from ``time_boot_ms``), the
vehicle clock -> UTC mapping, and the hazard debouncing, and turns messages into
:class:`Measurement`, :class:`VehicleStatus` and :class:`HazardReport` through an
:class:`Events` sink.

Vehicle clock -> our clock (capture time = ``offset_s + time_boot_ms / 1000``): every report
with ``time_boot_ms`` gives a sample ``receipt - boot``, the true offset plus its transport
delay. The offset is a bounded-rate lower envelope of the samples: a sample below it lowers it
at once (a capture time is never later than its receipt); at the end of each
``clock_window_s`` of vehicle time it rises towards that window's lowest sample by at most
``clock_max_drift`` x the window (a vehicle clock that runs slow, as PX4 SIH's by ~1 %, is
followed; jitter and delayed reports move nothing), or is re-anchored there, and the jump
counted, when that sample is more than ``clock_jump_s`` above it (a clock jump, or a drift
beyond the bound). A reboot (``time_boot_ms`` going back, or less uptime than the time the
vehicle went unheard: it booted while its link was down) starts over; so does a HEARTBEAT
whose ``system_status`` is back to UNINIT or BOOT after a later state (:func:`boot_again`:
a PX4 restarted within ~0.5 s, whose first position comes when its new clock is near the
old one, says so in its first HEARTBEAT). SYSTEM_TIME (``unix -
boot``, once the vehicle has GNSS time) is used only when it agrees with its own arrival (not
later, at most ``system_time_max_lag_s`` earlier); otherwise it is counted as rejected and the
arrival-based offset stays. See docs/vehicle-time.md.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from typing import Protocol

from adapters.mavlink import modes, wire
from adapters.mavlink.config import MavlinkConfig
from adapters.mavlink.mission import MissionItem
from gcs_utm.messages import FlightMode, HazardReport, LinkHealth, VehicleKey, VehicleStatus
from gcs_utm.model import (
    Autopilot,
    LaneSource,
    Measurement,
    Position,
    PositionLane,
    ThreatKind,
    VehicleKind,
)
from gcs_utm.ratelog import RateLimitedLog

_log = logging.getLogger(__name__)

_NAN = float("nan")
_NO_HEADING = 36000  # GLOBAL_POSITION_INT hdg: 0..35999 cdeg, UINT16_MAX when unknown
# A reported altitude outside this range (m AMSL) is no altitude: the same plausibility bounds
# as scenario and configuration input (gcs_utm.validation).
_MIN_ALT_AMSL_M = -500.0
_MAX_ALT_AMSL_M = 20_000.0
_INF = float("inf")
_MIN_UNIX_S = 1.5e9  # SYSTEM_TIME before 2017 means "no GNSS time yet"
_JAM_RE = re.compile(r"jam", re.IGNORECASE)
_SPOOF_RE = re.compile(r"spoof", re.IGNORECASE)
_GNSS_BAD_RE = re.compile(
    r"(gps|gnss).*(lost|fail|degrad|glitch|bad|no fix)|(lost|no).*(gps|gnss)", re.IGNORECASE
)


_MAV_STATE_BOOT = 1
_MAV_STATE_CALIBRATING = 2


def boot_again(before: int, now: int) -> bool:
    """Whether a HEARTBEAT's ``system_status`` ``now`` after ``before`` (the previous one's,
    -1 for none) shows a new boot. A boot is the only way back to MAV_STATE_UNINIT (0) or
    MAV_STATE_BOOT (1) from a later state: PX4 v1.15 sends UNINIT while its arming state is
    INIT (from boot until its checks first ran), then STANDBY/ACTIVE/CRITICAL/...; ArduPilot
    4.6 sends BOOT until it is initialised (STANDBY at once on the ground). See
    docs/vehicle-time.md."""
    return before >= _MAV_STATE_CALIBRATING and 0 <= now <= _MAV_STATE_BOOT


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleInfo:
    """A discovered vehicle (from its autopilot HEARTBEAT)."""

    key: VehicleKey
    autopilot: Autopilot
    vehicle_kind: VehicleKind | None
    mav_type: int
    first_heard_t_s: float


class Events(Protocol):
    def on_measurement(self, m: Measurement) -> None: ...
    def on_status(self, s: VehicleStatus) -> None: ...
    def on_hazard(self, h: HazardReport) -> None: ...
    def on_vehicle(self, v: VehicleInfo) -> None: ...
    def on_link_health(self, h: LinkHealth) -> None: ...


class VehicleState:
    """Everything we know about one vehicle component on one link."""

    streams_asked_t_s: float | None = None
    """When the hub last asked this (ArduPilot) vehicle for its streams (hub clock, s)."""

    position_t_s: float | None = None
    """When its last position report (GLOBAL_POSITION_INT) arrived (hub clock, s)."""

    position_capture_t_s: float | None = None
    """When the vehicle took that position (its time_boot_ms on the hub clock, else the
    arrival): a backlog read late under load arrives seconds after it was taken."""

    mission: list[MissionItem] | None = None
    """The vehicle's mission as last downloaded or read back after an upload (uploads keep
    its landing sequence)."""

    _heading_cdeg: int = _NO_HEADING
    """GLOBAL_POSITION_INT hdg: the vehicle's heading (a fixed wing's take-off run)."""

    _system_status: int = -1
    """The last HEARTBEAT's system_status (MAV_STATE), -1 before the first."""

    def __init__(
        self,
        key: VehicleKey,
        cfg: MavlinkConfig,
        t_s: float,
        lane: PositionLane | None = None,
        *,
        ratelog: RateLimitedLog | None = None,
    ) -> None:
        self.key = key
        # repeated warnings (a sender whose time_boot_ms keeps going back) are rate-limited
        self._ratelog = ratelog or RateLimitedLog(_log, cfg.warn_interval_s, max_causes=8)
        self.cfg = cfg
        self.sys_id = key.sys_id
        # where the vehicle was first heard: kept when its address moves (NAT rebinding), so
        # its track does not change identity; tells apart vehicles sharing a system id
        self.tag = key.address
        self.info: VehicleInfo | None = None
        self.autopilot = Autopilot.UNKNOWN
        self.kind: VehicleKind | None = None
        self.mode = FlightMode.UNKNOWN
        self.custom_mode = 0
        self.armed = False
        self.landed: bool | None = None
        # link statistics
        self.first_t_s = self.last_heard_t_s = t_s
        self.received = 0
        self.lost = 0
        self.duplicates = 0
        self.reboots = 0
        self._last_seq = -1
        self._rate_mark = (t_s, 0)
        self.rate_hz = 0.0
        # clock (see the module docstring)
        # the last time_boot_ms, and when it arrived
        self.last_boot_ms, self._boot_heard_t_s = -1, t_s
        self.offset_s: float | None = None  # our clock - boot time
        self.offset_from_system_time = False
        self.clock_jumps = 0  # re-anchors of the offset (jumps, drift beyond the bound)
        self.system_time_used = 0
        self.system_time_rejected = 0  # SYSTEM_TIME that disagreed with arrival times
        self._drift_per_ms = cfg.clock_max_drift / 1000.0
        self._window_ms = max(1, round(cfg.clock_window_s * 1000.0))
        self._window_start_ms = 0
        self._window_end_ms = 0
        self._window_min = _INF
        self._system_time_boot_ms = -1
        # home (HOME_POSITION) and the mission's opaque id (MISSION_CURRENT, MAVLink >= 2023)
        self.home: Position | None = None
        self.mission_id: int | None = None
        # GNSS / battery / mission
        self.fix_type: int | None = None
        self.satellites: int | None = None
        self.eph_m: float | None = None
        self.epv_m: float | None = None
        self.battery_pct: float | None = None
        self.battery_v: float | None = None
        self.mission_seq: int | None = None
        self.mission_total: int | None = None
        self._battery_low = False
        self._fix_lost = False
        self._eph_bad = False
        # the last reported (lat, lon, alt AMSL); a Position is built only for a hazard report
        self._last_fix: tuple[float, float, float] | None = None
        # Positions become entries of ``lane`` (the sink's); without one, each entry is handed
        # on at once as the Measurement it stands for (a lane of this vehicle's own names it).
        self._own_lane = lane is None
        self._lane = PositionLane() if lane is None else lane
        self._lane_put = self._lane.values.extend
        self._lane_index = self._lane.register(LaneSource(key.sys_id, key.link, self.tag))

    # --- link statistics ------------------------------------------------------------------
    def count_frame(self, seq: int, t_s: float) -> None:
        self.received += 1
        self.last_heard_t_s = t_s
        last = self._last_seq
        if last >= 0:
            gap = (seq - last - 1) & 0xFF
            if gap >= 128:  # behind the last one: a duplicate or a reordered datagram
                self.duplicates += 1
                return
            self.lost += gap
        self._last_seq = seq

    def health(self, t_s: float, bad_frames: int) -> LinkHealth:
        t0, n0 = self._rate_mark
        if t_s > t0:
            self.rate_hz = (self.received - n0) / (t_s - t0)
        self._rate_mark = (t_s, self.received)
        return LinkHealth(
            sys_id=self.sys_id,
            link=self.key.link,
            last_heard_t_s=self.last_heard_t_s,
            rate_hz=self.rate_hz,
            received=self.received,
            lost=self.lost,
            bad_frames=bad_frames,
            reboots=self.reboots,
            vehicle=self.tag,
            clock_jumps=self.clock_jumps,
            system_time_rejected=self.system_time_rejected,
        )

    # --- clock ----------------------------------------------------------------------------
    def boot_time(self, boot_ms: int, receipt_t_s: float) -> bool:
        """One ``time_boot_ms`` sample received at ``receipt_t_s``: the offset filter (module
        docstring). True when it shows a reboot. On the position hot path: a few operations."""
        sample = receipt_t_s - boot_ms * 0.001
        off = self.offset_s
        d_ms = boot_ms - self.last_boot_ms
        unheard_ms = (receipt_t_s - self._boot_heard_t_s) * 1000.0
        self._boot_heard_t_s = receipt_t_s
        tolerance_ms = self.cfg.reboot_tolerance_ms
        # a reboot: its clock went back, or it has been up for less time than it was unheard
        # (it booted while its link was down, and its new clock already passed the old one)
        if d_ms < -tolerance_ms or (off is not None and unheard_ms > boot_ms + tolerance_ms):
            self._rebooted(boot_ms)
            self._anchor(boot_ms, sample)
            return True
        if d_ms > 0:
            self.last_boot_ms = boot_ms
        if off is None:
            self._anchor(boot_ms, sample)
            return False
        if sample < off:  # never dated after its arrival: down at once
            self.offset_s = sample
        if sample < self._window_min:  # noqa: PLR1730 (a compare is cheaper than min() here)
            self._window_min = sample
        if boot_ms >= self._window_end_ms:
            self._close_window(boot_ms)
        return False

    def _anchor(self, boot_ms: int, sample: float) -> None:
        self.last_boot_ms = boot_ms
        self.offset_s = sample
        self.offset_from_system_time = False
        self._window_min = _INF
        self._window_start_ms = boot_ms
        self._window_end_ms = boot_ms + self._window_ms

    def _rebooted(self, boot_ms: int, why: str = "") -> None:
        """A new life of the vehicle: a new pre-flight. What the last one reported (fix,
        accuracy, home, landed state) is forgotten, so acquiring GNSS again on the ground is
        not a fix lost nor an accuracy jump. ``why``: what showed it, when not its clock."""
        self.reboots += 1
        self._last_seq = -1
        self._system_status = -1  # its first HEARTBEAT is not compared with the last life's
        self._system_time_boot_ms = -1
        self.fix_type = self.eph_m = self.epv_m = self.home = self.landed = None
        self._fix_lost = self._eph_bad = False
        self._ratelog.warning(
            f"reboot:{self.sys_id}",
            "%s rebooted (%s)",
            self.key,
            why or f"time_boot_ms {self.last_boot_ms} -> {boot_ms}",
        )

    def _close_window(self, boot_ms: int) -> None:
        """End of a clock window: the offset rises towards the window's lowest sample (its
        least delayed report) by at most ``clock_max_drift`` x the window's vehicle time, or
        is re-anchored there when that sample is more than ``clock_jump_s`` above it (a jump,
        or a drift beyond the bound). Rising only to a window's best sample keeps transport
        jitter out of the offset. A SYSTEM_TIME anchor holds the offset until it goes quiet."""
        if (
            self.offset_from_system_time
            and boot_ms - self._system_time_boot_ms > 3 * self._window_ms
        ):
            self.offset_from_system_time = False  # no SYSTEM_TIME lately: follow arrivals
        off = self.offset_s
        low = self._window_min
        if not self.offset_from_system_time and off is not None and low > off:
            if low - off > self.cfg.clock_jump_s:
                self.clock_jumps += 1
                self.offset_s = low
                # counted (LinkHealth.clock_jumps) and rate-limited: a simulator that cannot
                # keep its speed factor jumps often
                self._ratelog.warning(
                    "clock",
                    "%s clock re-anchored: arrivals %.3f s later than its time_boot_ms "
                    "predicted (clock jump or drift above %.0f %%)",
                    self.key,
                    low - off,
                    100.0 * self.cfg.clock_max_drift,
                )
            else:
                rise = self._drift_per_ms * (boot_ms - self._window_start_ms)
                self.offset_s = low if low < off + rise else off + rise
        self._window_min = _INF
        self._window_start_ms = boot_ms
        self._window_end_ms = boot_ms + self._window_ms

    def system_time(self, unix_us: int, boot_ms: int, receipt_t_s: float) -> bool:
        """SYSTEM_TIME (after :meth:`boot_time` of the same message): used as the offset only
        when it agrees with its own arrival; True when used."""
        unix_s = unix_us / 1e6
        if unix_s <= _MIN_UNIX_S or self.offset_s is None:
            return False  # no GNSS time yet
        candidate = unix_s - boot_ms * 0.001
        arrival = receipt_t_s - boot_ms * 0.001
        lag_s = arrival - candidate  # how much older than its arrival the vehicle says it is
        if not 0.0 <= lag_s <= self.cfg.system_time_max_lag_s:
            self.system_time_rejected += 1
            if self.system_time_rejected == 1 or self.offset_from_system_time:
                self._ratelog.warning(
                    "system_time",
                    "%s SYSTEM_TIME disagrees with arrival times by %.3f s (allowed: 0 to "
                    "%.3f s earlier): corrected from arrival times",
                    self.key,
                    lag_s,
                    self.cfg.system_time_max_lag_s,
                )
            self.offset_from_system_time = False
            return False
        self.system_time_used += 1
        self.offset_s = candidate
        self.offset_from_system_time = True
        self._system_time_boot_ms = boot_ms  # (it holds the offset; arrivals only lower it)
        return True

    def capture_t_s(self, boot_ms: int, receipt_t_s: float) -> float:
        if self.offset_s is None:
            return receipt_t_s
        return self.offset_s + boot_ms / 1000.0

    @property
    def last_position(self) -> Position | None:
        """The last reported position (GLOBAL_POSITION_INT), or None before the first."""
        fix = self._last_fix
        if fix is None:
            return None
        return Position(lat_deg=fix[0], lon_deg=fix[1], alt_amsl_m=fix[2])

    # --- status ---------------------------------------------------------------------------
    def status(self, t_s: float) -> VehicleStatus:
        return VehicleStatus(
            sys_id=self.sys_id,
            t_s=t_s,
            link=self.key.link,
            autopilot=self.autopilot,
            vehicle_kind=self.kind,
            mode=self.mode,
            armed=self.armed,
            landed=self.landed,
            battery_pct=self.battery_pct,
            battery_v=self.battery_v,
            gnss_fix_type=self.fix_type,
            gnss_satellites=self.satellites,
            eph_m=self.eph_m,
            epv_m=self.epv_m,
            mission_seq=self.mission_seq,
            mission_total=self.mission_total,
            vehicle=self.tag,
            home=self.home,
            mission_id=self.mission_id,
            position=self.last_position,
            position_t_s=self.position_capture_t_s,
            reboots=self.reboots,
            heading_deg=None if self._heading_cdeg >= _NO_HEADING else self._heading_cdeg / 100.0,
        )

    def hazard(self, kind: ThreatKind, t_s: float, message: str) -> HazardReport:
        _log.info("hazard %s sys %d: %s", kind.value, self.sys_id, message)
        return HazardReport(
            kind=kind,
            t_s=t_s,
            sys_id=self.sys_id,
            position=self.last_position,
            message=message,
            source=f"mavlink:{self.key.link}",
        )

    # --- message handlers (each returns nothing; events go to ``ev``) -----------------------
    def on_heartbeat(self, m: wire.MavMsg, t_s: float, ev: Events) -> bool:
        """Returns True when this heartbeat discovered the vehicle."""
        autopilot = modes.autopilot_from(m.autopilot)
        new = self.info is None
        if new:
            self.autopilot = autopilot
            self.kind = modes.kind_from(m.type)
            self.info = VehicleInfo(
                key=self.key,
                autopilot=autopilot,
                vehicle_kind=self.kind,
                mav_type=m.type,
                first_heard_t_s=t_s,
            )
            _log.info("discovered %s %s %s", self.key, autopilot.value, self.kind)
            ev.on_vehicle(self.info)
        self.custom_mode = int(m.custom_mode)
        self.mode = modes.mode_from(self.autopilot, self.kind, self.custom_mode)
        self.armed = bool(m.base_mode & 128)  # MAV_MODE_FLAG_SAFETY_ARMED
        state = int(m.system_status)
        if boot_again(self._system_status, state):
            self._rebooted(-1, f"system_status {self._system_status} -> {state}")
            self.last_boot_ms, self.offset_s = -1, None  # a new clock: the next report anchors
        self._system_status = state
        ev.on_status(self.status(t_s))
        return new

    def on_global_position(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        """GLOBAL_POSITION_INT -- the fast decoder's named tuple (any tuple of its fields in
        wire order) or a pymavlink message: a position report for tracking."""
        if isinstance(m, tuple):
            boot_ms, lat_e7, lon_e7, alt_mm, _, vx, vy, vz, hdg = m
        else:
            boot_ms, lat_e7, lon_e7, alt_mm = m.time_boot_ms, m.lat, m.lon, m.alt
            vx, vy, vz, hdg = m.vx, m.vy, m.vz, m.hdg
        self._heading_cdeg = hdg
        if lat_e7 == 0 and lon_e7 == 0:
            return  # no estimate yet
        self.boot_time(boot_ms, t_s)
        lat = lat_e7 / 1e7
        lon = lon_e7 / 1e7
        alt = alt_mm / 1000.0
        if not (
            -90.0 <= lat <= 90.0
            and -180.0 <= lon <= 180.0
            and _MIN_ALT_AMSL_M <= alt <= _MAX_ALT_AMSL_M
        ):
            return  # PX4 fills alt with INT32_MIN (-2147483.648 m) when it has no altitude
        self._last_fix = (lat, lon, alt)
        self.position_t_s = t_s
        offset = self.offset_s  # capture_t_s(), inline
        self.position_capture_t_s = t_s if offset is None else offset + boot_ms / 1000.0
        eph = self.eph_m
        epv = self.epv_m
        entry = (
            self._lane_index,
            t_s,
            t_s if offset is None else offset + boot_ms / 1000.0,
            lon, lat, alt, vx / 100.0, vy / 100.0, vz / 100.0,
            _NAN if eph is None else eph,
            _NAN if epv is None else epv,
        )  # fmt: skip
        if self._own_lane:
            ev.on_measurement(self._lane.measurement(entry, 0))
        else:
            self._lane_put(entry)

    def on_gps_raw(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        cfg = self.cfg
        fix = int(m.fix_type)
        self.satellites = None if m.satellites_visible == 255 else int(m.satellites_visible)
        h_acc = int(getattr(m, "h_acc", 0) or 0)
        v_acc = int(getattr(m, "v_acc", 0) or 0)
        prev_eph = self.eph_m
        if h_acc > 0:
            self.eph_m = h_acc / 1000.0
        elif m.eph != 0xFFFF:
            self.eph_m = m.eph / 100.0 * cfg.hdop_uere_m
        if v_acc > 0:
            self.epv_m = v_acc / 1000.0
        elif m.epv != 0xFFFF:
            self.epv_m = m.epv / 100.0 * cfg.hdop_uere_m
        had_fix = self.fix_type is not None and self.fix_type >= 3
        self.fix_type = fix
        if fix < 3 and had_fix and not self._fix_lost:
            self._fix_lost = True
            ev.on_hazard(
                self.hazard(ThreatKind.GNSS_DEGRADATION, t_s, f"GNSS fix lost (fix_type {fix})")
            )
        elif fix >= 3:
            self._fix_lost = False
        eph = self.eph_m
        if eph is None:
            return
        if (
            prev_eph is not None
            and eph - prev_eph >= cfg.eph_jump_m
            and fix >= 2
            and not self._eph_bad
        ):
            self._eph_bad = True
            ev.on_hazard(
                self.hazard(
                    ThreatKind.JAMMING_ATTACK,
                    t_s,
                    f"GNSS accuracy jumped {prev_eph:.1f} -> {eph:.1f} m (jamming sign)",
                )
            )
        elif eph >= cfg.eph_degraded_m and not self._eph_bad:
            self._eph_bad = True
            ev.on_hazard(
                self.hazard(ThreatKind.GNSS_DEGRADATION, t_s, f"GNSS accuracy {eph:.1f} m")
            )
        elif eph < cfg.eph_degraded_m / 2 and self._eph_bad:
            self._eph_bad = False  # recovered: re-arm

    def _battery(self, pct: float | None, t_s: float, ev: Events) -> None:
        if pct is None:
            return
        self.battery_pct = pct
        reserve = self.cfg.battery_reserve_pct
        if pct < reserve and not self._battery_low:
            self._battery_low = True
            ev.on_hazard(
                self.hazard(
                    ThreatKind.LACK_OF_BATTERY,
                    t_s,
                    f"battery {pct:.0f} % below the reserve {reserve:.0f} %",
                )
            )
        elif pct >= reserve + self.cfg.battery_hysteresis_pct:
            self._battery_low = False

    def on_sys_status(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        if m.voltage_battery != 0xFFFF:
            self.battery_v = m.voltage_battery / 1000.0
        self._battery(None if m.battery_remaining < 0 else float(m.battery_remaining), t_s, ev)

    def on_battery_status(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        self._battery(None if m.battery_remaining < 0 else float(m.battery_remaining), t_s, ev)

    def on_mission_current(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        """The current item, and what shows that the mission changed: its item count (0 when
        there is none) and its opaque id (PX4 >= 1.14). A status goes out on any change."""
        seq = int(m.seq)
        total = int(getattr(m, "total", 0) or 0)
        known = total != 0xFFFF and (total or getattr(m, "mission_state", 0))
        mission_id = wire.mission_current_id(m)
        changed = seq != self.mission_seq or mission_id != self.mission_id
        self.mission_seq = seq
        self.mission_id = mission_id
        if known and total != self.mission_total:
            # (0xFFFF: "not supported"; 0 with mission_state UNKNOWN: a frame without the
            # extension fields, as MAVLink 1 or an older autopilot sends it)
            self.mission_total = total
            changed = True
        if changed:
            ev.on_status(self.status(t_s))

    def on_home_position(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        """HOME_POSITION: the vehicle's home (AMSL); a status goes out when it moves. Only
        once the vehicle has a 3D fix: PX4 sends one 0.4 s after boot, before its fix, from an
        estimate that is not its position yet."""
        lat_e7, lon_e7 = int(m.latitude), int(m.longitude)
        if lat_e7 == 0 and lon_e7 == 0:
            return  # not set yet
        fix = self.fix_type
        if (fix is None and self._last_fix is None) or (fix is not None and fix < 3):
            return  # (a vehicle that sends no GPS_RAW_INT: once it reports positions)
        lat, lon, alt = lat_e7 / 1e7, lon_e7 / 1e7, m.altitude / 1000.0
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
            return
        old = self.home
        if (
            old is not None
            and abs(old.lat_deg - lat) < 1e-7
            and abs(old.lon_deg - lon) < 1e-7
            and abs(old.alt_amsl_m - alt) < 0.01
        ):
            return
        self.home = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=alt)
        _log.info("%s home %.7f %.7f %.2f m AMSL", self.key, lat, lon, alt)
        ev.on_status(self.status(t_s))

    def on_extended_sys_state(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        state = int(m.landed_state)
        self.landed = None if state == 0 else state == 1  # MAV_LANDED_STATE_ON_GROUND

    def on_statustext(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        text = str(m.text).rstrip("\x00")
        if _JAM_RE.search(text):
            ev.on_hazard(self.hazard(ThreatKind.JAMMING_ATTACK, t_s, f"vehicle says: {text}"))
        elif _SPOOF_RE.search(text):
            ev.on_hazard(self.hazard(ThreatKind.SPOOFING_ATTACK, t_s, f"vehicle says: {text}"))
        elif _GNSS_BAD_RE.search(text):
            ev.on_hazard(self.hazard(ThreatKind.GNSS_DEGRADATION, t_s, f"vehicle says: {text}"))

    def on_system_time(self, m: wire.MavMsg, t_s: float, ev: Events) -> None:
        boot_ms = int(m.time_boot_ms)
        self.boot_time(boot_ms, t_s)
        self.system_time(int(m.time_unix_usec), boot_ms, t_s)
