"""Seeded encounter generator: scenario files (the TOML of ``gcs-utm run``) of 2-6 UAS whose
filed plans meet, for fast-time closed-loop evaluation (``gcs-utm eval --generate N --seed S``).

Kinds (cycled, so every kind is in any set of 5 or more):
- ``crossing``: two straight tracks crossing at 45-135 deg, at the same time, missing by less
  than the pair's effective horizontal minimum;
- ``head_on``: opposite tracks, laterally offset by less than the minimum;
- ``overtaking``: same track, the faster UAS catches the slower one;
- ``vertical``: crossing tracks, one of them climbing or descending through the other's level
  at the crossing (at 80 % of its envelope's climb or descent rate);
- ``near_threshold``: crossing tracks whose miss distance is within a few metres of the pair's
  effective minimum, on either side (some are losses, some are not).
Each encounter mixes multirotors and fixed wings (speeds, volumes and climb rates of their
kind); UAS beyond the first pair either join the conflict at the same point or fly elsewhere,
and are placed only where no pair is near a loss of separation earlier than ``WARNING_S``
before the conflict (an encounter develops in flight; it does not start in a loss);
about half the encounters have a cylinder geofence beside the conflict (never on a filed
path), which a resolution must not enter. Two origins are used (Madrid, Seville) so frames far
from the UTM zone's central meridian are exercised.

Profiles (:data:`PROFILES`, docs/evaluation.md) change what the encounters stress: ``late``
(a UAS appears 3-15 s before the loss), ``lag`` (vehicles 2-15 s behind their filed plans),
``endpoint`` (a plan ends at the conflict point), ``fence`` (a geofence crossing, touching
or around filed paths and destinations), ``vertical`` (centimetres from the vertical
minimum), ``merge`` (3-6 UAS converging), ``mixed`` (a multirotor and a fixed wing);
``classic`` is the set above, ``all`` cycles through them.

Every filed plan, in every profile, is one its vehicle flies: within its envelope
(:mod:`gcs_utm.envelope`, which the simulated vehicle flies too) in vertical rates and speed,
and straight (no turn for a fixed wing's radius); the filing rule (:mod:`gcs_utm.flyable`)
accepts every generated file.

Units: metres east/north of the airspace origin (ENU), metres above ground, seconds after the
scenario start. Everything comes from ``random.Random(seed)``: the same seed gives the same files.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import random
from dataclasses import dataclass
from pathlib import Path

from gcs_utm.envelope import implied

KINDS = ("crossing", "head_on", "overtaking", "vertical", "near_threshold")
PROFILES = ("classic", "late", "lag", "endpoint", "fence", "vertical", "merge", "mixed")
"""Generator profiles (docs/evaluation.md); ``all`` cycles through them."""

ORIGINS: tuple[tuple[str, float, float, float], ...] = (
    # name, lat_deg, lon_deg, ground elevation m AMSL
    ("madrid", 40.65974645776713, -3.59689676974471, 675.0),
    ("seville", 37.3891, -5.9845, 10.0),
)

SEPARATION_H_M = 50.0  # MonitoringConfig defaults the encounters are designed around
SEPARATION_V_M = 15.0
CONFLICT_AT_S = (80.0, 110.0)  # when the first pair meets: time to detect, decide and fly
AFTER_S = 50.0  # flown after the conflict point
LEAD_IN_S = (60.0, 75.0)  # flown before it
WARNING_S = 30.0  # no pair of UAS is within its minima (plus a margin) earlier than this
# before the first pair's conflict time
FIRST_CLEAR_S = 3.0
"""Nor within it in the first seconds after the later of two UAS appears: the late
profile's shortest warning (3-15 s). A loss that begins under a second after a UAS appears
is one no system can act on; it measures the generator, not the UTM."""
_TRIES = 20
VERTICAL_RATE_SHARE = 0.8
"""A climbing or descending plan asks for this share of the vehicle's envelope rate."""


Waypoint = tuple[float, float, float, float]
"""east_m, north_m, alt_agl_m, t_s of one filed waypoint."""


