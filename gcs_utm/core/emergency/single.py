"""Decisions for one UAS at a time: TD's single-UAS alternatives (reroute, back to plan,
landing site or home; :func:`single`) and the avoidance of an intruder (:func:`intruder`).
Each sorts TD's options by the weighted score (energy first for ``land_or_home``), proposes
the best with the others as alternatives, and escalates with a command when there is none.
Pure."""

from __future__ import annotations

from gcs_utm.core.emergency.config import Action
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision, Mode
from gcs_utm.core.emergency.fence_late import fence_command
from gcs_utm.core.emergency.fenced_hold import fence_free_hold
from gcs_utm.core.emergency.immediate import held_by
from gcs_utm.core.emergency.options import detail, intended
from gcs_utm.core.emergency.selection import Selection, weighted
from gcs_utm.core.emergency.supervision import escalate_safe, safe_command
from gcs_utm.model import (
    AirspaceSnapshot,
    Alternative,
    Command,
    CommandKind,
    Maneuver,
    OperationId,
    Threat,
)


def _selection(op_id: OperationId, alts: list[Alternative], em: EmContext) -> Selection | None:
    """The first of ``alts`` (sorted) as the selection, for the audit."""
    if not alts:
        return None
    cfg = em.config
    return Selection(
        chosen={op_id: alts[0]},
        total=weighted(alts[0], cfg.alpha, cfg.beta),
        explored=len(alts),
        truncated=False,
    )


def single(  # noqa: PLR0917 - the case, its UAS and snapshot, what to offer, the sub-threat
    em: EmContext,
    case: Case,
    op_id: OperationId,
    snapshot: AirspaceSnapshot,
    maneuvers: frozenset[Maneuver],
    threat: Threat | None = None,
) -> Decision:
    """The best of TD's ``maneuvers`` for ``op_id`` against ``threat`` (default: the
    case's), less those refused before; none: land now (``land_or_home``) or escalate with
    the safe command."""
    now = snapshot.t_s
    t = threat or case.threat
    held = held_by(em, op_id, case) if case.action is Action.BACK_TO_PLAN else None
    if held:  # off its plan on purpose: not sent back into the loss it avoids
        why: dict[str, object] = {"reason": f"{op_id} follows {held}'s immediate command"}
        return Decision(audit=(em.audit(now, "deferred", case.threat.id, why),))
    snapshot = intended(em, snapshot, case)
    case.operations = dict(snapshot.operations)
    late = fence_command(em, case, op_id, snapshot, t)  # a fence entered before any plan
    if late is not None:
        return late
    case.modes[op_id] = Mode.SINGLE
    case.maneuvers[op_id] = maneuvers
    allowed = maneuvers - case.excluded.get(op_id, set())
    alts = em.td.resolve_single(
        t,
        op_id,
        snapshot,
        maneuvers=allowed,
        extra_geofences=tuple(case.geofences),
        start_t_s=em.plan_start(t, now),
        lead_in_from_t_s=em.earliest_receipt(now, (op_id,)),
    )
    cfg = em.config
    if case.action is Action.LAND_OR_HOME:
        # Energy first: with the battery or the vehicle failing, the option that is on the
        # ground soonest wins; the weighted score only breaks ties.
        alts.sort(
            key=lambda x: (
                x.plan.end_t_s if x.plan is not None else now,
                weighted(x, cfg.alpha, cfg.beta),
            )
        )
    else:
        alts.sort(key=lambda x: weighted(x, cfg.alpha, cfg.beta))
    sel = _selection(op_id, alts, em)
    audit_detail = detail(em, {op_id: alts}, sel, f"{t.kind.value}: {case.action.value}")
    if not alts:
        audit = (em.audit(now, "escalation", case.threat.id, audit_detail),)
        if case.action is Action.LAND_OR_HOME:
            # Low battery or failure and no reachable site: land where it is, and say so.
            cmd = Command(kind=CommandKind.LAND, operation_id=op_id)
            case.modes[op_id] = Mode.COMMAND
            msg = f"{case.threat.id}: no reachable landing site or home for {op_id}: land now"
            d = em.issue(case, op_id, now, command=cmd, reason=msg)
            return d.merge(Decision(escalations=(msg,), audit=audit))
        msg = f"{case.threat.id}: no feasible alternative for {op_id} ({t.kind.value})"
        instead = fence_free_hold(em, t, op_id, snapshot)  # a fixed wing's hold into a fence
        return Decision(audit=audit).merge(
            escalate_safe(em, case, [op_id], now, msg, *(instead or (None, None)))
        )
    best = alts[0]
    d = Decision(audit=(em.audit(now, "decision", case.threat.id, audit_detail),))
    return d.merge(
        em.issue(
            case,
            op_id,
            now,
            selected=best,
            alternatives=alts[1:],
            reason=f"{t.kind.value}: {best.maneuver.value}",
        )
    )


def intruder(em: EmContext, case: Case, op_id: OperationId, snapshot: AirspaceSnapshot) -> Decision:
    """TD's avoidance of the case's intruder for ``op_id`` (less the refused manoeuvres);
    none: the safe command (hold) proposed with an escalation."""
    snapshot = intended(em, snapshot, case)
    case.operations = dict(snapshot.operations)
    now = snapshot.t_s
    cfg = em.config
    case.modes[op_id] = Mode.INTRUDER
    banned = case.excluded.get(op_id, set())
    alts = [
        x
        for x in em.td.resolve_intruder(
            case.threat,
            op_id,
            snapshot,
            em.plan_start(case.threat, now),
            em.earliest_receipt(now, (op_id,)),
        )
        if x.maneuver not in banned
    ]
    alts.sort(key=lambda x: weighted(x, cfg.alpha, cfg.beta))
    audit_detail = detail(em, {op_id: alts}, _selection(op_id, alts, em), "intruder: avoidance")
    if not alts:
        # Nothing flyable keeps the minima: propose the safe command (hold) and escalate.
        cmd = Command(kind=safe_command(case.threat.kind), operation_id=op_id)
        case.modes[op_id] = Mode.COMMAND
        msg = (
            f"{case.threat.id}: no avoidance for {op_id} from intruder "
            f"{case.threat.intruder_id}: {cmd.kind.value} proposed"
        )
        audit = (em.audit(now, "escalation", case.threat.id, audit_detail),)
        d = em.issue(case, op_id, now, command=cmd, reason=msg)
        return d.merge(Decision(escalations=(msg,), audit=audit))
    d = Decision(audit=(em.audit(now, "decision", case.threat.id, audit_detail),))
    return d.merge(
        em.issue(
            case,
            op_id,
            now,
            selected=alts[0],
            alternatives=alts[1:],
            reason=f"intruder {case.threat.intruder_id}: {alts[0].maneuver.value}",
        )
    )
