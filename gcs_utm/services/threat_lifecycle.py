"""When a threat raised from a hazard is over (Monitoring closes its own threats).

The USM raises a threat for each hazard a vehicle, tracking or an alert reports (link loss,
GNSS degradation, jamming, a low battery, a system id claimed by another sender, ...). Such a
threat has no detector that re-evaluates it every cycle, so this module watches each one and
closes it when its cause is gone, with the reason:

============================  ==============================================================
threat kind                   closes when
============================  ==============================================================
COMMUNICATION_FAILURE         positions of the UAS are accepted again (newer than the threat,
                              none older than ``fresh_s``); without an operation: the vehicle
                              is heard again
GNSS_DEGRADATION              a 3D fix again and a horizontal accuracy below ``eph_good_m``
SYSID_CONFLICT                no claim for ``quiet_s``
ALERT_WARNING                 its area's end time has passed
any kind with a UAS           the UAS is on the ground (disarmed and not reported airborne,
                              in a status newer than the threat) or its operation landed or
                              ended
============================  ==============================================================

A cause must stay gone for ``clear_s`` (checked on every :meth:`ThreatCloser.check`) before
the threat closes, and a link loss needs positions that kept coming over that time: a link
that flaps back for one frame closes nothing (a link loss of an operation that landed or
ended closes on that alone: the flight sends nothing more). JAMMING_ATTACK,
SPOOFING_ATTACK, LACK_OF_BATTERY and TECHNICAL_FAILURE close on the ground only: nothing the
vehicle reports says they are over. What closing does (the store, EM dropping the geofences
the threat created, the audit) is the caller's ``close``.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field, replace

from gcs_utm.messages import LinkHealth, VehicleStatus
from gcs_utm.model import (
    Operation,
    OperationId,
    OperationState,
    SysId,
    Threat,
    ThreatId,
    ThreatKind,
    ThreatStatus,
)

_FIX_3D = 3


@dataclass(frozen=True, slots=True, kw_only=True)
class Evidence:
    """What the running service knows now (read through these callables at each check)."""

    operation: Callable[[OperationId], Operation | None]
    status: Callable[[SysId], VehicleStatus | None]
    health: Callable[[SysId], LinkHealth | None]
    last_position_t_s: Callable[[OperationId], float | None] = lambda _op: None
    """When the UAS's track last accepted a position (None: no track)."""


@dataclass(slots=True)
class _Watched:
    threat: Threat
    sys_id: SysId | None
    last_evidence_t_s: float  # the latest report of the same hazard (coalesced repeats too)
    gone_since_t_s: float | None = None


