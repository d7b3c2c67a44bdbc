"""Seeded encounter generator: scenario files (the TOML of ``gcs-utm run``) of 2-6 UAS whose
filed plans meet, for fast-time closed-loop evaluation (``gcs-utm eval --generate N --seed S``).

Kinds (cycled, so every kind is in any set of 5 or more):
- ``crossing``: two straight tracks crossing at 45-135 deg, at the same time, missing by less
  than the pair's effective horizontal minimum;
- ``head_on``: opposite tracks, laterally offset by less than the minimum;
- ``overtaking``: same track, the faster UAS catches the slower one;
- ``vertical``: crossing tracks, one of them climbing or descending through the other's level
  at the crossing;
- ``near_threshold``: crossing tracks whose miss distance is within a few metres of the pair's
  effective minimum, on either side (some are losses, some are not).
Each encounter mixes multirotors and fixed wings (speeds, volumes and climb rates of their
kind); UAS beyond the first pair either join the conflict at the same point or fly elsewhere,
and are placed only where no pair is near a loss of separation earlier than ``WARNING_S``
before the conflict (an encounter develops in flight; it does not start in a loss);
about half the encounters have a cylinder geofence beside the conflict (never on a filed
path), which a resolution must not enter. Two origins are used (Madrid, Seville) so frames far
from the UTM zone's central meridian are exercised.

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

KINDS = ("crossing", "head_on", "overtaking", "vertical", "near_threshold")

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
_TRIES = 20


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

    def waypoints(self, lead_in_s: float) -> list[tuple[float, float, float, float]]:
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
        half_s = abs(self.climb_m) / self.climb_rate_mps / 2.0 / 0.8  # at 80 % of the rate
        lo, hi = self.alt_agl_m - self.climb_m / 2.0, self.alt_agl_m + self.climb_m / 2.0
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


def _pair(rng: random.Random, kind: str, centre: tuple[float, float], t_s: float) -> list[_Uas]:
    """The first two UAS, meeting at ``centre`` at ``t_s`` as the kind says."""
    fw = [rng.random() < 0.35, rng.random() < 0.35]
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


def _extra(rng: random.Random, k: int, centre: tuple[float, float], t_s: float) -> _Uas:
    """UAS number ``k`` (3..6): joins the conflict at the centre, or flies 600+ m away."""
    fw = rng.random() < 0.35
    heading = rng.uniform(0.0, 360.0)
    alt = rng.uniform(50.0, 110.0)
    if rng.random() < 0.5:
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


def _at(plan: list[tuple[float, float, float, float]], t_s: float) -> tuple[float, float, float]:
    """Position on a filed plan at ``t_s`` (clamped to its ends)."""
    if t_s <= plan[0][3]:
        return plan[0][:3]
    for a, b in itertools.pairwise(plan):
        if t_s <= b[3]:
            u = (t_s - a[3]) / (b[3] - a[3])
            return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]))
    return plan[-1][:3]


def _apart_until(
    pa: list[tuple[float, float, float, float]],
    pb: list[tuple[float, float, float, float]],
    min_h_m: float,
    until_t_s: float,
) -> bool:
    """Are two filed plans clear of each other (with 10 m / 5 m to spare) while both fly,
    up to ``until_t_s``? An encounter must develop in flight, with time to resolve it: two
    UAS must not start in (or seconds from) a loss of separation."""
    t = max(pa[0][3], pb[0][3])
    while t <= until_t_s:
        a, b = _at(pa, t), _at(pb, t)
        if math.hypot(a[0] - b[0], a[1] - b[1]) < min_h_m + 10.0 and abs(a[2] - b[2]) < (
            SEPARATION_V_M + 5.0
        ):
            return False
        t += 0.5
    return True


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


def encounter(index: int, seed: int) -> Encounter:
    """Encounter number ``index`` of the set generated with ``seed``."""
    rng = random.Random(seed * 1_000_003 + index)
    kind = KINDS[index % len(KINDS)]
    origin = ORIGINS[rng.randrange(len(ORIGINS))]
    n_uas = rng.randint(2, 6)
    centre = (rng.uniform(-200.0, 200.0), rng.uniform(-200.0, 200.0))
    t_c = rng.uniform(*CONFLICT_AT_S)
    uas = _pair(rng, kind, centre, t_c)
    plans = {u.id: u.waypoints(min(rng.uniform(*LEAD_IN_S), u.t_s - 5.0)) for u in uas}
    for k in range(3, n_uas + 1):
        for _ in range(_TRIES):
            extra = _extra(rng, k, centre, t_c)
            wps = extra.waypoints(min(rng.uniform(*LEAD_IN_S), extra.t_s - 5.0))
            if all(
                _apart_until(wps, plans[u.id], _effective_h_m(extra, u), t_c - WARNING_S)
                for u in uas
            ):
                break
        else:
            continue  # no place for one more UAS: the encounter has fewer
        uas.append(extra)
        plans[extra.id] = wps
    # priorities 1-10, ties allowed as in the paper
    uas = [dataclasses.replace(u, priority=rng.randint(1, 10)) for u in uas]
    fence = None
    if rng.random() < 0.5:
        fence = _geofence(rng, centre, [[(w[0], w[1]) for w in p] for p in plans.values()])
    name = f"enc_{seed}_{index:04d}_{kind}"
    # time after the filed plans end for accepted plans that arrive later
    duration_s = math.ceil(max(p[-1][3] for p in plans.values()) + 45.0)
    text = _toml(
        name, kind=kind, origin=origin, duration_s=duration_s, uas=uas, plans=plans, fence=fence
    )
    return Encounter(
        name=name,
        kind=kind,
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
    plans: dict[str, list[tuple[float, float, float, float]]],
    fence: tuple[float, float, float] | None,
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


def generate(n: int, seed: int) -> list[Encounter]:
    """``n`` encounters of the set of ``seed``."""
    if n < 1:
        raise ValueError(f"generate: expected at least 1 encounter, got {n}")
    return [encounter(i, seed) for i in range(n)]


def write_encounters(out_dir: Path, n: int, seed: int) -> list[Path]:
    """Write ``n`` generated scenario files into ``out_dir``; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for enc in generate(n, seed):
        path = out_dir / f"{enc.name}.toml"
        path.write_text(enc.toml)
        paths.append(path)
    return paths
