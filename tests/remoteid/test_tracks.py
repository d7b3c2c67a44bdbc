"""Remote ID records on the tracks (adapters/remoteid/tracks.py): which track each record
belongs on, and which identities the store is given."""

from __future__ import annotations

from dataclasses import replace

from adapters.remoteid.f3411 import IdType, UaType
from adapters.remoteid.ingest import RidAircraft
from adapters.remoteid.tracks import RidTracks, changed_identities, remote_identity
from gcs_utm.model import (
    OperationId,
    Position,
    RemoteIdentity,
    SysId,
    Track,
    TrackId,
)
from tests.e2e.test_sysid_conflict import _operation


def _track(tid: str) -> Track:
    return Track(
        id=TrackId(tid), t_s=1.0, lat_deg=45.0, lon_deg=-73.0, alt_amsl_m=80.0, east_m=0.0,
        north_m=0.0, vel_enu_mps=(0.0, 0.0, 0.0), position_sigma_m=1.0, cooperative=False,
    )  # fmt: skip


def _rec(key: str, sys_id: int | None, uas_id: str, t_s: float = 5.0) -> RidAircraft:
    return RidAircraft(
        key=key,
        sys_id=sys_id,
        uas_id=uas_id,
        id_type=IdType.SERIAL_NUMBER,
        ua_type=UaType.AEROPLANE,
        operator_id="FIN87astrdge12k8",
        position=Position(lat_deg=45.1, lon_deg=-73.1, alt_amsl_m=120.0),
        position_t_s=4.0,
        updated_t_s=t_s,
    )


def test_remote_identity_of_a_record() -> None:
    ident = remote_identity(_rec("rid:0a0b", None, "SN1"))
    assert ident == RemoteIdentity(
        source="rid:0a0b", uas_id="SN1", id_type="SERIAL_NUMBER", ua_type="AEROPLANE",
        operator_id="FIN87astrdge12k8", lat_deg=45.1, lon_deg=-73.1, alt_m=120.0,
        location_t_s=4.0, updated_t_s=5.0,
    )  # fmt: skip


def test_each_record_goes_on_its_track() -> None:
    op = _operation(0.0)  # operation UAS1 flown by system 1
    records = {
        "sysid:1": _rec("sysid:1", 1, "OWN1"),  # -> the operation's track
        "sysid:2": _rec("sysid:2", 2, "OWN2"),  # no operation: the vehicle's own track
        "rid:0a0b": _rec("rid:0a0b", None, "HEARD"),  # -> its rid: track
        "sysid:9": _rec("sysid:9", 9, "NOTRACK"),  # no track: on none
    }
    tracks = {
        TrackId(t): _track(t)
        for t in ("UAS1", "sysid:2@127.0.0.1:14550", "rid:0a0b", "sysid:1@x", "icao:abc123")
    }
    out = RidTracks(lambda: records, lambda: [op]).attach(tracks)
    got = {tid: (t.remote_id.uas_id if t.remote_id else None) for tid, t in out.items()}
    assert got == {
        "UAS1": "OWN1",
        "sysid:2@127.0.0.1:14550": "OWN2",
        "rid:0a0b": "HEARD",
        "sysid:1@x": None,  # system 1 flies UAS1: its Remote ID is on the operation's track
        "icao:abc123": None,
    }
    assert op.sys_id == SysId(1) and op.id == OperationId("UAS1")
    assert tracks[TrackId("UAS1")].remote_id is None  # the snapshot given is not changed
    listed = RidTracks(lambda: records, lambda: [op]).attach_list(list(tracks.values()))
    assert [t.remote_id is not None for t in listed] == [True, True, True, False, False]


def test_no_remote_id_returns_the_snapshot_itself() -> None:
    tracks = {TrackId("UAS1"): _track("UAS1")}
    assert RidTracks(dict, list).attach(tracks) is tracks


def test_changed_identities_are_written_once_each() -> None:
    written: dict[str, float] = {}
    ident = remote_identity(_rec("rid:0a0b", None, "HEARD"))
    track = replace(_track("rid:0a0b"), remote_id=ident)
    assert changed_identities([track, _track("x")], written) == [(TrackId("rid:0a0b"), ident)]
    assert changed_identities([track], written) == []  # unchanged: not again
    newer = replace(track, remote_id=replace(ident, updated_t_s=6.0))
    assert changed_identities([newer], written) == [(TrackId("rid:0a0b"), newer.remote_id)]
