"""``gcs-utm pilot`` end to end: the command run as a subprocess (stdin piped) against a real
mosquitto (tests/mqtt/mqtt_helpers: password file + the gcs-utm ACL) and the real USM behind
the MQTT gateway with a fake vehicle port. It shows the recommendation, the pilot types
``a 0``, gcs-utm accepts it, uploads the plan and reports it applied; end of input exits 0."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "mqtt"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))

from mqtt_helpers import USERS, Broker, make_broker
from usm_fakes import OP, FakeVehicles, make_operation, make_plan

from gcs_utm.clock import ManualClock
from gcs_utm.model import (
    Alternative,
    Maneuver,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.mqtt_gateway import MqttGateway
from gcs_utm.services.usm import Usm

pytestmark = [pytest.mark.mqtt, pytest.mark.network]


def _rec(t0: float) -> Recommendation:
    up = Alternative(
        operation_id=OP,
        maneuver=Maneuver.GO_UP,
        plan=make_plan(2, t0 + 10),
        cost=0.25,
        risk=0.1,
        detail="climb; cost=0.25, risk=0.1, extra_distance_m=40.0, extra_time_s=6.5, "
        "min_separation_ratio=1.8",
        extra_length_m=40.0,
        extra_time_s=6.5,
        offset_m=30.0,
        separation_ratio=1.8,
    )
    hold = Alternative(operation_id=OP, maneuver=Maneuver.HOLD, plan=None, cost=0.5, risk=0.05)
    return Recommendation(
        id=RecommendationId("r1"),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=t0,
        deadline_t_s=t0 + 120.0,
        selected=up,
        alternatives=(hold,),
    )


class _Pilot:
    """The ``gcs-utm pilot`` subprocess: its stdout lines as they come."""

    def __init__(self, proc: asyncio.subprocess.Process) -> None:
        self.proc = proc
        self.out: list[str] = []

    async def until(self, text: str, timeout_s: float = 8.0) -> str:
        """The first line (from the start) containing ``text``."""
        assert self.proc.stdout is not None
        async with asyncio.timeout(timeout_s):
            while True:
                for line in self.out:
                    if text in line:
                        return line
                raw = await self.proc.stdout.readline()
                if not raw:
                    raise AssertionError(f"pilot exited before {text!r}: {self.out}")
                self.out.append(raw.decode().rstrip("\n"))

    async def type(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(line.encode() + b"\n")
        await self.proc.stdin.drain()


async def _exit_code(pilot: _Pilot, *, within_s: float) -> int:
    """The pilot's exit code; if it has not exited within ``within_s``, its threads' stacks
    (faulthandler, on SIGABRT) and its output go into the failure."""
    try:
        async with asyncio.timeout(within_s):
            return await pilot.proc.wait()
    except TimeoutError:
        pilot.proc.send_signal(signal.SIGABRT)
        assert pilot.proc.stdout is not None
        rest = await pilot.proc.stdout.read()
        await pilot.proc.wait()
        raise AssertionError(
            f"the pilot did not exit within {within_s} s of Ctrl-C; its output and stacks:\n"
            + "\n".join(pilot.out)
            + "\n"
            + rest.decode(errors="replace")
        ) from None


def _ctrl_c_as_at_a_prompt() -> None:
    """In the pilot's process before it starts: SIGINT as a pilot at a shell prompt has it.
    A non-interactive shell starts its background jobs with SIGINT ignored, and children
    inherit that (CI runs the suite's steps as such jobs, tests/check.sh): Python then
    leaves SIGINT ignored, so Ctrl-C never reached the pilot and the test hung."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@contextlib.asynccontextmanager
async def _pilot(broker: Broker, tmp_path: Path) -> AsyncIterator[_Pilot]:
    cfg = tmp_path / "pilot.toml"
    cfg.write_text(
        "[mqtt]\n"
        f'host = "127.0.0.1"\nport = {broker.port}\n'
        f'username = "alice"\npassword = "{USERS["alice"]}"\n'
        "backoff_initial_s = 0.05\nbackoff_max_s = 0.5\n"
    )
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "gcs_utm.cli",
        "pilot",
        "--operator",
        "alice",
        "--config",
        str(cfg),
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        env={**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONFAULTHANDLER": "1"},
        preexec_fn=_ctrl_c_as_at_a_prompt,
    )
    try:
        yield _Pilot(proc)
    finally:
        if proc.returncode is None:
            proc.kill()
            await proc.wait()


async def test_pilot_command_accepts_option_0_and_gcs_utm_applies_it(tmp_path: Path) -> None:
    broker = make_broker(tmp_path)
    # real time: the pilot's answer carries its wall-clock time, checked against the deadline
    t0 = time.time()
    clock = ManualClock(t0)
    airspace = Airspace()
    airspace.load([make_operation(t0, operator="alice")], ())
    usm = Usm(airspace, clock)
    vehicles = FakeVehicles()
    usm.attach_vehicles(vehicles)
    gateway = MqttGateway(usm, broker.config())
    gateway.attach()
    task = asyncio.create_task(gateway.run())
    try:
        await gateway.bridge.wait_connected(5.0)
        async with _pilot(broker, tmp_path) as pilot:
            await pilot.until("connected to")  # subscribed: nothing published is missed
            await usm.on_recommendation(_rec(t0))
            await pilot.until("recommendation r1 v1 for UAS UAS1: loss of separation")
            line0 = await pilot.until("[0] ")
            assert "Climb up to 30 m above the plan: 6 s and 40 m more flight" in line0
            assert "(proposed)" in line0
            assert "Hold at the current position" in await pilot.until("[1] ")
            await pilot.until("deadline ")
            await pilot.type("x")  # bad input: one line saying what is accepted
            assert "a N (accept option N)" in await pilot.until("is not an answer")
            await pilot.type("details")  # the raw figures, on request
            assert "+40 m, +6.5 s, min separation 1.80x" in await pilot.until("[go up, ")
            await pilot.type("a 0")
            await pilot.until("gcs-utm accepted the answer to recommendation r1 v1")
            await pilot.until("recommendation r1 v1 is now applied")
            assert pilot.proc.stdin is not None
            pilot.proc.stdin.close()  # Ctrl-D
            async with asyncio.timeout(5.0):
                assert await pilot.proc.wait() == 0
            await pilot.until("pilot station stopped")
            assert not [line for line in pilot.out if "Traceback" in line], pilot.out
        record = usm.recommendations[RecommendationId("r1")]
        assert record.rec.state is RecommendationState.APPLIED
        assert record.answered_by == "alice" and record.chosen_index is None
        assert len(vehicles.uploads) == 1
        assert usm.airspace.operation(OP).plan.version == 2  # the proposed climb
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        await usm.drain()
        await usm.close()
        broker.stop()


def test_pilot_help_imports_no_mqtt_client_or_app() -> None:
    code = (
        "import sys\n"
        "from gcs_utm.cli import main\n"
        "try:\n"
        "    main(['pilot', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "print('IMPORTED', *(m for m in ('aiomqtt', 'numpy', 'gcs_utm.app', "
        "'adapters.mqtt.station') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "--operator OPERATOR" in out.stdout
    assert out.stdout.splitlines()[-1] == "IMPORTED"


async def test_sigint_exits_cleanly_while_the_broker_is_unreachable(tmp_path: Path) -> None:
    broker = make_broker(tmp_path)
    broker.stop()  # its port is free: nothing listens
    async with _pilot(broker, tmp_path) as pilot:
        await pilot.until("cannot connect to the MQTT broker")
        pilot.proc.send_signal(signal.SIGINT)  # Ctrl-C
        # Bounded, with room for a loaded machine: the exit also joins a connection attempt
        # still running in an executor thread (the MQTT client connects on one).
        assert await _exit_code(pilot, within_s=15.0) == 0
        await pilot.until("pilot station stopped")
        assert not [line for line in pilot.out if "Traceback" in line], pilot.out
