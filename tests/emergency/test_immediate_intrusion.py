"""An immediate command that flies its UAS into a geofence ranks after one that does not
(issue 30, class 3; ``immediate._rank``, ``command_fences.fence_itself_entered``).

Seed 6's enc_6_0225_late_crossing: a fixed wing eastbound at 21.8 m/s and a multirotor
crossing its track at nearly its altitude, the loss predicted 6.3 s ahead. The turn left
(north) kept the minima (ratio 1.14) but its far point lay beyond a no-fly zone 224 m ahead
and left: flown forward it crossed the fence 40.7 m deep 13 s after the decision. A
combination that keeps the minima ranked before every one that does not, fence or no fence,
so the turn left was proposed; the fixed wing flew 4.2 s inside the fence (and, held there,
17.9 m from the multirotor). The turn right (ratio 0.90, 136 m from the fence) was there:
flown, it passed 75.7 m from the multirotor and nowhere near the fence. A command whose
positions come within the UAS's flight geometry of a fence is an intrusion and now ranks
after every command that is not; one that only comes within its operational volume (the
clearance TD keeps) still ranks by separation first."""

from __future__ import annotations

from dataclasses import replace

from gcs_utm.bench import deconfliction as sc
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency.fly_on import Choice
from gcs_utm.core.emergency.immediate import choose_commands
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.model import AirspaceSnapshot, Geofence, OperationId, Track, TrackId, VehicleKind

A, B = OperationId("A"), OperationId("B")
NOW = sc.T0_S + 89.0


def _track(op: str, e: float, n: float, vel: tuple[float, float]) -> Track:
    la, lo = sc.FRAME.point_to_wgs84(e, n)
    return Track(
        id=TrackId(op),
        t_s=NOW,
        lat_deg=la,
        lon_deg=lo,
        alt_amsl_m=100.0,
        east_m=e,
        north_m=n,
        vel_enu_mps=(vel[0], vel[1], 0.0),
        position_sigma_m=1.0,
        cooperative=True,
        operation_id=OperationId(op),
    )


def _crossing(fence: Geofence | None) -> AirspaceSnapshot:
    """Fixed wing B (priority 5) eastbound at 21.8 m/s; multirotor A (priority 7) heading
    north-east at 10 m/s to meet it 9 s from now at the origin, at its altitude."""
    a = sc.make_operation(
        "A", [(-67, -60, 100), (433, 386, 100)], priority=7, speed_mps=10.0, ov_m=15.0
    )
    b = sc.make_operation(
        "B", [(-196, 0, 100), (2000, 0, 100)], priority=5, speed_mps=21.8, ov_m=25.0
    )
    b = replace(b, vehicle_kind=VehicleKind.FIXED_WING, max_climb_rate_mps=5.0)
    tracks = {
        TrackId("A"): _track("A", -67.0, -60.0, (7.47, 6.65)),
        TrackId("B"): _track("B", -196.0, 0.0, (21.8, 0.0)),
    }
    snap = sc.snapshot([a, b], [fence] if fence else [], t_s=NOW)
    return replace(snap, tracks=tracks)


def _choose(fence: Geofence | None) -> Choice:
    td = TacticalDeconfliction(sc.FRAME, DeconflictionConfig(), MonitoringConfig())
    choice = choose_commands(td, _crossing(fence), [A, B], NOW + 3.0, NOW + 6.3, {A: 7, B: 5})
    assert choice is not None
    return choice


def _turn_left(choice: Choice) -> dict[str, object]:
    (rec,) = [x for x in choice.tried if x["commands"] == {"B": "turn left"}]
    return rec


def test_a_command_that_keeps_the_minima_through_a_fence_loses_to_one_that_enters_none() -> None:
    """Without a fence B turns left (north, away from A: 1.05 of the minima) and right keeps
    0.78. A no-fly zone of 30 m radius 300 m north, across the turn left's path: that turn
    (and B's hold, circling where it is) would fly into it, so B turns right."""
    assert _choose(None).actions == {B: "turn left"}
    choice = _choose(sc.cylinder("G1", -60.0, 300.0, 30.0))
    assert choice.actions == {B: "turn right"} and not choice.geofences, choice.actions
    assert 0.7 < choice.ratio < 1.0 and not choice.clear
    left = _turn_left(choice)
    assert float(str(left["ratio"])) > 1.0 and left.get("intrusion") is True, left


def test_a_command_that_only_comes_within_the_uas_volume_of_a_fence_keeps_the_minima() -> None:
    """The same fence 44 m further east: the turn left passes 22 m from its edge, inside B's
    25 m operational volume but beyond its 12.5 m flight geometry. That is a clearance kept
    short, not an intrusion: the turn that keeps the minima is still chosen (and the audit
    names the fence)."""
    choice = _choose(sc.cylinder("G1", -16.0, 300.0, 30.0))
    assert choice.actions == {B: "turn left"} and choice.clear, choice.actions
    assert choice.geofences == ("G1",)
    assert "intrusion" not in _turn_left(choice)
