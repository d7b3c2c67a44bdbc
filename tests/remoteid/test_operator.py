"""The operator's side of Remote ID (adapters/remoteid: identity, config, operator): what a
vehicle that declares Remote ID gets from the hub, from its operation and ``[remote_id]``, and
the clear errors for bad identities."""

from __future__ import annotations

import asyncio
import os
from typing import Any

import pytest

os.environ["MAVLINK20"] = "1"

from adapters.mavlink import MavlinkConfig, MavlinkHub
from adapters.remoteid.config import RemoteIdConfig
from adapters.remoteid.f3411 import ODID_EPOCH_UTC_S, EuCategory, EuClass
from adapters.remoteid.identity import (
    IdentityError,
    check_operator_id,
    check_serial_number,
    parse_classification,
)
from adapters.remoteid.operator import RemoteIdOperator
from gcs_utm.clock import RealClock
from gcs_utm.config import ConfigError, build
from gcs_utm.model import (
    FlightPlan,
    Operation,
    OperationId,
    OperationState,
    Position,
    SysId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)
from tests.mavlink.conftest import FakeVehicle, Sink

HOME = Position(lat_deg=47.397742, lon_deg=8.545594, alt_amsl_m=488.0)


def _operation(sys_id: int, *, operator: str = "acme", home: Position | None = HOME) -> Operation:
    oid = OperationId(f"op-{sys_id}")
    wp = Waypoint4D(lat_deg=47.3980, lon_deg=8.5460, alt_amsl_m=520.0, t_s=0.0)
    return Operation(
        id=oid,
        icao24=None,
        sys_id=SysId(sys_id),
        priority=1,
        plan=FlightPlan(operation_id=oid, version=1, waypoints=(wp,)),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=5.0,
        flight_geometry_m=10.0,
        operational_volume_m=30.0,
        home=home,
        operator=operator,
        state=OperationState.ACTIVE,
    )


# --- identities -------------------------------------------------------------------------------


@pytest.mark.parametrize("serial", ["1596A303716531B", "18656A24303", "ABCD1Z"])
def test_cta_2063_a_serials_accepted(serial: str) -> None:
    assert check_serial_number(serial) == serial


@pytest.mark.parametrize(
    ("serial", "reason"),
    [
        ("1596", "4 characters"),
        ("1596A30371653", "says 10 serial characters"),  # 8 after the length code
        ("1596O303716531B", "'O'"),  # O reads as 0
        ("1596a303716531b", "not allowed"),
        ("1596G303716531B", "length code 'G'"),
        ("1596F" + "1" * 16, "characters, expected 6..20"),
    ],
)
def test_bad_serials_say_why(serial: str, reason: str) -> None:
    with pytest.raises(IdentityError, match="ANSI/CTA-2063-A") as err:
        check_serial_number(serial)
    assert reason in err.value.reason


def test_operator_id_and_classification_checks() -> None:
    assert check_operator_id("FIN87astrdge12k8") == "FIN87astrdge12k8"
    for bad in ("", "FIN 87astrdge12k8", "X" * 21, "FIN87é"):
        with pytest.raises(IdentityError, match="operator ID"):
            check_operator_id(bad)
    c = parse_classification("Open/C1")
    assert (c.category, c.eu_class) == (EuCategory.OPEN, EuClass.CLASS_1)
    assert parse_classification("specific").eu_class is EuClass.UNDECLARED
    with pytest.raises(IdentityError, match="category"):
        parse_classification("closed")
    with pytest.raises(IdentityError, match="class"):
        parse_classification("open/C7")


def test_config_names_the_bad_key() -> None:
    with pytest.raises(ConfigError, match=r"remote_id.*'1596O3'") as err:
        build(
            RemoteIdConfig,
            {"serial_numbers": {"1": "1596O3"}},
            source="x.toml",
            section="remote_id",
        )
    assert err.value.source == "x.toml"
    with pytest.raises(ConfigError, match="not a system id"):
        build(
            RemoteIdConfig, {"serial_numbers": {"one": "1596A303716531B"}}, source="x", section="r"
        )
    with pytest.raises(ConfigError, match="LAT,LON,ALT_AMSL_M"):
        build(
            RemoteIdConfig, {"operator_locations": {"default": "47.3,8.5"}}, source="x", section="r"
        )
    with pytest.raises(ConfigError, match="unknown"):
        build(
            RemoteIdConfig, {"operator_locations": {"default": "0,0,10"}}, source="x", section="r"
        )


# --- to the vehicles ----------------------------------------------------------------------------


class _Env:
    def __init__(self, hub: MavlinkHub, port: int, operations: list[Operation]) -> None:
        self.hub, self.port, self.operations = hub, port, operations
        self.problems: list[str] = []
        self.hazards: list[Any] = []

    def operator(self, **cfg: Any) -> RemoteIdOperator:
        return RemoteIdOperator(
            RemoteIdConfig(**cfg),
            RealClock(),
            self.hub,
            vehicles=self.hub.remote_id,
            known=self.hub.vehicles,
            operations=lambda: self.operations,
            on_problem=self.problems.append,
            on_hazard=self.hazards.append,
        )

    async def vehicle(self, sys_id: int, autopilot: int = 3) -> FakeVehicle:
        v = await FakeVehicle(self.port, sys_id, autopilot=autopilot).start()
        v.heartbeat()
        await _until(lambda: any(i.key.sys_id == sys_id for i in self.hub.vehicles()))
        return v


async def _until(cond: Any, timeout_s: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not cond():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.01)


