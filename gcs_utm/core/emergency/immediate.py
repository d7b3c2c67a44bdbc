"""Immediate commands for a loss of separation that new plans cannot resolve in time.

A new plan acts only after the answer and the upload (:mod:`.lead`); a command acts after the
answer and its acknowledgement. EM proposes a command (through the same pilot prompt as
every recommendation, with an escalation that names it) instead of plans when:

- the predicted event is nearer than the time a new plan needs to start (a UAS that appears
  from nowhere, a conflict detected late): plans would start inside the loss; or nearer than
  that plus ``emergency.immediate_margin_s`` and the command keeps the minima
  (:func:`late_reason`): a plan would start just before the event;
- no combination of plans resolves the conflict;
- every plan keeps separation while the tracks predict the loss, even re-timed from the
  vehicles' progress (the snapshot EM decides on holds the plans as flown,
  :mod:`gcs_utm.core.deconfliction.retime`): a UAS is not where its plan says. Only the UAS
  whose track is off its plan (beyond its flight geometry) are commanded, when there are
  such, and only once the event is within the lead plus :data:`IMMINENT_S` (:func:`keep_all`).

A UAS under such a command is off its plan on purpose: a conformance decision (back to plan)
for it waits while the loss case is open (:func:`held_by`).

The commands are *hold* (a multirotor brakes and holds position and altitude; a fixed wing
circles where it is) and *climb* or *descend in place* (a GOTO to the point where the
vehicle stops, the vertical minimum plus a margin higher or lower, within the altitude band
and above the safety floor); a fixed wing may also turn left or right, climbing or
descending to those altitudes or not, or climb or descend flying straight on (:mod:`.turn`,
ranked after the others among those that keep the minima). Each UAS of the threat gets none
or one of them; every combination is flown forward on a 0.5 s grid: a commanded UAS at its
track's velocity up to the command time, then braking at :data:`BRAKE_MPS2` to a stop (a
fixed wing: anywhere within two turn radii of where it was commanded, and within its top
speed's reach of there) while climbing or descending at its rates; every other UAS on its
predicted path (the snapshot's prediction row of its track, else its velocity, else its
plan). The combination is kept that keeps TD's minima (effective minima plus tracking
tolerances) from the other UAS of the threat and from all other traffic with the fewest
commanded UAS, then the lowest priorities, then the largest separation; when none keeps
them, the one with the largest separation (the mean of acting when expected and on the
answer: ``t_early``). Either way a combination that takes no UAS into a geofence
(:mod:`.command_fences`) comes before one that does. Before all that, a combination that
takes a UAS into the fence itself (grown only by its flight geometry: an intrusion, not a
clearance kept short) comes after every one that does not, even one that does not keep the
minima: a turn that kept the minima through a no-fly zone was chosen over a turn away that
kept 0.90 of them (enc_6_0225_late_crossing, 4.2 s inside; the turn away flew 75.7 m from
the other UAS against 50 m). The audit lists every combination with its separation ratio
(and the geofences it enters, ``intrusion`` when it enters the fence itself)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.emergency.command_fences import fence_entered, fence_itself_entered
from gcs_utm.core.emergency.context import EmContext
from gcs_utm.core.emergency.decision import Case, Decision
from gcs_utm.core.emergency.endpoint import move_end
from gcs_utm.core.emergency.fly_on import Choice, fly_on, flying_on
from gcs_utm.core.emergency.supervision import escalate_safe
from gcs_utm.core.emergency.third_party import better, limiting_outsider
from gcs_utm.core.emergency.turn import turn_moves
from gcs_utm.core.monitoring.loss import separation_ratio
from gcs_utm.model import (
    AirspaceSnapshot,
    Command,
    CommandKind,
    FloatArray,
    Operation,
    OperationId,
    Position,
    RecommendationId,
    RecommendationState,
    Threat,
    ThreatKind,
)

if TYPE_CHECKING:
    from gcs_utm.core.deconfliction import TacticalDeconfliction

BRAKE_MPS2 = 2.5
"""Deceleration assumed for a multirotor that brakes (PX4 MPC_ACC_HOR 3 m/s^2, less a
margin)."""
STEP_S = 0.5
AFTER_EVENT_S = 30.0
"""The combinations are flown up to this long after the predicted event (at least
:data:`MIN_HORIZON_S` from now)."""
MIN_HORIZON_S = 30.0
MAX_UAS = 3
"""At most this many UAS of one threat get a command (4 options each)."""
VERTICAL_MARGIN_M = 5.0
"""A climb or descent in place goes this much beyond the pair's vertical minimum."""


