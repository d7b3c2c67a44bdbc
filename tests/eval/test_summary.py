"""What the evaluation counts, on hand-made reports: predicted / flown / avoided / created
losses, extra length and time of accepted plans, the detection-to-upload times; and the
report's ground truth between position records (true metres, linear motion in between)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import pytest
from pyproj import Geod

from gcs_utm.app.report import (
    EscalationReport,
    OperationReport,
    OriginReport,
    PlanReport,
    RecommendationReport,
    Report,
    SeparationMinimum,
    ThreatReport,
    TruthPair,
    TruthReport,
    truth,
)
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.eval.summary import markdown, outcome, summarise
from gcs_utm.geo import LocalFrame
from gcs_utm.scenario import load_any

LAT0, LON0 = 40.0, -3.0
GEOD = Geod(ellps="WGS84")


def _ll(east_m: float, north_m: float) -> tuple[float, float]:
    """lat, lon of a point east/north of the origin (geodesic, true metres)."""
    az = math.degrees(math.atan2(east_m, north_m))
    lon, lat, _ = GEOD.fwd(LON0, LAT0, az, math.hypot(east_m, north_m))
    return lat, lon


def _plan(version: int, rows: list[tuple[float, float, float, float]]) -> PlanReport:
    return PlanReport(
        version=version,
        reason="filed" if version == 1 else "go_left",
        waypoints=tuple((*_ll(e, n), alt, t) for e, n, alt, t in rows),
    )


def _threat(uas: tuple[str, str], at_s: float) -> ThreatReport:
    return ThreatReport(
        id=f"t-{uas[0]}-{uas[1]}-{at_s}",
        kind="LOSS_OF_SEPARATION",
        uas=uas,
        status="open",
        detected_at_s=at_s,
        predicted_event_at_s=at_s + 60.0,
        geofence=None,
        closest_approach_m=30.0,
        closest_approach_at_s=at_s + 60.0,
        position=None,
        message="",
    )


def _rec(uas: str, detected: float, created: float, verified: float | None) -> RecommendationReport:
    history: list[tuple[float | None, str]] = [(created, "proposed v1")]
    if verified is not None:
        history.append((verified, "applied v1: go_left: mission verified by readback"))
    return RecommendationReport(
        id=f"r-{uas}",
        version=1,
        uas=uas,
        threat="t",
        threat_kind="LOSS_OF_SEPARATION",
        threat_detected_at_s=detected,
        maneuver="go_left",
        cost=0.1,
        risk=0.1,
        latency_ms=0.0,
        created_at_s=created,
        deadline_at_s=created + 30.0,
        decision="accepted",
        answered_by="auto",
        answered_via="auto",
        chosen_alternative_index=0,
        state="applied" if verified is not None else "accepted",
        uploaded=verified is not None,
        verified=verified is not None,
        error="",
        history=tuple(history),
        alternatives=(),
    )


def _op(op_id: str, plans: tuple[PlanReport, ...]) -> OperationReport:
    return OperationReport(
        id=op_id,
        priority=1,
        conops="",
        vehicle="multirotor",
        state="active",
        flight_geometry_m=5.0,
        operational_volume_m=15.0,
        start_delay_s=0.0,
        plans=plans,
    )


def _report() -> Report:
    # A flies east 0 -> 1000 m in 100 s; its v2 (applied at 12 s) starts at 20 s (200 m) and
    # detours 100 m north around the middle (extra length 2 * (hypot(300, 100) - 300) m) and
    # arrives 5 s late.
    a1 = _plan(1, [(0, 0, 100, 0), (1000, 0, 100, 100)])
    a2 = _plan(
        2, [(200, 0, 100, 20), (500, 100, 100, 52.5), (800, 0, 100, 85), (1000, 0, 100, 105)]
    )
    b1 = _plan(1, [(500, -500, 100, 0), (500, 500, 100, 100)])
    return Report(
        scenario="hand-made",
        description="",
        speed="max",
        wall_clock_s=1.5,
        origin=OriginReport(lat_deg=LAT0, lon_deg=LON0, ground_elevation_amsl_m=0.0),
        separation_minimum=SeparationMinimum(
            mode="cylinder", horizontal_m=50.0, vertical_m=15.0, safety_distance_m=0.0
        ),
        operations=(_op("A", (a1, a2)), _op("B", (b1,)), _op("C", (b1,)), _op("D", (b1,))),
        geofences=(),
        # A-B predicted at 10 s and avoided; A-C predicted at 11 s and flown anyway; B-D
        # predicted only after A's plan was applied (no member of it was moved: not created);
        # A-D never predicted, flown after A's plan was applied: created by it
        threats=(_threat(("A", "B"), 10.0), _threat(("C", "A"), 11.0), _threat(("B", "D"), 30.0)),
        recommendations=(_rec("A", 10.0, 10.0, 12.0), _rec("B", 30.0, 31.0, None)),
        tracks={},
        telemetry={},
        counters={},
        adsb={},
        separation=(),
        geofence_intrusions=(),
        truth=TruthReport(
            pairs=(
                TruthPair(pair=("A", "B"), min_distance_m=80.0, loss_of_separation=False),
                TruthPair(
                    pair=("A", "C"),
                    min_distance_m=20.0,
                    loss_of_separation=True,
                    minimum_horizontal_m=50.0,
                    minimum_vertical_m=30.0,
                    horizontal_at_closest_m=20.0,
                    vertical_at_closest_m=3.5,
                    first_loss_at_s=40.0,
                ),
                TruthPair(
                    pair=("A", "D"),
                    min_distance_m=20.0,
                    loss_of_separation=True,
                    minimum_horizontal_m=50.0,
                    minimum_vertical_m=30.0,
                    horizontal_at_closest_m=21.0,
                    vertical_at_closest_m=0.5,
                    first_loss_at_s=50.0,
                ),
                TruthPair(pair=("B", "D"), min_distance_m=90.0, loss_of_separation=False),
            )
        ),
    )


def test_outcome_counts_predicted_flown_avoided_and_created_pairs() -> None:
    o = outcome(_report())
    assert o.predicted_pairs == (("A", "B"), ("A", "C"), ("B", "D"))
    assert o.flown_loss_pairs == (("A", "C"), ("A", "D"))
    assert (o.predicted, o.flown_predicted, o.avoided) == (3, 1, 2)
    assert o.created_pairs == (("A", "D"),)
    assert o.missed == 0
    assert o.detection_to_recommendation_s == (0.0, 1.0)
    assert o.detection_to_verified_upload_s == (2.0,)
    (plan,) = o.accepted_plans
    assert (plan.uas, plan.version) == ("A", 2)
    assert plan.extra_length_m == pytest.approx(2 * (math.hypot(300, 100) - 300), abs=0.05)
    assert plan.extra_time_s == pytest.approx(5.0)


def test_summary_totals_and_markdown() -> None:
    s = summarise([outcome(_report()), outcome(_report())], elapsed_wall_s=30.0, jobs=2)
    t = s.totals
    assert (t.predicted_losses, t.losses_avoided, t.share_avoided) == (
        6,
        4,
        pytest.approx(4 / 6, abs=1e-4),
    )
    assert t.losses_created_by_accepted_plans == 2
    assert (t.min_flown_horizontal_m, t.min_flown_vertical_m) == (20.0, 0.5)
    assert s.median_extra_length_m == pytest.approx(2 * (math.hypot(300, 100) - 300), abs=0.05)
    assert s.encounters_per_minute == pytest.approx(4.0)
    text = markdown(s)
    assert "| predicted losses avoided | 4 / 6 (66.7 %) |" in text
    assert "| elapsed (jobs), encounters per minute | 30 s (2), 4 |" in text
    assert (
        "| hand-made | 3 | 2: A-C predicted 20 / 3.5 m (minima 50 / 30); A-D created 21 / 0.5 m "
        "(minima 50 / 30) | 2 | 1 | 0 | 0 (0) | A v2 (+32 / +5) | 1.5 |"
    ) in text


@dataclass
class _Vehicle:
    sys_id: int
    position_history: list[tuple[float, float, float, float]]


def _scenario_two_uas(tmp_path: object) -> object:
    text = f"""
