"""The F3411 broadcast decoder (adapters/remoteid/f3411.py) against published encodings.

Vectors (tests/data/remoteid, sources in tests/data/SOURCES.md), with the decoded values their
publishers print:
- ``librid_cli_location.hex``: the Location/Vector example of tuupola/librid's CLI README.
- ``librid_basic_id.hex``, ``librid_system.hex``, ``librid_self_id.hex``,
  ``librid_operator_id.hex``, ``librid_auth_pages.hex``: the outputs printed in the READMEs of
  librid's examples (basic_id, system, self_id, operator_id, auth_page), with their values.
- ``opendroneid_core_c_wifi_beacon.hex``: the expected buffer of opendroneid-core-c's Wi-Fi
  beacon unit test (a frame prefix: the pack header and a complete Basic ID message).
"""

from __future__ import annotations

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


def _hex(name: str) -> bytes:
    return bytes.fromhex((DATA / name).read_text().strip())


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


def test_librid_basic_id_example() -> None:
    basic = f3411.decode_message(_hex("librid_basic_id.hex"))
    assert isinstance(basic, BasicId)
    assert basic.protocol_version == 2
    assert basic.id_type is IdType.SERIAL_NUMBER  # librid prints "ID type: 1"
    assert basic.ua_type is UaType.HELICOPTER_OR_MULTIROTOR  # "UA type: 2"
    assert basic.uas_id == "1ABCD2345EF678XYZ"


def test_librid_system_example() -> None:
    system = f3411.decode_message(_hex("librid_system.hex"))
    assert isinstance(system, System)
    assert system.protocol_version == 2
    assert system.operator_location_type is OperatorLocationType.TAKEOFF  # "loc type: 0"
    assert system.classification_type is ClassificationType.EUROPEAN_UNION  # "1"
    assert system.operator_latitude_deg == pytest.approx(60.2870324, abs=1e-9)  # 60.287032
    assert system.operator_longitude_deg == pytest.approx(24.5397187, abs=1e-9)  # 24.539719
    assert (system.area_count, system.area_radius_m) == (1, 100.0)
    assert (system.area_ceiling_m, system.area_floor_m) == (120.0, 0.0)
    assert system.eu_category is EuCategory.OPEN  # "UA category: 1"
    assert system.eu_class is EuClass.CLASS_1  # "UA class: 2", the code F3411 names Class 1
    assert system.operator_altitude_geodetic_m == 50.0
    assert system.timestamp_s == f3411.ODID_EPOCH_UTC_S + 3600  # "Timestamp: 3600"


def test_librid_self_id_and_operator_id_examples() -> None:
    self_id = f3411.decode_message(_hex("librid_self_id.hex"))
    operator = f3411.decode_message(_hex("librid_operator_id.hex"))
    assert isinstance(self_id, SelfId) and isinstance(operator, OperatorId)
    assert (self_id.protocol_version, self_id.description_type) == (2, 0)
    assert self_id.description == "Drone delivery test"
    assert (operator.protocol_version, operator.operator_id_type) == (2, 0)
    assert operator.operator_id == "FIN87astrdge12k8"


def test_librid_authentication_pages() -> None:
    data = _hex("librid_auth_pages.hex")
    pages = [f3411.decode_message(data[i : i + 25]) for i in range(0, len(data), 25)]
    assert all(isinstance(p, AuthPage) for p in pages) and len(pages) == 3
    first, second, last = (p for p in pages if isinstance(p, AuthPage))
    assert first.auth_type == 3  # "Auth type: 3"
    assert (first.page_number, first.last_page_index, first.length_bytes) == (0, 2, 56)
    assert first.timestamp_s == f3411.ODID_EPOCH_UTC_S + 189302400  # "Timestamp: 189302400"
    assert first.data == data[8:25]
    assert (second.page_number, last.page_number) == (1, 2)
    assert second.last_page_index is None and second.timestamp_s is None
    assert second.data == data[27:50] and last.data == data[52:75]
    signed = first.data + second.data + last.data
    assert signed[:4] == bytes.fromhex("30820122")  # the 56 bytes start a DER sequence
    assert signed[56:] == bytes(len(signed) - 56)  # null padding after "Length: 56"


def test_opendroneid_core_wifi_beacon_basic_id() -> None:
    """The message pack in opendroneid-core-c's expected Wi-Fi beacon (a prefix of the frame)."""
    frame = _hex("opendroneid_core_c_wifi_beacon.hex")
    vendor_ie = frame.index(bytes.fromhex("dd53fa0bbc0d"))  # IE 221, ASD-STAN OUI, type 0x0D
    pack = frame[vendor_ie + 7 :]  # after the message counter
    assert pack[:3] == bytes([0xF2, f3411.MESSAGE_SIZE, 3])  # pack v2, 25-byte messages, 3
    basic = f3411.decode_message(pack[3 : 3 + 25])
    assert isinstance(basic, BasicId)
    assert basic.protocol_version == 2
    assert basic.id_type is IdType.SERIAL_NUMBER
    assert basic.ua_type is UaType.HYBRID_LIFT
    assert basic.uas_id == "USS-Enterprise"
    assert basic.uas_id_raw == b"USS-Enterprise" + bytes(6)
    assert pack[28:30] == bytes([0x12, 0x20])  # the Location that follows: v2, airborne
    with pytest.raises(RemoteIdError, match="message pack"):
        f3411.decode(pack)  # the published buffer stops after the Location's second byte


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