class Immediate(Enum):
    """An immediate command for one UAS; the values are the audit's names."""

    HOLD = "hold"
    CLIMB = "climb"  # a GOTO the vertical minimum plus a margin above where it stops
    DESCEND = "descend"  # likewise below
    TURN_LEFT = "turn left"  # a fixed wing: a GOTO far abeam at its altitude (.turn)
    TURN_RIGHT = "turn right"
    # A fixed wing that climbs or descends as it turns, or flying straight on (.turn): it
    # changes altitude at its rates without circling where it was commanded.
    TURN_LEFT_CLIMB = "turn left and climb"
    TURN_LEFT_DESCEND = "turn left and descend"
    TURN_RIGHT_CLIMB = "turn right and climb"
    TURN_RIGHT_DESCEND = "turn right and descend"
    CLIMB_AHEAD = "climb ahead"
    DESCEND_AHEAD = "descend ahead"


_IN_PLACE = (Immediate.HOLD, Immediate.CLIMB, Immediate.DESCEND)
_LIVE = (RecommendationState.PROPOSED, RecommendationState.ACCEPTED, RecommendationState.APPLIED)


@dataclass(frozen=True, slots=True)
class _Move:
    """One UAS's commanded positions on the grid, and how much horizontal room its hold
    takes (a fixed wing circles)."""

    op_id: OperationId
    action: Immediate
    xyz: FloatArray
    slack_m: FloatArray
    command: Command


def track_xyz(
    td: TacticalDeconfliction, op: Operation, snapshot: AirspaceSnapshot
) -> FloatArray | None:
    """Where the vehicle is by its fresh track (local frame), None without one."""
    for tr in snapshot.tracks.values():
        if tr.operation_id == op.id and not tr.stale:
            e, n = td.frame.point_to_local(tr.lat_deg, tr.lon_deg)
            return np.array([e, n, tr.alt_amsl_m])
    return None


def predicted_path(
    td: TacticalDeconfliction,
    op: Operation,
    snapshot: AirspaceSnapshot,
    until_t_s: float,
    *,
    use_prediction: bool = True,
) -> LocalPlan:
    """Where the UAS is predicted to fly: its track's prediction row (which follows its
    plan), else (or with ``use_prediction`` False: how it flies until a command reaches it)
    its track at constant velocity, else its plan."""
    pred = snapshot.prediction
    for tid, tr in snapshot.tracks.items():
        if tr.operation_id != op.id or tr.stale:
            continue
        if use_prediction and pred is not None and tid in pred.track_ids:
            pts = pred.points[pred.track_ids.index(tid)]
            return LocalPlan(*(pts[:, i].copy() for i in range(4)))
        e, n = td.frame.point_to_local(tr.lat_deg, tr.lon_deg)
        ve, vn, vu = tr.vel_enu_mps
        span = max(until_t_s - tr.t_s, 1.0)
        return LocalPlan(
            np.array([e, e + ve * span]),
            np.array([n, n + vn * span]),
            np.array([tr.alt_amsl_m, tr.alt_amsl_m + vu * span]),
            np.array([tr.t_s, tr.t_s + span]),
        )
    return td.local_plan(op.plan)


def _at(path: LocalPlan, grid: FloatArray) -> FloatArray:
    e, n, z = path.coords(grid)
    return np.column_stack((e, n, z))


