"""Helpers of the MQTT tests: a real mosquitto on a free 127.0.0.1 port, with password file
and the gcs-utm ACL; a fake USM; a peer client.

The port is found by binding port 0 and closing it; the broker binds it a moment later (a
tiny race, acceptable for loopback tests). ``Broker.stop()``/``start()`` restart it on the
same port with persistence, like a broker restart in operation.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import socket
import subprocess
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import aiomqtt
import pytest
from fake_usm import AnswerBook

from adapters.mqtt.acl import mosquitto_acl
from adapters.mqtt.answers import AnswerOutcome
from adapters.mqtt.codec import (
    CommandAck,
    FlightPlanSubmission,
    FlightStatusReport,
    OperatorCommandRequest,
    validate,
)
from adapters.mqtt.config import MqttConfig
from gcs_utm.clock import ManualClock
from gcs_utm.messages import HazardReport, PilotAnswer
from gcs_utm.model import Measurement

MOSQUITTO = shutil.which("mosquitto") or (
    "/usr/sbin/mosquitto" if Path("/usr/sbin/mosquitto").exists() else None
)
MOSQUITTO_PASSWD = shutil.which("mosquitto_passwd")

USERS = {
    "gcs_utm": "utm-secret",
    "alice": "alice-pw",
    "bob": "bob-pw",
    "authority": "authority-pw",
    "adsb": "adsb-pw",
}

T0 = 1_700_000_000.0


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Broker:
    folder: Path
    port: int
    proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        assert MOSQUITTO is not None
        log = (self.folder / "mosquitto.log").open("ab")
        self.proc = subprocess.Popen(
            [MOSQUITTO, "-c", str(self.folder / "mosquitto.conf")],
            stdout=log,
            stderr=subprocess.STDOUT,
        )
        log.close()
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(
                    "mosquitto exited: " + (self.folder / "mosquitto.log").read_text()
                )
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.02)
        raise RuntimeError("mosquitto did not start listening")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()  # SIGTERM: mosquitto saves its persistence db
            try:
                self.proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def config(self, user: str = "gcs_utm", **overrides: Any) -> MqttConfig:
        base: dict[str, Any] = {
            "enabled": True,
            "host": "127.0.0.1",
            "port": self.port,
            "username": user,
            "password": USERS[user],
            "backoff_initial_s": 0.05,
            "backoff_max_s": 0.5,
            "traffic_rate_hz": 50.0,
            "publish_timeout_s": 5.0,
        }
        base.update(overrides)
        return MqttConfig(**base)


def make_broker(tmp_path: Path, *, persistence: bool = True) -> Broker:
    """Configure and start a broker in ``tmp_path`` (skips when mosquitto is missing).
    ``persistence=False`` is mosquitto's default: a restart forgets every session."""
    if MOSQUITTO is None or MOSQUITTO_PASSWD is None:
        pytest.skip("mosquitto / mosquitto_passwd not installed (apt-get install mosquitto)")
    port = _free_port()
    pwfile = tmp_path / "passwd"
    for i, (user, pw) in enumerate(USERS.items()):
        flags = ["-b", "-c"] if i == 0 else ["-b"]
        subprocess.run([MOSQUITTO_PASSWD, *flags, str(pwfile), user, pw], check=True)
    pwfile.chmod(0o600)
    acl = tmp_path / "acl"
    acl.write_text(mosquitto_acl("gcs_utm"))
    acl.chmod(0o600)
    (tmp_path / "persist").mkdir()
    (tmp_path / "mosquitto.conf").write_text(
        "\n".join(
            [
                # as root, mosquitto would drop to user "mosquitto" and lose tmp_path access
                "user root" if os.geteuid() == 0 else "",
                "per_listener_settings false",
                f"listener {port} 127.0.0.1",
                "allow_anonymous false",
                f"password_file {pwfile}",
                f"acl_file {acl}",
                f"persistence {'true' if persistence else 'false'}",
                # default 1000 per client: the 1000-malformed test answers with 1001 errors
                "max_queued_messages 10000",
                f"persistence_location {tmp_path / 'persist'}/",
                "log_type error",
                "log_type warning",
                "log_type notice",
                "",
            ]
        )
    )
    b = Broker(tmp_path, port)
    b.start()
    return b


