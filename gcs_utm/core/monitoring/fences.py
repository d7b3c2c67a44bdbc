"""Geofences converted once into the local frame for the exact 4D tests.

A :class:`LocalFence` holds either polygon edges (E, 4) or a circle, the AMSL altitude band
and the activation window (+-inf when unbounded), all in metres / POSIX seconds, plus its
horizontal bounding box for prefiltering. ``inflate_m`` grows the fence by a distance in all
directions (the strategic check inflates by the operational volume): cylinders exactly,
polygons with a shapely buffer whose radius is enlarged so its chords stay outside the true
rounded offset (never smaller than the exact Minkowski sum); the band grows by the same
distance up and down (a box-shaped growth, conservative at the fence's rims).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gcs_utm.core.monitoring.geometry import FloatArray, ring_edges, segment_entry
from gcs_utm.geo import LocalFrame
from gcs_utm.model import Geofence, GeofenceId, GeofenceShape

_QUAD_SEGS = 16


@dataclass(frozen=True, slots=True, kw_only=True, eq=False)
class LocalFence:
    id: GeofenceId
    edges: FloatArray | None
    center: tuple[float, float] | None
    radius_m: float
    z_lo: float
    z_hi: float
    t_lo: float
    t_hi: float
    bbox: tuple[float, float, float, float]  # east_min, north_min, east_max, north_max (m)

    def active_between(self, t0_s: float, t1_s: float) -> bool:
        return self.t_lo <= t1_s and self.t_hi >= t0_s

    def first_entry(self, p0: FloatArray, p1: FloatArray) -> FloatArray:
        """First entry parameter per segment (see :func:`segment_entry`)."""
        return segment_entry(
            p0,
            p1,
            edges=self.edges,
            center=self.center,
            radius_m=self.radius_m,
            z_lo=self.z_lo,
            z_hi=self.z_hi,
            t_lo=self.t_lo,
            t_hi=self.t_hi,
        )


def localise(fence: Geofence, frame: LocalFrame, inflate_m: float = 0.0) -> LocalFence:
    """Convert ``fence`` to the local frame, grown by ``inflate_m`` metres."""
    t_lo = -math.inf if fence.start_t_s is None else fence.start_t_s
    t_hi = math.inf if fence.end_t_s is None else fence.end_t_s
    z_lo = fence.min_alt_amsl_m - inflate_m
    z_hi = fence.max_alt_amsl_m + inflate_m
    if fence.shape is GeofenceShape.CYLINDER:
        assert fence.center is not None and fence.radius_m is not None
        cx, cy = frame.point_to_local(fence.center.lat_deg, fence.center.lon_deg)
        r = fence.radius_m + inflate_m
        return LocalFence(
            id=fence.id,
            edges=None,
            center=(cx, cy),
            radius_m=r,
            z_lo=z_lo,
            z_hi=z_hi,
            t_lo=t_lo,
            t_hi=t_hi,
            bbox=(cx - r, cy - r, cx + r, cy + r),
        )
    lat = np.array([v.lat_deg for v in fence.vertices])
    lon = np.array([v.lon_deg for v in fence.vertices])
    ex, ny = frame.to_local(lat, lon)
    if inflate_m > 0.0:
        # Chord of a 1/(4*QUAD_SEGS) turn arc sits r*cos(pi/(4 q)) from the centre: enlarge.
        r = inflate_m / math.cos(math.pi / (4 * _QUAD_SEGS))
        # imported here: only an inflated polygon needs shapely (command start-up time)
        from shapely.geometry import Polygon
        from shapely.geometry.polygon import orient

        poly = Polygon(np.column_stack([ex, ny])).buffer(r, quad_segs=_QUAD_SEGS)
        poly = orient(poly, 1.0)
        rings = [np.asarray(poly.exterior.coords)[:-1]]
        rings += [np.asarray(i.coords)[:-1] for i in poly.interiors]
        edges = np.concatenate([ring_edges(rg[:, 0], rg[:, 1]) for rg in rings])
    else:
        edges = ring_edges(ex, ny)
    return LocalFence(
        id=fence.id,
        edges=edges,
        center=None,
        radius_m=0.0,
        z_lo=z_lo,
        z_hi=z_hi,
        t_lo=t_lo,
        t_hi=t_hi,
        bbox=(
            float(edges[:, 0].min()),
            float(edges[:, 1].min()),
            float(edges[:, 0].max()),
            float(edges[:, 1].max()),
        ),
    )