def _moves(
    td: TacticalDeconfliction,
    op: Operation,
    path: LocalPlan,
    grid: FloatArray,
    *,
    t_cmd: float,
    rise_m: float,
) -> list[_Move]:
    """Hold, climb and descend in place for ``op`` commanded at ``t_cmd`` (see the module
    docstring); a climb or descent that the altitude band leaves no room for is left out."""
    env = op.performance()
    before = _at(path, grid)
    p0, p1 = _at(path, np.array([t_cmd, t_cmd + STEP_S]))
    v = (p1[:2] - p0[:2]) / STEP_S
    speed = float(np.hypot(v[0], v[1]))
    tau = np.clip(grid - t_cmd, 0.0, None)
    if env.can_hover and speed > 1e-6:
        t_stop = speed / BRAKE_MPS2
        tb = np.minimum(tau, t_stop)
        run = speed * tb - 0.5 * BRAKE_MPS2 * tb * tb
        stop_xy = p0[:2] + v / speed * run[:, None]
        slack = np.zeros_like(grid)
    else:
        stop_xy = np.repeat(p0[None, :2], grid.shape[0], axis=0)
        # A fixed wing circles somewhere within two turn radii of where it was commanded,
        # and it cannot be farther from there than its top speed carries it: the room grows
        # from nothing at the command (a constant 2 r from the command on hid the separation
        # a climb or descent builds up while it is still far away).
        reach = env.max_speed_mps * tau
        slack = np.zeros_like(grid) if env.can_hover else np.minimum(reach, 2 * env.turn_radius_m)
    lo, hi = td.alt_limits(op)
    out = []
    for action, target_z, rate in (
        (Immediate.HOLD, float(p0[2]), 1.0),
        (Immediate.CLIMB, min(float(p0[2]) + rise_m, hi), env.climb_rate_mps),
        (Immediate.DESCEND, max(float(p0[2]) - rise_m, lo), env.descent_rate_mps),
    ):
        if (action is Immediate.CLIMB and target_z < p0[2] + 1.0) or (
            action is Immediate.DESCEND and target_z > p0[2] - 1.0
        ):
            continue  # no room in the altitude band (or already outside it that way)
        dz = np.clip(target_z - p0[2], -rate * tau, rate * tau)
        xyz = before.copy()
        after = grid >= t_cmd
        xyz[after, :2] = stop_xy[after]
        xyz[after, 2] = p0[2] + dz[after]
        stop = stop_xy[-1]
        if action is Immediate.HOLD:
            command = Command(kind=CommandKind.HOLD, operation_id=op.id)
        else:
            lat, lon = td.frame.point_to_wgs84(float(stop[0]), float(stop[1]))
            target = Position(lat_deg=lat, lon_deg=lon, alt_amsl_m=target_z)
            command = Command(kind=CommandKind.GOTO, operation_id=op.id, target=target)
        out.append(_Move(op.id, action, xyz, slack, command))
    return out


_Flown = tuple[Operation, FloatArray, FloatArray | float]
"""A UAS, its positions on the grid and the horizontal room its hold takes (per grid time)."""


def _ratio(td: TacticalDeconfliction, fa: _Flown, fb: _Flown) -> float:
    """The smallest separation ratio of two grid paths under TD's minima for the pair."""
    (a, xa, sa), (b, xb, sb) = fa, fb
    h_min, v_min = td.pair_minima(a, b)
    dh = np.maximum(np.hypot(xa[:, 0] - xb[:, 0], xa[:, 1] - xb[:, 1]) - sa - sb, 0.0)
    r = separation_ratio(dh, xa[:, 2] - xb[:, 2], h_min, v_min, spherical=td.monitoring.spherical)
    return float(r.min())


def commands_now(
    em: EmContext,
    snapshot: AirspaceSnapshot,
    ids: Sequence[OperationId],
    event_t_s: float | None,
    *,
    early: bool = True,
) -> Choice | None:
    """:func:`choose_commands` for ``ids`` as EM decides now: from when a command can act
    (``em.lead``), by priority, and (``early``) ranked from the answer's time too."""
    now = snapshot.t_s
    ops = snapshot.operations
    return choose_commands(
        em.td,
        snapshot,
        ids,
        em.lead.command_at(ids, now),
        event_t_s,
        {k: ops[k].priority for k in ids if k in ops},
        t_early=now + em.lead.answer_s(ids) if early else None,
    )


def choose_commands(  # noqa: PLR0917 - the long form of commands_now
    td: TacticalDeconfliction,
    snapshot: AirspaceSnapshot,
    candidates: Sequence[OperationId],
    t_cmd: float,
    event_t_s: float | None,
    priority_of: dict[OperationId, int],
    *,
    turns: bool = True,
    t_early: float | None = None,
) -> Choice | None:
    """The immediate commands for ``candidates`` (see the module docstring); None when no
    candidate is in the snapshot. Without ``turns`` a fixed wing is not offered a turn.
    ``t_early`` (before ``t_cmd``): the earliest the commands can act (on the answer, before
    the acknowledgement comes back); combinations that separate alike from ``t_cmd`` are
    ranked by how they separate from then (:func:`sooner_combo`)."""
    ops = snapshot.operations
    cands = [ops[k] for k in candidates if k in ops][:MAX_UAS]
    if not cands:
        return None
    first = _choose(td, snapshot, cands, t_cmd, event_t_s, priority_of, turns, t_early)
    if first is None:
        return None
    # the best combination loses the minima to a UAS outside the threat: that UAS may be
    # commanded too (.third_party)
    outsider = limiting_outsider(first, len(cands), MAX_UAS)
    if outsider is None or outsider not in ops:
        return first[0]
    prio = {**priority_of, outsider: ops[outsider].priority}
    more = [*cands, ops[outsider]]
    second = _choose(td, snapshot, more, t_cmd, event_t_s, prio, turns, t_early)
    return first[0] if second is None else better(first[0], second[0])


