"""The F3411 broadcast decoder (adapters/remoteid/f3411.py) against published encodings.

Vectors (tests/data/remoteid, sources in tests/data/SOURCES.md), with the decoded values their
publishers print:
- ``librid_cli_location.hex``: the Location/Vector example of tuupola/librid's CLI README.
- ``bkerler_droneid_selftest_ble.hex``: the BLE advertisement of bkerler/DroneID's decoder
  self-test (OpenDroneID/selftest.py): a message pack of seven messages (two Basic IDs,
  Location, Authentication page 0, Self-ID, System, Operator ID), with its expected JSON.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from adapters.remoteid import f3411
from adapters.remoteid.f3411 import (
    AuthPage,
    BasicId,
    ClassificationType,
    EuCategory,
    EuClass,
    HeightType,
    IdType,
    Location,
    OperationalStatus,
    OperatorId,
    OperatorLocationType,
    RemoteIdError,
    SelfId,
    System,
    UaType,
)

DATA = Path(__file__).parent.parent / "data" / "remoteid"
BLE_SERVICE_HEADER = 6  # AD length, AD type 0x16, UUID 0xFFFA, application code 0x0D, counter


def _hex(name: str) -> bytes:
    return bytes.fromhex((DATA / name).read_text().strip())


def _pack() -> list[f3411.Message]:
    ad = _hex("bkerler_droneid_selftest_ble.hex")
    assert ad[1:5] == bytes.fromhex("16faff0d")  # service data, ASTM UUID, app code
    return f3411.decode(ad[BLE_SERVICE_HEADER:])


def test_librid_location_example() -> None:
    (loc,) = f3411.decode(_hex("librid_cli_location.hex"))
    assert isinstance(loc, Location)
    assert loc.protocol_version == 2
    assert loc.status is OperationalStatus.AIRBORNE
    assert loc.height_type is HeightType.ABOVE_TAKEOFF
    assert loc.latitude_deg == pytest.approx(62.683472, abs=1e-7)
    assert loc.longitude_deg == pytest.approx(21.974944, abs=1e-7)
    assert loc.altitude_geodetic_m == 120.5
    assert loc.altitude_pressure_m is None  # librid prints the "unknown" value -1000
    assert loc.height_m == 50.0
    assert loc.speed_horizontal_mps == 15.5
    assert loc.speed_vertical_mps == 2.0
    assert loc.track_deg == 45
    # accuracy classes 10 (< 10 m), 4 (< 10 m), speed 3 (< 1 m/s), baro 0 (unknown)
    assert loc.horizontal_accuracy_m == 10.0
    assert loc.vertical_accuracy_m == 10.0
    assert loc.speed_accuracy_mps == 1.0
    assert loc.baro_accuracy_m is None
    assert loc.time_since_hour_s == 1234.5  # 12345 tenths of a second
    assert loc.time_accuracy_s == 0.1


def test_bkerler_pack_identity_messages() -> None:
    msgs = _pack()
    assert [type(m) for m in msgs] == [
        BasicId, BasicId, Location, AuthPage, SelfId, System, OperatorId
    ]  # fmt: skip
    serial, caa = msgs[0], msgs[1]
    assert isinstance(serial, BasicId) and isinstance(caa, BasicId)
    assert serial.protocol_version == 0
    assert serial.id_type is IdType.SERIAL_NUMBER
    assert serial.ua_type is UaType.HELICOPTER_OR_MULTIROTOR
    assert serial.uas_id == "18656A24303"
    assert caa.id_type is IdType.CAA_REGISTRATION_ID
    assert caa.uas_id == "DJI"
    self_id, operator = msgs[4], msgs[6]
    assert isinstance(self_id, SelfId) and isinstance(operator, OperatorId)
    assert (self_id.protocol_version, self_id.description_type) == (2, 0)
    assert self_id.description == "Drones ID test flight"
    assert (operator.protocol_version, operator.operator_id_type) == (2, 0)
    assert operator.operator_id == ""


def test_bkerler_pack_location() -> None:
    loc = _pack()[2]
    assert isinstance(loc, Location)
    assert loc.protocol_version == 2
    assert loc.status is OperationalStatus.AIRBORNE
    assert loc.height_type is HeightType.ABOVE_TAKEOFF
    assert loc.track_deg == 94  # east segment
    assert loc.speed_horizontal_mps == 0.25
    assert loc.speed_vertical_mps == 0.0
    assert loc.latitude_deg == pytest.approx(33.6577004, abs=1e-9)
    assert loc.longitude_deg == pytest.approx(-82.2156164, abs=1e-9)
    assert loc.altitude_pressure_m is None  # "Undefined"
    assert loc.altitude_geodetic_m == 76.0
    assert loc.height_m == -9.0
    assert loc.vertical_accuracy_m == 10.0  # "<10 m"
    assert loc.horizontal_accuracy_m == 1.0  # "<1 m"
    assert loc.baro_accuracy_m == 10.0  # "<10 m"
    assert loc.speed_accuracy_mps == 0.3  # "<0.3 m/s"
    # the self-test prints the raw 5470; F3411 counts tenths of a second since the hour
    assert loc.time_since_hour_s == 547.0
    assert loc.time_accuracy_s == 0.2  # "0.2 s"


def test_bkerler_pack_auth_and_system() -> None:
    msgs = _pack()
    auth, system = msgs[3], msgs[5]
    assert isinstance(auth, AuthPage) and isinstance(system, System)
    stamp = datetime(2019, 1, 1, tzinfo=UTC).timestamp() + 170716129  # "timestamp_raw"
    assert auth.auth_type == 3  # message set signature
    assert (auth.page_number, auth.last_page_index, auth.length_bytes) == (0, 0, 17)
    assert auth.timestamp_s == stamp
    assert auth.data == bytes(17)
    assert system.operator_location_type is OperatorLocationType.TAKEOFF
    assert system.classification_type is ClassificationType.EUROPEAN_UNION
    assert system.operator_latitude_deg == pytest.approx(33.6631981, abs=1e-9)
    assert system.operator_longitude_deg == pytest.approx(-82.2205112, abs=1e-9)
    assert (system.area_count, system.area_radius_m) == (1, 0.0)
    assert (system.area_ceiling_m, system.area_floor_m) == (0.0, 0.0)
    assert system.eu_category is EuCategory.OPEN
    assert system.eu_class is EuClass.CLASS_1
    assert system.operator_altitude_geodetic_m == 85.0
    assert system.timestamp_s == stamp
    when = datetime.fromtimestamp(stamp, UTC)
    assert when.strftime("%Y-%m-%d %H:%M") == "2024-05-29 21:08"  # as the self-test prints


def _location(**changes: int) -> bytearray:
    """The librid Location example with some bytes replaced (offset -> value)."""
    data = bytearray(_hex("librid_cli_location.hex"))
    for key, value in changes.items():
        data[int(key[1:])] = value
    return data


def test_unknown_values_decode_to_none() -> None:
    data = _location(b1=0x23, b2=181, b3=255, b4=126)  # EW + 0.75 multiplier, 361 deg
    data[5:13] = bytes(8)
    data[21:23] = b"\xff\xff"
    loc = f3411.decode_message(bytes(data))
    assert isinstance(loc, Location)
    assert loc.track_deg is None and loc.speed_horizontal_mps is None
    assert loc.speed_vertical_mps is None
    assert loc.latitude_deg is None and loc.longitude_deg is None
    assert loc.time_since_hour_s is None


def test_fast_speed_and_west_track() -> None:
    loc = f3411.decode_message(bytes(_location(b1=0x23, b2=90, b3=10)))
    assert isinstance(loc, Location)
    assert loc.track_deg == 270
    assert loc.speed_horizontal_mps == 10 * 0.75 + 63.75


@pytest.mark.parametrize(
    ("data", "field"),
    [
        (bytes(24), "length"),
        (bytes([0x62]) + bytes(24), "message type"),
        (bytes([0xF2, 25, 1]) + bytes([0xF2]) + bytes(24), "message type"),  # pack in a pack
        (bytes([0xF2, 24, 1]) + bytes(25), "message pack size"),
        (bytes([0xF2, 25, 0]), "message pack count"),
        (bytes([0xF2, 25, 10]) + bytes(250), "message pack count"),
        (bytes([0xF2, 25, 2]) + bytes(25), "message pack"),
        (bytes([0x02, 0x12]) + b"AB\x07" + bytes(20), "UAS ID"),
        (bytes([0x02, 0x52]) + bytes(23), "ID type"),
        (bytes([0x12, 0x50]) + bytes(23), "operational status"),
        (bytes([0x42, 0x03]) + bytes(23), "operator location type"),
        (bytes([0x22, 0x30, 16]) + bytes(22), "last page index"),
    ],
)
def test_malformed_message_names_the_field(data: bytes, field: str) -> None:
    with pytest.raises(RemoteIdError) as err:
        f3411.decode(data)
    assert err.value.field == field
    assert field in str(err.value)


def test_bad_position_is_refused() -> None:
    data = _location()
    data[5:9] = (91 * 10**7).to_bytes(4, "little", signed=True)
    with pytest.raises(RemoteIdError, match="position"):
        f3411.decode_message(bytes(data))


@given(st.binary(min_size=0, max_size=3 + 9 * 25))
def test_any_bytes_decode_or_raise_remote_id_error(data: bytes) -> None:
    try:
        msgs = f3411.decode(data)
    except RemoteIdError:
        return
    assert 1 <= len(msgs) <= f3411.PACK_MAX_MESSAGES