@dataclass(slots=True)
class ThreatCloser:
    """See the module docstring. ``close(threat, reason)`` is called once per threat with its
    CLOSED version."""

    evidence: Evidence
    close: Callable[[Threat, str], Awaitable[None]]
    clear_s: float = 3.0
    fresh_s: float = 5.0
    eph_good_m: float = 5.0
    quiet_s: float = 30.0
    _watched: dict[ThreatId, _Watched] = field(default_factory=dict)

    def watch(self, threat: Threat, sys_id: SysId | None) -> None:
        self._watched[threat.id] = _Watched(threat, sys_id, threat.detected_at_s)

    def repeated(self, threat_id: ThreatId, t_s: float) -> None:
        """The hazard of ``threat_id`` was reported again (coalesced by the USM)."""
        w = self._watched.get(threat_id)
        if w is not None:
            w.last_evidence_t_s = max(w.last_evidence_t_s, t_s)
            w.gone_since_t_s = None

    def forget(self, threat_id: ThreatId) -> None:
        self._watched.pop(threat_id, None)

    def watching(self) -> Mapping[ThreatId, Threat]:
        return {k: w.threat for k, w in self._watched.items()}

    async def check(self, now_s: float) -> None:
        """Close every watched threat whose cause has been gone for ``clear_s``."""
        for tid, w in list(self._watched.items()):
            if tid not in self._watched:
                continue  # forgotten while an earlier one closed
            reason = self.cause_gone(w, now_s)
            if reason is None:
                w.gone_since_t_s = None
                continue
            if w.gone_since_t_s is None:
                w.gone_since_t_s = now_s
            if now_s - w.gone_since_t_s < self.clear_s or not self._still_heard(w):
                continue
            del self._watched[tid]
            closed = replace(w.threat, status=ThreatStatus.CLOSED, updated_at_s=now_s)
            await self.close(closed, reason)

    def _still_heard(self, w: _Watched) -> bool:
        """A link loss closes only on positions that kept coming while it looked over (one
        frame of a flapping link looks fresh for ``fresh_s``)."""
        t = w.threat
        if t.kind is not ThreatKind.COMMUNICATION_FAILURE or w.gone_since_t_s is None:
            return True
        if t.uas_ids and self._operation_over(t.uas_ids[0]):
            return True  # a flight that ended sends nothing more: its link loss is over
        if t.uas_ids:
            last = self.evidence.last_position_t_s(t.uas_ids[0])
        else:
            h = None if w.sys_id is None else self.evidence.health(w.sys_id)
            last = None if h is None else h.last_heard_t_s
        return last is not None and last >= w.gone_since_t_s

    def cause_gone(self, w: _Watched, now_s: float) -> str | None:
        """Why the threat of ``w`` is over now, or None while its cause holds."""
        t = w.threat
        op_id = t.uas_ids[0] if t.uas_ids else None
        op = None if op_id is None else self.evidence.operation(op_id)
        sys_id = w.sys_id if op is None or op.sys_id is None else op.sys_id
        ended = self._ended(op, sys_id, t)
        if ended is not None:
            return ended
        if t.kind is ThreatKind.COMMUNICATION_FAILURE:
            return self._heard_again(op_id, sys_id, t, now_s)
        if t.kind is ThreatKind.GNSS_DEGRADATION:
            return self._fix_back(sys_id, t)
        if t.kind is ThreatKind.SYSID_CONFLICT and now_s - w.last_evidence_t_s >= self.quiet_s:
            return f"no other sender claimed the system id for {self.quiet_s:.0f} s"
        if t.kind is ThreatKind.ALERT_WARNING and t.area is not None:
            end = t.area.end_t_s
            if end is not None and now_s >= end:
                return "the alert's area expired"
        return None

    def _ended(self, op: Operation | None, sys_id: SysId | None, t: Threat) -> str | None:
        if not t.uas_ids:
            return None
        if op is None:
            return f"operation {t.uas_ids[0]} is gone"
        if op.state in (OperationState.LANDED, OperationState.ENDED):
            return f"operation {op.id} {op.state.value}"
        s = None if sys_id is None else self.evidence.status(sys_id)
        if s is None or s.t_s <= t.detected_at_s or s.armed or s.landed is False:
            return None
        if t.kind is ThreatKind.COMMUNICATION_FAILURE:
            return None  # heard again: decided by its positions (below)
        return f"{op.id} is on the ground (disarmed)"

    def _operation_over(self, op_id: OperationId) -> bool:
        op = self.evidence.operation(op_id)
        return op is None or op.state in (OperationState.LANDED, OperationState.ENDED)

    def _heard_again(
        self, op_id: OperationId | None, sys_id: SysId | None, t: Threat, now_s: float
    ) -> str | None:
        if op_id is not None:
            last = self.evidence.last_position_t_s(op_id)
            if last is not None and last > t.detected_at_s and now_s - last <= self.fresh_s:
                return f"positions of {op_id} flow again (last {now_s - last:.1f} s ago)"
            return None
        h = None if sys_id is None else self.evidence.health(sys_id)
        if h is not None and t.detected_at_s < h.last_heard_t_s >= now_s - self.fresh_s:
            return f"system {sys_id} is heard again"
        return None

    def _fix_back(self, sys_id: SysId | None, t: Threat) -> str | None:
        s = None if sys_id is None else self.evidence.status(sys_id)
        if s is None or s.t_s <= t.detected_at_s or s.gnss_fix_type is None:
            return None
        if s.gnss_fix_type < _FIX_3D or (s.eph_m is not None and s.eph_m >= self.eph_good_m):
            return None
        eph = "" if s.eph_m is None else f", accuracy {s.eph_m:.1f} m"
        return f"GNSS fix back (fix_type {s.gnss_fix_type}{eph})"
