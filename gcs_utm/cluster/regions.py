"""The region map: square grid cells over the airspace's east/north frame, each with a halo.

Pure (no I/O). A point belongs to exactly one region (cells are half-open: west and south
edges inside, east and north edges outside; the outer edges clamp to the border cells, so
traffic beyond the grid still has an owner). A point is in the *halo* of every region whose
cell, grown by ``halo_m`` on each side, contains it: the owner of such a region watches that
traffic too, which is how a conflict across a border is seen by both sides.

Region ids are ``c<column>r<row>``, column 0 in the west, row 0 in the south.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import asdict, dataclass

_ID = re.compile(r"^c(\d+)r(\d+)$")


class RegionError(ValueError):
    """A region id or map that does not fit."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RegionMap:
    west_m: float
    south_m: float
    cell_m: float
    columns: int
    rows: int
    halo_m: float

    def __post_init__(self) -> None:
        if not (self.cell_m > 0 and self.columns >= 1 and self.rows >= 1 and self.halo_m >= 0):
            raise RegionError(f"bad region map: {self}")
        if self.halo_m >= self.cell_m:
            raise RegionError(
                f"halo_m ({self.halo_m} m) must be smaller than cell_m ({self.cell_m} m): a "
                "halo reaches the next region only"
            )

    # ---- ids ----------------------------------------------------------------------------
    def ids(self) -> list[str]:
        return [f"c{c}r{r}" for r in range(self.rows) for c in range(self.columns)]

    def cell(self, region_id: str) -> tuple[int, int]:
        m = _ID.match(region_id)
        if m is None:
            raise RegionError(f"region {region_id!r}: expected c<column>r<row>, e.g. c0r1")
        col, row = int(m.group(1)), int(m.group(2))
        if col >= self.columns or row >= self.rows:
            raise RegionError(f"region {region_id!r}: outside the {self.columns}x{self.rows} grid")
        return col, row

    def bounds_m(self, region_id: str) -> tuple[float, float, float, float]:
        """(west, south, east, north) of a region's cell, metres in the airspace frame."""
        col, row = self.cell(region_id)
        w = self.west_m + col * self.cell_m
        s = self.south_m + row * self.cell_m
        return w, s, w + self.cell_m, s + self.cell_m

    # ---- points -------------------------------------------------------------------------
    def _index(self, v_m: float, origin_m: float, n: int) -> int:
        return min(n - 1, max(0, math.floor((v_m - origin_m) / self.cell_m)))

    def region_of(self, east_m: float, north_m: float) -> str:
        """The one region a point belongs to."""
        col = self._index(east_m, self.west_m, self.columns)
        row = self._index(north_m, self.south_m, self.rows)
        return f"c{col}r{row}"

    def regions_near(self, east_m: float, north_m: float) -> set[str]:
        """Every region whose halo-grown cell contains the point (its own region included)."""
        out = {self.region_of(east_m, north_m)}
        h = self.halo_m
        for de in (-h, 0.0, h):
            for dn in (-h, 0.0, h):
                out.add(self.region_of(east_m + de, north_m + dn))
        return out

    def neighbours(self, region_id: str) -> list[str]:
        """The up to eight regions around one (whose halos overlap it)."""
        col, row = self.cell(region_id)
        return [
            f"c{c}r{r}"
            for r in range(max(0, row - 1), min(self.rows, row + 2))
            for c in range(max(0, col - 1), min(self.columns, col + 2))
            if (c, r) != (col, row)
        ]

    # ---- stored form --------------------------------------------------------------------
    def region_doc(self, region_id: str) -> str:
        """One region's row in the store: its cell and the map it belongs to, as JSON."""
        w, s, e, n = self.bounds_m(region_id)
        return json.dumps(
            {"map": asdict(self), "west_m": w, "south_m": s, "east_m": e, "north_m": n},
            sort_keys=True,
        )


__all__ = ["RegionError", "RegionMap"]
