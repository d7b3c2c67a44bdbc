"""The airspace map's pure renderer on a known scene at the sizes the dashboard gives it
(80x24 and 120x40 cells): where each vehicle's heading glyph lands, the scale bar, the
separation rings and the geofence outlines; and the view model built from a snapshot."""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.dashboard.airspace_map import MapGrid, glyph, map_legend, render_map, rows_to_fit
from gcs_utm.dashboard.airspace_scene import (
    MapFence,
    MapPlan,
    MapRing,
    MapScene,
    MapVehicle,
    scene_of,
)
from gcs_utm.dashboard.view import Minima, collect
from gcs_utm.model import (
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    OperationId,
    OperationState,
    SysId,
    Threat,
    ThreatId,
    ThreatKind,
    Track,
    TrackId,
)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_dashboard import _usm

# Two UAS 200 m apart flying at each other along UAS1's plan, their 50 m separation rings,
# an intruder 150 m north heading south, a 60 m circular geofence and a 100 x 50 m square one.
SCENE = MapScene(
    vehicles=(
        MapVehicle("UAS1", 0.0, 0.0, 90.0, in_threat=True),
        MapVehicle("UAS2", 200.0, 0.0, 270.0, in_threat=True),
        MapVehicle("a1b2c3", 100.0, 150.0, 180.0, intruder=True),
    ),
    plans=(MapPlan("UAS1", ((-200.0, 0.0), (400.0, 0.0))),),
    fences=(
        MapFence("fire", center=(-100.0, -100.0), radius_m=60.0),
        MapFence(
            "yard", vertices=((250.0, -150.0), (350.0, -150.0), (350.0, -100.0), (250.0, -100.0))
        ),
    ),
    rings=(MapRing((0.0, 0.0), 50.0), MapRing((200.0, 0.0), 50.0)),
)


def _distance_m(grid: MapGrid, a: tuple[int, int], b: tuple[int, int]) -> float:
    """Metres between the centres of two cells (rows span ``m_per_row`` metres)."""
    return math.hypot((a[1] - b[1]) * grid.m_per_col, (a[0] - b[0]) * grid.m_per_row)


def _cells(grid: MapGrid, char: str) -> list[tuple[int, int]]:
    return [
        (r, c)
        for r in range(grid.height)
        for c in range(grid.width)
        if grid.rows[r][c].char == char
    ]


# The bounding box is 600 m (east, the plan) by 310 m (north, geofence to intruder), with an
# 8 % margin of 48 m each side: 696 x 406 m around its centre (100 m E, 5 m S). At 80x24 the
# map has 23 rows (the last row is the scale bar), 22 row steps of 2 cells: 406 / 44 = 9.227
# m per column limits (696 / 77 columns is 9.04). At 120x40: 696 / 117 = 5.949 m per column.
CASES = {
    (80, 24): {
        "m_per_col": 406.0 / 44.0,
        "UAS1": (11, 29),  # column 39.5 - 100 / 9.227 = 28.66, row 11 - 5 / 18.45 = 10.73
        "UAS2": (11, 50),  # column 39.5 + 100 / 9.227 = 50.34
        "a1b2c3": (3, 40),  # row 11 - 155 / 18.45 = 2.60
        "yard": [(16, 56), (16, 67), (19, 56), (19, 67)],
        "fire": [(16, 11), (16, 24), (13, 18), (19, 18)],  # west edge 39.5 - 260 / 9.227
        "bar": "├" + "─" * 21 + "┤ 200 m",  # 200 / 9.227 = 21.7 -> 22 columns
    },
    (120, 40): {
        "m_per_col": 696.0 / 117.0,
        "UAS1": (19, 43),  # column 59.5 - 100 / 5.949 = 42.69, row 19 - 5 / 11.90 = 18.58
        "UAS2": (19, 76),
        "a1b2c3": (6, 60),  # row 19 - 155 / 11.90 = 5.97
        "yard": [(27, 85), (27, 102), (31, 85), (31, 102)],
        "fire": [(27, 16), (27, 36), (22, 26), (32, 26)],  # west edge 59.5 - 260 / 5.949
        "bar": "├" + "─" * 33 + "┤ 200 m",  # 200 / 5.949 = 33.6 -> 34 columns
    },
}


