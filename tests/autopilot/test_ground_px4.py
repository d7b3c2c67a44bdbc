"""Issue 31 items 2 and 3 on real PX4: nothing is decided for vehicles on the ground.

Two PX4 SIH quads boot beside a running ``gcs-utm serve --headless --auto-accept`` and their
pilots upload crossing missions without arming. Before the fix the missions were timed as if
flying now, the crossing was predicted, both missions were replaced before take-off and
AUTO.MISSION was set on the disarmed quads. Now: each operation is filed from the whole
mission with the home PX4 reports after its 3D fix, and for ~60 simulated seconds (the
crossing's time on the filed plans) no recommendation is made, no mission replaced, and
PX4's mode stays the pilot's. A vehicle on the ground is not traffic: Monitoring does not
predict the crossing of the filed missions at all (no LOSS_OF_SEPARATION threat).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.autopilot.autopilots import PX4_DEFAULT_HOME, SitlProcess
from tests.autopilot.closed_loop import (
    Crossing,
    _config,
    _total,
    _wait_operations,
    rows,
    serve_process,
)
from tests.autopilot.pilot import PilotLink, mission_items

SPEED = 4.0
AUTO_MISSION = (4 << 16) | (4 << 24)  # PX4 custom mode: main AUTO, sub MISSION
WATCH_S = 16.0  # wall seconds after filing: 64 simulated, past the filed crossing (~44 s)


@pytest.mark.timeout(240)
def test_disarmed_px4_quads_with_crossing_missions_get_no_decision(
    px4: Callable[..., SitlProcess], tmp_path: Path
) -> None:
    crossing = Crossing(origin=PX4_DEFAULT_HOME[:2], ground_amsl_m=PX4_DEFAULT_HOME[2])
    db, log_path = tmp_path / "store.sqlite", tmp_path / "serve.log"
    cfg = _config(tmp_path / "serve.toml", crossing, ["udpin:127.0.0.1:14550"])
    pilots: list[PilotLink] = []
    modes: list[int] = []
    try:
        with serve_process(cfg, db, log_path, SPEED) as serve:
            # serve hears PX4 from its boot: HOME_POSITION before the fix included
            for i, home in enumerate(crossing.starts()):
                px4(instance=i, airframe="quad", home=home, speed=SPEED)
            pilots = [PilotLink(0), PilotLink(1)]
            for p in pilots:
                p.wait_ready()
            for p, start, end in zip(pilots, crossing.starts(), crossing.ends(), strict=True):
                assert p.home is not None
                alt = crossing.cruise_agl_m + p.home[2]
                p.upload(mission_items(p.sys_id, start, [(*start, alt), (*end, alt)]))
            for p in pilots:
                p.poll(1.0)
            before = [_total(p) for p in pilots]
            _wait_operations(db, 2, 40.0, serve)
            end_t = time.monotonic() + WATCH_S
            while time.monotonic() < end_t:
                for p in pilots:
                    modes += [
                        int(m.custom_mode)
                        for m in p.poll(0.05)
                        if m.get_type() == "HEARTBEAT" and m.autopilot != 8
                    ]
    finally:
        for p in pilots:
            p.close()
    text = log_path.read_text(errors="replace")
    tail = text[-4000:]
    recs = rows(db, "SELECT state FROM recommendations")
    assert recs == [], f"recommendations for vehicles on the ground: {recs}\n{tail}"
    assert [_total(p) for p in pilots] == before, f"a mission was replaced\n{tail}"
    assert modes and AUTO_MISSION not in modes, f"mission mode set on the ground\n{tail}"
    filed = rows(db, "SELECT operation_id FROM flight_plans WHERE version = 1")
    assert len(filed) == 2, filed
    # a vehicle on the ground is not traffic: the crossing of the filed missions is not
    # even predicted (no threat, so nothing to leave undecided)
    threats = rows(db, "SELECT id FROM threats WHERE kind = 'LOSS_OF_SEPARATION'")
    assert threats == [], f"loss of separation predicted on the ground: {threats}\n{tail}"
    for sys_id in (1, 2):  # the home is the one after the fix
        fix = text.find(f"sysid {sys_id}: fix")
        home = text.find(f"sysid {sys_id}: home ")
        assert 0 <= fix < home, f"sysid {sys_id}: home before its fix\n{tail}"
