"""Operator commands in a cluster (gcs_utm.cluster.commands): only the holder of the region
a UAS departed from commands its vehicle. Another instance refuses, naming the region and
its holder, sends nothing, and over MQTT publishes nothing (the owner, subscribed to the
same topics, answers); the owner refuses too once its lease deadline has passed."""

from __future__ import annotations

import asyncio

from adapters.mqtt.codec import OperatorCommandRequest
from adapters.mqtt.config import MqttConfig
from gcs_utm.clock import RealClock
from gcs_utm.cluster.commands import CommandGate
from gcs_utm.messages import FlightMode, VehicleStatus
from gcs_utm.model import Autopilot, Command, OperationId, SysId, VehicleKind
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm
from tests.cluster.harness import Member, config, file_airspace, frame, member


class Recording:
    """A vehicle port that acknowledges every command and records it."""

    def __init__(self) -> None:
        self.commands: list[tuple[SysId, Command]] = []

    async def send_command(self, sys_id: SysId, command: Command) -> object:
        self.commands.append((sys_id, command))

        class Ok:
            ok = True
            verified = True
            error = ""

        return Ok()

    async def upload_plan(self, *args: object, **kwargs: object) -> object:
        raise AssertionError("no upload expected")


def _usm_of(m: Member, ops: list) -> tuple[Usm, Recording]:  # type: ignore[type-arg]
    """A real USM over ``ops`` (this member's own and, as foreign, the others') with the
    member's gate, every vehicle heard and flying."""
    airspace = Airspace()
    airspace.load(ops, ())
    usm = Usm(airspace, RealClock(), record=lambda _r: None)
    vehicles = Recording()
    usm.attach_vehicles(vehicles)  # type: ignore[arg-type]
    for op in ops:
        assert op.sys_id is not None
        usm.on_status(
            VehicleStatus(
                sys_id=op.sys_id,
                t_s=usm.clock.now_s(),
                autopilot=Autopilot.PX4,
                vehicle_kind=VehicleKind.MULTIROTOR,
                mode=FlightMode.MISSION,
                armed=True,
                landed=False,
                mission_total=2,
            )
        )
    node = m.node
    node.policy.operations_of = lambda: airspace.operations
    usm.operator_commands.gate = CommandGate(node.member, node.policy, frame(), node.may_act)
    usm.operator_commands.confirm_s = 0.0  # no mode to wait for here
    return usm, vehicles


async def test_only_the_region_holder_commands_and_others_name_it(pg_url: str) -> None:
    ops = file_airspace(pg_url)  # UAS1 departs in c0r0, UAS2 in c1r0
    a = await member(pg_url, config("A", "c0r0", standby=False))
    b = await member(pg_url, config("B", "c1r0", standby=False))
    try:
        assert await a.step() == ["gained c0r0"] and await b.step() == ["gained c1r0"]
        await b.step()  # B's next round reads A's lease
        b.node.policy.foreign.add(OperationId("UAS1"))  # B watches UAS1 (halo)
        usm, vehicles = _usm_of(b, ops)
        # UAS1 is A's: B refuses on every channel, naming the region and A
        refused = await usm.operator_command("UAS1", "hold", operator="x", source="dashboard")
        assert refused.outcome.value == "refused" and refused.elsewhere
        assert refused.reason == (
            f"UAS1 belongs to region c0r0, held by instance {a.node.member.holder}: "
            "only that instance commands it"
        )
        unknown = await usm.operator_command("UAS7", "land", operator="x", source="dashboard")
        assert unknown.elsewhere and "not in a region B#" in unknown.reason
        # over MQTT B stays silent: A hears the same message and answers
        gateway = MqttGateway(usm, MqttConfig())
        request = OperatorCommandRequest(
            uas="UAS1", command="rtl", request_id="r1", operator="admin", t_s=0.0
        )
        assert await gateway.on_operator_command(request) is None
        assert vehicles.commands == []
        # UAS2 is B's own: sent, and answered over MQTT
        mine = OperatorCommandRequest(
            uas="UAS2", command="hold", request_id="r2", operator="admin", t_s=0.0
        )
        ack = await gateway.on_operator_command(mine)
        assert ack is not None and ack.outcome in ("confirmed", "acknowledged")
        assert [(s, c.kind.value) for s, c in vehicles.commands] == [(SysId(2), "hold")]
    finally:
        await a.close()
        await b.close()


async def test_an_owner_past_its_lease_deadline_refuses(pg_url: str) -> None:
    ops = file_airspace(pg_url)
    b = await member(pg_url, config("B", "c1r0", standby=False, lease_s=1.0))
    try:
        assert await b.step() == ["gained c1r0"]
        usm, vehicles = _usm_of(b, [op for op in ops if op.id == "UAS2"])
        await asyncio.sleep(1.1)  # no renewal for lease_s: a stall
        result = await usm.operator_command("UAS2", "land", operator="x", source="dashboard")
        assert result.outcome.value == "refused"
        assert "lease has expired (self-fenced)" in result.reason
        assert vehicles.commands == [] and b.failed  # and the instance stops
    finally:
        await b.close()
