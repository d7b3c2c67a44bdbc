"""The review of the threats earlier lives left open (gcs_utm.services.restart_review) with
fake ports: pending proposals superseded at once, a threat of an operation that ended closed
at once, the same condition adopted, a link loss of a UAS still silent raised again (and of
one heard again closed), the rest closed after the review, each with its geofences."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from gcs_utm.messages import HazardReport
from gcs_utm.model import (
    AuditEntry,
    Command,
    CommandKind,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    OperationId,
    OperationState,
    Recommendation,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)
from gcs_utm.services.restart_review import Held, RestartReview, ReviewPorts, held_threats

sys.path.insert(0, str(Path(__file__).resolve().parent))
from usm_fakes import make_operation

T0 = 1000.0
A, B = OperationId("A"), OperationId("B")


def _threat(tid: str, kind: ThreatKind, uas: OperationId) -> Threat:
    return Threat(id=ThreatId(tid), kind=kind, uas_ids=(uas,), detected_at_s=T0 - 50.0)


def _rec(threat: Threat, state: RecommendationState) -> Recommendation:
    op = threat.uas_ids[0]
    return Recommendation(
        id=RecommendationId(f"{threat.id}/{op}"),
        version=1,
        threat_id=threat.id,
        threat_kind=threat.kind,
        operation_id=op,
        created_t_s=T0 - 49.0,
        deadline_t_s=T0 - 30.0,
        command=Command(kind=CommandKind.LAND, operation_id=op),
        state=state,
    )


def _fence(gid: str) -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=100.0,
        center=LatLon(lat_deg=40.0, lon_deg=-3.0),
        radius_m=50.0,
    )


class _Ports:
    def __init__(self) -> None:
        self.settled: list[Threat | Recommendation] = []
        self.recorded: list[object] = []
        self.removed: list[GeofenceId] = []
        self.hazards: list[HazardReport] = []
        self.adopted: dict[ThreatId, Held] = {}
        base = make_operation(T0)
        self.ops = {
            A: replace(base, id=A, plan=replace(base.plan, operation_id=A)),
            B: replace(base, id=B, plan=replace(base.plan, operation_id=B)),
        }
        self.positions: dict[OperationId, float] = {}

    async def remove(self, ids: Sequence[GeofenceId]) -> None:
        self.removed.extend(ids)

    def ports(self) -> ReviewPorts:
        return ReviewPorts(
            settle=self.settled.append,
            record=self.recorded.append,
            log_event=lambda _k, _t: None,
            remove_geofences=self.remove,
            raise_hazard=self.hazards.append,
            operation=self.ops.get,
            last_position_t_s=self.positions.get,
            adopt=self.adopted.__setitem__,
        )

    def reasons(self) -> dict[str, str]:
        return {
            a.subject: str(a.detail["reason"])
            for a in self.recorded
            if isinstance(a, AuditEntry) and a.action == "threat_closed"
        }


async def test_the_review_adopts_relays_and_closes() -> None:
    gnss = _threat("E1-gnss_degradation-1", ThreatKind.GNSS_DEGRADATION, A)
    lost = _threat("E1-communication_failure-2", ThreatKind.COMMUNICATION_FAILURE, A)
    heard = _threat("E1-communication_failure-3", ThreatKind.COMMUNICATION_FAILURE, B)
    ended = _threat("E1-lack_of_battery-4", ThreatKind.LACK_OF_BATTERY, B)
    gone = _threat("E1-T1-CONF", ThreatKind.UAS_OUT_OV, A)
    applied, pending = (
        _rec(gnss, RecommendationState.APPLIED),
        _rec(gone, RecommendationState.PROPOSED),
    )
    fences = [_fence(f"em-{lost.id}-A"), _fence("em-E0-other-A")]
    held = held_threats([gnss, lost, heard, ended, gone], [applied, pending], fences, {})
    f = _Ports()
    f.ops[B] = replace(f.ops[B], state=OperationState.ENDED)
    review = RestartReview(held, f.ports(), started_s=T0, review_s=10.0)
    await review.start(T0)
    # a pending proposal of the dead life: superseded; the ended operation's threats: closed
    (sup,) = [x for x in f.settled if isinstance(x, Recommendation)]
    assert sup.id == pending.id and sup.state is RecommendationState.SUPERSEDED
    assert f.reasons() == {heard.id: "operation B ended", ended.id: "operation B ended"}
    # the same condition again: adopted, with what was in force
    new = replace(gnss, id=ThreatId("E2-gnss_degradation-1"), detected_at_s=T0 + 2.0)
    await review.on_threats([new])
    assert f.adopted[new.id].threat == gnss and f.adopted[new.id].recommendations == (applied,)
    closed = {x.id: x for x in f.settled if isinstance(x, Threat)}
    assert closed[gnss.id].status is ThreatStatus.CLOSED and "adopted by" in closed[gnss.id].message
    # end of the review: A is still silent, its link loss is raised again; the rest closed
    await review.check(T0 + 11.0)
    (h,) = f.hazards
    assert h.kind is ThreatKind.COMMUNICATION_FAILURE and h.operation_id == A
    await review.on_threats([replace(lost, id=ThreatId("E2-communication_failure-1"))])
    assert f.adopted[ThreatId("E2-communication_failure-1")].geofences == (fences[0],)
    await review.check(T0 + 11.5)
    assert "not detected again" in f.reasons()[gone.id]
    assert review.done() and f.removed == []  # the adopted fence stays (EM's case has it)


async def test_a_link_loss_heard_again_is_closed_and_its_fence_removed() -> None:
    lost = _threat("E1-communication_failure-1", ThreatKind.COMMUNICATION_FAILURE, A)
    fence = _fence(f"em-{lost.id}-A")
    f = _Ports()
    review = RestartReview(
        held_threats([lost], [], [fence], {}), f.ports(), started_s=T0, review_s=5.0
    )
    await review.start(T0)
    f.positions[A] = T0 + 1.0
    await review.check(T0 + 6.0)
    assert f.hazards == []
    await review.check(T0 + 6.5)
    assert "not detected again" in f.reasons()[lost.id] and f.removed == [fence.id]


def test_held_threats_follow_adoption_chains() -> None:
    first = _threat("E1-gnss_degradation-1", ThreatKind.GNSS_DEGRADATION, A)
    third = _threat("E3-gnss_degradation-1", ThreatKind.GNSS_DEGRADATION, A)
    rec = _rec(first, RecommendationState.APPLIED)
    chain = {"E3-gnss_degradation-1": "E2-gnss_degradation-1", "E2-gnss_degradation-1": first.id}
    (h,) = held_threats([third], [rec], [], chain)
    assert h.recommendations == (rec,)
