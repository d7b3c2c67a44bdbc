"""Mission items as a vehicle runs them (pure): the order DO_JUMP loops give them, the
parameters of the items the plan models (loiters, take-off), and the item a PX4 mission
started on the ground really starts from. Used by :mod:`.vehicle_ops`."""

from __future__ import annotations

from collections.abc import Sequence

from gcs_utm.messages import VehicleStatus
from gcs_utm.model import Autopilot
from gcs_utm.services import fixed_wing_point as fwp

_DO_JUMP = 177
_JUMP_ITEMS_MAX = 500
"""A mission with DO_JUMP loops is filed as flown up to this many items."""


def flown_order(items: Sequence[object]) -> list[tuple[int, object]]:
    """(index, item) in the order the autopilot runs them: a DO_JUMP (param1 the target
    seq, param2 the repeats, -1 forever) sends it back that many times, up to
    :data:`_JUMP_ITEMS_MAX` items in all (a loop forever is filed that far). Without a jump,
    the items as they are."""
    seqs = {int(getattr(it, "seq", i)): i for i, it in enumerate(items)}
    left: dict[int, int] = {}
    out: list[tuple[int, object]] = []
    i = 0
    while i < len(items) and len(out) < _JUMP_ITEMS_MAX:
        it = items[i]
        out.append((i, it))
        if int(getattr(it, "command", -1)) == _DO_JUMP:
            repeats = int(getattr(it, "param2", 0.0))
            left.setdefault(i, repeats if repeats >= 0 else _JUMP_ITEMS_MAX)
            target = seqs.get(int(getattr(it, "param1", -1)))
            if left[i] > 0 and target is not None:
                left[i] -= 1
                i = target
                continue
        i += 1
    return out


def item_params(it: object, command: int) -> tuple[float, float]:
    """(radius, turns, seconds or pitch) of a loiter or take-off item (MAVLink:
    LOITER_TO_ALT radius in param2; LOITER_TURNS and LOITER_TIME turns/seconds in param1,
    radius in param3; NAV_TAKEOFF a fixed wing's minimum pitch in param1)."""
    if command == fwp.NAV_TAKEOFF:
        return 0.0, float(getattr(it, "param1", 0.0))
    if command == fwp.NAV_LOITER_TO_ALT:
        return float(getattr(it, "param2", 0.0)), 0.0
    if command in (fwp.NAV_LOITER_TURNS, fwp.NAV_LOITER_TIME):
        return float(getattr(it, "param3", 0.0)), float(getattr(it, "param1", 0.0))
    return 0.0, 0.0


def current_seq(
    s: VehicleStatus, autopilot: Autopilot, stale: int | None, started: bool
) -> tuple[int | None, int | None]:
    """(the item the vehicle runs, a stale MISSION_CURRENT seq to read as item 0 until it
    changes) at status ``s`` (its MISSION_CURRENT seq and item count); ``started``: it
    switched to a mission mode armed at this status.

    PX4 v1.15 (``MissionBase::checkMissionRestart``, on activating the mission) goes back to
    item 0 when it was disarmed since the mission last ran and its current item is the last
    (a mission flown to its landing): its MISSION_CURRENT goes on saying the last item for a
    moment after the arming and the switch to MISSION. Taken as it came, a plane's second
    flight was planned from its landing item, a line from where it stood to the landing
    point behind it (UAS_OUT_OV 32.6 m as it rolled, an auto-accepted hold). A start on the
    ground (landed) stands for the disarm: PX4 disarms itself after a landing."""
    seq, total = s.mission_seq, s.mission_total
    if seq is None:
        return None, stale
    if stale is not None and seq == stale:
        return 0, stale
    restarts = started and s.landed is True and autopilot is Autopilot.PX4
    if restarts and total is not None and total > 1 and seq + 1 == total:
        return 0, seq
    return seq, None
