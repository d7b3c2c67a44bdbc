"""Settings of the MAVLink adapter (``[mavlink]``): links, buffers, mission and command retries,
hazard thresholds, per-vehicle signing keys, link reconnects and the bounds of per-sender
state. Frozen; validated by the shared loader, cross-field rules (backoff order, link strings,
keys) in ``__post_init__``."""

from __future__ import annotations

from dataclasses import dataclass

from adapters.mavlink.endpoint import EndpointError, parse_endpoint
from gcs_utm.config import setting


@dataclass(frozen=True, slots=True, kw_only=True)
class MavlinkConfig:
    links: tuple[str, ...] = setting(
        ("udpin:127.0.0.1:14550",),
        "connection strings as in pymavlink/MAVProxy: udpin:HOST:PORT, udpout:HOST:PORT, "
        "tcp:HOST:PORT, /dev/ttyX:BAUD",
    )
    gcs_sys_id: int = setting(255, "our MAVLink system id (GCS convention)", min=1, max=255)
    gcs_comp_id: int = setting(
        190, "our MAVLink component id (MAV_COMP_ID_MISSIONPLANNER)", min=1, max=255
    )
    udp_rcvbuf_bytes: int = setting(
        4 * 1024 * 1024,
        "UDP receive buffer; the 208 KiB default drops a third of a 10,000-datagram burst",
        min=65536,
        unit="bytes",
    )
    fast_decode: bool = setting(
        True,
        "decode hot telemetry (position, heartbeat, GPS, status) with struct instead of "
        "pymavlink on datagram links; false = pymavlink for everything",
    )
    udp_batch: int = setting(
        64,
        "datagrams read per socket wake-up (bounds the time one busy link holds the loop)",
        min=1,
        max=4096,
    )
    heartbeat_period_s: float = setting(
        1.0, "period of our GCS HEARTBEAT on every link", min=0.05, unit="s"
    )
    health_period_s: float = setting(
        1.0, "period of LinkHealth reports to the sink", min=0.05, unit="s"
    )
    item_timeout_s: float = setting(
        0.25, "mission item timeout (PX4 re-requests every 250 ms)", min=0.01, unit="s"
    )
    min_retry_s: float = setting(
        0.02,
        "first retransmission timeout of a mission step (x1.5 per silent retry up "
        "to item_timeout_s): loopback and LAN answer in milliseconds",
        min=0.001,
        unit="s",
    )
    max_retries: int = setting(
        10, "retries of one mission protocol step before the transfer fails", min=0
    )
    transfer_timeout_s: float = setting(
        20.0, "hard bound of one upload or download when no deadline is given", min=0.1, unit="s"
    )
    command_timeout_s: float = setting(
        0.5, "wait for COMMAND_ACK before resending", min=0.01, unit="s"
    )
    command_retries: int = setting(3, "COMMAND_LONG resends (confirmation incremented)", min=0)
    battery_reserve_pct: float = setting(
        25.0, "LACK_OF_BATTERY below this remaining charge", min=0.0, max=100.0, unit="%"
    )
    battery_hysteresis_pct: float = setting(
        3.0, "charge above the reserve that re-arms the battery hazard", min=0.0, unit="%"
    )
    eph_jump_m: float = setting(
        5.0,
        "horizontal accuracy worsening in one GPS_RAW_INT sample that signals jamming",
        min=0.1,
        unit="m",
    )
    eph_degraded_m: float = setting(
        10.0, "horizontal accuracy above which GNSS is degraded", min=0.1, unit="m"
    )
    hdop_uere_m: float = setting(
        4.0,
        "user range error that turns HDOP into metres when h_acc is not sent",
        min=0.1,
        unit="m",
    )
    reboot_tolerance_ms: int = setting(
        2000,
        "time_boot_ms going back more than this is a reboot (less: reordering), as is an "
        "uptime this much shorter than the vehicle's silence",
        min=0,
        unit="ms",
    )
    clock_max_drift: float = setting(
        0.1,
        "fastest rate (s/s) at which a vehicle clock is assumed to fall behind ours: the "
        "capture-time offset rises at most this fast (once per clock window; it falls at once)",
        min=0.0,
        max=1.0,
    )
    clock_jump_s: float = setting(
        0.5,
        "all reports of a clock window (clock_window_s) arriving this much later than the "
        "offset predicts re-anchor it (a clock jump, or a drift beyond clock_max_drift)",
        min=0.01,
        unit="s",
    )
    clock_window_s: float = setting(
        1.0,
        "vehicle-time window whose least delayed report the offset rises to (within "
        "clock_max_drift) and over which clock jumps are judged",
        min=0.1,
        unit="s",
    )
    system_time_max_lag_s: float = setting(
        1.0,
        "SYSTEM_TIME is used only when its UTC is at most this much older than its arrival "
        "(and not later): otherwise the vehicle's clock is corrected from arrival times",
        min=0.0,
        unit="s",
    )
    address_move_s: float = setting(
        3.0,
        "a sysid heard from a new address after this silence has moved (else: a 2nd "
        "vehicle with the same sysid)",
        min=0.0,
        unit="s",
    )
    ardupilot_stream_hz: float = setting(
        5.0,
        "telemetry rate requested from ArduPilot (it sends nothing unasked)",
        min=0.1,
        max=50.0,
        unit="Hz",
    )
    max_speed_mps: float = setting(
        25.0, "clamp of the DO_CHANGE_SPEED derived from plan timing", min=0.1, unit="m/s"
    )
    signing_keys: dict[str, str] = setting(
        {},
        'MAVLink 2 signing keys by sysid: {"1" = "<64 hex digits>"}; outgoing commands '
        "and uploads to that vehicle are signed",
    )
    sysid_binding: bool = setting(
        True,
        "a system id belongs to the link and address it was first heard on: another sender "
        "claiming it is dropped and reported (SYSID_CONFLICT); false = each (link, address) "
        "with a system id is a vehicle of its own (fleets reusing system ids, e.g. ArduPilot "
        "SITL instances all at sysid 1), addressed by VehicleKey",
    )
    reconnect_min_s: float = setting(
        0.5,
        "first wait before reopening a TCP or serial link that is down (doubled per failed "
        "attempt up to reconnect_max_s)",
        min=0.01,
        unit="s",
    )
    reconnect_max_s: float = setting(
        10.0,
        "longest wait between attempts to reopen a link (>= reconnect_min_s)",
        min=0.01,
        unit="s",
    )
    max_senders: int = setting(
        1024,
        "source addresses per link with parser state; beyond it the least recently heard are "
        "evicted (counted: senders_evicted)",
        min=1,
    )
    max_vehicles: int = setting(
        1024,
        "vehicle states (address, sysid, compid) in the hub; beyond it the least recently "
        "heard are evicted (counted: vehicles_evicted)",
        min=1,
    )
    sender_idle_s: float = setting(
        60.0,
        "a source address or vehicle not heard for this long is forgotten (a vehicle that "
        "comes back is discovered again)",
        min=1.0,
        unit="s",
    )
    warn_interval_s: float = setting(
        10.0,
        "repeated warnings of one cause (reboots, sysid claims, send errors) are written at "
        "most once per interval, with the count of those held back",
        min=0.0,
        unit="s",
    )

    def __post_init__(self) -> None:
        if self.reconnect_min_s > self.reconnect_max_s:
            raise ValueError(
                f"reconnect_min_s ({self.reconnect_min_s}) must not exceed reconnect_max_s "
                f"({self.reconnect_max_s})"
            )
        for text in self.links:
            try:
                parse_endpoint(text)
            except EndpointError as exc:
                raise ValueError(f"links: {exc}") from exc
        for sid, hexkey in self.signing_keys.items():
            if not sid.isdigit() or not 1 <= int(sid) <= 255:
                raise ValueError(f"signing_keys: {sid!r} is not a system id (1..255)")
            try:
                key = bytes.fromhex(hexkey.strip())
            except ValueError as exc:
                raise ValueError(f"signing_keys.{sid}: not hexadecimal: {exc}") from exc
            if len(key) != 32:
                raise ValueError(
                    f"signing_keys.{sid}: a MAVLink signing key has 32 bytes (64 hex digits), "
                    f"got {len(key)}"
                )
