"""``run --fly`` is only valid with ``--external`` (the built-in vehicles fly the plans)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from gcs_utm.app import RunOptions


def test_fly_without_external_is_refused() -> None:
    with pytest.raises(ValueError, match="fly makes external autopilots fly"):
        RunOptions(fly=True)
    assert RunOptions(fly=True, external=True, speed=4.0).fly


def test_cli_fly_without_external_is_one_clear_error() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "gcs_utm", "run", "config/scenarios/use_case_1.toml", "--fly",
         "--auto-accept", "--headless"],
        capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL, check=False,
    )  # fmt: skip
    assert run.returncode == 2
    assert "fly makes external autopilots fly the plans" in run.stderr
    assert "Traceback" not in run.stderr


async def test_a_fly_step_is_sent_again_while_the_vehicle_stays_silent() -> None:
    """A loaded autopilot can miss every resend of one COMMAND_LONG: the step (mission mode,
    take-off, ...) is sent again, and only a refusal or lasting silence fails the flight."""
    from adapters.mavlink.transfer import CommandResult
    from gcs_utm.app.fly import SILENT_TRIES, FlyRefusedError, _answered

    silent = CommandResult(ok=False, result=None, attempts=4, error="no COMMAND_ACK")
    answers = [silent, silent, CommandResult(ok=True, result=0, attempts=1)]
    sent: list[int] = []

    async def send() -> CommandResult:
        sent.append(1)
        return answers[len(sent) - 1]

    await _answered(send, "mission mode")
    assert len(sent) == 3 <= SILENT_TRIES

    refused = CommandResult(ok=False, result=4, attempts=1, error="MAV_RESULT_FAILED")
    sent.clear()
    answers[:] = [refused, silent, silent]
    with pytest.raises(FlyRefusedError, match="mission mode refused: MAV_RESULT_FAILED"):
        await _answered(send, "mission mode")
    assert len(sent) == 1  # a refusal is final

    sent.clear()
    answers[:] = [silent] * SILENT_TRIES
    with pytest.raises(FlyRefusedError, match="take-off refused: no COMMAND_ACK"):
        await _answered(send, "take-off")
    assert len(sent) == SILENT_TRIES
