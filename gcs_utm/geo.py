"""Frames: WGS84 <-> the airspace's local metric frame, local ENU, AGL <-> AMSL.

Computation happens in metres of ONE transverse Mercator projection per airspace (pyproj,
WGS84 ellipsoid), centred on the airspace's origin with unit scale there: its central
meridian is the origin's longitude, its false origin the origin itself. So ``east_m`` /
``north_m`` are true local metres near the origin: the point scale grows as 1 + d^2 / (2 R^2)
with the distance d from the central meridian (5e-6 at 20 km: a 50 m distance is off by
0.25 mm), and grid north is true north at the origin. A UTM zone's grid is not: its scale is
0.9996 on the central meridian and up to 1.0010 at the zone border (50 m became 49.976 m at
Madrid, 50.023 m near Seville), enough to flip separation decisions at the minimum. An
airspace that straddles a UTM zone border still has one continuous frame. ``epsg`` keeps the
UTM zone of the origin for reference (logs, exports); no computation uses it.

``LocalFrame.enu_*`` gives true local East-North-Up around the origin (the paper's repository
stores its scenarios in ENU); ENU uses the WGS84 ellipsoid height of the origin plane and
treats ``up`` as metres above the origin altitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from pyproj import CRS, Transformer

FloatArray = npt.NDArray[np.float64]
ArrayLike = float | FloatArray


class FrameError(ValueError):
    """A coordinate outside what the frame can represent."""


def utm_epsg_for(lat_deg: float, lon_deg: float) -> int:
    """EPSG code of the WGS84 UTM zone containing (lat, lon), incl. Norway/Svalbard rules."""
    if not (-80.0 <= lat_deg <= 84.0):
        raise FrameError(f"latitude {lat_deg} is outside the UTM range [-80, 84]")
    zone = int((lon_deg + 180.0) // 6.0) + 1
    zone = min(max(zone, 1), 60)
    if 56.0 <= lat_deg < 64.0 and 3.0 <= lon_deg < 12.0:
        zone = 32
    if 72.0 <= lat_deg < 84.0 and lon_deg >= 0.0:
        if lon_deg < 9.0:
            zone = 31
        elif lon_deg < 21.0:
            zone = 33
        elif lon_deg < 33.0:
            zone = 35
        elif lon_deg < 42.0:
            zone = 37
    return (32600 if lat_deg >= 0.0 else 32700) + zone


def local_tmerc(lat_deg: float, lon_deg: float) -> CRS:
    """Transverse Mercator on WGS84 centred on (lat, lon) with unit scale there."""
    return CRS.from_proj4(
        f"+proj=tmerc +lat_0={lat_deg!r} +lon_0={lon_deg!r} +k_0=1 +x_0=0 +y_0=0 "
        "+ellps=WGS84 +units=m +no_defs +type=crs"
    )


@dataclass(frozen=True, slots=True)
class LocalFrame:
    """The metric frame of one airspace, fixed by its origin."""

    origin_lat_deg: float
    origin_lon_deg: float
    ground_elevation_amsl_m: float = 0.0
    origin_alt_amsl_m: float | None = None
    epsg: int = 0
    _fwd: Transformer = field(init=False, repr=False, compare=False)
    _inv: Transformer = field(init=False, repr=False, compare=False)
    _origin_en: tuple[float, float] = field(init=False, repr=False, compare=False)
    _ecef_fwd: Transformer = field(init=False, repr=False, compare=False)
    _ecef_inv: Transformer = field(init=False, repr=False, compare=False)
    _basis: list[tuple[FloatArray, FloatArray]] = field(
        init=False, repr=False, compare=False, default_factory=list
    )  # the ENU origin and rotation, computed on first use (a transform per call otherwise)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.origin_lat_deg) and math.isfinite(self.origin_lon_deg)):
            raise FrameError("origin must be finite")
        epsg = self.epsg or utm_epsg_for(self.origin_lat_deg, self.origin_lon_deg)
        object.__setattr__(self, "epsg", epsg)
        local = local_tmerc(self.origin_lat_deg, self.origin_lon_deg)
        fwd = Transformer.from_crs(CRS.from_epsg(4326), local, always_xy=True)
        inv = Transformer.from_crs(local, CRS.from_epsg(4326), always_xy=True)
        object.__setattr__(self, "_fwd", fwd)
        object.__setattr__(self, "_inv", inv)
        e0, n0 = fwd.transform(self.origin_lon_deg, self.origin_lat_deg)
        object.__setattr__(self, "_origin_en", (float(e0), float(n0)))
        # WGS84 geodetic (lon, lat, h) <-> ECEF for the ENU helpers.
        object.__setattr__(
            self, "_ecef_fwd", Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
        )
        object.__setattr__(
            self, "_ecef_inv", Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
        )

    # ---- local transverse Mercator, relative to the origin ----------------------------------
    def to_local(self, lat_deg: ArrayLike, lon_deg: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """WGS84 degrees -> (east_m, north_m) relative to the origin (local frame metres)."""
        lat = np.asarray(lat_deg, dtype=np.float64)
        lon = np.asarray(lon_deg, dtype=np.float64)
        e, n = self._fwd.transform(lon, lat)
        return (
            np.asarray(e, dtype=np.float64) - self._origin_en[0],
            np.asarray(n, dtype=np.float64) - self._origin_en[1],
        )

    def to_local_in_place(self, lon_east: FloatArray, lat_north: FloatArray) -> None:
        """:meth:`to_local` written over its inputs (C-contiguous float64 arrays): longitudes
        become east_m and latitudes north_m. The same numbers, without the copies a small
        batch pays for."""
        self._fwd.transform(lon_east, lat_north, inplace=True)
        lon_east -= self._origin_en[0]
        lat_north -= self._origin_en[1]

    def to_wgs84(self, east_m: ArrayLike, north_m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(east_m, north_m) relative to the origin -> (lat_deg, lon_deg)."""
        e = np.asarray(east_m, dtype=np.float64) + self._origin_en[0]
        n = np.asarray(north_m, dtype=np.float64) + self._origin_en[1]
        lon, lat = self._inv.transform(e, n)
        return np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)

    def point_to_local(self, lat_deg: float, lon_deg: float) -> tuple[float, float]:
        e, n = self.to_local(lat_deg, lon_deg)
        return float(e), float(n)

    def point_to_wgs84(self, east_m: float, north_m: float) -> tuple[float, float]:
        lat, lon = self.to_wgs84(east_m, north_m)
        return float(lat), float(lon)

    # ---- altitude references --------------------------------------------------------------
    def agl_to_amsl(self, alt_agl_m: ArrayLike) -> ArrayLike:
        """Above ground level -> above mean sea level, with the airspace's ground elevation."""
        return alt_agl_m + self.ground_elevation_amsl_m

    def amsl_to_agl(self, alt_amsl_m: ArrayLike) -> ArrayLike:
        return alt_amsl_m - self.ground_elevation_amsl_m

    # ---- true local East-North-Up ---------------------------------------------------------
    def _enu_basis(self) -> tuple[FloatArray, FloatArray]:
        if not self._basis:
            self._basis.append(self._compute_enu_basis())
        return self._basis[0]

    def _compute_enu_basis(self) -> tuple[FloatArray, FloatArray]:
        lat = math.radians(self.origin_lat_deg)
        lon = math.radians(self.origin_lon_deg)
        h0 = (
            self.origin_alt_amsl_m
            if self.origin_alt_amsl_m is not None
            else self.ground_elevation_amsl_m
        )
        x0, y0, z0 = self._ecef_fwd.transform(self.origin_lon_deg, self.origin_lat_deg, h0)
        rot = np.array(
            [
                [-math.sin(lon), math.cos(lon), 0.0],
                [-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)],
                [math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)],
            ]
        )
        return np.array([x0, y0, z0], dtype=np.float64), rot

    def enu_to_wgs84(
        self, east_m: ArrayLike, north_m: ArrayLike, up_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Local ENU around the origin -> (lat_deg, lon_deg, alt_m) where alt is ellipsoidal
        height treated as AMSL (the geoid separation is ignored, consistently both ways)."""
        origin, rot = self._enu_basis()
        enu = np.stack(
            np.broadcast_arrays(
                np.asarray(east_m, np.float64),
                np.asarray(north_m, np.float64),
                np.asarray(up_m, np.float64),
            ),
            axis=-1,
        )
        ecef = enu @ rot + origin
        lon, lat, h = self._ecef_inv.transform(ecef[..., 0], ecef[..., 1], ecef[..., 2])
        return (
            np.asarray(lat, np.float64),
            np.asarray(lon, np.float64),
            np.asarray(h, np.float64),
        )

    def wgs84_to_enu(
        self, lat_deg: ArrayLike, lon_deg: ArrayLike, alt_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        origin, rot = self._enu_basis()
        x, y, z = self._ecef_fwd.transform(
            np.asarray(lon_deg, np.float64),
            np.asarray(lat_deg, np.float64),
            np.asarray(alt_m, np.float64),
        )
        d = np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1) - origin
        enu = d @ rot.T
        return enu[..., 0], enu[..., 1], enu[..., 2]


def haversine_m(lat1_deg: float, lon1_deg: float, lat2_deg: float, lon2_deg: float) -> float:
    """Great-circle distance on a sphere of radius 6,371,008.8 m (the IUGG mean radius)."""
    p1 = math.radians(lat1_deg)
    p2 = math.radians(lat2_deg)
    dp = p2 - p1
    dl = math.radians(lon2_deg - lon1_deg)
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    return 2.0 * 6_371_008.8 * math.asin(min(1.0, math.sqrt(a)))