@dataclass(frozen=True, slots=True, kw_only=True)
class _Uas:
    """One generated operation: a straight (or climbing) track through ``point`` at ``t_s``."""

    id: str
    fixed_wing: bool
    speed_mps: float
    heading_deg: float
    point: tuple[float, float]  # east_m, north_m at the conflict time
    alt_agl_m: float
    t_s: float
    climb_m: float = 0.0  # altitude change across the conflict point (vertical kind)
    priority: int = 5

    @property
    def volume_m(self) -> float:
        return 25.0 if self.fixed_wing else 15.0

    @property
    def geometry_m(self) -> float:
        return 15.0 if self.fixed_wing else 8.0

    @property
    def climb_rate_mps(self) -> float:
        return 5.0 if self.fixed_wing else 2.0

    def vertical_rate_mps(self) -> float:
        """The rate its plan climbs or descends at: 80 % of its envelope's (the UTM's and the
        simulated vehicle's, :func:`gcs_utm.envelope.implied`) climb or descent rate, so the
        filed plan is one the vehicle flies (a fixed wing descends at 3 m/s, not at its 5 m/s
        climb rate)."""
        env = implied(self.fixed_wing, self.speed_mps, self.climb_rate_mps)
        return VERTICAL_RATE_SHARE * (
            env.climb_rate_mps if self.climb_m > 0.0 else env.descent_rate_mps
        )

    def waypoints(self, lead_in_s: float) -> list[Waypoint]:
        """(east_m, north_m, alt_agl_m, t_s) of the filed plan."""
        h = math.radians(self.heading_deg)
        de, dn = math.sin(h) * self.speed_mps, math.cos(h) * self.speed_mps  # m/s

        def at(dt_s: float, alt_m: float) -> tuple[float, float, float, float]:
            return (
                round(self.point[0] + de * dt_s, 2),
                round(self.point[1] + dn * dt_s, 2),
                round(alt_m, 2),
                round(self.t_s + dt_s, 3),
            )

        if self.climb_m == 0.0:
            return [at(-lead_in_s, self.alt_agl_m), at(AFTER_S, self.alt_agl_m)]
        half_s = abs(self.climb_m) / self.vertical_rate_mps() / 2.0
        lo, hi = self.alt_agl_m - self.climb_m / 2.0, self.alt_agl_m + self.climb_m / 2.0
        if lead_in_s < half_s:  # appears already climbing (late profile)
            u = (half_s - lead_in_s) / (2.0 * half_s)
            return [at(-lead_in_s, lo + u * (hi - lo)), at(half_s, hi), at(AFTER_S, hi)]
        return [
            at(-lead_in_s, lo),
            at(-half_s, lo),
            at(half_s, hi),
            at(AFTER_S, hi),
        ]


@dataclass(frozen=True, slots=True, kw_only=True)
class Encounter:
    """One generated scenario: its file text and what it was built to contain."""

    name: str
    kind: str
    profile: str
    n_uas: int
    fixed_wings: int
    geofence: bool
    origin: str
    toml: str


def _effective_h_m(a: _Uas, b: _Uas) -> float:
    return max(SEPARATION_H_M, a.volume_m + b.volume_m)


def _speed(rng: random.Random, fixed_wing: bool) -> float:
    return round(rng.uniform(16.0, 24.0) if fixed_wing else rng.uniform(4.0, 10.0), 1)


def _offset(point: tuple[float, float], heading_deg: float, side_m: float) -> tuple[float, float]:
    """``point`` moved ``side_m`` to the right of ``heading_deg``."""
    h = math.radians(heading_deg + 90.0)
    return (point[0] + math.sin(h) * side_m, point[1] + math.cos(h) * side_m)