[scenario]
name = "two"
description = ""
duration_s = 100.0
[airspace]
origin_lat_deg = {LAT0}
origin_lon_deg = {LON0}
ground_elevation_amsl_m = 0.0
[[operations]]
id = "A"
sys_id = 1
priority = 1
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
waypoints = [
    {{ east_m = 0.0, north_m = 0.0, alt_agl_m = 50.0 }},
    {{ east_m = 100.0, north_m = 0.0, alt_agl_m = 50.0 }},
]
[[operations]]
id = "B"
sys_id = 2
priority = 1
cruise_speed_mps = 5.0
flight_geometry_m = 5.0
operational_volume_m = 10.0
waypoints = [
    {{ east_m = 0.0, north_m = 10.0, alt_agl_m = 50.0 }},
    {{ east_m = 100.0, north_m = 10.0, alt_agl_m = 50.0 }},
]
"""
    path = tmp_path / "two.toml"  # type: ignore[operator]
    path.write_text(text)
    return load_any(path, t0_s=0.0)


def test_truth_sees_a_head_on_pass_between_records(tmp_path: object) -> None:
    """Two UAS head-on at 30 m/s each, 40 m apart laterally, passing half-way between two
    records (once a second): no two records are closer than 50 m, the pass is at 40 m."""
    scenario = _scenario_two_uas(tmp_path)
    a = [(float(t), *_ll(-915.0 + 30.0 * t, 0.0), 100.0) for t in range(61)]
    b = [(float(t), *_ll(915.0 - 30.0 * t, 40.0), 100.0) for t in range(61)]
    sampled = min(
        math.hypot(*(np.subtract(_tp(p[1:3]), _tp(q[1:3])))) for p, q in zip(a, b, strict=True)
    )
    assert sampled > 49.99
    mon = MonitoringConfig()
    (pair,) = truth([_Vehicle(1, a), _Vehicle(2, b)], scenario, scenario.frame, mon).pairs  # type: ignore[attr-defined]
    assert pair.loss_of_separation
    assert pair.min_distance_m == pytest.approx(40.0, abs=0.05)


def _tp(latlon: tuple[float, float]) -> tuple[float, float]:
    az, _, dist = GEOD.inv(LON0, LAT0, latlon[1], latlon[0])
    return dist * math.sin(math.radians(az)), dist * math.cos(math.radians(az))


def test_truth_measures_true_metres_not_map_metres(tmp_path: object) -> None:
    """50.02 m apart (geodesic) is no loss, whatever the UTM zone's scale factor here."""
    scenario = _scenario_two_uas(tmp_path)
    frame: LocalFrame = scenario.frame  # type: ignore[attr-defined]
    a = [(float(t), *_ll(3000.0, 0.0), 100.0) for t in range(10)]
    b = [(float(t), *_ll(3000.0, 50.02), 100.0) for t in range(10)]
    (pair,) = truth([_Vehicle(1, a), _Vehicle(2, b)], scenario, frame, MonitoringConfig()).pairs  # type: ignore[arg-type]
    assert pair.min_distance_m == pytest.approx(50.02, abs=0.005)
    assert not pair.loss_of_separation


