"""Issue 31 on real PX4 (v1.15.2 SIH): a reboot on the ground starts a new pre-flight, not an
emergency (ArduCopter: test_ground_reboot.py).

A PX4 quad with a mission sits disarmed beside ``gcs-utm serve --headless --auto-accept``. Its
process is stopped and started again at once on the same working directory (parameters and
mission kept, as a power cycle). Its positions stop until the new boot's estimator has a
position (~30 simulated seconds): on the ground that silence is a pre-flight finding. The
reboot is seen (``sysid 1: rebooted``, at the new boot's first HEARTBEAT: MAV_STATE_UNINIT),
the home is taken again from the new boot, and no threat is raised from the vehicle, no
recommendation made and no mode set on it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SITL_ROOT, SitlProcess
from tests.autopilot.closed_loop import Crossing, _config, _wait_operations, rows
from tests.autopilot.pilot import PilotLink, mission_items

SPEED = 4.0
AUTO_MISSION = (4 << 16) | (4 << 24)  # PX4 custom mode: main AUTO, sub MISSION
AFTER_S = 5.0  # wall seconds watched after the new home: 20 simulated
VEHICLE_KINDS = {"GNSS_DEGRADATION", "JAMMING_ATTACK", "LACK_OF_BATTERY", "COMMUNICATION_FAILURE"}


def _log_after(path: Path, marker: str, text: str) -> bool:
    """Whether ``text`` is in the log at ``path`` after its first ``marker``."""
    log = path.read_text(errors="replace")
    at = log.find(marker)
    return at >= 0 and text in log[at + len(marker) :]


@pytest.mark.timeout(240)
def test_a_rebooted_px4_on_the_ground_starts_a_new_preflight(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    lat0, lon0, ground = PX4_DEFAULT_HOME
    crossing = Crossing(origin=(lat0, lon0), ground_amsl_m=ground)
    # kept across the restart, outside /tmp (PX4 runs with a private /tmp)
    workdir = SITL_ROOT / f"gcs-utm-px4-reboot-{os.getpid()}" / "px4-w"
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, ["udpin:127.0.0.1:14550"])
    serve: subprocess.Popen[bytes] | None = None
    pilot: PilotLink | None = None
    modes: list[int] = []
    try:
        with log_path.open("wb") as log:
            serve = subprocess.Popen(
                [sys.executable, "-m", "gcs_utm", "-v", "serve", "--headless",
                 "--auto-accept", "--config", str(cfg), "--db", str(db),
                 "--speed", str(SPEED)],
                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            )  # fmt: skip
        p = px4(instance=0, speed=SPEED, workdir=workdir)
        pilot = PilotLink(0)
        pilot.wait_ready()
        assert pilot.home is not None
        alt = pilot.home[2] + 30.0
        _upload(pilot, mission_items(1, (lat0, lon0), [(lat0 + 0.001, lon0, alt)]))
        _wait_operations(db, 1, 40.0, serve)
        # power cycle: the same working directory (parameters, mission)
        pilot.close()
        p.stop()
        # started again at once: its first position comes when its new clock may be past
        # the old one, after a silence no longer than its new uptime; its first HEARTBEATs
        # (MAV_STATE_UNINIT, a boot) tell the two lives apart
        px4(instance=0, speed=SPEED, workdir=workdir)
        pilot = PilotLink(0)
        reboot = "sysid 1: rebooted"
        end = time.monotonic() + 60.0  # heard again, then its fix and home (~10 s wall)
        while not _log_after(log_path, reboot, "sysid 1: home "):
            assert time.monotonic() < end, (
                "no reboot, or no home after it:\n" + log_path.read_text(errors="replace")[-3000:]
            )
            modes += _modes(pilot.poll(0.5))
        end = time.monotonic() + AFTER_S
        while time.monotonic() < end:
            modes += _modes(pilot.poll(0.5))
        assert serve.poll() is None, "gcs-utm serve exited"
    except (AssertionError, TimeoutError) as exc:
        tail = log_path.read_text(errors="replace")[-4000:]
        raise AssertionError(f"{exc}\n--- gcs-utm serve log\n{tail}") from exc
    finally:
        if pilot is not None:
            pilot.close()
        if serve is not None and serve.poll() is None:
            serve.terminate()
            serve.wait(timeout=30)
        shutil.rmtree(workdir.parent, ignore_errors=True)
    text = log_path.read_text(errors="replace")
    tail = text[-4000:]
    kinds = [str(r[0]) for r in rows(db, "SELECT kind FROM threats")]
    assert not VEHICLE_KINDS & set(kinds), f"emergency on the ground: {kinds}\n{tail}"
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for a quad on the ground: {recs}\n{tail}"
    assert modes and AUTO_MISSION not in modes, f"mission mode set on the ground\n{tail}"
    # seen by its first HEARTBEAT (MAV_STATE_UNINIT), not by its clock: a PX4 heard again
    # at once may show a clock near the old one at its first position (docs/vehicle-time.md)
    assert "rebooted (system_status 3 -> 0)" in text, tail
    # the silence was noticed (no positions until the new boot's estimator has a fix, ~30
    # simulated seconds): a pre-flight finding, not a link loss of the airspace
    assert "sys1 on the ground: COMMUNICATION_FAILURE" in text, tail


def _modes(msgs: list[object]) -> list[int]:
    """PX4's custom modes in its HEARTBEATs among ``msgs``."""
    return [
        int(m.custom_mode)  # type: ignore[attr-defined]
        for m in msgs
        if m.get_type() == "HEARTBEAT" and m.autopilot != 8  # type: ignore[attr-defined]
    ]


def _upload(pilot: PilotLink, items: list[object], tries: int = 3) -> None:
    """Upload ``items``, again when PX4 did not answer (busy with serve's download of its
    mission on the other link, or a datagram lost on a loaded machine)."""
    for k in range(tries):
        try:
            pilot.upload(items)
            return
        except TimeoutError:
            if k == tries - 1:
                raise
