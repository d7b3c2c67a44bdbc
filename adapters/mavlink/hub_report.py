"""What the MAVLink hub reports about itself: its counters (:attr:`MavlinkHub.counters`) and
the state of each of its links (:meth:`MavlinkHub.links`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(slots=True)
class HubCounters:
    datagrams: int = 0
    bytes: int = 0
    frames: int = 0
    bad_crc: int = 0
    garbage: int = 0
    unknown_msg: int = 0
    truncated: int = 0
    bad_signature: int = 0
    not_for_us: int = 0
    gcs_heartbeats: int = 0  # HEARTBEATs without an autopilot (ground stations): no vehicle
    address_changes: int = 0
    sysid_collisions: int = 0
    handler_errors: int = 0
    send_errors: int = 0
    uploads_failed: int = 0
    uploads_verified: int = 0
    mission_retries: int = 0  # our own timeouts in mission transfers (upload, readback)
    # per-sender bookkeeping and sender checks (see the module docstring)
    senders_evicted: int = 0
    vehicles_evicted: int = 0
    sysid_zero: int = 0
    sysid_claims: int = 0
    unsigned: int = 0  # frames of a keyed vehicle without a signature
    replayed: int = 0  # frames of a keyed vehicle with an old signing timestamp
    links_down: int = 0  # times a stream link went down
    dropped_link_down: int = 0  # frames not sent because their link was down

    def snapshot(self) -> dict[str, int]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass(frozen=True, slots=True, kw_only=True)
class LinkState:
    """One link as the hub sees it (:meth:`MavlinkHub.links`)."""

    name: str
    up: bool
    connects: int  # successful opens of a stream link (reconnects = connects - 1)
    failures: int  # failed opens in a row
    dropped_down: int  # frames not sent while down
    senders: int  # source addresses with parser state
    last_error: str