def test_truth_judges_a_pass_after_both_plans_have_ended(tmp_path: object) -> None:
    """The truth has no notion of plan ends: a vehicle is traffic while it is in the air.
    A pass at 40 m after both plans ended (A's and B's filed plans end at 100 s in the
    scenario; the pass is at 130 s) is a flown loss, with its one set of minima and the
    distances at the closest approach."""
    scenario = _scenario_two_uas(tmp_path)
    a = [(float(t), *_ll(-3900.0 + 30.0 * t, 0.0), 50.0) for t in range(161)]
    b = [(float(t), *_ll(3900.0 - 30.0 * t, 40.0), 52.0) for t in range(161)]
    frame = scenario.frame  # type: ignore[attr-defined]
    (pair,) = truth([_Vehicle(1, a), _Vehicle(2, b)], scenario, frame, MonitoringConfig()).pairs  # type: ignore[arg-type]
    assert pair.loss_of_separation
    assert (pair.minimum_horizontal_m, pair.minimum_vertical_m) == (50.0, 20.0)
    assert pair.closest_at_s == pytest.approx(130.0, abs=0.05)
    assert pair.horizontal_at_closest_m == pytest.approx(40.0, abs=0.05)
    assert pair.vertical_at_closest_m == pytest.approx(2.0, abs=0.01)
    assert pair.first_loss_at_s == pytest.approx(130.0 - 15.0 / 30.0 * 1.0, abs=0.05)
    assert pair.loss_duration_s == pytest.approx(1.0, abs=0.05)