def _choose(  # noqa: PLR0917 - choose_commands's arguments, resolved
    td: TacticalDeconfliction,
    snapshot: AirspaceSnapshot,
    cands: list[Operation],
    t_cmd: float,
    event_t_s: float | None,
    priority_of: dict[OperationId, int],
    turns: bool,
    t_early: float | None,
) -> tuple[Choice, OperationId | None] | None:
    """:func:`choose_commands` for the UAS ``cands``, with the UAS outside them that the
    chosen combination comes closest to when that limits its ratio (None when a pair of
    ``cands`` does, or it keeps the minima)."""
    now = snapshot.t_s
    ops = snapshot.operations
    until = max(now + MIN_HORIZON_S, (event_t_s or now) + AFTER_EVENT_S)
    grid = np.arange(now, until + STEP_S, STEP_S)
    others = [
        o
        for k, o in ops.items()
        if k not in {c.id for c in cands}
        and k not in snapshot.grounded  # a vehicle on the ground is not traffic
        and (track_xyz(td, o, snapshot) is not None or o.plan.start_t_s <= now <= o.plan.end_t_s)
    ]
    paths = {o.id: _at(predicted_path(td, o, snapshot, until), grid) for o in cands + others}
    options = _options(td, snapshot, (cands, others), grid, t_cmd, turns=turns, until=until)
    early = None
    if t_early is not None and t_early < t_cmd:
        opts = _options(td, snapshot, (cands, others), grid, t_early, turns=turns, until=until)
        early = {(m.op_id, m.action): m for o in opts for m in o if m is not None}
    fenced = {
        id(m): fence_entered(td, snapshot, m.op_id, m.xyz, m.slack_m, grid, t_cmd)
        for opts in options
        for m in opts
        if m is not None
    }
    inside = {
        k: fence_itself_entered(td, snapshot, m.op_id, m.xyz, m.slack_m, grid, t_cmd)
        for opts in options
        for m in opts
        if m is not None and fenced[k := id(m)]
    }
    best: tuple[tuple[float, ...], Choice] | None = None
    score = 0.0  # the best's separation as ranked (.fly_on)
    best_combo: Sequence[_Move | None] = ()
    tried: list[dict[str, object]] = []
    for combo in itertools.product(*options):
        moves = [m for m in combo if m is not None]
        if not moves:
            continue
        ratio = _combo_ratio(td, cands, others, combo, paths)
        clear = ratio >= 1.0
        fences = sorted({fenced[id(m)] for m in moves} - {""})
        sooner = ratio
        if early is not None:
            sooner = _combo_ratio(td, cands, others, sooner_combo(combo, early), paths)
        intrudes = any(inside.get(id(m)) for m in moves)
        key = _rank(ratio, (bool(fences), intrudes), moves, priority_of, sooner)
        actions = {m.op_id: m.action.value for m in moves}
        record: dict[str, object] = {"commands": {str(k): v for k, v in actions.items()}}
        record["ratio"] = round(ratio, 3)
        if early is not None:
            record["ratio_if_sooner"] = round(sooner, 3)
        if fences:
            record["geofences"] = fences
        if intrudes:
            record["intrusion"] = True
        tried.append(record)
        if best is None or key < best[0]:
            cmds = {m.op_id: m.command for m in moves}
            best = (key, Choice(cmds, actions, ratio, clear, tried, tuple(fences)))
            score = (ratio + sooner) / 2.0
            best_combo = combo
    if best is None:
        return None
    choice = fly_on(best[1], _combo_ratio(td, cands, others, [], paths), score)
    if choice.clear or not choice.commands:
        return choice, None
    return choice, worst_other(td, cands, others, best_combo, paths)


