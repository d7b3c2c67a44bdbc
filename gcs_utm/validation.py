"""Rules every input shares, wherever it enters (scenario files, GAUSS files, configuration,
MQTT messages): one definition of a valid polygon, the plausibility bounds of positions and
altitudes, and a depth limit for nested documents.

Each check returns the problem as text (``None`` when the value is fine), so each loader can
wrap it in its own error type naming its file, item and key. Plain data only: this module
imports nothing from the rest of the package, so every layer may use it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

ALT_AMSL_MIN_M = -500.0
"""Below the lowest dry land (Dead Sea shore, about -430 m): nothing flies lower."""
ALT_AMSL_MAX_M = 20_000.0
"""Above any airliner or UAS ceiling (ADS-B intruders included)."""
LOCAL_OFFSET_MAX_M = 500_000.0
"""East or north from the airspace origin: the frame fixes one UTM zone (about 670 km wide at
the equator); farther out the projection's scale error and the zone boundary make local
metres meaningless."""
RADIUS_MAX_M = 500_000.0
"""A geofence wider than the airspace itself is a unit mistake (km for m)."""
MAX_NESTING = 64
"""Our documents nest a few levels (a table, an array of tables, a point); far deeper
nesting is a malformed or hostile file. Parsers recurse per level and Python's default
recursion limit is 1,000: the limit keeps every later walk of the document well inside it."""


def polygon_problem(vertices: Sequence[tuple[float, float]]) -> str | None:
    """Why ``vertices`` (latitude, longitude in degrees, in order, not closed) is not a valid
    polygon, or None. Valid: at least 3 vertices, finite coordinates in range, a simple ring
    (no self-intersection: a bow-tie is refused) with a positive area.

    The ring is checked in a local plane (equirectangular about its first vertex): the
    projection keeps which edges cross for any polygon smaller than a continent, so the same
    rule holds whether a file gives degrees or local metres."""
    if len(vertices) < 3:
        return f"a polygon needs at least 3 vertices, got {len(vertices)}"
    for i, (lat, lon) in enumerate(vertices):
        problem = latlon_problem(lat, lon)
        if problem is not None:
            return f"vertex {i}: {problem}"
    lat0, lon0 = vertices[0]
    k = math.cos(math.radians(lat0))
    xy = [(((lon - lon0 + 180.0) % 360.0 - 180.0) * k, lat - lat0) for lat, lon in vertices]
    return planar_polygon_problem(xy)


def planar_polygon_problem(xy: Sequence[tuple[float, float]]) -> str | None:
    """:func:`polygon_problem` for vertices already in a plane (local metres)."""
    if len(xy) < 3:
        return f"a polygon needs at least 3 vertices, got {len(xy)}"
    if not all(math.isfinite(v) for p in xy for v in p):
        return "a polygon's coordinates must be finite numbers"
    from shapely.geometry import Polygon  # here: only polygons need it (start-up time)

    poly = Polygon(list(xy))
    if not poly.convex_hull.area > 0.0:
        return "the polygon has no area (its vertices are on one line or repeated)"
    if not poly.is_valid:
        return "the polygon intersects itself (its edges cross or touch): give a simple ring"
    return None


def latlon_problem(lat_deg: float, lon_deg: float) -> str | None:
    if not (math.isfinite(lat_deg) and -90.0 <= lat_deg <= 90.0):
        return f"latitude must be in [-90, 90] degrees, got {lat_deg!r}"
    if not (math.isfinite(lon_deg) and -180.0 <= lon_deg <= 180.0):
        return f"longitude must be in [-180, 180] degrees, got {lon_deg!r}"
    return None


def offset_problem(value_m: float) -> str | None:
    """A local east/north offset from the airspace origin, in metres."""
    if not (math.isfinite(value_m) and abs(value_m) <= LOCAL_OFFSET_MAX_M):
        return (
            f"expected metres from the airspace origin within +-{LOCAL_OFFSET_MAX_M:.0f} m,"
            f" got {value_m!r}"
        )
    return None


def altitude_problem(alt_amsl_m: float, *, ground_amsl_m: float | None = None) -> str | None:
    """An altitude in metres AMSL. With ``ground_amsl_m`` the value was given above ground,
    and the bounds are said above ground too."""
    if math.isfinite(alt_amsl_m) and ALT_AMSL_MIN_M <= alt_amsl_m <= ALT_AMSL_MAX_M:
        return None
    if ground_amsl_m is None:
        return (
            f"expected an altitude in [{ALT_AMSL_MIN_M:.0f}, {ALT_AMSL_MAX_M:.0f}] m AMSL,"
            f" got {alt_amsl_m!r}"
        )
    lo, hi = ALT_AMSL_MIN_M - ground_amsl_m, ALT_AMSL_MAX_M - ground_amsl_m
    return (
        f"expected a height in [{lo:.0f}, {hi:.0f}] m above ground (ground at"
        f" {ground_amsl_m:g} m AMSL), got {alt_amsl_m - ground_amsl_m!r}"
    )


def radius_problem(radius_m: float) -> str | None:
    if not (math.isfinite(radius_m) and 0.0 < radius_m <= RADIUS_MAX_M):
        return f"expected a radius in (0, {RADIUS_MAX_M:.0f}] m, got {radius_m!r}"
    return None


def nesting_depth(doc: object, limit: int = MAX_NESTING) -> int:
    """How deep lists and dicts nest in ``doc`` (a scalar is 0), counted without recursion;
    the walk stops once it passes ``limit`` (the result is then ``limit + 1``).

    A container shared by several parents (YAML anchors and aliases) is walked again only
    when reached deeper than before, so an alias bomb (each level repeating the one below
    ten times) costs at most ``limit`` visits per distinct container, not an exponential
    number."""
    deepest = 0
    seen_at: dict[int, int] = {}
    stack: list[tuple[object, int]] = [(doc, 0)]
    while stack:
        node, depth = stack.pop()
        if isinstance(node, dict):
            children: Sequence[object] = list(node.values())
        elif isinstance(node, list | tuple):
            children = node
        else:
            continue
        depth += 1
        if depth > limit:
            return limit + 1
        if seen_at.get(id(node), 0) >= depth:
            continue
        seen_at[id(node)] = depth
        deepest = max(deepest, depth)
        stack.extend((c, depth) for c in children)
    return deepest


def too_deep(limit: int = MAX_NESTING) -> str:
    """The one message for a document nested too deeply (also for a parser's RecursionError,
    which is the same fault found earlier)."""
    return f"nested deeper than {limit} levels (tables or arrays inside each other)"


def nesting_problem(doc: object, limit: int = MAX_NESTING) -> str | None:
    return too_deep(limit) if nesting_depth(doc, limit) > limit else None


__all__ = [
    "ALT_AMSL_MAX_M",
    "ALT_AMSL_MIN_M",
    "LOCAL_OFFSET_MAX_M",
    "MAX_NESTING",
    "RADIUS_MAX_M",
    "altitude_problem",
    "latlon_problem",
    "nesting_depth",
    "nesting_problem",
    "offset_problem",
    "planar_polygon_problem",
    "polygon_problem",
    "radius_problem",
    "too_deep",
]