@pytest.fixture
async def rid_env() -> Any:
    cfg = MavlinkConfig(links=("udpin:127.0.0.1:0",), heartbeat_period_s=0.2)
    hub = MavlinkHub(cfg, RealClock(), Sink())
    await hub.start()
    link = next(iter(hub.link_names()))
    yield _Env(hub, hub.local_port(link), [])
    await hub.close()


def _got(v: FakeVehicle, name: str) -> list[Any]:
    return [m for m in v.received if m.get_type() == name]


async def test_declared_vehicle_gets_operator_part(rid_env: Any) -> None:
    env = rid_env
    env.operations.append(_operation(1))
    op = env.operator(
        operator_ids={"acme": "FIN87astrdge12k8"},
        serial_numbers={"1": "1596A303716531B"},
        classifications={"1": "open/C2"},
    )
    v = await env.vehicle(1)
    op.tick(1000.0)
    await asyncio.sleep(0.1)
    assert _got(v, "OPEN_DRONE_ID_SYSTEM") == []  # not declared: nothing sent
    # ArduPilot with DID_ENABLE=1 and no operator location says so on every link
    v.send(v.mav.statustext_encode(4, b"ODID: lost operator location"), lossy=False)
    await _until(lambda: 1 in env.hub.remote_id.declared)
    t0 = ODID_EPOCH_UTC_S + 1000.0
    op.tick(t0)
    op.tick(t0 + 1.0)  # a second SYSTEM; the static part only every static_period_s
    await _until(lambda: len(_got(v, "OPEN_DRONE_ID_SYSTEM")) == 2)
    s = _got(v, "OPEN_DRONE_ID_SYSTEM")[0]
    assert (s.target_system, s.target_component) == (1, 0)
    assert (s.operator_latitude, s.operator_longitude) == (473977420, 85455940)
    assert s.operator_altitude_geo == 488.0 and s.operator_location_type == 0  # take-off
    assert (s.classification_type, s.category_eu, s.class_eu) == (1, 1, 3)
    assert s.timestamp == 1000
    [b] = _got(v, "OPEN_DRONE_ID_BASIC_ID")
    assert bytes(b.uas_id).rstrip(b"\0") == b"1596A303716531B"
    assert (b.id_type, b.ua_type) == (1, 2)  # serial number, multirotor
    [o] = _got(v, "OPEN_DRONE_ID_OPERATOR_ID")
    assert o.operator_id.rstrip("\x00") == "FIN87astrdge12k8"
    assert env.problems == [] and env.hazards == []
    v.close()


async def test_missing_parts_are_reported_once(rid_env: Any) -> None:
    env = rid_env
    op = env.operator(vehicles=(2,))
    v = await env.vehicle(2)
    op.tick(1.0)
    op.tick(2.0)
    assert 2 in env.hub.remote_id.declared  # listed in [remote_id] vehicles
    # no operation, nothing configured: each missing part reported once, no SYSTEM sent
    assert [p.split(" ")[:3] for p in env.problems] == [
        ["no", "operator", "location"],
        ["no", "operator", "ID"],
        ["no", "UA", "serial"],
    ]
    assert "no operation is filed" in env.problems[0]
    # and it broadcasts an identity nobody filed: one hazard, not one per round
    [h] = env.hazards
    assert h.kind is ThreatKind.REMOTE_ID_MISMATCH and h.sys_id == 2
    assert "declares Remote ID ([remote_id] vehicles) but no operation" in h.message
    env.operations.append(_operation(2, operator="nobody", home=None))
    op.tick(3.0)
    op.tick(4.0)
    await _until(lambda: len(_got(v, "OPEN_DRONE_ID_SYSTEM")) == 2)
    s = _got(v, "OPEN_DRONE_ID_SYSTEM")[-1]
    assert (s.operator_latitude, s.operator_longitude) == (473980000, 85460000)  # 1st waypoint
    assert _got(v, "OPEN_DRONE_ID_BASIC_ID") == [] and _got(v, "OPEN_DRONE_ID_OPERATOR_ID") == []
    assert len(env.problems) == 4 and "'nobody'" in env.problems[3]  # its operator has no ID
    assert len(env.hazards) == 1  # filed now: no more
    v.close()


async def test_fixed_operator_location_and_odid_message_declares(rid_env: Any) -> None:
    env = rid_env
    op = env.operator(operator_locations={"default": "47.5,8.6,500"})
    v = await env.vehicle(3, autopilot=12)
    # a PX4 vehicle's own Remote ID Location: declares it
    v.send(
        v.mav.open_drone_id_location_encode(
            0,
            0,
            [0] * 20,
            2,
            9000,
            500,
            0,
            473977420,
            85455940,
            500,
            510,
            0,
            20,
            10,
            4,
            0,
            3,
            12.3,
            1,
        ),
        lossy=False,
    )
    await _until(lambda: 3 in env.hub.remote_id.declared)
    op.tick(5.0)
    await _until(lambda: len(_got(v, "OPEN_DRONE_ID_SYSTEM")) == 1)
    s = _got(v, "OPEN_DRONE_ID_SYSTEM")[0]
    assert (s.operator_latitude, s.operator_longitude, s.operator_location_type) == (
        475000000, 86000000, 2
    )  # fmt: skip
    assert s.classification_type == 0  # undeclared
    # another aircraft heard by the vehicle's receiver (id_or_mac set) declares nothing
    v2 = await env.vehicle(4, autopilot=12)
    v2.send(
        v2.mav.open_drone_id_basic_id_encode(
            0, 0, [1] * 20, 1, 2, list(b"1596A303716531B".ljust(20, b"\0"))
        ),
        lossy=False,
    )
    await _until(lambda: env.hub.remote_id.counters.about_others == 1)
    assert 4 not in env.hub.remote_id.declared
    v.close()
    v2.close()