def _options(
    td: TacticalDeconfliction,
    snapshot: AirspaceSnapshot,
    traffic: tuple[list[Operation], list[Operation]],
    grid: FloatArray,
    t_cmd: float,
    *,
    turns: bool,
    until: float,
) -> list[list[_Move | None]]:
    """Each candidate's options commanded at ``t_cmd``: none, then its moves (in place, then
    a fixed wing's turns and climbs or descents flying on, with ``turns``)."""
    cands, others = traffic
    options: list[list[_Move | None]] = []
    for c in cands:
        v_mins = [td.pair_minima(c, o)[1] for o in cands + others if o.id != c.id]
        rise = max(v_mins, default=td.monitoring.separation_vertical_m)
        path = predicted_path(td, c, snapshot, until, use_prediction=False)
        moves = _moves(td, c, path, grid, t_cmd=t_cmd, rise_m=rise + VERTICAL_MARGIN_M)
        turned = _turns(td, c, path, grid, t_cmd, moves) if turns else []
        options.append([None, *moves, *turned])
    return options


def sooner_combo(
    combo: Sequence[_Move | None], early: dict[tuple[OperationId, Immediate], _Move]
) -> list[_Move | None]:
    """The same commands acting at the earlier time (a move without its early twin, e.g. a
    climb the band leaves no room for then, stays as it is)."""
    return [None if m is None else early.get((m.op_id, m.action), m) for m in combo]


def _turns(  # noqa: PLR0917 - one call site
    td: TacticalDeconfliction,
    op: Operation,
    path: LocalPlan,
    grid: FloatArray,
    t_cmd: float,
    in_place: list[_Move],
) -> list[_Move]:
    """A fixed wing's turns left and right (:mod:`.turn`), level and climbing or descending
    to the altitudes its climb and descent in place (``in_place``) go to, and its climb and
    descent straight ahead: no room beyond its positions."""
    targets = {
        m.action.value: m.command.target.alt_amsl_m
        for m in in_place
        if m.action in {Immediate.CLIMB, Immediate.DESCEND} and m.command.target is not None
    }
    return [
        _Move(op.id, Immediate(name), xyz, np.zeros_like(grid), cmd)
        for name, xyz, cmd in turn_moves(td, op, path, grid, t_cmd=t_cmd, targets_z=targets)
    ]


def _rank(
    ratio: float,
    fenced: tuple[bool, bool],
    moves: list[_Move],
    priority_of: dict[OperationId, int],
    sooner: float,
) -> tuple[float, ...]:
    """Order of combinations: those that take no UAS into a fence itself (``fenced``: into a
    geofence grown by the UAS's volume, into one grown by its flight geometry) first, then
    those that keep the minima, then those that take no UAS into a grown geofence; among the
    ones that keep the minima, the fewest commanded UAS, the lowest priorities, the fewest
    turns (a turned fixed wing leaves its plan for good), the largest separation; among the
    others, the largest separation, then the fewest turns (the smallest separation often
    comes before any command acts, and then every combination ties: it is the mean of the
    separations with the commands acting when expected and sooner, on the answer, as they
    may: the vehicle acts on the command before its acknowledgement is back)."""
    prio = float(sum(priority_of.get(m.op_id, 0) for m in moves))
    fence = 1.0 if fenced[0] else 0.0
    intrusion = 1.0 if fenced[1] else 0.0
    turned = float(sum(m.action not in _IN_PLACE for m in moves))
    if ratio >= 1.0:
        return (intrusion, 0.0, fence, float(len(moves)), prio, turned, -ratio, -sooner)
    spread = -(ratio + sooner) / 2.0
    return (intrusion, 1.0, fence, spread, -sooner, turned, float(len(moves)), prio)


def _combo_ratio(
    td: TacticalDeconfliction,
    cands: list[Operation],
    others: list[Operation],
    combo: Sequence[_Move | None],
    paths: dict[OperationId, FloatArray],
) -> float:
    """The smallest separation ratio of a combination: between the threat's UAS and from
    each of them to all other traffic."""
    combo = list(combo) or [None] * len(cands)  # none: every UAS flies on
    xyz = {c.id: (paths[c.id] if m is None else m.xyz) for c, m in zip(cands, combo, strict=True)}
    slack: dict[OperationId, FloatArray | float] = {
        c.id: (0.0 if m is None else m.slack_m) for c, m in zip(cands, combo, strict=True)
    }
    worst = np.inf
    for i, a in enumerate(cands):
        for b in cands[i + 1 :]:
            worst = min(worst, _ratio(td, (a, xyz[a.id], slack[a.id]), (b, xyz[b.id], slack[b.id])))
        for o in others:
            worst = min(worst, _ratio(td, (a, xyz[a.id], slack[a.id]), (o, paths[o.id], 0.0)))
    return float(worst)


