"""``serve`` after a restart: the review of the threats earlier lives left open
(:mod:`gcs_utm.services.restart_review`), wired to this life's store, USM, EM and tracking."""

from __future__ import annotations

import asyncio
from pathlib import Path

from gcs_utm.model import Recommendation, Threat, ThreatId, TrackId
from gcs_utm.services.restart_review import (
    ACTOR,
    Held,
    RestartReview,
    ReviewPorts,
    held_threats,
)
from gcs_utm.store import open_store

from .wiring import Runtime

_PERIOD_S = 0.5


def load_held(location: str | Path, epoch: int, busy_timeout_s: float) -> list[Held]:
    """The threats the lives before ``epoch`` left open, with their latest recommendations
    and the active geofences their cases created."""
    with open_store(location, readonly=True, busy_timeout_s=busy_timeout_s) as reader:
        threats = reader.open_threats_of_earlier_lives(epoch)
        if not threats:
            return []
        recs = reader.load_recommendations()
        fences = reader.load_geofences(active_only=True)
        adopted = {
            a.subject: str(a.detail.get("from"))
            for a in reader.load_audit()
            if a.actor == ACTOR and a.action == "threat_adopted"
        }
    return held_threats(threats, recs, fences, adopted)


def attach_restart_review(rt: Runtime, held: list[Held]) -> RestartReview | None:
    """The review of ``held`` for this runtime (None when there is nothing to review): it
    sees the USM's threats ahead of EM and hands EM the cases it adopts."""
    if not held:
        return None
    writer = rt.store.writer
    tracker = rt.tracker

    def settle(item: Threat | Recommendation) -> None:
        writer.submit(lambda s: s.settle_inherited(item))

    def adopt(new_id: ThreatId, h: Held) -> None:
        rt.emergency.adoptions[new_id] = (h.threat, h.recommendations, h.geofences)

    ports = ReviewPorts(
        settle=settle,
        record=rt.store.record,
        log_event=rt.usm.log_event,
        remove_geofences=rt.usm.remove_geofences,
        raise_hazard=rt.usm.on_hazard,
        operation=rt.usm.operation_or_none,
        last_position_t_s=lambda op_id: tracker.last_accepted_t_s(TrackId(op_id)),
        adopt=adopt,
    )
    review = RestartReview(
        held, ports, started_s=rt.clock.now_s(), review_s=rt.settings.usm.restart_review_s
    )
    rt.usm.attach_threat_sink(review.on_threats, first=True)
    return review


def start_review(
    tg: asyncio.TaskGroup, rt: Runtime, location: str | Path, *, cluster: bool
) -> list[asyncio.Task[None]]:
    """The review's task for the store at ``location`` (none when nothing is held, or for a
    cluster member: its other lives are other instances, alive), attached before any threat
    arrives (call it before the service's tasks first run)."""
    if cluster:
        return []
    held = load_held(location, rt.store.epoch, rt.settings.store.busy_timeout_s)
    review = attach_restart_review(rt, held)
    if review is None:
        return []
    return [tg.create_task(run_review(rt, review), name="restart-review")]


async def run_review(rt: Runtime, review: RestartReview) -> None:
    """Start the review, then check it until every held threat is adopted or closed."""
    await review.start(rt.clock.now_s())
    while not review.done():
        await review.check(rt.clock.now_s())
        await rt.clock.sleep(_PERIOD_S)