def _pair(
    rng: random.Random,
    kind: str,
    centre: tuple[float, float],
    t_s: float,
    *,
    fixed_wings: tuple[bool, bool] | None = None,
) -> list[_Uas]:
    """The first two UAS, meeting at ``centre`` at ``t_s`` as the kind says (``fixed_wings``:
    their vehicle kinds, else drawn: a fixed wing with probability 0.35)."""
    fw = [rng.random() < 0.35, rng.random() < 0.35]
    if fixed_wings is not None:
        fw = list(fixed_wings)
    h1 = rng.uniform(0.0, 360.0)
    alt = rng.uniform(50.0, 110.0)
    if kind == "overtaking":
        fw[1] = fw[1] or fw[0]  # the overtaking one is at least as fast a kind
        v_slow = _speed(rng, fw[0])
        v_fast = max(_speed(rng, fw[1]), v_slow + 4.0)
        side = rng.uniform(0.0, 20.0)
        a = _Uas(
            id="UAS1",
            fixed_wing=fw[0],
            speed_mps=v_slow,
            heading_deg=h1,
            point=centre,
            alt_agl_m=alt,
            t_s=t_s,
        )
        b = _Uas(
            id="UAS2",
            fixed_wing=fw[1],
            speed_mps=v_fast,
            heading_deg=h1,
            point=_offset(centre, h1, side),
            alt_agl_m=alt + rng.uniform(-5.0, 5.0),
            t_s=t_s,
        )
        return [a, b]
    if kind == "head_on":
        h2 = h1 + 180.0
    else:
        h2 = h1 + rng.choice((-1.0, 1.0)) * rng.uniform(45.0, 135.0)
    a = _Uas(
        id="UAS1",
        fixed_wing=fw[0],
        speed_mps=_speed(rng, fw[0]),
        heading_deg=h1,
        point=centre,
        alt_agl_m=alt,
        t_s=t_s,
    )
    b = _Uas(
        id="UAS2",
        fixed_wing=fw[1],
        speed_mps=_speed(rng, fw[1]),
        heading_deg=h2 % 360.0,
        point=centre,
        alt_agl_m=alt,
        t_s=t_s,
    )
    minimum = _effective_h_m(a, b)
    if kind == "near_threshold":
        miss = minimum + rng.uniform(-6.0, 6.0)
    else:
        miss = rng.uniform(0.0, 0.7 * minimum)
    # offset across the relative velocity: the closest approach of the two straight tracks
    # is then exactly ``miss``, at the conflict time
    ha, hb = math.radians(a.heading_deg), math.radians(b.heading_deg)
    rel_e = math.sin(hb) * b.speed_mps - math.sin(ha) * a.speed_mps  # m/s
    rel_n = math.cos(hb) * b.speed_mps - math.cos(ha) * a.speed_mps
    b_point = _offset(centre, math.degrees(math.atan2(rel_e, rel_n)), miss)
    climb = 0.0
    b_alt = alt + (rng.uniform(-4.0, 4.0) if kind != "near_threshold" else 0.0)
    if kind == "vertical":
        climb = rng.choice((-1.0, 1.0)) * rng.uniform(30.0, 50.0)
        b_alt = alt
    b = _Uas(
        id="UAS2",
        fixed_wing=fw[1],
        speed_mps=b.speed_mps,
        heading_deg=b.heading_deg,
        point=b_point,
        alt_agl_m=b_alt,
        t_s=t_s,
        climb_m=climb,
    )
    return [a, b]


def _extra(
    rng: random.Random, k: int, centre: tuple[float, float], t_s: float, *, join: bool | None
) -> _Uas:
    """UAS number ``k`` (3..6): joins the conflict at the centre, or flies 600+ m away
    (``join``: always joins; None: one or the other with equal chance)."""
    fw = rng.random() < 0.35
    heading = rng.uniform(0.0, 360.0)
    alt = rng.uniform(50.0, 110.0)
    if rng.random() < 0.5 or join:
        point = _offset(centre, heading, rng.uniform(-20.0, 20.0))
        when = t_s + rng.uniform(-6.0, 6.0)
    else:
        away = rng.uniform(0.0, 2.0 * math.pi)
        point = (centre[0] + 700.0 * math.sin(away), centre[1] + 700.0 * math.cos(away))
        when = t_s
    return _Uas(
        id=f"UAS{k}",
        fixed_wing=fw,
        speed_mps=_speed(rng, fw),
        heading_deg=heading,
        point=point,
        alt_agl_m=alt,
        t_s=when,
    )


def _at(plan: list[Waypoint], t_s: float) -> tuple[float, float, float]:
    """Position on a filed plan at ``t_s`` (clamped to its ends)."""
    if t_s <= plan[0][3]:
        return plan[0][:3]
    for a, b in itertools.pairwise(plan):
        if t_s <= b[3]:
            u = (t_s - a[3]) / (b[3] - a[3])
            return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))
    return plan[-1][:3]