def worst_other(
    td: TacticalDeconfliction,
    cands: list[Operation],
    others: list[Operation],
    combo: Sequence[_Move | None],
    paths: dict[OperationId, FloatArray],
) -> OperationId | None:
    """The UAS of ``others`` whose separation from a commanded UAS of ``combo`` is the
    combination's smallest (None when a pair of ``cands`` has it)."""
    worst = _combo_ratio(td, cands, [], combo, paths) if len(cands) > 1 else np.inf
    found = None
    for o in others:
        r = _combo_ratio(td, cands, [o], combo, paths)
        if r < worst:
            worst, found = r, o.id
    return found


def off_plan(td: TacticalDeconfliction, snapshot: AirspaceSnapshot) -> list[OperationId]:
    """The UAS whose track is farther than their flight geometry from their plan now."""
    out = []
    for k, op in snapshot.operations.items():
        pos = track_xyz(td, op, snapshot)
        if pos is None:
            continue
        plan_pos = td.local_plan(op.plan).position_at(snapshot.t_s)
        if float(np.linalg.norm(pos - plan_pos)) > op.flight_geometry_m:
            out.append(k)
    return out


def too_late(em: EmContext, threat: Threat, now: float) -> str:
    """Why a new plan decided ``now`` would start inside the predicted loss ("" when it
    would not, or the threat predicts no event time)."""
    event = threat.predicted_event_at_s
    lead_s = em.plan_start(threat, now) - now
    if event is None or event - now >= lead_s:
        return ""
    return (
        f"{threat.id}: loss predicted in {event - now:.1f} s, sooner than a new plan can "
        f"start ({lead_s:.1f} s: answer, upload, margin)"
    )


