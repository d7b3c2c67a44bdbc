"""Public, frozen descriptions of simulated vehicles, their missions and faults, and the clock.

Units are in the names: degrees WGS84, metres AMSL, m/s, seconds. Every `at_s` is seconds of
*simulated* time after fleet start (SimTime.elapsed_s()).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from enum import Enum
from typing import Protocol


@dataclass(frozen=True, slots=True, kw_only=True)
class MissionItemSpec:
    """A waypoint; a speed means a DO_CHANGE_SPEED item is emitted/obeyed before it."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    speed_mps: float | None = None
    acceptance_radius_m: float | None = None


class FaultKind(Enum):
    GNSS_JAMMING = "gnss_jamming"
    SPOOFING = "spoofing"
    BATTERY_DROP = "battery_drop"
    BATTERY_DRAIN = "battery_drain"
    LINK_LOSS = "link_loss"
    PACKET_LOSS = "packet_loss"
    LATENCY = "latency"
    MOTOR_FAILURE = "motor_failure"


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultSpec:
    """A fault starting at `at_s` (simulated s after fleet start), lasting `duration_s` (None =
    until the end). `value` per kind: BATTERY_DROP battery percent to drop to; BATTERY_DRAIN
    extra %/s; PACKET_LOSS probability 0..1 per datagram and direction; LATENCY one-way delay in
    simulated seconds; SPOOFING reported-position offset in metres north; GNSS_JAMMING drift rate
    of the reported position in m/s. None picks the documented default (see DEFAULT_FAULT_VALUE).
    """

    kind: FaultKind
    at_s: float
    duration_s: float | None = None
    value: float | None = None


DEFAULT_FAULT_VALUE: dict[FaultKind, float] = {
    FaultKind.GNSS_JAMMING: 1.0,  # m/s drift, typical of dead reckoning on IMU only
    FaultKind.SPOOFING: 200.0,  # m north
    FaultKind.BATTERY_DROP: 10.0,  # % left: below PX4's 15 % low threshold
    FaultKind.BATTERY_DRAIN: 1.0,  # %/s
    FaultKind.LINK_LOSS: 1.0,  # unused
    FaultKind.PACKET_LOSS: 0.3,  # probability
    FaultKind.LATENCY: 0.5,  # s one way
    FaultKind.MOTOR_FAILURE: 1.0,  # unused
}

MULTIROTOR = "multirotor"
FIXED_WING = "fixed_wing"
PX4 = "px4"
ARDUPILOT = "ardupilot"

# PX4-like default stream rates on the GCS link, Hz of simulated time (PX4 "normal" mode).
DEFAULT_STREAM_RATES_HZ: tuple[tuple[str, float], ...] = (
    ("HEARTBEAT", 1.0),
    ("GLOBAL_POSITION_INT", 5.0),
    ("GPS_RAW_INT", 1.0),
    ("SYS_STATUS", 1.0),
    ("BATTERY_STATUS", 0.5),
    ("EXTENDED_SYS_STATE", 1.0),
    ("HOME_POSITION", 0.5),
    ("MISSION_CURRENT", 1.0),
    ("ATTITUDE", 5.0),
    ("SYSTEM_TIME", 1.0),
    ("VFR_HUD", 2.0),
)


