"""The safety floor and the performance envelope every generated plan must respect.

A candidate plan of Tactical Deconfliction is dropped (with the reason) when:

- a waypoint it generated lies below ``floor_amsl_m`` (the vehicle's home altitude plus the
  configured minimum height, ``deconfliction.min_height_above_home_m``). Waypoints the filed
  plan already had (its own take-off and landing points) are not generated; nor is the final
  touchdown point of a manoeuvre that lands (return home, landing site);
- a segment asks for more than the envelope allows: horizontal speed above its maximum,
  climb above its climb rate, descent above its descent rate, or (a vehicle that cannot
  hover) a speed below its minimum. Each limit is widened to what the filed plan itself
  already asked, so a filed plan is never judged worse than it was accepted;
- (a vehicle with a turn radius R) a turn at a generated waypoint does not fit: turning by
  an angle a starts R * tan(a / 2) before the waypoint and ends as far after it, so the two
  legs must be long enough for it and for the turns at their other ends (a turn back, a
  = 180 degrees, never fits). A turn the filed plan already makes at that horizontal place
  (as much or more) is the filed plan's, at whatever height.
"""

from __future__ import annotations

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.envelope import PerformanceEnvelope

SPEED_TOLERANCE = 1.02
"""Relative slack on the speed checks: re-timing arithmetic and the WGS84 round trip move
a segment's speed by far less; a real excess (a descent at 1.8 m/s for 1.5) is caught."""
SAME_POINT_M = 0.05
"""A generated point this close to a filed waypoint is that waypoint."""
MIN_SEGMENT_S = 0.5
"""Segments shorter than this in time are not rated (a join between two legs)."""