def late_reason(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> str:
    """Why the loss of ``case`` gets the immediate command now rather than new plans ("" when
    plans are tried): the event is nearer than a new plan's lead (:func:`too_late`), or
    nearer than the lead plus ``emergency.immediate_margin_s`` and the immediate command
    keeps the minima without taking a UAS into a geofence (a fixed wing's turn or climb
    flying on only when nothing in place does). A plan that starts just before
    the event leaves no room for the vehicles' tracking error: on generated late encounters
    plans starting 1-3 s before the event were flown 0.5-1.6 m inside the minima."""
    t = case.threat
    now = snapshot.t_s
    late = too_late(em, t, now)
    event = t.predicted_event_at_s
    if late or event is None:
        return late
    lead_s = em.plan_start(t, now) - now
    margin_s = em.config.immediate_margin_s
    if event - now >= lead_s + margin_s:
        return ""
    ops = snapshot.operations
    ids = list(t.uas_ids)
    prio = {k: ops[k].priority for k in ids if k in ops}
    at = em.lead.command_at(ids, now)
    # Without turns: a turned fixed wing leaves its plan for good, and a plan is still in time.
    choice = choose_commands(em.td, snapshot, ids, at, event, prio, turns=False)
    if choice is None or not choice.clear or choice.geofences:
        # ... unless only a fixed wing's turn or climb flying on keeps them: a plan that
        # starts just before the event does not (enc_3_0225: 0.15 s before, flown 47.6 m
        # against 50 m)
        choice = choose_commands(em.td, snapshot, ids, at, event, prio)
    if choice is None or not choice.clear or choice.geofences:
        return ""  # the plans (kept off geofences by TD) are tried
    return (
        f"{t.id}: loss predicted in {event - now:.1f} s, within a new plan's lead "
        f"({lead_s:.1f} s) plus {margin_s:.1f} s"
    )


IMMINENT_S = 10.0
"""With every plan kept, the immediate command waits until the event is this much beyond
the lead: further ahead the plans or the tracks often change (a UAS catches up, a plan
ends), and a UAS held early is where no plan says for the rest of its flight."""


def keep_all(em: EmContext, case: Case, snapshot: AirspaceSnapshot) -> Decision:
    """Every plan of the case is kept while the tracks predict the loss: warn (once per
    case) and, once the event is within the lead plus :data:`IMMINENT_S`, propose the
    immediate command for the UAS whose track is off its plan (all of the threat's when
    none is); until then the case is decided again at that time."""
    moved = move_end(em, case, snapshot)  # two UAS waiting after their plans: not a command
    if moved is not None:
        return moved
    t = case.threat
    now = snapshot.t_s
    off = [k for k in t.uas_ids if k in off_plan(em.td, snapshot)]
    msg = f"{t.id}: loss predicted for {', '.join(t.uas_ids)} although the plans keep "
    msg += f"separation ({', '.join(off) or 'none'} off its plan)"
    d = Decision() if case.off_plan_escalated else Decision(warnings=(msg,))
    case.off_plan_escalated = True
    event = t.predicted_event_at_s
    due_t_s = None if event is None else event - (em.plan_start(t, now) - now) - IMMINENT_S
    if due_t_s is not None and due_t_s > now:
        # decided again at due_t_s (the retry of a case that ended without a plan)
        case.attempt_t_s = due_t_s - em.config.retry_after_s
        why = f"{msg}; immediate command deferred to {due_t_s - now:.1f} s from now"
        return d.merge(Decision(audit=(em.audit(now, "immediate", t.id, {"reason": why}),)))
    return d.merge(propose(em, case, snapshot, msg, off or list(t.uas_ids)))


def propose(
    em: EmContext,
    case: Case,
    snapshot: AirspaceSnapshot,
    why: str,
    candidates: Sequence[OperationId],
    *,
    choose: bool = True,
) -> Decision:
    """Escalate with ``why`` and propose the immediate commands chosen for ``candidates``
    (the threat's safe command when nothing can be computed, or without ``choose``: not a
    loss of separation); nothing new when the same commands are already proposed or in
    force for the case."""
    now = snapshot.t_s
    t = case.threat
    if not choose:
        return escalate_safe(em, case, list(candidates), now, why)
    moved = None if too_late(em, t, now) else move_end(em, case, snapshot)
    if moved is not None:  # two UAS waiting after their plans: a new end point, in time
        return moved
    choice = commands_now(em, snapshot, candidates, t.predicted_event_at_s)
    if choice is None:
        return escalate_safe(em, case, list(candidates), now, why)
    if not choice.commands:  # every command separates them less than flying on (.fly_on)
        return flying_on(em, case, now, why, choice)
    if _standing(em, case, choice):
        stand: dict[str, object] = {"reason": f"{why}; the immediate commands stand"}
        stand["selected"] = choice.actions
        return Decision(audit=(em.audit(now, "immediate", t.id, stand),))
    how = "keeps" if choice.clear else "does not keep (the best there is)"
    text = f"{why}; immediate command {how} the minima (ratio {choice.ratio:.2f})"
    detail: dict[str, object] = {"reason": text, "selected": choice.actions}
    detail["tried"] = choice.tried
    detail["acts_in_s"] = round(em.lead.command_at(candidates, now) - now, 3)
    detail["measured_s"] = em.lead.measured()
    audit = Decision(audit=(em.audit(now, "immediate", t.id, detail),))
    ids = list(choice.commands)
    return audit.merge(escalate_safe(em, case, ids, now, text, choice.commands, choice.actions))


def held_by(em: EmContext, op_id: OperationId, other: Case) -> str:
    """The loss-of-separation case (other than ``other``) whose immediate command for
    ``op_id`` is proposed, accepted or applied ("" when none): the UAS is off its plan on
    purpose (or about to be: the pilot's answer may come in the same second, and the plan
    back would undo the command), and a conformance decision must not send it back into the
    loss (back to plan)."""
    for tid in em.open_threats():
        case = em.case(tid)
        if case is None or case is other or case.threat.kind is not ThreatKind.LOSS_OF_SEPARATION:
            continue
        rec = em.recommendation(RecommendationId(f"{tid}/{op_id}"))
        if rec is not None and rec.command is not None and rec.state in _LIVE:
            return str(tid)
    return ""


def _standing(em: EmContext, case: Case, choice: Choice) -> bool:
    """Every chosen command is already proposed or in force for its UAS in this case."""
    live = {}
    for rid in case.rec_ids:
        r = em.recommendation(rid)
        if r is not None and r.state in _LIVE and r.command is not None:
            live[r.operation_id] = r.command.kind
    return all(live.get(k) is c.kind for k, c in choice.commands.items())
