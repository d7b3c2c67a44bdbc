"""Properties of the frames (gcs_utm.geo) and validation of the model (gcs_utm.model)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Measurement,
    ModelError,
    OperationId,
    Position,
    Recommendation,
    RecommendationId,
    RecommendationState,
    ThreatId,
    ThreatKind,
    TransitionError,
    Waypoint4D,
    slot_setters,
)

lats = st.floats(-79.0, 83.0)
lons = st.floats(-179.0, 179.0)
offsets_m = st.floats(-20_000.0, 20_000.0)


@settings(max_examples=60, deadline=None)
@given(lat0=lats, lon0=lons, de=offsets_m, dn=offsets_m)
def test_utm_round_trip_to_1_mm(lat0: float, lon0: float, de: float, dn: float) -> None:
    frame = LocalFrame(lat0, lon0)
    lat, lon = frame.point_to_wgs84(de, dn)
    e, n = frame.point_to_local(lat, lon)
    assert abs(e - de) < 1e-3 and abs(n - dn) < 1e-3


@settings(max_examples=30, deadline=None)
@given(lat0=lats, lon0=lons, d_deg=st.lists(st.floats(-0.2, 0.2), min_size=2, max_size=20))
def test_to_local_in_place_equals_to_local(lat0: float, lon0: float, d_deg: list[float]) -> None:
    frame = LocalFrame(lat0, lon0)
    lat = np.clip(lat0 + np.array(d_deg), -80.0, 84.0)
    lon = lon0 + np.array(d_deg[::-1])
    want_e, want_n = frame.to_local(lat, lon)
    lon_east, lat_north = lon.copy(), lat.copy()
    frame.to_local_in_place(lon_east, lat_north)
    assert np.array_equal(lon_east, want_e) and np.array_equal(lat_north, want_n)


@settings(max_examples=60, deadline=None)
@given(lat0=lats, lon0=lons, e=offsets_m, n=offsets_m, u=st.floats(-100.0, 3000.0))
def test_enu_round_trip(lat0: float, lon0: float, e: float, n: float, u: float) -> None:
    frame = LocalFrame(lat0, lon0, 600.0)
    lat, lon, h = frame.enu_to_wgs84(e, n, u)
    e2, n2, u2 = frame.wgs84_to_enu(lat, lon, h)
    assert abs(float(e2) - e) < 1e-3 and abs(float(n2) - n) < 1e-3 and abs(float(u2) - u) < 1e-3


@settings(max_examples=40, deadline=None)
@given(
    lat0=st.floats(-70.0, 70.0),
    zone=st.integers(1, 59),
    side=st.floats(0.0001, 0.01),
    de=st.floats(2_000.0, 15_000.0),
)
def test_origin_near_zone_border_serves_the_next_zone(
    lat0: float, zone: int, side: float, de: float
) -> None:
    border = -180.0 + 6.0 * zone
    frame = LocalFrame(lat0, border - side)  # origin just west of the border
    lat, lon = frame.point_to_wgs84(de, 0.0)  # a point east of it, in the next zone
    e, n = frame.point_to_local(lat, lon)
    assert abs(e - de) < 1e-3 and abs(n) < 1e-3
    assert lon > border  # the point really is in the next zone (<= 1.1 km origin offset)
    assert frame.epsg % 100 == zone or 56.0 <= lat0 < 64.0 or lat0 >= 72.0


@given(ground=st.floats(-400.0, 5000.0), agl=st.floats(-50.0, 10_000.0))
def test_agl_amsl_round_trip(ground: float, agl: float) -> None:
    frame = LocalFrame(40.0, -3.0, ground)
    amsl = frame.agl_to_amsl(agl)
    assert amsl == pytest.approx(agl + ground)
    assert frame.amsl_to_agl(amsl) == pytest.approx(agl, abs=1e-9)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_nan_and_inf_are_rejected(bad: float) -> None:
    with pytest.raises(ModelError, match="finite"):
        Position(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=bad)
    with pytest.raises(ModelError, match="finite"):
        Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=10.0, t_s=bad)


@pytest.mark.parametrize("lat", [-90.0001, 90.5, 180.0])
def test_latitude_outside_range(lat: float) -> None:
    with pytest.raises(ModelError) as info:
        LatLon(lat_deg=lat, lon_deg=0.0)
    assert info.value.field_name == "lat_deg"


def _fence(**kw: object) -> Geofence:
    args: dict[str, object] = {
        "id": GeofenceId("g"),
        "shape": GeofenceShape.CYLINDER,
        "min_alt_amsl_m": 0.0,
        "max_alt_amsl_m": 100.0,
        "center": LatLon(lat_deg=40.0, lon_deg=-3.0),
        "radius_m": 50.0,
    }
    args.update(kw)
    return Geofence(**args)  # type: ignore[arg-type]


def test_geofence_validation() -> None:
    with pytest.raises(ModelError, match="above max"):
        _fence(min_alt_amsl_m=200.0)
    with pytest.raises(ModelError, match="after end"):
        _fence(start_t_s=10.0, end_t_s=5.0)
    with pytest.raises(ModelError, match="at least 3"):
        _fence(shape=GeofenceShape.POLYGON, vertices=(LatLon(lat_deg=0, lon_deg=0),) * 2)
    g = _fence(start_t_s=10.0, end_t_s=20.0)
    assert (
        not g.active_at(9.9) and g.active_at(10.0) and g.active_at(20.0) and not g.active_at(20.1)
    )


def test_plan_times_must_not_go_backwards() -> None:
    a = Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=10.0)
    b = Waypoint4D(lat_deg=40.001, lon_deg=-3.0, alt_amsl_m=700.0, t_s=9.0)
    with pytest.raises(ModelError) as info:
        FlightPlan(operation_id=OperationId("A"), version=1, waypoints=(a, b))
    assert info.value.field_name == "waypoints[1].t_s"
    with pytest.raises(ModelError):
        FlightPlan(operation_id=OperationId("A"), version=1, waypoints=())


def test_recommendation_lifecycle() -> None:
    rec = Recommendation(
        id=RecommendationId("R"),
        version=1,
        threat_id=ThreatId("T"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OperationId("A"),
        created_t_s=0.0,
        deadline_t_s=30.0,
    )
    applied = (
        rec.transition(RecommendationState.ACCEPTED, 1.0)
        .transition(RecommendationState.UPLOADING, 2.0)
        .transition(RecommendationState.APPLIED, 3.0, "uploaded")
    )
    assert applied.state is RecommendationState.APPLIED and applied.state_t_s == 3.0
    assert rec.state is RecommendationState.PROPOSED  # frozen: the original is unchanged
    with pytest.raises(TransitionError):
        applied.transition(RecommendationState.ACCEPTED, 4.0)
    rejected = rec.transition(RecommendationState.REJECTED, 1.0)
    for nxt in RecommendationState:
        with pytest.raises(TransitionError):
            rejected.transition(nxt, 2.0)
    with pytest.raises(TransitionError):
        rec.transition(RecommendationState.APPLIED, 1.0)


def test_slot_setters_only_for_the_class_they_describe() -> None:
    """The fast constructors fall back to the plain one when the class is not exactly what
    they were written for: other fields, no slots, or a __post_init__."""
    names = tuple(f.name for f in dataclasses.fields(Measurement))
    assert slot_setters(Measurement, names) is not None
    assert slot_setters(Measurement, names[:-1]) is None
    assert slot_setters(Measurement, names[::-1]) is None

    @dataclasses.dataclass(frozen=True)
    class NoSlots:
        a: int

    @dataclasses.dataclass(frozen=True, slots=True)
    class Checked:
        a: int

        def __post_init__(self) -> None:
            if self.a < 0:
                raise ValueError("a")

    assert slot_setters(NoSlots, ("a",)) is None
    assert slot_setters(Checked, ("a",)) is None
    assert slot_setters(int, ()) is None