def _rates(lp: LocalPlan) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per segment longer than MIN_SEGMENT_S: horizontal speed, climb, descent, 3D speed."""
    dt = lp.t[1:] - lp.t[:-1]
    keep = dt >= MIN_SEGMENT_S
    dt = dt[keep]
    dh = np.hypot(lp.e[1:] - lp.e[:-1], lp.n[1:] - lp.n[:-1])[keep]
    dz = (lp.z[1:] - lp.z[:-1])[keep]
    return dh / dt, np.maximum(dz, 0.0) / dt, np.maximum(-dz, 0.0) / dt, np.hypot(dh, dz) / dt


def _peak(x: np.ndarray) -> float:
    return float(x.max()) if x.size else 0.0


def envelope_flags(new: LocalPlan, old: LocalPlan, envelope: PerformanceEnvelope) -> list[str]:
    """What in ``new`` the vehicle cannot fly (empty: all inside the envelope)."""
    if len(new) < 2:
        return []
    vh, up, down, v3 = _rates(new)
    ovh, oup, odown, ov3 = _rates(old) if len(old) >= 2 else (np.zeros(0),) * 4
    flags = []
    limits = (
        ("horizontal speed", vh, max(envelope.max_speed_mps, _peak(ovh)), "m/s above"),
        ("climb", up, max(envelope.climb_rate_mps, _peak(oup)), "m/s above"),
        ("descent", down, max(envelope.descent_rate_mps, _peak(odown)), "m/s above"),
    )
    for name, got, limit, word in limits:
        if got.size and float(got.max()) > limit * SPEED_TOLERANCE:
            flags.append(f"{name} {float(got.max()):.2f} {word} the envelope's {limit:.2f}")
    if not envelope.can_hover and v3.size:
        floor = min(envelope.min_speed_mps, float(ov3.min()) if ov3.size else np.inf)
        if float(v3.min()) * SPEED_TOLERANCE < floor:
            flags.append(
                f"speed {float(v3.min()):.2f} m/s below the envelope's minimum {floor:.2f}"
            )
    return flags


def turn_flags(new: LocalPlan, old: LocalPlan, turn_radius_m: float) -> list[str]:
    """Turns at generated waypoints of ``new`` that a vehicle with this turn radius cannot
    fly within the legs around them (empty: all fit)."""
    if turn_radius_m <= 0.0 or len(new) < 3:
        return []
    de = new.e[1:] - new.e[:-1]
    dn = new.n[1:] - new.n[:-1]
    length = np.hypot(de, dn)
    keep = length > SAME_POINT_M
    if int(keep.sum()) < 2:
        return []
    # Turns between consecutive legs that move horizontally, at the point between them.
    legs = np.flatnonzero(keep)
    heading = np.arctan2(dn[legs], de[legs])
    turn = np.abs((heading[1:] - heading[:-1] + np.pi) % (2.0 * np.pi) - np.pi)
    need = turn_radius_m * np.tan(np.minimum(turn, np.pi * 0.999) / 2.0)  # m, each side
    at = legs[1:]  # waypoint index of each turn
    filed = old.xyz()
    pts = new.xyz()[at]
    generated = np.ones(at.shape[0], dtype=bool)
    if filed.shape[0]:
        dist = np.linalg.norm(pts[:, None, :] - filed[None, :, :], axis=2).min(axis=1)
        generated = (dist > SAME_POINT_M) & ~_filed_turns(pts, turn, old)
    used = np.zeros(legs.shape[0])
    used[:-1] += need  # a turn uses the end of the leg before it...
    used[1:] += need  # ...and the start of the leg after it
    short = (used[:-1] > length[legs[:-1]] * SPEED_TOLERANCE) | (
        used[1:] > length[legs[1:]] * SPEED_TOLERANCE
    )
    bad = np.flatnonzero(short & generated & (turn > np.radians(1.0)))
    if bad.size == 0:
        return []
    k = int(bad[np.argmax(turn[bad])])
    return [
        f"turn of {np.degrees(turn[k]):.0f} deg at waypoint {int(at[k])} does not fit a "
        f"{turn_radius_m:.0f} m turn radius"
    ]


def _filed_turns(pts: np.ndarray, turn: np.ndarray, old: LocalPlan) -> np.ndarray:
    """Which turns (at ``pts``, by ``turn`` radians) the filed plan ``old`` already makes
    there: a filed waypoint at the same horizontal place turning as much or more. A plan
    moved up or down (an intruder's go_up) keeps the pilot's corners at new heights: the
    vehicle flies them as it flies the filed plan (a PX4 plane's 153 deg turn towards its
    approach dropped every avoidance of an intruder), as the limits above are widened to what
    the filed plan asked."""
    out = np.zeros(pts.shape[0], dtype=bool)
    if len(old) < 3:
        return out
    de, dn = old.e[1:] - old.e[:-1], old.n[1:] - old.n[:-1]
    legs = np.flatnonzero(np.hypot(de, dn) > SAME_POINT_M)
    if legs.size < 2:
        return out
    heading = np.arctan2(dn[legs], de[legs])
    old_turn = np.abs((heading[1:] - heading[:-1] + np.pi) % (2.0 * np.pi) - np.pi)
    corner = legs[1:]  # the filed waypoint of each filed turn
    dh = np.hypot(
        pts[:, None, 0] - old.e[corner][None, :], pts[:, None, 1] - old.n[corner][None, :]
    )
    same = (dh <= SAME_POINT_M) & (turn[:, None] <= old_turn[None, :] + np.radians(1.0))
    out[:] = same.any(axis=1)
    return out


FLOOR_START_TOLERANCE_M = 1.0
"""How far below the floor a plan may start and still fly on at that height (a UAS at the
floor within its tracking error)."""


def floor_flags(new: LocalPlan, old: LocalPlan, floor_amsl_m: float, *, lands: bool) -> list[str]:
    """Generated waypoints of ``new`` below ``floor_amsl_m`` (empty: none). A plan starting
    at most :data:`FLOOR_START_TOLERANCE_M` below the floor may fly on at its start's height:
    a UAS sent down to the floor flies it within its tracking error, else nothing could be
    planned for it; one further below is still refused."""
    if len(new) and floor_amsl_m - FLOOR_START_TOLERANCE_M <= float(new.z[0]):
        floor_amsl_m = min(floor_amsl_m, float(new.z[0]))
    low = np.flatnonzero(new.z < floor_amsl_m - 1e-6)
    if lands:
        low = low[low != len(new) - 1]
    if low.size == 0:
        return []
    filed = old.xyz()
    pts = new.xyz()[low]
    if filed.shape[0]:
        dist = np.linalg.norm(pts[:, None, :] - filed[None, :, :], axis=2).min(axis=1)
        low = low[dist > SAME_POINT_M]
    if low.size == 0:
        return []
    k = int(low[np.argmin(new.z[low])])
    return [
        f"waypoint {k} at {float(new.z[k]):.1f} m AMSL, below the safety floor {floor_amsl_m:.1f} m"
    ]
