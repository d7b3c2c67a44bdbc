"""What a restarted service does with the threats its previous lives left open.

A process killed with -9 closes nothing: its open threats stayed open in the store forever,
and every new life detected the same GNSS degradation again and proposed (and, with
auto-accept, applied) the same safety command again. At start the new life holds every threat
an earlier life left open (OPEN or UPDATED) and reviews it:

- **adopted**: the new life detects the same condition again (same kind, same UAS, same
  intruder) under a new id. The old threat is closed "adopted by <new id>", and EM takes
  its case over (:mod:`gcs_utm.core.emergency.adoption`): what it put in force (accepted or
  applied recommendations, its dynamic geofences) stands and nothing is proposed again.
  A link loss cannot be detected again by a tracker that never heard the vehicle: a UAS
  with no position since the restart gets its COMMUNICATION_FAILURE raised again at the end
  of the review, which is then adopted the same way.
- **closed**: not detected again within ``review_s`` of the start, or its operation is gone,
  landed or ended: closed with that reason, and the geofences its case created removed.

A recommendation an earlier life was still waiting an answer for (PROPOSED) is superseded at
once: its prompt died with that process (the threat, if it holds, gets a new decision).
Every step is audited (actor ``usm``: ``restart_review``, ``threat_adopted``,
``threat_closed``). The store's rows of an earlier life change only through
``settle_inherited`` (closing a threat, superseding a pending version).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass, replace

from gcs_utm.core.emergency.adoption import IN_FORCE
from gcs_utm.messages import HazardReport
from gcs_utm.model import (
    AuditEntry,
    Geofence,
    GeofenceId,
    Operation,
    OperationId,
    OperationState,
    Recommendation,
    RecommendationState,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)

ACTOR = "usm"


@dataclass(frozen=True, slots=True)
class Held:
    """An earlier life's open threat under review: its latest recommendations and the active
    geofences its case created."""

    threat: Threat
    recommendations: tuple[Recommendation, ...]
    geofences: tuple[Geofence, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class ReviewPorts:
    """What the review acts through (the app wires the store, the USM and tracking)."""

    settle: Callable[[Threat | Recommendation], None]
    """Writes a closed threat / superseded version of an earlier life (``settle_inherited``)."""
    record: Callable[[object], None]
    log_event: Callable[[str, str], None]
    remove_geofences: Callable[[Sequence[GeofenceId]], Awaitable[None]]
    raise_hazard: Callable[[HazardReport], None]
    operation: Callable[[OperationId], Operation | None]
    last_position_t_s: Callable[[OperationId], float | None]
    adopt: Callable[[ThreatId, Held], None]
    """Hands EM the held threat a new threat adopts, before that threat reaches EM."""


def _key(t: Threat) -> tuple[ThreatKind, frozenset[str], str | None]:
    return t.kind, frozenset(t.uas_ids), t.intruder_id


def held_threats(
    threats: Sequence[Threat],
    recommendations: Sequence[Recommendation],
    geofences: Sequence[Geofence],
    adopted: Mapping[str, str],
) -> list[Held]:
    """Each open threat with its recommendations and the geofences EM made for it
    (``em-<threat>-<operation>``), and those of the threats it adopted, in turn
    (``adopted``: threat id -> the id it adopted, from the ``threat_adopted`` audit)."""
    out = []
    for t in threats:
        chain: list[str] = [t.id]
        while (prev := adopted.get(chain[-1])) is not None and prev not in chain:
            chain.append(prev)
        recs = tuple(r for r in recommendations if r.threat_id in chain)
        fences = tuple(g for g in geofences if any(g.id.startswith(f"em-{c}-") for c in chain))
        out.append(Held(t, recs, fences))
    return out


class RestartReview:
    """See the module docstring. ``start`` once, ``on_threats`` as a threat sink ahead of EM,
    ``check`` periodically (``run``)."""

    def __init__(
        self, held: Sequence[Held], ports: ReviewPorts, *, started_s: float, review_s: float
    ) -> None:
        self.ports = ports
        self.started_s = started_s
        self.review_s = review_s
        self._held: dict[ThreatId, Held] = {h.threat.id: h for h in held}
        self._relayed = False

    def held(self) -> list[Threat]:
        return [h.threat for h in self._held.values()]

    def _audit(self, now: float, action: str, subject: str, detail: dict[str, object]) -> None:
        self.ports.record(
            AuditEntry(t_s=now, actor=ACTOR, action=action, subject=subject, detail=detail)
        )

    async def start(self, now: float) -> None:
        """Supersede the pending proposals of dead lives; close at once the held threats whose
        operation is gone, landed or ended."""
        for h in list(self._held.values()):
            pending = [r for r in h.recommendations if r.state is RecommendationState.PROPOSED]
            for r in pending:
                why = "its prompt ended with the life that made it (restart)"
                self.ports.settle(r.transition(RecommendationState.SUPERSEDED, now, why))
            self._audit(
                now,
                "restart_review",
                h.threat.id,
                {
                    "kind": h.threat.kind.value,
                    "superseded": [f"{r.id} v{r.version}" for r in pending],
                    "review_s": self.review_s,
                },
            )
            over = self._operation_over(h.threat)
            if over is not None:
                await self._close(h, now, over)
        n = len(self._held)
        if n:
            self.ports.log_event(
                "restart",
                f"{n} threats an earlier life left open: under review for "
                f"{self.review_s:.0f} s (adopted if detected again, else closed)",
            )

    async def on_threats(self, threats: list[Threat]) -> None:
        """The new life's threats: a new one with the condition of a held threat adopts it."""
        for t in threats:
            if t.status is ThreatStatus.CLOSED:
                continue
            match = next((h for h in self._held.values() if _key(h.threat) == _key(t)), None)
            if match is None:
                continue
            del self._held[match.threat.id]
            self.ports.adopt(t.id, match)
            now = t.detected_at_s
            self._settle_closed(match, now, f"adopted by {t.id} (detected again after a restart)")
            in_force = [
                f"{r.id} v{r.version} {r.state.value}"
                for r in match.recommendations
                if r.state in IN_FORCE
            ]
            self._audit(
                now,
                "threat_adopted",
                t.id,
                {
                    "from": match.threat.id,
                    "in_force": in_force,
                    "geofences": [g.id for g in match.geofences],
                },
            )
            self.ports.log_event("restart", f"{t.id} adopts {match.threat.id} of an earlier life")

    def done(self) -> bool:
        return not self._held

    async def check(self, now: float) -> None:
        """At the end of the review: relay the link losses of UAS still silent, close the rest."""
        if now - self.started_s < self.review_s:
            return
        if not self._relayed:
            self._relayed = True
            for h in list(self._held.values()):
                self._relay_link_loss(h, now)
            return  # the relayed hazards arrive (and adopt) before the rest is closed
        for h in list(self._held.values()):
            reason = f"not detected again within {self.review_s:.0f} s of the restart"
            await self._close(h, now, reason)

    def _relay_link_loss(self, h: Held, now: float) -> None:
        t = h.threat
        if t.kind is not ThreatKind.COMMUNICATION_FAILURE or len(t.uas_ids) != 1:
            return
        last = self.ports.last_position_t_s(t.uas_ids[0])
        if last is not None and last > self.started_s:
            return  # heard since the restart: closed below
        self.ports.raise_hazard(
            HazardReport(
                kind=t.kind,
                t_s=now,
                operation_id=t.uas_ids[0],
                position=t.position,
                message=f"no position since the restart (was {t.id})",
                source="restart",
            )
        )

    def _operation_over(self, t: Threat) -> str | None:
        for op_id in t.uas_ids:
            op = self.ports.operation(op_id)
            if op is None:
                return f"operation {op_id} is gone"
            if op.state in (OperationState.LANDED, OperationState.ENDED):
                return f"operation {op_id} {op.state.value}"
        return None

    def _settle_closed(self, h: Held, now: float, reason: str) -> None:
        t = h.threat
        text = f"{t.message}; closed: {reason}" if t.message else f"closed: {reason}"
        closed = replace(t, status=ThreatStatus.CLOSED, updated_at_s=now, message=text)
        self.ports.settle(closed)

    async def _close(self, h: Held, now: float, reason: str) -> None:
        self._held.pop(h.threat.id, None)
        self._settle_closed(h, now, reason)
        self._audit(
            now, "threat_closed", h.threat.id, {"kind": h.threat.kind.value, "reason": reason}
        )
        self.ports.log_event("threat", f"{h.threat.id} of an earlier life closed: {reason}")
        if h.geofences:
            await self.ports.remove_geofences([g.id for g in h.geofences])
