"""EmergencyService on a ManualClock: order, answers, deadlines, failures, cancellation."""

from __future__ import annotations

import asyncio
from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.clock import ManualClock
from gcs_utm.core.emergency import Decision, EmergencyManager
from gcs_utm.model import (
    AirspaceSnapshot,
    OperationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
)
from gcs_utm.services.emergency import EmergencyService


class Harness:
    def __init__(self, snap: AirspaceSnapshot) -> None:
        self.clock = ManualClock(snap.t_s)
        self.snap = snap
        self.decisions: list[Decision] = []
        self.em: EmergencyManager = sc.build_manager()
        self.svc = EmergencyService(self.em, self.provider, self.clock, self.sink)

    def provider(self, t_s: float) -> AirspaceSnapshot:
        return replace(self.snap, t_s=t_s)

    async def sink(self, d: Decision) -> None:
        self.decisions.append(d)

    async def until(self, cond: object, steps: int = 2000) -> None:
        for _ in range(steps):
            if callable(cond) and cond():
                return
            await asyncio.sleep(0)
        raise AssertionError("condition not reached")


async def test_threat_answer_and_order() -> None:
    snap, threat = sc.scenario_los_2uas()
    h = Harness(snap)
    task = asyncio.create_task(h.svc.run())
    try:
        warn = Threat(
            id=ThreatId("w"),
            kind=ThreatKind.UAS_IN_CV,
            uas_ids=(OperationId("B"),),
            detected_at_s=snap.t_s,
        )
        await h.svc.submit_threats([threat, warn])
        await h.until(lambda: len(h.decisions) >= 2)
        assert h.decisions[0].recommendations and h.decisions[1].warnings  # in order
        (rec,) = h.svc.pending()
        await h.svc.submit_answer(rec.id, rec.version, True)
        await h.until(lambda: len(h.decisions) >= 3)
        assert h.decisions[2].recommendations[0].state is RecommendationState.ACCEPTED
        assert h.svc.pending() == []
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_deadline_expiry_on_the_clock_escalates_and_replans() -> None:
    snap, threat = sc.scenario_los_2uas()
    h = Harness(snap)
    task = asyncio.create_task(h.svc.run())
    try:
        await h.svc.submit_threats([threat])
        await h.until(lambda: any(d.escalations for d in h.decisions))
        expired = next(d for d in h.decisions if d.escalations)
        (old,) = [r for r in expired.recommendations if r.state is RecommendationState.EXPIRED]
        assert h.clock.now_s() >= old.deadline_t_s
        assert h.svc.pending(), "re-planned after the expiry"
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_failing_decision_becomes_an_escalation_and_the_loop_survives() -> None:
    snap, threat = sc.scenario_los_2uas()
    h = Harness(snap)

    calls: list[float] = []

    def broken(t_s: float) -> AirspaceSnapshot:
        calls.append(t_s)
        if len(calls) == 1:
            raise RuntimeError("store unavailable")
        return replace(snap, t_s=t_s)

    h.svc = EmergencyService(h.em, broken, h.clock, h.sink)
    task = asyncio.create_task(h.svc.run())
    try:
        await h.svc.submit_threats([threat])
        await h.until(lambda: len(h.decisions) >= 1)
        assert "store unavailable" in h.decisions[0].escalations[0]
        assert h.svc.failures == 1
        await h.svc.submit_threats([replace(threat, id=ThreatId("t2"))])
        await h.until(lambda: len(h.decisions) >= 2)
        assert h.decisions[1].recommendations
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_cancel_is_clean() -> None:
    snap, _ = sc.scenario_los_2uas()
    h = Harness(snap)
    task = asyncio.create_task(h.svc.run())
    await asyncio.sleep(0)
    task.cancel()
    results = await asyncio.gather(task, return_exceptions=True)
    assert isinstance(results[0], asyncio.CancelledError)
    assert [t for t in asyncio.all_tasks() if t is not asyncio.current_task()] == []


async def test_em_decides_nothing_for_a_threat_with_a_uas_on_the_ground() -> None:
    """A mission on a disarmed PX4 quad was timed as if flying now: the conflict was decided
    and both missions replaced before take-off (issue 31.2)."""
    snap, threat = sc.scenario_los_2uas()
    h = Harness(replace(snap, grounded=frozenset({OperationId("A")})))
    task = asyncio.create_task(h.svc.run())
    try:
        await h.svc.submit_threats([threat])
        await h.until(lambda: len(h.decisions) >= 1)
        (d,) = h.decisions
        assert d.recommendations == () and d.commands == ()
        assert [a.action for a in d.audit] == ["not_decided"]
        h.snap = replace(h.snap, grounded=frozenset(), airborne=frozenset({OperationId("A")}))
        await h.svc.submit_threats([replace(threat, updated_at_s=snap.t_s + 1.0)])
        await h.until(lambda: len(h.decisions) >= 2)
        assert h.decisions[1].recommendations  # airborne: decided as usual
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