@dataclass(frozen=True, slots=True, kw_only=True)
class VehicleSpec:
    """One simulated vehicle. Limits left as None take the per-kind defaults of `limits()`."""

    instance: int
    sys_id: int | None = None  # None: instance + 1, as PX4
    kind: str = MULTIROTOR  # "multirotor" | "fixed_wing"
    autopilot: str = PX4  # "px4" | "ardupilot"
    home_lat_deg: float = 47.397742  # PX4 SITL default home (Zurich)
    home_lon_deg: float = 8.545594
    home_alt_amsl_m: float = 488.0
    cruise_speed_mps: float | None = None
    max_speed_mps: float | None = None
    climb_rate_mps: float | None = None
    descent_rate_mps: float | None = None
    accel_mps2: float | None = None
    min_airspeed_mps: float | None = None  # fixed wing
    max_bank_deg: float | None = None  # fixed wing
    loiter_radius_m: float | None = None  # fixed wing
    acceptance_radius_m: float | None = None  # default for waypoints without one
    takeoff_alt_rel_m: float = 10.0  # PX4 MIS_TAKEOFF_ALT-like (2.5 in PX4; 10 is friendlier)
    rtl_alt_rel_m: float = 30.0  # PX4 RTL_RETURN_ALT-like
    mission: tuple[MissionItemSpec, ...] = ()
    auto_start_at_s: float | None = None
    # Scenario runs: at auto start, appear in flight at the first mission waypoint already
    # moving towards the next one (instead of taking off from home), so a vehicle follows a 4D
    # plan from its first waypoint at a precise time. Not PX4 behaviour; off by default.
    start_airborne: bool = False
    boot_at_s: float = 0.0  # power-on time: nothing is sent before it (start delay)
    gcs_host: str = "127.0.0.1"
    gcs_port: int = 14550
    bind_host: str = "127.0.0.1"
    bind_port: int | None = None  # None: 18570 + instance; 0: ephemeral
    api_link: bool = False  # PX4's second UDP link 14580+i -> 14540+i
    api_bind_port: int | None = None
    api_port: int | None = None
    tcp_port: int | None = None  # ArduPilot: None = 5760 + 10*instance; 0 = ephemeral
    faults: tuple[FaultSpec, ...] = ()
    battery_capacity_s: float = 1200.0  # endurance at hover/cruise, simulated s
    gnss_noise_m: float = 0.0  # std-dev of reported horizontal position noise
    # GNSS acquisition: simulated s after boot without a fix (GPS_RAW_INT fix_type 0, 100 m
    # accuracy, no global position). Meanwhile a PX4 sends HOME_POSITION from its estimate,
    # HOME_PRE_FIX_OFFSET_M off in altitude (PX4 SIH sends one 0.4 s after boot, before its
    # fix); an ArduPilot sends none before its fix (both measured). 0: a fix at boot.
    gnss_fix_after_s: float = 0.0
    wind_north_mps: float = 0.0  # wind toward... blowing *to* the north (fixed wing drift)
    wind_east_mps: float = 0.0
    seed: int = 0
    stream_rates_hz: tuple[tuple[str, float], ...] = DEFAULT_STREAM_RATES_HZ
    max_real_stream_hz: float = 50.0  # cap per stream in wall-clock Hz (bounds load at speed-up)
    max_mission_items: int = 500
    # MAVLink 2 signing key, 64 hex digits (32 bytes), as PX4 MAV_SIGN_CFG / ArduPilot signing:
    # the vehicle then accepts only correctly signed messages (RADIO_STATUS may be unsigned),
    # counts the rest (`rejected_unsigned`, `rejected_bad_signature`) and signs all it sends.
    signing_key: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in (MULTIROTOR, FIXED_WING):
            raise ValueError(
                f"VehicleSpec.kind: expected 'multirotor' or 'fixed_wing', got {self.kind!r}"
            )
        if self.autopilot not in (PX4, ARDUPILOT):
            raise ValueError(
                f"VehicleSpec.autopilot: expected 'px4' or 'ardupilot', got {self.autopilot!r}"
            )
        if self.instance < 0:
            raise ValueError("VehicleSpec.instance must be >= 0")
        if self.signing_key is not None:
            if not isinstance(self.signing_key, str):
                raise ValueError(
                    "VehicleSpec.signing_key: expected a string of 64 hex digits, "
                    f"got {type(self.signing_key).__name__}"
                )
            try:
                signing_key_bytes(self.signing_key)
            except ValueError as exc:
                raise ValueError(f"VehicleSpec.signing_key: {exc}") from exc

    def signing_key_bytes(self) -> bytes | None:
        """The 32-byte signing key, or None when signing is off."""
        return None if self.signing_key is None else signing_key_bytes(self.signing_key)

    @property
    def system_id(self) -> int:
        return self.sys_id if self.sys_id is not None else self.instance + 1

    def limits(self) -> Limits:
        fw = self.kind == FIXED_WING
        d = Limits(
            cruise_speed_mps=18.0 if fw else 8.0,
            max_speed_mps=28.0 if fw else 12.0,
            climb_rate_mps=5.0 if fw else 3.0,
            descent_rate_mps=3.0 if fw else 1.5,
            accel_mps2=2.0 if fw else 3.0,
            min_airspeed_mps=12.0 if fw else 0.0,
            max_bank_deg=35.0 if fw else 0.0,
            loiter_radius_m=80.0 if fw else 0.0,
            acceptance_radius_m=15.0 if fw else 2.0,
        )
        return Limits(
            cruise_speed_mps=_pick(self.cruise_speed_mps, d.cruise_speed_mps),
            max_speed_mps=_pick(self.max_speed_mps, d.max_speed_mps),
            climb_rate_mps=_pick(self.climb_rate_mps, d.climb_rate_mps),
            descent_rate_mps=_pick(self.descent_rate_mps, d.descent_rate_mps),
            accel_mps2=_pick(self.accel_mps2, d.accel_mps2),
            min_airspeed_mps=_pick(self.min_airspeed_mps, d.min_airspeed_mps),
            max_bank_deg=_pick(self.max_bank_deg, d.max_bank_deg),
            loiter_radius_m=_pick(self.loiter_radius_m, d.loiter_radius_m),
            acceptance_radius_m=_pick(self.acceptance_radius_m, d.acceptance_radius_m),
        )


