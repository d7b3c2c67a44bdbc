"""The ring a fixed wing flies round a loiter circle of its plan, for conformance. Pure.

A fixed wing's loiter is filed as points on its circle (services/fixed_wing_loiter.py: a
regular polygon, 22.5 degrees a step). The autopilot flies the circle on its navigation
controller, not on those chords: ArduPlane's L1 captures the circle with an overshoot and
tracks it outside the nominal radius by a lag that grows with speed and NAVL1_PERIOD
(measured on ArduPlane 4.6 SITL, WP_LOITER_RAD 80 m at 22 m/s, NAVL1_PERIOD 15: 81-96 m
from the centre, 16 m outside right after the capture); its radius is the vehicle's
parameter, which a plan filed with the default only approximates. So a vertex of a circle in
the plan (a run of equal legs turning equally about one centre) stands for the ring
``[rho (1 - LOITER_RING_FRACTION), rho (1 + LOITER_RING_FRACTION)]`` around that centre,
between its neighbours' altitudes, while the window reaches it. A plane that leaves its
loiter is as far from its plan as beyond that ring (and then its volume): still
non-conformant.
"""

from __future__ import annotations

import numpy as np

from gcs_utm.core.monitoring.geometry import BoolArray, FloatArray

LOITER_RING_FRACTION = 0.25
"""Half the ring's width, as a fraction of the circle's radius (16 m measured on 80 m)."""
_MAX_TURN_RAD = 0.8  # a circle's step: 22.5 deg filed; more is a corner, not a circle
_MIN_TURN_RAD = 0.05
_SAME = 0.02  # legs of a circle are equal to 2 %, their centres within 2 % of the radius
_MAX_RADIUS_M = 2000.0


def loiter_distance(
    p: FloatArray, pos: FloatArray, window: tuple[FloatArray, FloatArray]
) -> FloatArray:
    """Distance (M,) from positions (M, 3) to the loiter rings (module docstring) of their
    plans ``p`` (M, K, 4: east, north, alt, t) within the plan times ``window``; inf where
    none."""
    if p.shape[1] < 4:
        return np.full(len(pos), np.inf)
    a, b, c = p[:, :-2], p[:, 1:-1], p[:, 2:]  # (M, K-2, 4)
    centre, rho, ok = _circumcircle(a[..., :2], b[..., :2], c[..., :2])
    # a vertex of a circle: its centre shared with a neighbouring vertex
    same = np.hypot(*np.moveaxis(centre[:, 1:] - centre[:, :-1], -1, 0)) <= _SAME * rho[:, 1:]
    same &= np.abs(rho[:, 1:] - rho[:, :-1]) <= _SAME * rho[:, 1:]
    pair = ok[:, 1:] & ok[:, :-1] & same
    has_next = np.zeros_like(ok)
    has_next[:, :-1] = pair
    has_prev = np.zeros_like(ok)
    has_prev[:, 1:] = pair
    circle = ok & (has_next | has_prev)
    q = pos[:, None, :2]
    off = np.hypot(*np.moveaxis(q - centre, -1, 0))  # m from the centre
    half = LOITER_RING_FRACTION * rho
    dh = np.maximum(np.maximum(off - (rho + half), (rho - half) - off), 0.0)
    low = np.minimum(np.minimum(a[..., 2], b[..., 2]), c[..., 2])
    high = np.maximum(np.maximum(a[..., 2], b[..., 2]), c[..., 2])
    z = pos[:, None, 2]
    dv = np.maximum(np.maximum(low - z, z - high), 0.0)
    in_time = (a[..., 3] <= window[1][:, None]) & (c[..., 3] >= window[0][:, None])
    d = np.where(circle & in_time, np.hypot(dh, dv), np.inf)
    out: FloatArray = d.min(axis=1) if d.shape[1] else np.full(len(pos), np.inf)
    return out


def _circumcircle(
    a: FloatArray, b: FloatArray, c: FloatArray
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Centre (.., 2), radius (..) of the circle through each a, b, c (..., 2), and whether b
    is a vertex of a regular polygon on it: equal legs, a turn of a circle's step."""
    u, v = b - a, c - b
    lu, lv = np.hypot(u[..., 0], u[..., 1]), np.hypot(v[..., 0], v[..., 1])
    cross = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
    dot = (u * v).sum(axis=-1)
    turn = np.abs(np.arctan2(cross, dot))
    ok = (lu > 0.5) & (np.abs(lu - lv) <= _SAME * np.maximum(lu, lv))
    ok &= (turn >= _MIN_TURN_RAD) & (turn <= _MAX_TURN_RAD)
    rho = np.where(ok, lu / np.maximum(2.0 * np.sin(turn / 2.0), 1e-9), 0.0)  # m
    ok &= rho <= _MAX_RADIUS_M
    # the centre: rho from b, square to the tangent there (the mean of the legs' directions),
    # on the turn's inside
    side = np.where(cross >= 0.0, 1.0, -1.0)  # +1: a left turn (centre on the left)
    ub = (u / np.maximum(lu, 1e-9)[..., None] + v / np.maximum(lv, 1e-9)[..., None]) / 2.0
    nb = np.hypot(ub[..., 0], ub[..., 1])
    ub = ub / np.maximum(nb, 1e-9)[..., None]
    normal = side[..., None] * np.stack([-ub[..., 1], ub[..., 0]], axis=-1)
    centre = b + rho[..., None] * normal
    return centre, rho, ok
