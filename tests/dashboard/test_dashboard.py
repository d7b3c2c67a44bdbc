"""Dashboard: Textual Pilot presses the accept and reject keys and the answers reach the USM;
views render as plain text with the data the operator relies on."""

from __future__ import annotations

from io import StringIO

from rich.console import Console

from gcs_utm.clock import ManualClock
from gcs_utm.dashboard.airspace_map import render_map
from gcs_utm.dashboard.airspace_scene import scene_of
from gcs_utm.dashboard.headless import HeadlessView
from gcs_utm.dashboard.tui import DashboardApp
from gcs_utm.dashboard.view import collect, operations_table, recommendation_panel
from gcs_utm.messages import PilotAnswer
from gcs_utm.model import (
    Alternative,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Maneuver,
    Operation,
    OperationId,
    Recommendation,
    RecommendationId,
    RecommendationState,
    SysId,
    ThreatId,
    ThreatKind,
    Track,
    TrackId,
    VehicleKind,
    Waypoint4D,
)
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.usm import AnswerOutcome, AnswerStatus, Usm

OP = OperationId("UAS1")


def _plan() -> FlightPlan:
    return FlightPlan(
        operation_id=OP,
        version=1,
        waypoints=(
            Waypoint4D(lat_deg=40.0, lon_deg=-3.0, alt_amsl_m=700.0, t_s=0.0),
            Waypoint4D(lat_deg=40.002, lon_deg=-3.001, alt_amsl_m=700.0, t_s=60.0),
        ),
    )


def _usm() -> Usm:
    airspace = Airspace()
    airspace.load(
        [
            Operation(
                id=OP,
                icao24=None,
                sys_id=SysId(1),
                priority=2,
                plan=_plan(),
                vehicle_kind=VehicleKind.MULTIROTOR,
                cruise_speed_mps=5.0,
                flight_geometry_m=5.0,
                operational_volume_m=20.0,
                conops="agriculture",
            )
        ],
        [
            Geofence(
                id=GeofenceId("fire"),
                shape=GeofenceShape.CYLINDER,
                center=LatLon(lat_deg=40.001, lon_deg=-3.0005),
                radius_m=50.0,
                min_alt_amsl_m=0.0,
                max_alt_amsl_m=1000.0,
                reason="wildfire",
            )
        ],
    )
    return Usm(airspace, ManualClock(10.0))


def _tracks() -> dict[TrackId, Track]:
    return {
        TrackId(OP): Track(
            id=TrackId(OP),
            t_s=10.0,
            lat_deg=40.0003,
            lon_deg=-3.0001,
            alt_amsl_m=701.0,
            east_m=0.0,
            north_m=0.0,
            vel_enu_mps=(3.0, 4.0, 0.0),
            position_sigma_m=1.0,
            cooperative=True,
            operation_id=OP,
        )
    }


def _rec(rec_id: str = "r1") -> Recommendation:
    alt = Alternative(operation_id=OP, maneuver=Maneuver.GO_LEFT, plan=_plan(), cost=0.2, risk=0.05)
    return Recommendation(
        id=RecommendationId(rec_id),
        version=1,
        threat_id=ThreatId("t1"),
        threat_kind=ThreatKind.LOSS_OF_SEPARATION,
        operation_id=OP,
        created_t_s=10.0,
        deadline_t_s=40.0,
        selected=alt,
        alternatives=(
            Alternative(
                operation_id=OP, maneuver=Maneuver.GO_DOWN, plan=_plan(), cost=0.3, risk=0.07
            ),
        ),
    )


def _render(renderable: object) -> str:
    buf = StringIO()
    Console(file=buf, width=100, color_system=None).print(renderable)
    return buf.getvalue()


def test_operations_table_shows_track_and_plan_progress() -> None:
    text = _render(operations_table(collect(_usm(), _tracks)))
    assert "UAS1" in text
    assert "5.0 m/s" in text  # ground speed from the track's velocity (3, 4)
    assert "agriculture" in text
    assert "Remote ID" not in text  # no column until some UAS broadcasts Remote ID


def test_operations_table_shows_the_remote_id_once_heard() -> None:
    from dataclasses import replace

    from gcs_utm.model import RemoteIdentity

    rid = RemoteIdentity(source="sysid:1", uas_id="1596A303716531B", operator_id="FIN87astr")
    tracks = {k: replace(t, remote_id=rid) for k, t in _tracks().items()}
    buf = StringIO()
    Console(file=buf, width=200, color_system=None).print(
        operations_table(collect(_usm(), lambda: tracks), width=200)
    )
    text = buf.getvalue()
    assert "Remote ID" in text and "1596A303716531B / FIN87astr" in text


def test_prompt_shows_threat_options_in_words_scores_behind_details_and_deadline() -> None:
    usm = _usm()
    text = _render(recommendation_panel(_rec(), collect(usm, _tracks)))
    assert "LOSS_OF_SEPARATION" in text
    assert "Turn left" in text and "Descend below the plan" in text
    assert "0.200" not in text  # the raw scores are behind [d]
    assert "[d] show scores" in text
    details = _render(recommendation_panel(_rec(), collect(usm, _tracks), details=True))
    assert "go_left" in details and "go_down" in details
    assert "0.200" in details and "0.070" in details
    assert "30 s left" in text
    assert "[a] accept 0 go_left" in text


def test_map_draws_geofence_plan_and_track() -> None:
    text = render_map(scene_of(collect(_usm(), _tracks)), 40, 12).plain()
    assert "#" in text and "·" in text and "↗UAS1" in text  # course 37 deg: north-east


async def _run_keys(keys: list[str]) -> tuple[Usm, list[PilotAnswer], DashboardApp]:
    usm = _usm()
    seen: list[PilotAnswer] = []
    original = usm.answer

    async def spy(a: PilotAnswer) -> AnswerOutcome:
        seen.append(a)
        return await original(a)

    usm.answer = spy  # type: ignore[method-assign]
    app = DashboardApp(usm, _tracks, refresh_s=0.1, guard_s=0.0)
    usm.attach_operator(app)
    async with app.run_test(size=(140, 50)) as pilot:
        await usm.on_recommendation(_rec("r1"))
        await usm.on_recommendation(_rec("r2"))
        await pilot.pause()
        for key in keys:
            await pilot.press(key)
            await pilot.pause()
    await usm.drain()
    return usm, seen, app


async def test_pilot_accept_key_answers_the_shown_recommendation() -> None:
    usm, seen, app = await _run_keys(["a"])
    assert [(a.recommendation_id, a.decision.value, a.source) for a in seen] == [
        ("r1", "accept", "dashboard")
    ]
    # no vehicle link in this test: accepted, then failed upload, never applied
    assert usm.recommendations[RecommendationId("r1")].rec.state is RecommendationState.FAILED
    assert app.outcomes[0].status is AnswerStatus.ACCEPTED


async def test_pilot_reject_then_next_pending() -> None:
    usm, seen, _app = await _run_keys(["r", "r"])
    assert [(a.recommendation_id, a.decision.value) for a in seen] == [
        ("r1", "reject"),
        ("r2", "reject"),
    ]
    assert all(
        usm.recommendations[RecommendationId(r)].rec.state is RecommendationState.REJECTED
        for r in ("r1", "r2")
    )


async def test_headless_view_prints_recommendation() -> None:
    usm = _usm()
    buf = StringIO()
    view = HeadlessView(usm, _tracks, Console(file=buf, width=100, color_system=None))
    await view.present(_rec())
    view.status()
    out = buf.getvalue()
    assert "Turn left" in out and "1 ops" in out