@pytest.mark.parametrize("size", list(CASES))
def test_known_scene_lands_where_the_scale_says(size: tuple[int, int]) -> None:
    want = CASES[size]
    grid = render_map(SCENE, *size)
    assert (grid.width, grid.height) == size
    assert grid.m_per_col == pytest.approx(want["m_per_col"])
    assert grid.m_per_row == pytest.approx(2.0 * grid.m_per_col)  # equal metres, 2:1 cells
    # each vehicle: its course arrow where the scale puts it, its label right after it
    assert grid.find("→UAS1") == want["UAS1"]
    assert grid.find("←UAS2") == want["UAS2"]
    assert grid.find("⇓a1b2c3") == want["a1b2c3"]
    # the scale bar: a round length, ticks that many metres apart; north at the right
    bottom = grid.line(grid.height - 1)
    assert bottom.startswith(want["bar"])
    assert grid.scale_m == 200.0
    ticks = (bottom.index("┤") - bottom.index("├")) * grid.m_per_col
    assert abs(ticks - 200.0) <= grid.m_per_col / 2
    assert bottom.endswith("↑N")
    # geofence outlines: the square's corners and the circle's extreme points
    for r, c in want["yard"] + want["fire"]:
        assert grid.rows[r][c].char == "#", (r, c, grid.plain())
    # separation rings: many ring cells, every one 50 m (within a cell) from UAS1 or UAS2
    ring = _cells(grid, "∘")
    assert len(ring) >= 20
    centres = [want["UAS1"], want["UAS2"]]
    slack_m = grid.m_per_row
    assert all(
        min(abs(_distance_m(grid, cell, c) - 50.0) for c in centres) <= slack_m for cell in ring
    )
    # the plan runs along row of the two UAS, faint
    row = want["UAS1"][0]
    assert grid.line(row).count("·") >= size[0] // 2
    assert grid.rows[row][want["UAS1"][1]].style == "bold white on red"  # the threat's pair


def test_no_rings_without_a_threat_and_labels_stay_inside() -> None:
    calm = replace(
        SCENE, rings=(), vehicles=tuple(replace(v, in_threat=False) for v in SCENE.vehicles)
    )
    grid = render_map(calm, 80, 24)
    assert not _cells(grid, "∘")
    # a UAS at the east edge of the scene (column 39.5 + 300 / 9.227 = 72) has its label
    # on its left, whole, when it does not fit on the right
    edge = replace(calm, vehicles=(*calm.vehicles, MapVehicle("EDGE-VEHICLE-9", 400.0, 0.0, 0.0)))
    grid = render_map(edge, 80, 24)
    assert grid.find("EDGE-VEHICLE-9↑") == (11, 72 - 14)


@pytest.mark.parametrize(
    ("course", "intruder", "expected"),
    [
        (0.0, False, "↑"),
        (44.0, False, "↗"),
        (90.0, False, "→"),
        (135.0, False, "↘"),
        (180.0, False, "↓"),
        (230.0, False, "↙"),
        (270.0, False, "←"),
        (316.0, False, "↖"),
        (350.0, False, "↑"),
        (None, False, "●"),
        (90.0, True, "⇒"),
        (None, True, "◆"),
    ],
)
def test_heading_glyph_by_course_over_ground(
    course: float | None, intruder: bool, expected: str
) -> None:
    assert glyph(MapVehicle("X", 0.0, 0.0, course, intruder=intruder)) == expected


def test_lone_hovering_uas_gets_a_readable_scale_and_empty_airspace_says_so() -> None:
    grid = render_map(MapScene(vehicles=(MapVehicle("UAS1", 0.0, 0.0, None),)), 26, 10)
    assert grid.find("●UAS1") is not None
    assert grid.line(9).startswith("├") and grid.line(9).endswith("↑N")
    assert "(empty airspace)" in render_map(MapScene(), 26, 10).plain()


