"""Mission items as a vehicle runs them (pure): the order DO_JUMP loops give them, and the
parameters of the items the plan models (loiters, take-off). Used by :mod:`.vehicle_ops`."""

from __future__ import annotations

from collections.abc import Sequence

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
