"""The local frame measures true metres: a 50 m distance anywhere within 20 km of the origin
is 50 m in the frame to 1 mm (issue 19: UTM grid metres turned 50 m into 49.976 m at Madrid
and 50.023 m near Seville, enough to flip a separation decision at the minimum)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod

from gcs_utm.geo import LocalFrame

_GEOD = Geod(ellps="WGS84")

ORIGINS = [
    (40.4168, -3.7038),  # Madrid (UTM scale 0.99953 there)
    (37.41, -6.0),  # Seville (1.00046)
    (47.3977, 8.5456),  # Zurich
    (45.4671, -73.7578),  # PX4 SIH default home
    (-33.86, 151.21),  # southern hemisphere
    (60.0, 11.99),  # near a zone border, Norway rules
]


@settings(max_examples=300, deadline=None)
@given(
    origin=st.sampled_from(ORIGINS),
    bearing_deg=st.floats(0.0, 360.0),
    dist_m=st.floats(0.0, 20_000.0),
    pair_bearing_deg=st.floats(0.0, 360.0),
)
def test_fifty_metres_is_fifty_metres_within_20_km(
    origin: tuple[float, float], bearing_deg: float, dist_m: float, pair_bearing_deg: float
) -> None:
    lat0, lon0 = origin
    frame = LocalFrame(lat0, lon0, 0.0)
    lon1, lat1, _ = _GEOD.fwd(lon0, lat0, bearing_deg, dist_m)
    lon2, lat2, _ = _GEOD.fwd(lon1, lat1, pair_bearing_deg, 50.0)
    e, n = frame.to_local(np.array([lat1, lat2]), np.array([lon1, lon2]))
    got = math.hypot(float(e[1] - e[0]), float(n[1] - n[0]))
    assert abs(got - 50.0) < 1e-3


def test_origin_is_zero_and_north_is_north() -> None:
    frame = LocalFrame(40.4168, -3.7038, 650.0)
    assert frame.point_to_local(40.4168, -3.7038) == (0.0, 0.0)
    lon, lat, _ = _GEOD.fwd(-3.7038, 40.4168, 0.0, 1000.0)
    e, n = frame.point_to_local(lat, lon)
    assert abs(e) < 1e-6 and abs(n - 1000.0) < 1e-3
