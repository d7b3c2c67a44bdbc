"""Recommendations in a pilot's words: each option as an action and its effect, a command as
what the vehicle will do, and one line saying why the proposed option was chosen.

Pure functions of the recommendation's data (no I/O, no clock): the dashboard, the line
prompt, the MQTT recommendation (``text`` of each option) and ``gcs-utm pilot`` all show the
same words. The raw scores (cost, risk, the scoring terms of ``detail``) stay available
behind a key for whoever wants them.

An option reads as: verb, by how much, the extra flight (time and distance), the closest
separation it keeps from another UAS in metres against the minima that separation was
judged by (the pair's effective minima, see ``Closest``), and the clearance from geofences:

    Descend up to 36 m below the plan: 21 s and 36 m more flight; keeps 62 m vertically
    from UAS2 (min 50 m h / 30 m v); 120 m from geofences
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from gcs_utm.model import Alternative, Closest, Command, CommandKind, Maneuver, Recommendation

_ACTIONS: dict[Maneuver, str] = {
    Maneuver.GO_UP: "Climb up to {m} above the plan",
    Maneuver.GO_DOWN: "Descend up to {m} below the plan",
    Maneuver.GO_LEFT: "Turn left, up to {m} off the plan",
    Maneuver.GO_RIGHT: "Turn right, up to {m} off the plan",
    Maneuver.DELAY: "Hold {s} where it is, then fly the plan",
    Maneuver.SPEED_CHANGE: "Fly the plan slower",
    Maneuver.REROUTE: "Reroute around the geofence, up to {m} off the plan",
    Maneuver.ESCAPE: "Leave the geofence by the shortest way",
    Maneuver.DIRECT_TO_GOAL: "Fly direct to the last waypoint",
    Maneuver.BACK_TO_PLAN: "Return to the plan",
    Maneuver.NEXT_WAYPOINT: "Fly straight to the next waypoint",
    Maneuver.RETURN_HOME: "Return home",
    Maneuver.LANDING_SITE: "Divert and land at a landing site",
    Maneuver.KEEP_PLAN: "Keep the current plan",
    Maneuver.HOLD: "Hold at the current position",
    Maneuver.LAND: "Land now",
    Maneuver.VERTICAL_AVOIDANCE: "Climb or descend away from the intruder, up to {m}",
    Maneuver.MOVE_END: "Move the end point {m} away from traffic and wait there",
}

_COMMANDS: dict[CommandKind, str] = {
    CommandKind.HOLD: "Hold at the current position (brake and hover; a fixed wing circles)",
    CommandKind.LAND: "Land now where it is",
    CommandKind.RTL: "Return to launch",
    CommandKind.RESUME: "Resume the mission",
    CommandKind.GOTO: "Climb or descend in place",
}


def _m(value: float | None) -> str:
    return "?" if value is None or not math.isfinite(value) else f"{value:.0f} m"


def action_text(alt: Alternative) -> str:
    """What the UAS will do under ``alt``: verb and by how much (metres, seconds)."""
    template = _ACTIONS.get(alt.maneuver, alt.maneuver.value.replace("_", " ").capitalize())
    seconds = "?" if alt.extra_time_s is None else f"{alt.extra_time_s:.0f} s"
    text = template.format(m=_m(alt.offset_m), s=seconds)
    if alt.offset_m is None and "{m}" in template:  # size not known: say only the verb
        text = template.split(",")[0].replace(" up to {m}", "").format(s=seconds)
    return text


def extra_text(alt: Alternative) -> str:
    """The extra flight: "21 s and 36 m more flight" / "no extra flight"."""
    t = alt.extra_time_s if alt.extra_time_s is not None else 0.0
    d = alt.extra_length_m if alt.extra_length_m is not None else 0.0
    if alt.extra_time_s is None and alt.extra_length_m is None:
        return ""
    if round(t) <= 0 and round(d) <= 0:
        return "no extra flight"
    return f"{t:.0f} s and {d:.0f} m more flight"


def minima_text(c: Closest) -> str:
    """The minima a separation is judged by: "min 50 m h / 30 m v" ("min 50 m" in 3D)."""
    if c.spherical:
        return f"min {c.min_horizontal_m:.0f} m"
    return f"min {c.min_horizontal_m:.0f} m h / {c.min_vertical_m:.0f} m v"


def separation_text(c: Closest) -> str:
    """The closest separation kept, on the axis that keeps it (cylinder rule: separated when
    either axis is at its minimum), in metres, with the minima."""
    other = f" from {c.other}" if c.other else ""
    if c.spherical:
        d = math.hypot(c.horizontal_m, c.vertical_m)
        verb = "keeps" if d >= c.min_horizontal_m else "comes within"
        return f"{verb} {d:.0f} m{other} ({minima_text(c)})"
    ratio_h = c.horizontal_m / c.min_horizontal_m if c.min_horizontal_m > 0 else math.inf
    ratio_v = c.vertical_m / c.min_vertical_m if c.min_vertical_m > 0 else math.inf
    verb = "keeps" if max(ratio_h, ratio_v) >= 1.0 else "comes within"
    if ratio_h >= ratio_v:
        return f"{verb} {c.horizontal_m:.0f} m horizontally{other} ({minima_text(c)})"
    return f"{verb} {c.vertical_m:.0f} m vertically{other} ({minima_text(c)})"


def fence_text(fence_m: float | None) -> str:
    """Clearance from the active geofences ("" when none is near)."""
    if fence_m is None:
        return ""
    if fence_m < 0:
        return f"enters a geofence by {-fence_m:.0f} m"
    return f"{fence_m:.0f} m from geofences"


def effect_text(alt: Alternative) -> str:
    """The effect of ``alt``: extra flight; separation kept; fence clearance."""
    parts = [extra_text(alt)]
    if alt.closest is not None:
        parts.append(separation_text(alt.closest))
    elif alt.separation_ratio is not None:
        parts.append(f"keeps {alt.separation_ratio:.1f}x the minima from the other UAS")
    parts.append(fence_text(alt.fence_distance_m))
    return "; ".join(p for p in parts if p)


def option_text(alt: Alternative) -> str:
    """One option as an action and its effect."""
    effect = effect_text(alt)
    return f"{action_text(alt)}: {effect}" if effect else action_text(alt)


def command_text(cmd: Command, alt_now_amsl_m: float | None = None) -> str:
    """A command as what the vehicle will do (a GOTO in place names its altitude, and with
    the UAS's altitude now, whether it climbs or descends and by how much)."""
    if cmd.kind is CommandKind.GOTO and cmd.target is not None:
        to = cmd.target.alt_amsl_m
        if alt_now_amsl_m is None:
            return f"Climb or descend in place to {to:.0f} m AMSL and hover"
        if abs(to - alt_now_amsl_m) < 1.0:  # a fixed wing's turn (emergency.turn)
            return f"Turn towards a point far abeam and fly on at {to:.0f} m AMSL"
        verb = "Climb" if to >= alt_now_amsl_m else "Descend"
        return f"{verb} {abs(to - alt_now_amsl_m):.0f} m in place to {to:.0f} m AMSL and hover"
    return _COMMANDS.get(cmd.kind, cmd.kind.value)


def options(rec: Recommendation) -> list[Alternative]:
    """The options in prompt order: the proposed one first, then the alternatives."""
    return ([rec.selected] if rec.selected is not None else []) + list(rec.alternatives)


def _lowest(values: Sequence[float], i: int) -> bool:
    return all(values[i] <= v + 1e-12 for v in values)


def why_text(rec: Recommendation) -> str:
    """One line saying why the proposed option (or command) was proposed."""
    if rec.selected is None:
        if rec.command is None:
            return rec.reason
        return f"safe command: {rec.reason}" if rec.reason else "safe command"
    return _why_option(options(rec))


def _why_option(opts: list[Alternative]) -> str:
    """Why ``opts[0]`` (the proposed option) rather than the others."""
    n = len(opts)
    clears = [o.fence_distance_m is None or o.fence_distance_m >= 0 for o in opts]
    cheapest = _lowest([o.cost for o in opts], 0)
    safest = _lowest([o.risk for o in opts], 0)
    if n == 1:
        why = "the only option that keeps the minima"
    elif clears[0] and not any(clears[1:]):
        why = f"the only option of {n} clearing the geofences"
    elif cheapest or safest:
        what = " and ".join(w for w, ok in (("cost", cheapest), ("risk", safest)) if ok)
        why = f"lowest {what} among {n} safe options"
    elif opts[0].maneuver is Maneuver.KEEP_PLAN:
        why = "the other UAS's new plans resolve the conflict: this UAS keeps its plan"
    else:
        why = f"best together with the other UAS's options (joint selection among {n})"
    return why


def proposal_text(rec: Recommendation) -> str:
    """The proposal in one line: the proposed option's words, else the command's."""
    if rec.selected is not None:
        return option_text(rec.selected)
    if rec.command is not None:
        return command_text(rec.command)
    return "no action proposed"