def signing_key_bytes(text: str) -> bytes:
    """A 32-byte MAVLink signing key from 64 hex digits; ValueError naming what is wrong."""
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        raise ValueError(f"expected 64 hex digits, got {text!r}") from None
    if len(key) != 32:
        raise ValueError(f"expected 64 hex digits (32 bytes), got {len(key)} bytes") from None
    return key


def _pick(value: float | None, default: float) -> float:
    return default if value is None else value


@dataclass(frozen=True, slots=True, kw_only=True)
class Limits:
    cruise_speed_mps: float
    max_speed_mps: float
    climb_rate_mps: float
    descent_rate_mps: float
    accel_mps2: float
    min_airspeed_mps: float
    max_bank_deg: float
    loiter_radius_m: float
    acceptance_radius_m: float


class SimClock(Protocol):
    """What the vehicles need of a clock. :class:`SimTime` is the wall-clock one; a ground
    service that runs the vehicles on its own simulated clock (fast time) passes any object
    with these members, so both sides read one clock."""

    @property
    def speed(self) -> float:
        """Simulated seconds per second of the event loop's time."""
        ...

    @property
    def start_utc_s(self) -> float: ...

    def elapsed_s(self) -> float:
        """Simulated seconds since the clock's start."""
        ...

    def now_s(self) -> float: ...

    def real_delay_s(self, sim_s: float) -> float:
        """Event-loop seconds that `sim_s` simulated seconds take."""
        ...


class SimTime:
    """Simulated clock: sim_utc = start_utc_s + (monotonic - start_mono_s) * speed.

    Like PX4_SIM_SPEED_FACTOR: simulated time runs `speed` times faster than the wall clock.
    A ground side built on the same (start_utc_s, speed, start_mono_s) agrees with every
    time_boot_ms and SYSTEM_TIME the vehicles send. A Fleet counts fault and start times from
    the `elapsed_s()` at which it started; it never re-anchors the clock.
    """

    def __init__(
        self,
        speed: float = 1.0,
        start_utc_s: float | None = None,
        *,
        start_mono_s: float | None = None,
    ) -> None:
        if speed <= 0:
            raise ValueError("SimTime.speed must be > 0")
        self._speed = float(speed)
        self._start_utc_s = time.time() if start_utc_s is None else float(start_utc_s)
        # Pass the ground clock's monotonic anchor: two clocks with the same start_utc_s but
        # anchored a few hundred ms apart disagree by that gap times the speed-up, which shows
        # up as a constant telemetry delay.
        self._start_mono = time.monotonic() if start_mono_s is None else float(start_mono_s)

    @property
    def speed(self) -> float:
        return self._speed

    @property
    def start_utc_s(self) -> float:
        return self._start_utc_s

    @property
    def start_mono_s(self) -> float:
        return self._start_mono

    def elapsed_s(self) -> float:
        return (time.monotonic() - self._start_mono) * self._speed

    def now_s(self) -> float:
        return self._start_utc_s + self.elapsed_s()

    def real_delay_s(self, sim_s: float) -> float:
        """Wall-clock seconds that `sim_s` simulated seconds take."""
        return sim_s / self._speed
