"""MQTT input in a cluster (gcs_utm.cluster.inbound): every instance's gateway hears a pilot's
answer, a flight plan and an operator command; the holder of the region concerned carries it
out and answers, the others publish nothing, and when no instance holds the region one
instance (the arbiter: the holder of the lowest live region) refuses it, naming why.

Two members on one PostgreSQL (tests/cluster/harness.py), each with a real USM, airspace and
MQTT gateway on one mosquitto; a station (a plain MQTT client, operator ``admin``) sends the
messages and counts the answers on its ``status`` and ``errors`` topics."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import shutil
import subprocess
import time
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import aiomqtt
import pytest

from adapters.mqtt.config import MqttConfig
from gcs_utm.app.wiring import Persistence
from gcs_utm.clock import RealClock
from gcs_utm.cluster.commands import CommandGate
from gcs_utm.cluster.config import ClusterConfig
from gcs_utm.model import Operation, OperationId, RecommendationId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm
from gcs_utm.store import open_store
from tests.cluster.harness import Member, config, file_airspace, frame, member
from tests.cluster.test_border_conflict import _free_port, _start_broker
from tests.store.test_store import _rec

Doc = dict[str, Any]


@pytest.fixture
def mqtt_port(tmp_path: Path) -> Iterator[int]:
    """A mosquitto of its own (anonymous, loopback)."""
    mosquitto = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
    if not os.path.exists(mosquitto):
        pytest.skip("mosquitto not installed (apt-get install mosquitto)")
    port = _free_port()
    conf = tmp_path / "mosquitto.conf"
    conf.write_text(f"listener {port} 127.0.0.1\nallow_anonymous true\n")
    proc = _start_broker(mosquitto, conf, tmp_path / "broker.log", port)
    try:
        yield port
    finally:
        proc.terminate()
        try:
            proc.wait(5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@dataclass
class Instance:
    m: Member
    usm: Usm
    airspace: Airspace
    gateway: MqttGateway
    task: asyncio.Task[None]


async def _instance(url: str, port: int, cfg: ClusterConfig) -> Instance:
    """A member with a real USM and airspace on its store, and its MQTT gateway (as
    ``serve --cluster`` wires it: the member's arbiter decides who answers)."""
    made: list[tuple[Usm, Airspace]] = []

    def services(store: Persistence) -> tuple[Usm, Airspace]:
        airspace = Airspace(on_operation=store.save_operation)
        made.append((Usm(airspace, RealClock(), record=store.record), airspace))
        return made[0]

    m = await member(url, cfg, services=services)
    usm, airspace = made[0]
    mqtt = MqttConfig(
        enabled=True,
        port=port,
        client_id=f"gcs-utm-{cfg.instance}",
        backoff_initial_s=0.05,
        backoff_max_s=0.5,
    )
    gateway = MqttGateway(usm, mqtt, frame=frame())
    gateway.attach()
    gateway.arbiter = m.node.inbound
    node = m.node
    usm.operator_commands.gate = CommandGate(node.member, node.policy, frame(), node.may_act)
    task = asyncio.create_task(gateway.run())
    await gateway.bridge.wait_connected(10.0)
    return Instance(m, usm, airspace, gateway, task)


async def _stop(*instances: Instance) -> None:
    for i in instances:
        i.task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await i.task
        await i.m.close()


@contextlib.asynccontextmanager
async def _station(port: int) -> AsyncIterator[aiomqtt.Client]:
    async with aiomqtt.Client("127.0.0.1", port, identifier="test-station") as client:
        await client.subscribe("gcs_utm/operators/admin/status", qos=1)
        await client.subscribe("gcs_utm/operators/admin/errors", qos=1)
        yield client


async def _send(
    client: aiomqtt.Client,
    kind: str,
    body: Doc,
    wanted: Callable[[Doc], bool],
    *,
    decided: Callable[[], bool],
) -> list[Doc]:
    """Publish ``body`` on the station's ``kind`` topic; every answer ``wanted`` picks, until
    ``decided()`` (every instance has handled the message) and 0.5 s after the last answer
    (at most 10 s)."""
    await client.publish(f"gcs_utm/operators/admin/{kind}", json.dumps(body), qos=1)
    answers: list[Doc] = []
    loop = asyncio.get_running_loop()
    end = loop.time() + 10.0
    quiet_until = end
    messages = aiter(client.messages)
    while loop.time() < min(end, quiet_until):
        try:
            msg = await asyncio.wait_for(anext(messages), 0.1)
        except TimeoutError:
            if decided() and quiet_until == end:
                quiet_until = loop.time() + 0.5
            continue
        doc = json.loads(bytes(msg.payload))  # type: ignore[arg-type]
        if wanted(doc):
            answers.append(doc)
            if decided():
                quiet_until = loop.time() + 0.5
    return answers


def _answer(rec_id: str, version: int) -> Doc:
    return {
        "schema_version": 1,
        "type": "pilot_answer",
        "recommendation_id": rec_id,
        "version": version,
        "decision": "reject",
        "t_s": time.time(),
    }


def _answered(rec_id: str) -> Callable[[Doc], bool]:
    return lambda d: d.get("recommendation_id") == rec_id and "answer" in d


def _command(uas: str, request_id: str) -> Doc:
    body = {"schema_version": 1, "type": "operator_command", "uas": uas, "command": "hold"}
    return {**body, "id": request_id, "t_s": time.time()}


def _plan(op: Operation, op_id: str) -> Doc:
    waypoints = [
        {"lat_deg": w.lat_deg, "lon_deg": w.lon_deg, "alt_amsl_m": w.alt_amsl_m, "t_s": w.t_s}
        for w in op.plan.waypoints
    ]
    body = {"schema_version": 1, "type": "flight_plan", "operation_id": op_id}
    return {**body, "t_s": time.time(), "waypoints": waypoints}


def _about(op_id: str) -> Callable[[Doc], bool]:
    return lambda d: d.get("type") == "error" and op_id in str(d.get("reason"))


def _handled(*counters: Callable[[], int]) -> Callable[[], bool]:
    """True once each counter has grown since this call."""
    before = [c() for c in counters]
    return lambda: all(c() > b for c, b in zip(counters, before, strict=True))


@pytest.mark.timeout(90)
async def test_the_holder_alone_acts_on_an_answer_or_a_plan_and_answers(
    pg_url: str, mqtt_port: int
) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}  # UAS1 departs in c0r0, UAS2 in c1r0
    a = await _instance(pg_url, mqtt_port, config("A", "c0r0", standby=False))
    b = await _instance(pg_url, mqtt_port, config("B", "c1r0", standby=False))
    try:
        assert await a.m.step() == ["gained c0r0"] and await b.m.step() == ["gained c1r0"]
        await a.m.step()  # A's next round reads B's lease
        rec = replace(_rec(), deadline_t_s=time.time() + 600.0)  # for A's UAS1
        await a.usm.on_recommendation(rec)
        rejected = lambda: a.usm.recommendations[rec.id].rec.state.value == "rejected"  # noqa: E731
        b_ignored = _handled(lambda: b.m.node.inbound.ignored)
        async with _station(mqtt_port) as station:
            # the pilot rejects A's recommendation: A takes the answer, B says nothing
            answers = await _send(
                station,
                "answers",
                _answer(rec.id, rec.version),
                _answered(rec.id),
                decided=lambda: rejected() and b_ignored(),
            )
            assert [d["answer"]["outcome"] for d in answers] == ["accepted"], answers
            assert a.usm.recommendations[rec.id].rec.state.value == "rejected"
            assert RecommendationId(rec.id) not in b.usm.recommendations
            # an answer no instance can place: one refusal, from the arbiter (A: c0r0)
            answers = await _send(
                station,
                "answers",
                _answer("R-nowhere", 1),
                _answered("R-nowhere"),
                decided=_handled(
                    lambda: a.m.node.inbound.refused, lambda: b.m.node.inbound.ignored
                ),
            )
            assert [d["answer"]["outcome"] for d in answers] == ["refused"], answers
            assert "no instance has it" in answers[0]["reason"]
            # a plan departing in B's region: filed by B only, no error from anyone
            answers = await _send(
                station,
                "flight_plans",
                _plan(ops[OperationId("UAS2")], "PLAN-B"),
                _about("PLAN-B"),
                decided=_handled(
                    lambda: a.m.node.inbound.ignored, lambda: len(b.airspace.operations)
                ),
            )
            assert answers == []
            assert OperationId("PLAN-B") in b.airspace.operations
            assert b.m.node.policy.owns(OperationId("PLAN-B"))
            assert OperationId("PLAN-B") not in a.airspace.operations
            # the pilot starts UAS2's flight: B (its owner) starts it, A says nothing
            uas2 = OperationId("UAS2")
            body = {"schema_version": 1, "type": "flight_status", "operation_id": "UAS2"}
            a_ignored = _handled(lambda: a.m.node.inbound.ignored)
            answers = await _send(
                station,
                "flight_status",
                {**body, "status": "start", "t_s": time.time()},
                _about("UAS2"),
                decided=lambda: b.airspace.operations[uas2].state.value == "active" and a_ignored(),
            )
            assert answers == [] and uas2 not in a.airspace.operations
    finally:
        await _stop(a, b)