# ---- the view model from a dashboard snapshot ----------------------------------------------


def _track(
    op: str, lat: float, lon: float, vel: tuple[float, float], *, coop: bool = True
) -> Track:
    return Track(
        id=TrackId(op),
        t_s=10.0,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=700.0,
        east_m=0.0,
        north_m=0.0,
        vel_enu_mps=(vel[0], vel[1], 0.0),
        position_sigma_m=1.0,
        cooperative=coop,
        operation_id=OperationId(op) if coop else None,
    )


def test_scene_of_a_snapshot_rings_fences_plans_and_intruders() -> None:
    usm = _usm()
    op1 = usm.airspace.operations[OperationId("UAS1")]
    # a second operation with 40 m operational volume: the pair's minimum becomes 20 + 40 m
    op2 = replace(
        op1,
        id=OperationId("UAS2"),
        sys_id=SysId(2),
        plan=replace(op1.plan, operation_id=OperationId("UAS2")),
        operational_volume_m=40.0,
    )
    ended = replace(
        op1,
        id=OperationId("UAS3"),
        sys_id=SysId(3),
        plan=replace(op1.plan, operation_id=OperationId("UAS3")),
        state=OperationState.ENDED,
    )
    yard = Geofence(
        id=GeofenceId("yard"),
        shape=GeofenceShape.POLYGON,
        vertices=(
            LatLon(lat_deg=40.0, lon_deg=-3.002),
            LatLon(lat_deg=40.0, lon_deg=-3.0015),
            LatLon(lat_deg=40.0005, lon_deg=-3.0015),
        ),
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=1000.0,
    )
    usm.airspace.load([op2, ended], [yard])
    usm.threats[ThreatId("los")] = Threat(
        id=ThreatId("los"),
        kind=ThreatKind.LOSS_OF_SEPARATION,
        uas_ids=(OperationId("UAS1"), OperationId("UAS2")),
        detected_at_s=9.0,
    )
    usm.threats[ThreatId("intr")] = Threat(
        id=ThreatId("intr"),
        kind=ThreatKind.INTRUDER,
        uas_ids=(OperationId("UAS1"),),
        intruder_id=TrackId("icao:a1b2c3"),
        detected_at_s=9.0,
    )
    tracks = {
        TrackId("UAS1"): _track("UAS1", 40.0, -3.0, (3.0, 3.0)),
        TrackId("UAS2"): _track("UAS2", 40.0009, -3.0, (0.0, -5.0)),  # 100 m north
        TrackId("icao:a1b2c3"): _track("icao:a1b2c3", 40.001, -3.001, (0.1, 0.0), coop=False),
    }
    minima = Minima(horizontal_m=50.0, vertical_m=15.0, intruder_horizontal_m=150.0)
    scene = scene_of(collect(usm, lambda: tracks, minima))
    by = {v.label: v for v in scene.vehicles}
    assert set(by) == {"UAS1", "UAS2", "a1b2c3"}
    assert by["UAS1"].course_deg == pytest.approx(45.0) and by["UAS2"].course_deg == pytest.approx(
        180.0
    )
    assert by["a1b2c3"].intruder and by["a1b2c3"].course_deg is None  # 0.1 m/s: hovering
    assert all(v.in_threat for v in scene.vehicles)
    north_m = by["UAS2"].north_m - by["UAS1"].north_m
    assert north_m == pytest.approx(100.07, abs=0.1)  # 0.0009 deg of latitude
    # rings: the pair's minimum max(50, 20 + 40) = 60 m around UAS1 and UAS2; the intruder
    # minimum 150 m around UAS1 and the intruder
    radii = sorted((r.radius_m, r.center) for r in scene.rings)
    assert [r for r, _ in radii] == [60.0, 60.0, 150.0, 150.0]
    assert [p.label for p in scene.plans] == ["UAS1", "UAS2"]  # not the ended UAS3
    fences = {f.label: f for f in scene.fences}
    assert fences["fire"].radius_m == 50.0 and fences["fire"].center is not None
    assert len(fences["yard"].vertices) == 3
    assert "separation 60/150 m" in map_legend(scene).plain
    # without minima no ring is drawn (the radius would be a guess); the pair stays marked
    bare = scene_of(collect(usm, lambda: tracks))
    assert not bare.rings and all(v.in_threat for v in bare.vehicles)


