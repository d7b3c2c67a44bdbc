"""MAVLink 2 signing on a sitl vehicle with a key (as PX4 MAV_SIGN_CFG / ArduPilot signing),
checked with raw pymavlink from the test side: only correctly signed messages are obeyed
(RADIO_STATUS may be unsigned), the rest is counted, and everything the vehicle sends is signed
with its key."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import pytest

import sitl
from sitl.fleetfile import FleetFileError, load_fleet
from tests.sitl.conftest import RawGcs, mav, px4_spec

KEY = bytes(range(32))
WRONG = bytes(range(1, 33))
EPOCH = 1420070400.0


def _signer(key: bytes) -> Any:
    m = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    m.signing.secret_key = key
    m.signing.sign_outgoing = True
    m.signing.timestamp = int((time.time() - EPOCH) * 100_000)
    return m


def _hold(m: Any) -> bytes:
    # PX4 AUTO.LOITER through DO_SET_MODE
    msg = m.command_long_encode(1, 1, mav.MAV_CMD_DO_SET_MODE, 0, 1, 4, 3, 0, 0, 0, 0)
    return bytes(msg.pack(m))


async def test_signed_vehicle_obeys_only_signed_commands(gcs: RawGcs) -> None:
    spec = px4_spec(gcs.port, signing_key=KEY.hex())
    checker = mav.MAVLink(None)
    checker.signing.secret_key = KEY  # verifies every frame: unsigned or forged ones fail
    async with sitl.Fleet([spec], sitl.SimTime(speed=4.0)) as fleet:
        v = fleet.vehicles[0]
        await gcs.wait_type("HEARTBEAT", start=0)
        await asyncio.sleep(0.3)
        # every frame from the vehicle carries a signature that verifies with the key
        assert len(gcs.msgs) > 5
        for m in gcs.msgs:
            (checked,) = checker.parse_buffer(bytes(m.get_msgbuf()))
            assert checked._signed, m.get_type()
        assert checker.signing.goodsig_count == len(gcs.msgs)
        # unsigned command: ignored, no COMMAND_ACK, counted by message
        gcs.raw(v.local_port, _hold(gcs.enc))
        with pytest.raises(TimeoutError):
            await gcs.wait_type("COMMAND_ACK", timeout=0.5)
        assert v.counters["rejected_unsigned"] == 1
        assert v.rejected_messages == {"COMMAND_LONG": 1}
        assert v.counters["commands"] == 0
        # signed with another key: ignored, counted as a bad signature
        gcs.raw(v.local_port, _hold(_signer(WRONG)))
        with pytest.raises(TimeoutError):
            await gcs.wait_type("COMMAND_ACK", timeout=0.5)
        assert v.counters["rejected_bad_signature"] == 1
        assert v.rejected_messages == {"COMMAND_LONG": 2}
        # RADIO_STATUS may come unsigned (MAVLink spec): accepted, not counted as rejected
        before = v.counters["rx_messages"]
        gcs.send(v.local_port, gcs.enc.radio_status_encode(200, 190, 100, 50, 40, 0, 0))
        await asyncio.sleep(0.2)
        assert v.counters["rx_messages"] == before + 1
        assert v.counters["rejected_unsigned"] == 1
        # correctly signed: obeyed, and the answer is signed too
        good = _signer(KEY)
        gcs.raw(v.local_port, _hold(good))
        ack = await gcs.wait_type("COMMAND_ACK", timeout=2.0, command=mav.MAV_CMD_DO_SET_MODE)
        assert ack.result == mav.MAV_RESULT_ACCEPTED
        (checked,) = checker.parse_buffer(bytes(ack.get_msgbuf()))
        assert checked._signed
        assert v.counters["commands"] == 1
        # a replay of an already seen signed frame (same timestamp) is rejected
        replay = _hold(good)
        gcs.raw(v.local_port, replay)
        await gcs.wait_type("COMMAND_ACK", timeout=2.0, command=mav.MAV_CMD_DO_SET_MODE)
        gcs.raw(v.local_port, replay)
        await asyncio.sleep(0.3)
        assert v.counters["rejected_bad_signature"] == 2
        assert v.counters["commands"] == 2


@pytest.mark.parametrize(
    ("value", "words"),
    [("abc", "64 hex digits"), ("00" * 31, "31 bytes"), (12, "string")],
)
def test_bad_signing_key_is_refused(value: object, words: str) -> None:
    with pytest.raises(ValueError, match="signing_key") as ei:
        sitl.VehicleSpec(instance=0, signing_key=value)  # type: ignore[arg-type]
    assert words in str(ei.value)


def test_fleet_file_signing_key(tmp_path: Path) -> None:
    p = tmp_path / "fleet.toml"
    p.write_text(f'[[vehicle]]\ninstance = 0\nsigning_key = "{KEY.hex()}"\n')
    (spec,), _, _ = load_fleet(p)
    assert spec.signing_key_bytes() == KEY
    p.write_text('[[vehicle]]\ninstance = 0\nsigning_key = "zz"\n')
    with pytest.raises(FleetFileError, match="signing_key"):
        load_fleet(p)