def _apart_until(
    pa: list[Waypoint],
    pb: list[Waypoint],
    minima_m: tuple[float, float],
    until_t_s: float,
) -> bool:
    """Are two filed plans clear of each other (with 10 m / 5 m to spare on ``minima_m``, the
    pair's effective horizontal and vertical minima) while both fly, up to ``until_t_s`` and
    for at least :data:`FIRST_CLEAR_S` after the later one appears? An encounter must
    develop in flight, with time to resolve it: two UAS must not start in (or seconds from)
    a loss of separation."""
    t = max(pa[0][3], pb[0][3])
    end = max(until_t_s, t + FIRST_CLEAR_S)
    while t <= end:
        a, b = _at(pa, t), _at(pb, t)
        if math.hypot(a[0] - b[0], a[1] - b[1]) < minima_m[0] + 10.0 and abs(a[2] - b[2]) < (
            minima_m[1] + 5.0
        ):
            return False
        t += 0.5
    return True


def _minima_m(a: _Uas, b: _Uas) -> tuple[float, float]:
    """The pair's effective minima (horizontal, vertical), as Monitoring grows them with the
    two volumes (as :func:`_loss_start` takes them)."""
    return _effective_h_m(a, b), max(SEPARATION_V_M, a.volume_m + b.volume_m)


def _segment_distance_m(
    p: tuple[float, float], a: tuple[float, float], b: tuple[float, float]
) -> float:
    ax, ay = b[0] - a[0], b[1] - a[1]
    n2 = ax * ax + ay * ay
    u = 0.0 if n2 == 0.0 else max(0.0, min(1.0, ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / n2))
    return math.hypot(p[0] - a[0] - u * ax, p[1] - a[1] - u * ay)


def _geofence(
    rng: random.Random, centre: tuple[float, float], paths: list[list[tuple[float, float]]]
) -> tuple[float, float, float] | None:
    """A cylinder (east_m, north_m, radius_m) beside the conflict, clear of every filed path by
    at least its radius plus 40 m; None when 20 tries found no such place."""
    for _ in range(20):
        radius = rng.uniform(30.0, 70.0)
        bearing = rng.uniform(0.0, 2.0 * math.pi)
        dist = radius + rng.uniform(60.0, 140.0)
        c = (centre[0] + dist * math.sin(bearing), centre[1] + dist * math.cos(bearing))
        clear = all(
            _segment_distance_m(c, path[i], path[i + 1]) >= radius + 40.0
            for path in paths
            for i in range(len(path) - 1)
        )
        if clear:
            return (round(c[0], 2), round(c[1], 2), round(radius, 1))
    return None


def _classic_uas(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> tuple[list[_Uas], dict[str, list[Waypoint]]]:
    """Today's encounter: the pair of the kind, then extras placed where they are clear."""
    uas = _pair(rng, kind, centre, t_c)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=n_uas)
    return uas, plans


def _add_extras(
    rng: random.Random,
    uas: list[_Uas],
    plans: dict[str, list[Waypoint]],
    *,
    centre: tuple[float, float],
    t_c: float,
    n_uas: int,
    join: bool | None = None,
) -> None:
    """UAS 3..n_uas, each placed only where it is clear of the others until WARNING_S before
    the conflict (``join``: all join the conflict point; None: half of them)."""
    for k in range(len(uas) + 1, n_uas + 1):
        for _ in range(_TRIES):
            extra = _extra(rng, k, centre, t_c, join=join)
            wps = extra.waypoints(min(rng.uniform(*LEAD_IN_S), extra.t_s - 5.0))
            if all(
                _apart_until(wps, plans[u.id], _minima_m(extra, u), t_c - WARNING_S) for u in uas
            ):
                break
        else:
            continue  # no place for one more UAS: the encounter has fewer
        uas.append(extra)
        plans[extra.id] = wps


@dataclass(frozen=True, slots=True, kw_only=True)
class _Built:
    """What a profile builds: the UAS, their filed plans, a geofence (east_m, north_m,
    radius_m) and vehicles' start delays (s after their filed start: they lag their plan)."""

    uas: list[_Uas]
    plans: dict[str, list[Waypoint]]
    fence: tuple[float, float, float] | None = None
    delays_s: dict[str, float] = dataclasses.field(default_factory=dict)