class FakeUsm:
    """Implements MqttHandler: records calls, answers with the AnswerBook rules."""

    def __init__(self, clock: ManualClock) -> None:
        self.clock = clock
        self.book = AnswerBook()
        self.measurements: list[Measurement] = []
        self.hazards: list[HazardReport] = []
        self.answers: list[PilotAnswer] = []
        self.outcomes: list[AnswerOutcome] = []
        self.plans: list[FlightPlanSubmission] = []
        self.statuses: list[FlightStatusReport] = []
        self.commands: list[OperatorCommandRequest] = []
        self.event = asyncio.Event()

    def _poke(self) -> None:
        self.event.set()

    async def on_measurement(self, m: Measurement) -> None:
        self.measurements.append(m)
        self._poke()

    async def on_hazard(self, h: HazardReport) -> None:
        self.hazards.append(h)
        self._poke()

    async def on_pilot_answer(self, a: PilotAnswer) -> AnswerOutcome:
        self.answers.append(a)
        outcome = self.book.answer(a, self.clock.now_s())
        self.outcomes.append(outcome)
        self._poke()
        return outcome

    async def on_flight_plan(self, s: FlightPlanSubmission) -> None:
        s.to_operation()  # raises ModelError on inconsistent values -> error topic
        self.plans.append(s)
        self._poke()

    async def on_flight_status(self, s: FlightStatusReport) -> None:
        self.statuses.append(s)
        self._poke()

    async def on_operator_command(self, c: OperatorCommandRequest) -> CommandAck:
        """Every command is carried out once per id (refused for a UAS named ``nope``)."""
        self.commands.append(c)
        self._poke()
        if c.uas == "nope":
            return CommandAck(
                request_id=c.request_id,
                uas=c.uas,
                command=c.command,
                outcome="refused",
                reason="unknown UAS 'nope'",
            )
        return CommandAck(
            request_id=c.request_id,
            uas=c.uas,
            command=c.command,
            outcome="confirmed",
            reason=f"vehicle reports {c.command}",
            mode=c.command,
        )

    async def wait_for(self, cond: Any, timeout_s: float = 5.0) -> None:
        async with asyncio.timeout(timeout_s):
            while not cond():
                self.event.clear()
                await self.event.wait()


@dataclass
class Peer:
    """A remote pilot station / stakeholder: an aiomqtt client that collects messages."""

    client: aiomqtt.Client
    inbox: asyncio.Queue[tuple[str, dict[str, Any], bool]] = field(default_factory=asyncio.Queue)

    failures: list[str] = field(default_factory=list)

    async def send(self, topic: str, obj: dict[str, Any] | bytes, qos: int = 1) -> None:
        payload = obj if isinstance(obj, bytes) else json.dumps(obj).encode()
        await self.client.publish(topic, payload, qos=qos)

    async def next(
        self, topic: str | None = None, timeout_s: float = 5.0
    ) -> tuple[str, dict[str, Any], bool]:
        """Next message (on ``topic`` if given; others are skipped), schema-validated."""
        try:
            async with asyncio.timeout(timeout_s):
                while True:
                    assert not self.failures, self.failures
                    t, obj, retained = await self.inbox.get()
                    if topic is None or t == topic:
                        return t, obj, retained
        except TimeoutError:
            raise AssertionError(
                f"nothing on {topic} within {timeout_s} s; failures: {self.failures}"
            ) from None

    def empty_for(self) -> list[tuple[str, dict[str, Any], bool]]:
        out = []
        while not self.inbox.empty():
            out.append(self.inbox.get_nowait())
        return out


@asynccontextmanager
async def peer(
    broker: Broker,
    user: str,
    subscribe: tuple[str, ...] = (),
    client_id: str | None = None,
    clean: bool = True,
) -> AsyncIterator[Peer]:
    client = aiomqtt.Client(
        "127.0.0.1",
        broker.port,
        username=user,
        password=USERS[user],
        identifier=client_id,
        clean_session=clean,
        timeout=5.0,
    )
    async with client:
        p = Peer(client)
        for f in subscribe:
            await client.subscribe(f, qos=1)

        async def pump() -> None:
            async for m in client.messages:
                raw = m.payload
                assert isinstance(raw, bytes | bytearray)
                try:
                    obj = json.loads(raw)
                    # every outgoing message must be valid JSON of its declared schema
                    validate(obj["type"], obj, str(m.topic))
                except Exception as exc:
                    p.failures.append(f"{m.topic}: {exc!r}: {raw[:200]!r}")
                    continue
                p.inbox.put_nowait((str(m.topic), obj, bool(m.retain)))

        task = asyncio.create_task(pump())
        try:
            yield p
        finally:
            task.cancel()
            with suppress(asyncio.CancelledError, aiomqtt.MqttError):
                await task
