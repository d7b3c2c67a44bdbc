"""ASTM F3411 / ASD-STAN prEN 4709-002 broadcast Remote ID messages (25 bytes) -> typed records.

Pure: bytes in, frozen dataclasses out, no I/O. One message is 25 bytes: a header byte
(message type in the high nibble, protocol version in the low: 0 = F3411-19, 1 = F3411-20,
2 = F3411-22a) and 24 bytes of payload, little-endian:

- 0x0 Basic ID: ID type and UA type, the UAS ID (20 bytes: ASCII for a serial number, a CAA
  or UTM registration; binary for a specific session ID).
- 0x1 Location/Vector: status, track, ground and vertical speed, position (1e-7 deg), pressure
  and geodetic altitude and height (0.5 m, offset -1000 m), accuracies, time since the hour.
- 0x2 Authentication: one page of up to 16 (page 0 carries the page count, data length and a
  timestamp, 17 data bytes; the others 23 data bytes).
- 0x3 Self-ID: a description type and 23 characters of text.
- 0x4 System: operator location type and position, area, classification, operator altitude.
- 0x5 Operator ID: the operator's registration number (20 characters).
- 0xF Message Pack: a message size (25), a count (1-9) and that many messages.

Special values the standard gives for "unknown" (track 361, speed 255 at the 0.75 multiplier,
vertical speed 63 m/s, position 0/0, altitude -1000 m, accuracy code 0) decode to ``None``.
Accuracies decode to the bound of their class (a 95 % bound, metres or m/s).

A message that cannot be decoded raises :class:`RemoteIdError` naming the field and why.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import IntEnum
from typing import TypeVar

MESSAGE_SIZE = 25
PACK_MAX_MESSAGES = 9  # F3411-22a: at most 9 messages in a pack (a BLE 5 / Wi-Fi frame)
ODID_EPOCH_UTC_S = datetime(2019, 1, 1, tzinfo=UTC).timestamp()  # F3411 timestamps count from it

_E = TypeVar("_E", bound=IntEnum)

_ALT_UNKNOWN_M = -1000.0  # encoded 0: the standard's "invalid, no value or unknown"
_SPEED_UNKNOWN_ENCODED = 255  # with the 0.75 m/s multiplier
_VSPEED_UNKNOWN_MPS = 63.0
_DIRECTION_UNKNOWN_DEG = 361

# accuracy class -> its bound (95 %); index 0 is "unknown" (None)
_HORIZONTAL_ACCURACY_M = (
    None, 18520.0, 7408.0, 3704.0, 1852.0, 926.0, 555.6, 185.2, 92.6, 30.0, 10.0, 3.0, 1.0,
)  # fmt: skip
_VERTICAL_ACCURACY_M = (None, 150.0, 45.0, 25.0, 10.0, 3.0, 1.0)
_SPEED_ACCURACY_MPS = (None, 10.0, 3.0, 1.0, 0.3)


class RemoteIdError(ValueError):
    """A Remote ID message that cannot be decoded. ``field`` names what was wrong."""

    def __init__(self, data: bytes, field: str, reason: str) -> None:
        super().__init__(f"Remote ID message {data[:MESSAGE_SIZE].hex()}: {field}: {reason}")
        self.data = data
        self.field = field
        self.reason = reason


class MessageType(IntEnum):
    BASIC_ID = 0x0
    LOCATION = 0x1
    AUTH = 0x2
    SELF_ID = 0x3
    SYSTEM = 0x4
    OPERATOR_ID = 0x5
    MESSAGE_PACK = 0xF


class IdType(IntEnum):
    NONE = 0
    SERIAL_NUMBER = 1  # ANSI/CTA-2063-A
    CAA_REGISTRATION_ID = 2
    UTM_ASSIGNED_UUID = 3
    SPECIFIC_SESSION_ID = 4


class UaType(IntEnum):
    NONE = 0
    AEROPLANE = 1
    HELICOPTER_OR_MULTIROTOR = 2
    GYROPLANE = 3
    HYBRID_LIFT = 4
    ORNITHOPTER = 5
    GLIDER = 6
    KITE = 7
    FREE_BALLOON = 8
    CAPTIVE_BALLOON = 9
    AIRSHIP = 10
    FREE_FALL_PARACHUTE = 11
    ROCKET = 12
    TETHERED_POWERED_AIRCRAFT = 13
    GROUND_OBSTACLE = 14
    OTHER = 15


class OperationalStatus(IntEnum):
    UNDECLARED = 0
    GROUND = 1
    AIRBORNE = 2
    EMERGENCY = 3
    REMOTE_ID_SYSTEM_FAILURE = 4


class HeightType(IntEnum):
    ABOVE_TAKEOFF = 0
    ABOVE_GROUND_LEVEL = 1


class OperatorLocationType(IntEnum):
    TAKEOFF = 0
    LIVE_GNSS = 1
    FIXED = 2


class ClassificationType(IntEnum):
    UNDECLARED = 0
    EUROPEAN_UNION = 1


class EuCategory(IntEnum):
    UNDECLARED = 0
    OPEN = 1
    SPECIFIC = 2
    CERTIFIED = 3


class EuClass(IntEnum):
    UNDECLARED = 0
    CLASS_0 = 1
    CLASS_1 = 2
    CLASS_2 = 3
    CLASS_3 = 4
    CLASS_4 = 5
    CLASS_5 = 6
    CLASS_6 = 7


@dataclass(frozen=True, slots=True, kw_only=True)
class BasicId:
    protocol_version: int
    id_type: IdType
    ua_type: UaType
    uas_id: str  # ASCII IDs as text (padding removed); a session ID as hex
    uas_id_raw: bytes  # the 20 bytes as sent


@dataclass(frozen=True, slots=True, kw_only=True)
class Location:
    protocol_version: int
    status: OperationalStatus
    height_type: HeightType
    track_deg: int | None  # true course over ground, 0..359
    speed_horizontal_mps: float | None
    speed_vertical_mps: float | None  # positive up
    latitude_deg: float | None  # None when the position is unknown (0, 0)
    longitude_deg: float | None
    altitude_pressure_m: float | None
    altitude_geodetic_m: float | None  # WGS84 height
    height_m: float | None  # above takeoff or ground (height_type)
    horizontal_accuracy_m: float | None
    vertical_accuracy_m: float | None
    baro_accuracy_m: float | None
    speed_accuracy_mps: float | None
    time_since_hour_s: float | None  # tenths of a second since the full UTC hour
    time_accuracy_s: float | None


@dataclass(frozen=True, slots=True, kw_only=True)
class AuthPage:
    protocol_version: int
    auth_type: int  # 1 UAS ID signature, 2 operator ID, 3 message set, 4 network RID, 5 specific
    page_number: int
    last_page_index: int | None  # page 0 only
    length_bytes: int | None  # page 0 only: the data length over all pages
    timestamp_s: float | None  # page 0 only: UTC (Unix seconds)
    data: bytes  # this page's data bytes


@dataclass(frozen=True, slots=True, kw_only=True)
class SelfId:
    protocol_version: int
    description_type: int  # 0 text, 1 emergency, 2 extended status
    description: str


@dataclass(frozen=True, slots=True, kw_only=True)
class System:
    protocol_version: int
    operator_location_type: OperatorLocationType
    classification_type: ClassificationType
    operator_latitude_deg: float | None
    operator_longitude_deg: float | None
    area_count: int
    area_radius_m: float
    area_ceiling_m: float | None
    area_floor_m: float | None
    eu_category: EuCategory
    eu_class: EuClass
    operator_altitude_geodetic_m: float | None
    timestamp_s: float | None  # UTC (Unix seconds); None when 0 (unknown)


@dataclass(frozen=True, slots=True, kw_only=True)
class OperatorId:
    protocol_version: int
    operator_id_type: int  # 0 = operator ID
    operator_id: str


Message = BasicId | Location | AuthPage | SelfId | System | OperatorId


def decode_message(data: bytes) -> Message:
    """One 25-byte message (not a pack: :func:`decode` takes both)."""
    _check_size(data)
    kind = data[0] >> 4
    if kind == MessageType.MESSAGE_PACK:
        raise RemoteIdError(data, "message type", "a message pack inside a message pack")
    decoder = _DECODERS.get(kind)
    if decoder is None:
        raise RemoteIdError(data, "message type", f"unknown type 0x{kind:x}")
    return decoder(bytes(data[:MESSAGE_SIZE]))


def decode(data: bytes) -> list[Message]:
    """One message or one message pack -> its messages, in order."""
    if len(data) >= 1 and data[0] >> 4 == MessageType.MESSAGE_PACK:
        return decode_pack(data)
    return [decode_message(data)]


def decode_pack(data: bytes) -> list[Message]:
    """A message pack (type 0xF): header, size byte (25), count (1-9), the messages."""
    if len(data) < 3:
        raise RemoteIdError(data, "message pack", f"{len(data)} bytes, needs at least 3")
    if data[0] >> 4 != MessageType.MESSAGE_PACK:
        raise RemoteIdError(data, "message type", f"0x{data[0] >> 4:x} is not a message pack")
    size, count = data[1], data[2]
    if size != MESSAGE_SIZE:
        raise RemoteIdError(data, "message pack size", f"{size}, expected {MESSAGE_SIZE}")
    if not 1 <= count <= PACK_MAX_MESSAGES:
        raise RemoteIdError(data, "message pack count", f"{count}, expected 1..9")
    end = 3 + count * MESSAGE_SIZE
    if len(data) < end:
        raise RemoteIdError(data, "message pack", f"{len(data)} bytes for {count} messages")
    return [decode_message(data[i : i + MESSAGE_SIZE]) for i in range(3, end, MESSAGE_SIZE)]


def _check_size(data: bytes) -> None:
    if len(data) < MESSAGE_SIZE:
        raise RemoteIdError(data, "length", f"{len(data)} bytes, expected {MESSAGE_SIZE}")


def _ascii(data: bytes, raw: bytes, field: str) -> str:
    text = raw.split(b"\0", 1)[0]
    if any(b < 0x20 or b > 0x7E for b in text):
        raise RemoteIdError(data, field, f"not printable ASCII: {text.hex()}")
    return text.decode("ascii")


def _enum(data: bytes, cls: type[_E], value: int, field: str) -> _E:
    try:
        return cls(value)
    except ValueError:
        raise RemoteIdError(data, field, f"reserved value {value}") from None


def _altitude_m(raw: int) -> float | None:
    value = raw * 0.5 - 1000.0
    return None if value == _ALT_UNKNOWN_M else value


def _latlon_deg(lat_e7: int, lon_e7: int) -> tuple[float | None, float | None]:
    if lat_e7 == 0 and lon_e7 == 0:
        return None, None
    return lat_e7 * 1e-7, lon_e7 * 1e-7


def _odid_time_s(raw: int) -> float | None:
    return None if raw == 0 else ODID_EPOCH_UTC_S + raw


def _accuracy(table: tuple[float | None, ...], code: int) -> float | None:
    return table[code] if code < len(table) else None  # a reserved class: unknown


def _basic_id(data: bytes) -> BasicId:
    id_type = _enum(data, IdType, data[1] >> 4, "ID type")
    ua_type = UaType(data[1] & 0x0F)
    raw = data[2:22]
    if id_type is IdType.SPECIFIC_SESSION_ID:
        uas_id = raw.rstrip(b"\0").hex()
    else:
        uas_id = _ascii(data, raw, "UAS ID")
    return BasicId(
        protocol_version=data[0] & 0x0F,
        id_type=id_type,
        ua_type=ua_type,
        uas_id=uas_id,
        uas_id_raw=raw,
    )


def _location(data: bytes) -> Location:
    flags = data[1]
    track, speed, vspeed = data[2], data[3], struct.unpack_from("<b", data, 4)[0]
    lat_e7, lon_e7, p_alt, g_alt, height = struct.unpack_from("<iiHHH", data, 5)
    acc_v_h, acc_b_s = data[19], data[20]
    (tenths,) = struct.unpack_from("<H", data, 21)
    track_deg = track + 180 if flags & 0x02 else track
    if flags & 0x01:  # 0.75 m/s steps above 63.75 m/s
        speed_mps = None if speed == _SPEED_UNKNOWN_ENCODED else speed * 0.75 + 255 * 0.25
    else:
        speed_mps = speed * 0.25
    vspeed_mps = vspeed * 0.5
    if not -90e7 <= lat_e7 <= 90e7 or not -180e7 <= lon_e7 <= 180e7:
        raise RemoteIdError(data, "position", f"latitude {lat_e7}e-7, longitude {lon_e7}e-7")
    lat, lon = _latlon_deg(lat_e7, lon_e7)
    return Location(
        protocol_version=data[0] & 0x0F,
        status=_enum(data, OperationalStatus, flags >> 4, "operational status"),
        height_type=HeightType((flags >> 2) & 0x01),
        track_deg=None if track_deg >= _DIRECTION_UNKNOWN_DEG else track_deg % 360,
        speed_horizontal_mps=speed_mps,
        speed_vertical_mps=None if abs(vspeed_mps) >= _VSPEED_UNKNOWN_MPS else vspeed_mps,
        latitude_deg=lat,
        longitude_deg=lon,
        altitude_pressure_m=_altitude_m(p_alt),
        altitude_geodetic_m=_altitude_m(g_alt),
        height_m=_altitude_m(height),
        horizontal_accuracy_m=_accuracy(_HORIZONTAL_ACCURACY_M, acc_v_h & 0x0F),
        vertical_accuracy_m=_accuracy(_VERTICAL_ACCURACY_M, acc_v_h >> 4),
        baro_accuracy_m=_accuracy(_VERTICAL_ACCURACY_M, acc_b_s >> 4),
        speed_accuracy_mps=_accuracy(_SPEED_ACCURACY_MPS, acc_b_s & 0x0F),
        time_since_hour_s=None if tenths == 0xFFFF else tenths / 10.0,
        time_accuracy_s=(data[23] & 0x0F) / 10.0 or None,
    )


def _auth(data: bytes) -> AuthPage:
    page = data[1] & 0x0F
    version, auth_type = data[0] & 0x0F, data[1] >> 4
    if page == 0:
        last, length, stamp = data[2], data[3], struct.unpack_from("<I", data, 4)[0]
        if last > 15:
            raise RemoteIdError(data, "last page index", f"{last}, expected 0..15")
        return AuthPage(
            protocol_version=version,
            auth_type=auth_type,
            page_number=0,
            last_page_index=last,
            length_bytes=length,
            timestamp_s=_odid_time_s(stamp),
            data=data[8:25],
        )
    return AuthPage(
        protocol_version=version,
        auth_type=auth_type,
        page_number=page,
        last_page_index=None,
        length_bytes=None,
        timestamp_s=None,
        data=data[2:25],
    )


def _self_id(data: bytes) -> SelfId:
    return SelfId(
        protocol_version=data[0] & 0x0F,
        description_type=data[1],
        description=_ascii(data, data[2:25], "self-ID description"),
    )


def _system(data: bytes) -> System:
    flags = data[1]
    lat_e7, lon_e7, area_count, radius, ceiling, floor = struct.unpack_from("<iiHBHH", data, 2)
    cat_class = data[17]
    (alt,) = struct.unpack_from("<H", data, 18)
    (stamp,) = struct.unpack_from("<I", data, 20)
    lat, lon = _latlon_deg(lat_e7, lon_e7)
    return System(
        protocol_version=data[0] & 0x0F,
        operator_location_type=_enum(
            data, OperatorLocationType, flags & 0x03, "operator location type"
        ),
        classification_type=_enum(
            data, ClassificationType, (flags >> 2) & 0x07, "classification type"
        ),
        operator_latitude_deg=lat,
        operator_longitude_deg=lon,
        area_count=area_count,
        area_radius_m=radius * 10.0,
        area_ceiling_m=_altitude_m(ceiling),
        area_floor_m=_altitude_m(floor),
        eu_category=_enum(data, EuCategory, cat_class >> 4, "EU category"),
        eu_class=_enum(data, EuClass, cat_class & 0x0F, "EU class"),
        operator_altitude_geodetic_m=_altitude_m(alt),
        timestamp_s=_odid_time_s(stamp),
    )


def _operator_id(data: bytes) -> OperatorId:
    return OperatorId(
        protocol_version=data[0] & 0x0F,
        operator_id_type=data[1],
        operator_id=_ascii(data, data[2:22], "operator ID"),
    )


_DECODERS: dict[int, Callable[[bytes], Message]] = {
    MessageType.BASIC_ID: _basic_id,
    MessageType.LOCATION: _location,
    MessageType.AUTH: _auth,
    MessageType.SELF_ID: _self_id,
    MessageType.SYSTEM: _system,
    MessageType.OPERATOR_ID: _operator_id,
}