def test_legend_names_only_the_marks_drawn_and_breaks_between_entries() -> None:
    legend = map_legend(SCENE, width=26).plain.splitlines()
    assert legend == ["↑=UAS ⇑=intruder ·=plan", "#=geofence", "∘=separation 50 m"]
    bare = map_legend(MapScene(vehicles=(MapVehicle("UAS1", 0.0, 0.0, None),))).plain
    assert bare == "↑=UAS"


_coord = st.floats(min_value=-5000.0, max_value=5000.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(
    points=st.lists(st.tuples(_coord, _coord), min_size=1, max_size=6),
    size=st.sampled_from([(26, 10), (80, 24), (120, 40)]),
)
def test_every_vehicle_is_drawn_where_it_is(
    points: list[tuple[float, float]], size: tuple[int, int]
) -> None:
    """Any scene: each vehicle's cell is inside the map and within half a cell of where the
    scale puts it; the first vehicle drawn in a cell keeps its glyph there."""
    vehicles = tuple(MapVehicle(f"V{i}", e, n, None) for i, (e, n) in enumerate(points))
    grid = render_map(MapScene(vehicles=vehicles), *size)
    e_c = (min(p[0] for p in points) + max(p[0] for p in points)) / 2
    n_c = (min(p[1] for p in points) + max(p[1] for p in points)) / 2
    seen: set[tuple[int, int]] = set()
    for e, n in points:
        col_f = (size[0] - 1) / 2 + (e - e_c) / grid.m_per_col
        row_f = (size[1] - 2) / 2 - (n - n_c) / grid.m_per_row
        r, c = math.floor(row_f + 0.5), math.floor(col_f + 0.5)  # halves up, as drawn
        assert abs(col_f - c) <= 0.5 + 1e-9 and abs(row_f - r) <= 0.5 + 1e-9
        assert 0 <= r < size[1] - 1 and 0 <= c < size[0]
        if (r, c) not in seen:
            assert grid.rows[r][c].char == "●", (r, c, grid.plain())
        seen.add((r, c))


@pytest.mark.parametrize("width", [26, 40, 80])
def test_rows_to_fit_are_the_rows_the_east_west_scale_needs(width: int) -> None:
    """The map widget asks for :func:`rows_to_fit` rows: with them the scene's east-west
    extent sets the scale (696 m over ``width - 3`` columns); one row fewer and its
    north-south extent would (a coarser scale)."""
    rows = rows_to_fit(SCENE, width)
    east_m_per_col = 696.0 / (width - 3)
    assert rows == math.ceil(406.0 / (2 * east_m_per_col)) + 2
    assert render_map(SCENE, width, rows).m_per_col == pytest.approx(east_m_per_col)
    assert render_map(SCENE, width, rows - 1).m_per_col > east_m_per_col


def test_a_geofence_outline_stays_visible_over_a_ring_it_shares() -> None:
    """A jamming geofence of 50 m around a UAS in a threat, with a 50 m ring: the outline
    is drawn over the ring, the ring shows where it differs."""
    uas = MapVehicle("UAS1", 0.0, 0.0, None, in_threat=True)
    shared = MapScene(
        vehicles=(uas,),
        fences=(MapFence("jam", center=(0.0, 0.0), radius_m=50.0),),
        rings=(MapRing((0.0, 0.0), 50.0), MapRing((0.0, 0.0), 80.0)),
    )
    grid = render_map(shared, 80, 24)
    alone = render_map(replace(shared, rings=shared.rings[1:]), 80, 24)  # same bounding box
    assert _cells(grid, "#") == _cells(alone, "#")
    assert _cells(grid, "∘")  # the 80 m ring