@pytest.mark.timeout(90)
async def test_one_instance_refuses_what_no_instance_holds(pg_url: str, mqtt_port: int) -> None:
    ops = {op.id: op for op in file_airspace(pg_url)}
    uas2_rec = replace(
        _rec(),
        id=RecommendationId("R2"),
        operation_id=OperationId("UAS2"),
        deadline_t_s=time.time() + 600.0,
    )
    with open_store(pg_url) as s:  # UAS2's owner, dead now, had proposed R2
        s.begin_life()
        s.save_recommendation(uas2_rec)
    a = await _instance(pg_url, mqtt_port, config("A", "c0r0", standby=False))
    # B has not claimed its region c1r0 yet (no lease round): nobody holds c1r0
    b = await _instance(pg_url, mqtt_port, config("B", "c1r0", standby=False))
    try:
        assert await a.m.step() == ["gained c0r0"]
        async with _station(mqtt_port) as station:
            # a command for UAS2 (c1r0, held by nobody): one refusal, from A, naming why
            answers = await _send(
                station,
                "commands",
                _command("UAS2", "c1"),
                lambda d: d.get("type") == "command_status" and d.get("id") == "c1",
                decided=_handled(
                    lambda: a.m.node.inbound.refused, lambda: b.m.node.inbound.ignored
                ),
            )
            assert [d["outcome"] for d in answers] == ["refused"], answers
            assert "region c1r0, held by no instance now" in answers[0]["reason"]
            # a command for a UAS nobody has: one refusal
            answers = await _send(
                station,
                "commands",
                _command("UAS7", "c2"),
                lambda d: d.get("type") == "command_status" and d.get("id") == "c2",
                decided=_handled(
                    lambda: a.m.node.inbound.refused, lambda: b.m.node.inbound.ignored
                ),
            )
            assert [d["outcome"] for d in answers] == ["refused"], answers
            assert "unknown UAS 'UAS7': no instance has" in answers[0]["reason"]
            # a plan departing in c1r0: refused once, filed nowhere
            answers = await _send(
                station,
                "flight_plans",
                _plan(ops[OperationId("UAS2")], "PLAN-C"),
                _about("PLAN-C"),
                decided=_handled(
                    lambda: a.m.node.inbound.refused, lambda: b.m.node.inbound.ignored
                ),
            )
            assert len(answers) == 1, answers
            assert "departs in region c1r0, held by no instance now" in answers[0]["reason"]
            assert all(OperationId("PLAN-C") not in i.airspace.operations for i in (a, b))
            # an answer to the dead owner's recommendation: refused once, saying what comes
            answers = await _send(
                station,
                "answers",
                _answer("R2", 1),
                _answered("R2"),
                decided=_handled(
                    lambda: a.m.node.inbound.refused, lambda: b.m.node.inbound.ignored
                ),
            )
            assert [d["answer"]["outcome"] for d in answers] == ["refused"], answers
            assert "its new holder proposes it again" in answers[0]["reason"]
            # B takes c1r0; the station sends its first command again (no answer reached
            # it, say): B carries it out now (no vehicle link here), and alone answers
            assert await b.m.step() == ["gained c1r0"]
            answers = await _send(
                station,
                "commands",
                _command("UAS2", "c1"),
                lambda d: d.get("type") == "command_status" and d.get("id") == "c1",
                decided=_handled(
                    lambda: len(b.usm.operator_commands.results), lambda: a.m.node.inbound.ignored
                ),
            )
            assert [d["reason"] for d in answers] == ["no vehicle link for UAS2"], answers
    finally:
        await _stop(a, b)
