"""An unfiled MAVLink vehicle on the ground is not an intruder (services/ground_vehicles.py)."""

from __future__ import annotations

from gcs_utm.model import SysId, Track, TrackId
from gcs_utm.services.airspace import Airspace
from gcs_utm.services.ground_vehicles import grounded_tracks, track_sys_id


def _track(tid: str, *, cooperative: bool = False) -> Track:
    return Track(
        id=TrackId(tid), t_s=0.0, lat_deg=0.0, lon_deg=0.0, alt_amsl_m=0.0, east_m=0.0,
        north_m=0.0, vel_enu_mps=(0.0, 0.0, 0.0), position_sigma_m=1.0, cooperative=cooperative,
    )  # fmt: skip


def test_the_system_id_of_a_track_id() -> None:
    assert track_sys_id("sysid:2") == 2
    assert track_sys_id("sysid:17@127.0.0.1:5770") == 17
    assert track_sys_id("icao:abc123") is None
    assert track_sys_id("sysid:x@h") is None
    assert track_sys_id("rid:0a0b") is None


def test_the_tracks_of_vehicles_on_the_ground() -> None:
    tracks = {
        TrackId(t.id): t
        for t in (
            _track("sysid:2@h:1"),
            _track("sysid:3"),
            _track("icao:abc123"),
            _track("OP1", cooperative=True),
        )
    }
    assert grounded_tracks(tracks, {SysId(2)}) == {"sysid:2@h:1"}
    assert grounded_tracks(tracks, set()) == frozenset()


def test_the_airspace_snapshot_names_them_from_the_vehicles_own_state() -> None:
    airspace = Airspace()
    tracks = {TrackId("sysid:2@h:1"): _track("sysid:2@h:1"), TrackId("sysid:3"): _track("sysid:3")}
    airspace.set_airborne(SysId(2), False)  # disarmed on the ground
    airspace.set_airborne(SysId(3), True)  # flying
    snap = airspace.snapshot(0.0, lambda: (tracks, None))
    assert snap.grounded_tracks == {"sysid:2@h:1"}
