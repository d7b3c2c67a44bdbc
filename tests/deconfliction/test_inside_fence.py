"""From inside a geofence grown by its volume, a UAS is always offered a way out: escape and
rejoin when the plan leads out, and otherwise leave and hold outside, return home or land at
a site (each leaving by the closest border point first)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.deconfliction.geometry import plan_to_local
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.core.monitoring.strategic import plan_vs_geofences
from gcs_utm.model import (
    AirspaceSnapshot,
    GeofenceId,
    Maneuver,
    OperationId,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
)

MON = MonitoringConfig()


def _track_at(op_id: str, e: float, n: float, z: float, t_s: float) -> Track:
    lat, lon = sc.FRAME.point_to_wgs84(e, n)
    return Track(
        id=TrackId(op_id),
        t_s=t_s,
        lat_deg=lat,
        lon_deg=lon,
        alt_amsl_m=z,
        east_m=e,
        north_m=n,
        vel_enu_mps=(0.0, 0.0, 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId(op_id),
    )


def test_inside_a_fence_that_holds_the_destination_a_way_out_is_offered() -> None:
    # The plan ends at the centre of a 200 m fence and the UAS is already 150 m inside it.
    # Escape (leave, then rejoin the plan) has nowhere to rejoin: before, nothing else was
    # tried and nothing was commanded (a UAS hovered inside a fence for 67 s).
    fence = sc.cylinder("F", 0.0, 0.0, 200.0)
    op = sc.make_operation(
        "A",
        [(-600, 0, 100), (0, 0, 100)],
        landing_sites=[(-400, 300, 0.0)],
        home_enz=(-600, 0, 0.0),
    )
    t = sc.T0_S + 45.0
    snap = AirspaceSnapshot(
        t_s=t,
        operations={op.id: op},
        tracks={TrackId("A"): _track_at("A", -50, 0, 100, t)},
        geofences=(fence,),
    )
    threat = sc.threat(ThreatKind.GEOFENCE_INTRUSION, ["A"], t_s=t, geofence_id=GeofenceId("F"))
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    alts = td.resolve_single(threat, OperationId("A"), snap)
    got = {a.maneuver: a for a in alts}
    assert {Maneuver.HOLD, Maneuver.RETURN_HOME, Maneuver.LANDING_SITE} <= set(got), td.dropped
    assert Maneuver.ESCAPE not in got  # nowhere to rejoin: dropped with the reason
    for a in got.values():
        assert a.plan is not None
        # Out by the closest border point first (west: the UAS is 150 m from it)...
        lp = plan_to_local(a.plan, sc.FRAME)
        out = np.hypot(lp.e, lp.n) > 200.0 + op.operational_volume_m
        i = int(np.argmax(out))
        assert out[i] and np.hypot(lp.e[i] + 50.0, lp.n[i]) < 200.0  # not the far side
        # ...and clean from there on (the leg out of the fence is unavoidable).
        rest = replace(a.plan, waypoints=a.plan.waypoints[i:])
        assert plan_vs_geofences(rest, op, snap.geofences, sc.FRAME, MON) == [], a.maneuver
    # The hold ends where it left the fence, and stays there.
    hold = plan_to_local(got[Maneuver.HOLD].plan, sc.FRAME)  # type: ignore[arg-type]
    assert np.allclose(hold.xyz()[-1], hold.xyz()[-2])
    assert hold.t[-1] - hold.t[-2] >= 60.0


def test_a_fixed_wing_is_offered_home_ending_above_it_not_a_vertical_descent() -> None:
    """A fixed wing cannot descend vertically onto home: its return-home plan ends above
    home at its altitude, where it circles (the autopilot's RTL loiter) and lands on its own
    landing sequence. Before, the plan ended with a vertical descent, which the envelope
    check refused ("speed ... below the envelope's minimum"), so a fixed wing was never
    offered home."""
    fence = sc.cylinder("F", 0.0, 0.0, 200.0)
    op = replace(
        sc.make_operation(
            "A",
            [(-1200, 0, 100), (0, 0, 100)],
            speed_mps=20.0,
            landing_sites=[(-700, 600, 0.0)],
            home_enz=(-1200, 0, 0.0),
        ),
        vehicle_kind=VehicleKind.FIXED_WING,
        operational_volume_m=25.0,
    )
    t = sc.T0_S + 55.0
    snap = AirspaceSnapshot(
        t_s=t,
        operations={op.id: op},
        tracks={TrackId("A"): _track_at("A", -120, 0, 100, t)},
        geofences=(fence,),
    )
    threat = sc.threat(ThreatKind.GEOFENCE_INTRUSION, ["A"], t_s=t, geofence_id=GeofenceId("F"))
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(min_height_above_home_m=0.0), MON)
    got = {a.maneuver: a for a in td.resolve_single(threat, OperationId("A"), snap)}
    assert Maneuver.RETURN_HOME in got, td.dropped
    home = got[Maneuver.RETURN_HOME]
    assert "circle above it" in home.detail
    lp = plan_to_local(home.plan, sc.FRAME)  # type: ignore[arg-type]
    assert np.hypot(lp.e[-1] + 1200.0, lp.n[-1]) < 1.0  # over home
    assert lp.z[-1] == pytest.approx(100.0, abs=1.0)  # at its altitude, not on the ground
    site = got[Maneuver.LANDING_SITE]
    assert site.detail.startswith("circle above site 0"), site.detail
