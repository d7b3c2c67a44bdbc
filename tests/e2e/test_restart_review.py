"""Restarts over the same store (issue 32 item 5): a life that dies (kill -9) closes nothing.
The next life reviews every threat an earlier life left open: the same condition detected
again adopts it (what was put in force stands, nothing is proposed twice), one not detected
again is closed; the audit says which. Several lives in a row, as the campaign's 10 kills."""

from __future__ import annotations

import asyncio
import dataclasses
import sys
import time
from pathlib import Path

from gcs_utm.app.restart import load_held, start_review
from gcs_utm.app.wiring import Persistence, Runtime, build_runtime
from gcs_utm.clock import RealClock
from gcs_utm.core.emergency import EmergencyConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.messages import HazardReport
from gcs_utm.model import RecommendationState, ThreatKind, ThreatStatus
from gcs_utm.services.usm import UsmConfig
from gcs_utm.settings import Settings
from gcs_utm.store import Store, StoreWriter

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "services"))
from usm_fakes import OP, FakeVehicles, make_operation

REVIEW_S = 0.6


async def _until(cond: object, timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not cond():  # type: ignore[operator]
        assert time.monotonic() < end, what
        await asyncio.sleep(0.02)


async def _life(db: Path, *, degraded: bool) -> int:
    """One life of the service on ``db``: GNSS degraded or not; ends without closing anything
    (as kill -9 does). Returns its epoch."""
    settings = dataclasses.replace(
        Settings(),
        emergency=EmergencyConfig(autonomous=True),  # decided = commanded at once
        usm=UsmConfig(restart_review_s=REVIEW_S),
    )
    frame = LocalFrame(40.0, -3.0, 600.0)
    store = Persistence(StoreWriter(db, settings.store))
    clock = RealClock()
    rt: Runtime = build_runtime(settings, clock, frame, store)
    with Store(db) as reader:
        rt.airspace.load(reader.load_operations(), reader.load_geofences(active_only=True))
    if not rt.airspace.operations:
        rt.airspace.add_operation(make_operation(clock.now_s()))
    rt.usm.attach_vehicles(FakeVehicles())
    held = load_held(db, store.epoch, 5.0)
    try:
        async with asyncio.TaskGroup() as tg:
            tasks = [
                tg.create_task(rt.emergency.run()),
                tg.create_task(rt.usm.run()),
                *start_review(tg, rt, db, cluster=False),
            ]
            if degraded:
                rt.usm.on_hazard(
                    HazardReport(
                        kind=ThreatKind.GNSS_DEGRADATION,
                        t_s=clock.now_s(),
                        operation_id=OP,
                        message="GNSS accuracy 14.0 m",
                    )
                )
            if held:
                review = next(t for t in tasks if t.get_name() == "restart-review")
                await asyncio.wait_for(review, 10.0)  # every held threat adopted or closed
            await _until(rt.emergency._queue.empty, 10.0, "EM busy")
            await asyncio.sleep(0.2)
            await rt.usm.drain()
            for t in tasks:
                t.cancel()
    finally:
        store.writer.flush()
        store.close()  # the writer's queue is flushed; nothing was closed on the way out
    return store.epoch


async def test_restarts_adopt_what_holds_close_what_does_not_and_propose_nothing_twice(
    tmp_path: Path,
) -> None:
    db = tmp_path / "utm.sqlite"
    epochs = [await _life(db, degraded=True)]
    with Store(db) as s:
        (first,) = s.load_threats()
        assert first.status is ThreatStatus.OPEN  # the dead life left it open
        recs = s.load_recommendations()
        assert len(recs) == 1 and recs[0].state is RecommendationState.ACCEPTED
    for _ in range(3):  # three restarts, the GNSS still degraded
        epochs.append(await _life(db, degraded=True))
    epochs.append(await _life(db, degraded=False))  # then healthy
    assert epochs == sorted(set(epochs))
    with Store(db) as s:
        threats = s.load_threats()
        recs = s.load_recommendations(latest_only=False)
        audit = s.load_audit()
    # no threat of a dead life stays open
    assert [t.id for t in threats if t.status is not ThreatStatus.CLOSED] == []
    assert len(threats) == 4  # one per degraded life, each adopted by the next
    # the safety decision of the first life was made once and never proposed again
    assert len(recs) == 1, [(r.id, r.version, r.state) for r in recs]
    adopted = [a for a in audit if a.action == "threat_adopted"]
    assert [a.detail["from"] for a in adopted] == [t.id for t in threats[:3]]
    assert all(a.detail["in_force"] == [f"{recs[0].id} v1 accepted"] for a in adopted)
    assert len([a for a in audit if a.actor == "EM" and a.action == "adopted"]) == 3
    closed = [a for a in audit if a.action == "threat_closed" and a.actor == "usm"]
    assert [a.subject for a in closed] == [threats[-1].id]
    assert "not detected again" in str(closed[0].detail["reason"])
    for t in threats[:3]:
        assert "adopted by" in t.message
