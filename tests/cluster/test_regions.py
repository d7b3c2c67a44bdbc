"""The region map: one owner per point, halos across borders, ids and bad maps."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gcs_utm.cluster.regions import RegionError, RegionMap

GRID = RegionMap(west_m=-1000.0, south_m=0.0, cell_m=1000.0, columns=2, rows=2, halo_m=100.0)


def test_points_belong_to_one_region_and_outer_edges_clamp() -> None:
    assert GRID.ids() == ["c0r0", "c1r0", "c0r1", "c1r1"]
    assert GRID.region_of(-500.0, 500.0) == "c0r0"
    assert GRID.region_of(0.0, 500.0) == "c1r0"  # the west edge belongs to the cell
    assert GRID.region_of(-0.001, 999.999) == "c0r0"
    assert GRID.region_of(500.0, 1000.0) == "c1r1"
    assert GRID.region_of(-50_000.0, -50_000.0) == "c0r0"  # beyond the grid: border cell
    assert GRID.region_of(50_000.0, 50_000.0) == "c1r1"
    assert GRID.bounds_m("c1r1") == (0.0, 1000.0, 1000.0, 2000.0)


def test_halo_reaches_the_neighbours_across_a_border_and_a_corner() -> None:
    assert GRID.regions_near(-500.0, 500.0) == {"c0r0"}
    assert GRID.regions_near(-50.0, 500.0) == {"c0r0", "c1r0"}
    assert GRID.regions_near(-50.0, 950.0) == {"c0r0", "c1r0", "c0r1", "c1r1"}
    assert GRID.regions_near(-150.0, 500.0) == {"c0r0"}
    assert sorted(GRID.neighbours("c0r0")) == ["c0r1", "c1r0", "c1r1"]


@given(st.floats(-3000, 3000), st.floats(-2000, 4000))
def test_own_region_is_always_near_and_near_means_within_the_halo(e: float, n: float) -> None:
    near = GRID.regions_near(e, n)
    assert GRID.region_of(e, n) in near
    for r in near:
        w, s, east, north = GRID.bounds_m(r)
        col, row = GRID.cell(r)
        # clamped border cells reach to infinity outward
        w = -float("inf") if col == 0 else w
        s = -float("inf") if row == 0 else s
        east = float("inf") if col == GRID.columns - 1 else east
        north = float("inf") if row == GRID.rows - 1 else north
        assert w - GRID.halo_m <= e <= east + GRID.halo_m
        assert s - GRID.halo_m <= n <= north + GRID.halo_m


def test_bad_ids_and_maps_are_refused() -> None:
    with pytest.raises(RegionError, match="c<column>r<row>"):
        GRID.cell("west")
    with pytest.raises(RegionError, match="outside the 2x2 grid"):
        GRID.cell("c2r0")
    with pytest.raises(RegionError, match="smaller than cell_m"):
        RegionMap(west_m=0.0, south_m=0.0, cell_m=100.0, columns=1, rows=1, halo_m=100.0)