def _build_classic(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    uas, plans = _classic_uas(rng, kind, centre, t_c, n_uas)
    return _Built(uas=uas, plans=plans)


def _build_late(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """UAS2 appears in flight 3-15 s before it meets UAS1: no time for a planned fix."""
    uas = _pair(rng, kind, centre, t_c)
    a, b = uas
    plan_a = a.waypoints(min(rng.uniform(*LEAD_IN_S), a.t_s - 5.0))
    # the loss of the two filed plans begins before the closest approach at t_c
    full_b = b.waypoints(min(LEAD_IN_S[0], b.t_s - 5.0))
    loss_at = min(t_c, _loss_start(plan_a, full_b, _effective_h_m(a, b), a.volume_m + b.volume_m))
    plans = {a.id: plan_a, b.id: b.waypoints(t_c - loss_at + rng.uniform(3.0, 15.0))}
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=n_uas)
    return _Built(uas=uas, plans=plans)


def _build_lag(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """Vehicles that fly 2-15 s behind their filed plans (a late start, as a slow take-off or
    a pilot's delay gives): each lagging UAS's plan is filed that much earlier than it flies,
    so the flown encounter is the designed one and the plans disagree with it."""
    uas, plans = _classic_uas(rng, kind, centre, t_c, n_uas)
    delays: dict[str, float] = {}
    for u in uas:
        if u.id == "UAS2" or rng.random() < 0.5:
            lag_s = round(min(rng.uniform(2.0, 15.0), plans[u.id][0][3] - 1.0), 1)
            if lag_s > 0.0:
                plans[u.id] = [(e, n, a, round(t - lag_s, 3)) for e, n, a, t in plans[u.id]]
                delays[u.id] = lag_s
    return _Built(uas=uas, plans=plans, delays_s=delays)


def _loss_start(pa: list[Waypoint], pb: list[Waypoint], min_h_m: float, floor_v_m: float) -> float:
    """When two filed plans first come inside the minima (sampled every 0.1 s; the end of
    the shorter when they never do)."""
    v_min = max(SEPARATION_V_M, floor_v_m)
    t, end = max(pa[0][3], pb[0][3]), min(pa[-1][3], pb[-1][3])
    while t <= end:
        a, b = _at(pa, t), _at(pb, t)
        if math.hypot(a[0] - b[0], a[1] - b[1]) < min_h_m and abs(a[2] - b[2]) < v_min:
            return t
        t += 0.1
    return end


def _cut(plan: list[Waypoint], t_end_s: float) -> list[Waypoint]:
    """``plan`` ending at ``t_end_s`` (its position then as the last waypoint)."""
    e, n, a = _at(plan, t_end_s)
    kept = [w for w in plan if w[3] < t_end_s - 0.5]
    return [*kept, (round(e, 2), round(n, 2), round(a, 2), round(t_end_s, 3))]


def _build_endpoint(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """UAS2's plan ends at the conflict point (a multirotor hovers there, a fixed wing circles
    it); UAS1 passes there 5-40 s later. Sometimes UAS1's plan ends nearby too."""
    uas = _pair(rng, kind, centre, t_c)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    plans["UAS2"] = _cut(plans["UAS2"], t_c)
    first = plans["UAS1"]
    for _ in range(_TRIES):  # UAS1 must not appear on top of UAS2 (FIRST_CLEAR_S)
        dt_s = rng.uniform(5.0, 40.0)
        plans["UAS1"] = [(e, n, a, round(t + dt_s, 3)) for e, n, a, t in first]
        if _apart_until(plans["UAS1"], plans["UAS2"], _minima_m(*uas), 0.0):
            break
    if rng.random() < 0.3:
        plans["UAS1"] = _cut(plans["UAS1"], t_c + dt_s + rng.uniform(0.0, 10.0))
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=n_uas)
    return _Built(uas=uas, plans=plans)


def _fence_on_paths(
    rng: random.Random, plans: dict[str, list[Waypoint]]
) -> tuple[float, float, float] | None:
    """A cylinder crossing a filed path, touching one (its edge within 3 m of it), or around a
    destination, never around a UAS's first waypoint (it would start inside)."""
    paths = [[(w[0], w[1]) for w in p] for p in plans.values()]
    starts = [p[0] for p in paths]
    for _ in range(20):
        radius = rng.uniform(30.0, 80.0)
        path = paths[rng.randrange(len(paths))]
        how = rng.choice(("crossing", "touching", "destination"))
        if how == "destination":
            c = _offset(path[-1], rng.uniform(0.0, 360.0), rng.uniform(0.0, 20.0))
        else:
            k = rng.randrange(len(path) - 1)
            u = rng.uniform(0.3, 1.0)
            p = (
                path[k][0] + u * (path[k + 1][0] - path[k][0]),
                path[k][1] + u * (path[k + 1][1] - path[k][1]),
            )
            heading = math.degrees(
                math.atan2(path[k + 1][0] - path[k][0], path[k + 1][1] - path[k][1])
            )
            side = rng.choice((-1.0, 1.0))
            away = (
                rng.uniform(0.0, 0.7 * radius)
                if how == "crossing"
                else radius + rng.uniform(-3.0, 3.0)
            )
            c = _offset(p, heading, side * away)
        if all(math.dist(c, s) > radius + 20.0 for s in starts):
            return (round(c[0], 2), round(c[1], 2), round(radius, 1))
    return None


def _build_fence(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    uas, plans = _classic_uas(rng, kind, centre, t_c, n_uas)
    return _Built(uas=uas, plans=plans, fence=_fence_on_paths(rng, plans))


def _build_vertical(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """Level tracks crossing within the horizontal minimum, 1-10 cm above or below the pair's
    effective vertical minimum (plans that are, or are not, a loss by centimetres)."""
    uas = _pair(rng, "crossing" if kind in ("vertical", "near_threshold") else kind, centre, t_c)
    a, b = uas
    v_min = max(SEPARATION_V_M, a.volume_m + b.volume_m)
    offset = v_min + rng.choice((-1.0, 1.0)) * rng.uniform(0.01, 0.10)
    sign = 1.0 if a.alt_agl_m - offset < 30.0 or rng.random() < 0.5 else -1.0
    alt_b = round(round(a.alt_agl_m, 2) + sign * offset, 3)  # UAS1's as filed (cm)
    uas[1] = dataclasses.replace(b, alt_agl_m=alt_b, climb_m=0.0)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    plans["UAS2"] = [(e, n, alt_b, t) for e, n, _, t in plans["UAS2"]]
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=n_uas)
    return _Built(uas=uas, plans=plans)


def _build_merge(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """3-6 UAS converging on one point within seconds of each other."""
    uas = _pair(rng, kind, centre, t_c)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=max(3, n_uas), join=True)
    return _Built(uas=uas, plans=plans)


def _build_mixed(
    rng: random.Random, kind: str, centre: tuple[float, float], t_c: float, n_uas: int
) -> _Built:
    """A multirotor and a fixed wing in the pair (the slower one overtaken)."""
    fws = (False, True) if kind == "overtaking" or rng.random() < 0.5 else (True, False)
    uas = _pair(rng, kind, centre, t_c, fixed_wings=fws)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    _add_extras(rng, uas, plans, centre=centre, t_c=t_c, n_uas=n_uas)
    return _Built(uas=uas, plans=plans)


_BUILDERS = {
    "classic": _build_classic,
    "late": _build_late,
    "lag": _build_lag,
    "endpoint": _build_endpoint,
    "fence": _build_fence,
    "vertical": _build_vertical,
    "merge": _build_merge,
    "mixed": _build_mixed,
}


def _rng(index: int, seed: int, profile: str) -> random.Random:
    if profile == "classic":
        return random.Random(seed * 1_000_003 + index)  # today's sets stay as they were
    return random.Random(f"{seed}:{index}:{profile}")  # str seeds are stable across runs


def encounter(index: int, seed: int, profile: str = "classic") -> Encounter:
    """Encounter number ``index`` of the set generated with ``seed`` and ``profile`` (``all``
    cycles through :data:`PROFILES`)."""
    if profile == "all":
        profile = PROFILES[index % len(PROFILES)]
    if profile not in PROFILES:
        raise ValueError(
            f"generator: unknown profile {profile!r}; expected one of "
            f"{', '.join((*PROFILES, 'all'))}"
        )
    rng = _rng(index, seed, profile)
    kind = KINDS[index % len(KINDS)]
    origin = ORIGINS[rng.randrange(len(ORIGINS))]
    n_uas = rng.randint(2, 6)
    centre = (rng.uniform(-200.0, 200.0), rng.uniform(-200.0, 200.0))
    t_c = rng.uniform(*CONFLICT_AT_S)
    built = _BUILDERS[profile](rng, kind, centre, t_c, n_uas)
    uas, plans = built.uas, built.plans
    # priorities 1-10, ties allowed as in the paper
    uas = [dataclasses.replace(u, priority=rng.randint(1, 10)) for u in uas]
    fence = built.fence
    if profile != "fence" and rng.random() < 0.5:
        fence = _geofence(rng, centre, [[(w[0], w[1]) for w in p] for p in plans.values()])
    name = (
        f"enc_{seed}_{index:04d}_{kind}"
        if profile == "classic"
        else (f"enc_{seed}_{index:04d}_{profile}_{kind}")
    )
    # time after the filed plans end for accepted plans that arrive later (and for what the
    # vehicles do after their plans: hover, loiter)
    duration_s = math.ceil(max(p[-1][3] for p in plans.values()) + 45.0)
    text = _toml(
        name,
        kind=kind,
        origin=origin,
        duration_s=duration_s,
        uas=uas,
        plans=plans,
        fence=fence,
        delays=built.delays_s,
    )
    return Encounter(
        name=name,
        kind=kind,
        profile=profile,
        n_uas=len(uas),
        fixed_wings=sum(u.fixed_wing for u in uas),
        geofence=fence is not None,
        origin=origin[0],
        toml=text,
    )


def _toml(
    name: str,
    *,
    kind: str,
    origin: tuple[str, float, float, float],
    duration_s: float,
    uas: list[_Uas],
    plans: dict[str, list[Waypoint]],
    fence: tuple[float, float, float] | None,
    delays: dict[str, float],
) -> str:
    lines = [
        f"# Generated encounter ({kind}), gcs_utm.eval.generator: {len(uas)} UAS meeting near",
        f"# ({uas[0].point[0]:.0f}, {uas[0].point[1]:.0f}) m at t = {uas[0].t_s:.0f} s.",
        "",
        "[scenario]",
        f'name = "{name}"',
        f'description = "generated {kind} encounter of {len(uas)} UAS ({origin[0]})"',
        f"duration_s = {duration_s:.1f}",
        "",
        "[airspace]",
        f"origin_lat_deg = {origin[1]!r}",
        f"origin_lon_deg = {origin[2]!r}",
        f"ground_elevation_amsl_m = {origin[3]!r}",
    ]
    for i, u in enumerate(uas):
        wps = ",\n".join(
            f"    {{ east_m = {e!r}, north_m = {n!r}, alt_agl_m = {a!r}, t_s = {t!r} }}"
            for e, n, a, t in plans[u.id]
        )
        lines += [
            "",
            "[[operations]]",
            f'id = "{u.id}"',
            f"sys_id = {i + 1}",
            f"priority = {u.priority}",
            f'vehicle = "{"fixed_wing" if u.fixed_wing else "multirotor"}"',
            f"cruise_speed_mps = {u.speed_mps!r}",
            f"flight_geometry_m = {u.geometry_m!r}",
            f"operational_volume_m = {u.volume_m!r}",
            f"max_climb_rate_mps = {u.climb_rate_mps!r}",
            "endurance_s = 3600.0",
            *([f"start_delay_s = {delays[u.id]!r}"] if u.id in delays else []),
            f"waypoints = [\n{wps},\n]",
        ]
    if fence is not None:
        lines += [
            "",
            "[[geofences]]",
            'id = "G1"',
            'reason = "generated no-fly zone beside the encounter"',
            f"cylinder = {{ east_m = {fence[0]!r}, north_m = {fence[1]!r}, "
            f"radius_m = {fence[2]!r} }}",
            "min_alt_agl_m = 0.0",
            "max_alt_agl_m = 300.0",
        ]
    return "\n".join(lines) + "\n"


def generate(n: int, seed: int, profile: str = "classic") -> list[Encounter]:
    """``n`` encounters of the set of ``seed`` and ``profile``."""
    if n < 1:
        raise ValueError(f"generate: expected at least 1 encounter, got {n}")
    return [encounter(i, seed, profile) for i in range(n)]


def write_encounters(out_dir: Path, n: int, seed: int, profile: str = "classic") -> list[Path]:
    """Write ``n`` generated scenario files into ``out_dir``; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for enc in generate(n, seed, profile):
        path = out_dir / f"{enc.name}.toml"
        path.write_text(enc.toml)
        paths.append(path)
    return paths
