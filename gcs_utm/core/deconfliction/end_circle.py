"""A fixed wing's circle after its plan, before it is flown: what a new plan must keep clear.

A fixed wing cannot stop: when its mission ends the autopilot circles the last waypoint at
the loiter radius (:func:`gcs_utm.core.tracking.loiter.loiter_radius_m`). Until the circle is
seen on its track (:mod:`.loitering` then gives it as timed points), TD's traffic takes such
an aircraft at its last waypoint, the circle's centre (its plan, or its plan followed by a
hover there when it is airborne), and Monitoring's plan-against-plan check then measures the
distance to the centre: a new plan that ends hovering 68 m from a fixed wing's end point
(an 80 m circle) was accepted and flown 46.6 m from the circle (minima 50 m).

So each new plan, and each pair of alternatives of EM's joint selection, is also checked
against every fixed wing's circle from the time its plan stops moving on: anywhere within the
loiter radius of that point, at its altitude (the transit from the centre out to the circle
and the circle's phase and direction are not known before it is flown). A pair is flagged
when, at a time both are there, the other UAS is within the pair's minima of that disk:
``max(0, d - r) < h`` and ``|dz| < v`` (sphere mode: ``hypot(max(0, d - r), dz) < h``).
Checked at the other plan's waypoints and every :data:`STEP_S` between. Pure.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from gcs_utm.core.deconfliction.geometry import LocalPlan
from gcs_utm.core.tracking.loiter import loiter_radius_m
from gcs_utm.model import FlightPlan, Operation

STEP_S = 0.5
"""Spacing of the checked times: a multirotor moves 5 m between them at 10 m/s."""
SAME_POINT_M = 1.0
"""Points of a plan's tail this close horizontally are one point (a hover, a hold)."""


def circle_from(lp: LocalPlan) -> tuple[float, float, float, float]:
    """(time, east, north, alt) from which the plan stays at its last horizontal point: the
    first waypoint of the tail that does not move (its hover after the end, or its end)."""
    k = len(lp) - 1
    e, n = float(lp.e[k]), float(lp.n[k])
    while k > 0 and math.hypot(float(lp.e[k - 1]) - e, float(lp.n[k - 1]) - n) <= SAME_POINT_M:
        k -= 1
    return float(lp.t[k]), e, n, float(lp.z[k])


def _one_way(  # noqa: PLR0917 - the pair as the caller has it
    circling: LocalPlan,
    radius_m: float,
    other: LocalPlan,
    h_m: float,
    v_m: float,
    spherical: bool,
) -> float | None:
    """The first time ``other`` comes within the minima of the circle of ``circling``'s end
    (None: never)."""
    t0, ce, cn, cz = circle_from(circling)
    t1 = float(other.t[-1])
    if t1 < t0 or len(other) < 1:
        return None
    start = max(t0, float(other.t[0]))
    grid = np.arange(start, t1 + 1e-9, STEP_S)
    inner = other.t[(other.t > start) & (other.t < t1)]
    times = np.unique(np.concatenate((grid, inner, [t1])))
    e, n, z = other.coords(times)
    off_m = np.maximum(np.hypot(e - ce, n - cn) - radius_m, 0.0)
    dz = np.abs(z - cz)
    hit = np.hypot(off_m, dz) < h_m if spherical else (off_m < h_m) & (dz < v_m)
    if not hit.any():
        return None
    return float(times[int(np.argmax(hit))])


def _both(
    a: tuple[LocalPlan, float], b: tuple[LocalPlan, float], h_m: float, v_m: float, spherical: bool
) -> float | None:
    """When two fixed wings both circle their end points: the time from which both do, if the
    circles come within the minima (None: they do not)."""
    ta, ea, na, za = circle_from(a[0])
    tb, eb, nb, zb = circle_from(b[0])
    t = max(ta, tb)
    off_m = max(math.hypot(ea - eb, na - nb) - a[1] - b[1], 0.0)
    dz = abs(za - zb)
    close = math.hypot(off_m, dz) < h_m if spherical else off_m < h_m and dz < v_m
    return t if close else None


def circle_flags(
    op: Operation,
    plan: LocalPlan,
    others: Sequence[tuple[Operation, LocalPlan]],
    minima: Callable[[Operation, Operation], tuple[float, float]],
    spherical: bool,
) -> list[str]:
    """Flags of ``op`` flying ``plan`` against ``others`` (each with its plan as TD takes it)
    when either of a pair is a fixed wing whose end circle the other comes within the pair's
    minima of (see the module doc); [] when none does."""
    flags = []
    r_own = loiter_radius_m(op)
    for o, lp in others:
        if o.id == op.id:
            continue
        r_other = loiter_radius_m(o)
        if r_own <= 0.0 and r_other <= 0.0:
            continue
        h, v = minima(op, o)
        hits: list[tuple[float | None, str]] = []
        if r_own > 0.0:
            hits.append((_one_way(plan, r_own, lp, h, v, spherical), str(op.id)))
        if r_other > 0.0:
            hits.append((_one_way(lp, r_other, plan, h, v, spherical), str(o.id)))
        if r_own > 0.0 and r_other > 0.0:
            hits.append((_both((plan, r_own), (lp, r_other), h, v, spherical), f"{op.id}, {o.id}"))
        found = sorted((t, who) for t, who in hits if t is not None)
        if found:
            t, who = found[0]
            flags.append(f"separation with {o.id} at t={t:.1f} (circle of {who} after its plan)")
    return flags


def plans_of(
    others: Sequence[Operation], local: Callable[[FlightPlan], LocalPlan]
) -> list[tuple[Operation, LocalPlan]]:
    """Each operation with its plan in the local frame."""
    return [(o, local(o.plan)) for o in others]
