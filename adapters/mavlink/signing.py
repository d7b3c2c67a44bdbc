"""Verification of incoming MAVLink 2 signatures (sans-IO).

With ``[mavlink] signing_keys`` naming a vehicle's key, every frame that claims that system id
must carry a signature that verifies with the key (MAVLink 2 message signing: the first 6 bytes
of SHA-256(key + header + payload + CRC + link id + timestamp)), with a timestamp that moves
forward on its stream (link id, system id, component id); a new stream's first timestamp may be
at most one minute behind ours (as pymavlink and the autopilots check). Everything else from
that system id is dropped and counted: unsigned frames (MAVLink 1 included) in
``unsigned``, wrong signatures in ``bad_signature``, old timestamps (replays) in ``replayed``.
RADIO_STATUS may come unsigned: radios inject it (MAVLink spec; PX4 and ArduPilot accept it).
System ids without a key are not checked (nothing to check against).

Our timestamp is the larger of the wall clock (10 us units since 2015-01-01, ``now``) and the
newest timestamp verified, as the spec asks. Stream entries are only made by frames whose
signature verified, so only key holders can grow that table.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from adapters.mavlink import wire

_SIGNATURE_LEN = 13  # link id (1) + timestamp (6) + signature (6)
_NEW_STREAM_WINDOW = 6_000_000  # one minute in 10 us units
_RADIO_STATUS = 109
_IFLAG_SIGNED = 0x01


@dataclass(slots=True)
class SigningCounters:
    verified: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0


class SignatureCheck:
    """Checks decoded frames of the system ids in ``keys`` (module docstring)."""

    def __init__(self, keys: Mapping[int, bytes], *, now: Callable[[], float] = time.time) -> None:
        self.keys = dict(keys)
        self.now = now
        self.counters = SigningCounters()
        self._streams: dict[tuple[int, int, int], int] = {}
        self._timestamp = 0

    def accept(self, f: wire.Frame) -> str:
        """``""`` when ``f`` may be used, else the cause it was dropped for (``unsigned``,
        ``bad_signature``, ``replayed``). Frames of system ids without a key pass."""
        key = self.keys.get(f.sys_id)
        if key is None:
            return ""
        raw = _signed_frame(f.msg)
        if raw is None:
            cause = "" if f.msg_id == _RADIO_STATUS else "unsigned"
        elif len(raw) < 10 + 2 + _SIGNATURE_LEN or (
            hashlib.sha256(key + raw[:-6]).digest()[:6] != raw[-6:]
        ):
            cause = "bad_signature"
        else:
            cause = self._fresh(raw, f.sys_id, f.comp_id)
        if cause:
            setattr(self.counters, cause, getattr(self.counters, cause) + 1)
        return cause

    def _fresh(self, raw: bytes, sys_id: int, comp_id: int) -> str:
        """``""`` and the stream's timestamp moved on when the verified frame ``raw`` is newer
        than the last one of its stream (a new stream: at most one minute behind ours), else
        ``replayed``."""
        stamp = int.from_bytes(raw[-12:-6], "little")
        stream = (raw[-_SIGNATURE_LEN], sys_id, comp_id)  # (link id, sys_id, comp_id)
        last = self._streams.get(stream)
        if last is not None:
            if stamp <= last:
                return "replayed"
        elif stamp + _NEW_STREAM_WINDOW < max(self._timestamp, wire.signing_timestamp(self.now())):
            return "replayed"
        self._streams[stream] = stamp
        self._timestamp = max(self._timestamp, stamp)
        self.counters.verified += 1
        return ""


def _signed_frame(m: wire.MavMsg) -> bytes | None:
    """The raw bytes of a signed pymavlink frame, None for an unsigned one (fast-path tuples
    are unsigned frames)."""
    header = getattr(m, "_header", None)
    buf = getattr(m, "_msgbuf", None)
    if header is None or buf is None or not header.incompat_flags & _IFLAG_SIGNED:
        return None
    return bytes(buf)