def test_truth_leaves_out_vehicles_on_the_ground(tmp_path: object) -> None:
    """Two vehicles on the ground at their homes (the scenario's ground, 0 m AMSL) are not in
    the air: no loss however close, until one takes off."""
    scenario = _scenario_two_uas(tmp_path)
    frame = scenario.frame  # type: ignore[attr-defined]
    a = [(float(t), *_ll(0.0, 0.0), 0.0) for t in range(20)]
    b = [(float(t), *_ll(5.0, 0.0), 0.0 if t < 10 else 3.0) for t in range(20)]
    (ground,) = truth([_Vehicle(1, a), _Vehicle(2, b)], scenario, frame, MonitoringConfig()).pairs  # type: ignore[arg-type]
    assert not ground.loss_of_separation and ground.min_distance_m is None
    a_up = [(t, lat, lon, 2.0) for t, lat, lon, _ in a]
    (flying,) = truth(
        [_Vehicle(1, a_up), _Vehicle(2, b)], scenario, frame, MonitoringConfig()
    ).pairs  # type: ignore[arg-type]
    assert flying.loss_of_separation and flying.first_loss_at_s == pytest.approx(10.0)


def test_truth_intrusions_on_true_positions_with_their_duration(tmp_path: object) -> None:
    """A vehicle 12 s inside a cylinder that applies to it (records once a second), none for
    the exempt one."""
    from gcs_utm.model import Geofence, GeofenceShape, LatLon

    scenario = _scenario_two_uas(tmp_path)
    frame = scenario.frame  # type: ignore[attr-defined]
    lat, lon = _ll(0.0, 500.0)
    fence = Geofence(
        id="G",
        shape=GeofenceShape.CYLINDER,
        center=LatLon(lat_deg=lat, lon_deg=lon),
        radius_m=60.0,
        min_alt_amsl_m=0.0,
        max_alt_amsl_m=300.0,
        exempt=("B",),
    )
    path = [(float(t), *_ll(-205.0 + 10.0 * t, 500.0), 50.0) for t in range(41)]
    vehicles = [_Vehicle(1, path), _Vehicle(2, list(path))]
    report = truth(vehicles, scenario, frame, MonitoringConfig(), geofences={"G": fence})  # type: ignore[arg-type]
    (g,) = report.intrusions
    assert (g.uas, g.geofence, g.samples_inside) == ("A", "G", 12)  # east -55..55 m
    assert g.first_at_s == 15.0 and g.duration_s == 12.0


def test_escalations_without_a_proposed_command() -> None:
    """An escalation counts as carrying a command when a recommendation of the threat it
    names (else of a UAS it names) was proposed within a second of it."""
    base = _report()
    escalations = (
        EscalationReport(at_s=10.5, text="t: no feasible alternative for A"),  # A's rec at 10
        EscalationReport(at_s=31.0, text="t-B-D-30.0: no conflict-free combination"),
        EscalationReport(at_s=31.0, text="r-B v1 (B) expired without an answer"),
        EscalationReport(at_s=50.0, text="t: no feasible alternative for A"),
    )
    report = dataclasses.replace(base, escalations=escalations)
    o = outcome(report)
    # the rec of "t" proposed at 10 s: the first has a command; "t-B-D-30.0" has no rec
    # (B's rec is of threat "t"): none; the third names no threat, B's rec at 31 s: one;
    # the fourth is 40 s after any proposal: none
    assert (o.escalations, o.escalations_without_command) == (4, 2)
