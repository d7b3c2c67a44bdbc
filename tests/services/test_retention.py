"""Retention: operations that ended and geofences that expired leave memory after keep_s (a
day of traffic must not accumulate in serve), and the tracker drops the forgotten
operations' tracks."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tracking"))
from tracking_helpers import T0, meas, new_tracker, operation, plan_from_local
from usm_fakes import OP, make_operation

from gcs_utm.clock import ManualClock
from gcs_utm.model import (
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Measurement,
    MeasurementSource,
    OperationId,
    OperationState,
    SysId,
    TrackId,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.retention import Retention
from gcs_utm.services.usm import Usm


def _fence(gid: str, end_t_s: float | None) -> Geofence:
    return Geofence(
        id=GeofenceId(gid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=100.0,
        center=LatLon(lat_deg=47.0, lon_deg=8.0),
        radius_m=50.0,
        end_t_s=end_t_s,
    )


def test_ended_operations_and_expired_geofences_are_forgotten_after_keep_s() -> None:
    done = make_operation(T0)
    flying = dataclasses.replace(
        done,
        id=OperationId("flying"),
        plan=dataclasses.replace(done.plan, operation_id=OperationId("flying")),
    )
    airspace = Airspace()
    airspace.load(
        [dataclasses.replace(done, state=OperationState.ENDED), flying],
        [_fence("old", T0), _fence("open", None)],
    )
    told: list[list[OperationId]] = []
    retention = Retention(airspace=airspace, on_forgotten=told.append, keep_s=100.0)
    assert retention.sweep(T0) == []  # first seen ended now
    assert retention.sweep(T0 + 99.0) == []
    assert set(airspace.operations) == {done.id, flying.id}
    assert retention.sweep(T0 + 100.0) == [done.id]
    assert set(airspace.operations) == {flying.id}
    assert [g.id for g in airspace.geofences()] == ["open"]
    assert told == [[done.id]]
    assert retention.sweep(T0 + 1000.0) == []  # the active one stays


def test_the_tracker_drops_the_tracks_of_forgotten_operations() -> None:
    tr = new_tracker()
    ops = [
        operation(name, plan_from_local(name, [(0, 0, 100, T0)]), sys_id=i + 1)
        for i, name in enumerate(("op1", "op2"))
    ]
    tr.set_operations(ops)
    tr.ingest([meas(0, 0, 100, T0, sys_id=1), meas(500, 0, 100, T0, sys_id=2)])
    assert set(tr.tracks()) == {TrackId("op1"), TrackId("op2")}
    tr.set_operations(ops[1:])
    assert set(tr.tracks()) == {TrackId("op2")}


def test_the_usm_forgets_the_sources_and_recommendations_of_forgotten_operations() -> None:
    clock = ManualClock(T0)
    airspace = Airspace()
    airspace.load([make_operation(T0)], [])
    usm = Usm(airspace, clock, record=lambda _obj: None)
    for source, sys_id in ((MeasurementSource.MQTT, None), (MeasurementSource.TELEMETRY, 1)):
        usm.on_measurement(
            Measurement(
                source=source,
                capture_t_s=T0,
                receipt_t_s=T0,
                lat_deg=47.0,
                lon_deg=8.0,
                alt_amsl_m=500.0,
                operation_id=OP if sys_id is None else None,
                sys_id=None if sys_id is None else SysId(sys_id),
            )
        )
    assert set(usm.telemetry) == {f"mqtt:{OP}", "telemetry:1"}
    usm.forget_operations({OP})
    assert set(usm.telemetry) == {"telemetry:1"}  # a vehicle's own link stays
