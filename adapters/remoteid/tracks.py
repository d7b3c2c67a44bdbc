"""Remote ID on the tracks: what the dashboard, the MQTT traffic feed and the store show.

:class:`~adapters.remoteid.ingest.RidIngest` keeps the latest of each Remote ID record
(``sysid:<n>``: what vehicle n reports of itself; ``rid:<hex>``: an aircraft a vehicle's
receiver heard). :class:`RidTracks` puts each record on the track it is about, as the model's
:class:`~gcs_utm.model.RemoteIdentity` in ``Track.remote_id``:

- a ``rid:`` record on the track of the same id (its Locations make that track);
- a ``sysid:<n>`` record on the track of the operation flown by system n, else on the
  vehicle's own track (``sysid:<n>``, or ``sysid:<n>@<address>`` as tracking names a vehicle
  it knows by its link address).

A record whose track does not exist (yet) is on no track. :meth:`RidTracks.attach` is cheap
when no Remote ID was heard (the snapshot is returned as it is).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import replace

from adapters.remoteid.ingest import RidAircraft
from gcs_utm.model import Operation, RemoteIdentity, Track, TrackId

_WRITTEN_MAX = 8192  # sources remembered by changed_identities


def remote_identity(rec: RidAircraft) -> RemoteIdentity:
    """The model's view of one Remote ID record."""
    where = rec.position
    return RemoteIdentity(
        source=rec.key,
        uas_id=rec.uas_id,
        id_type="" if rec.id_type is None else rec.id_type.name,
        ua_type="" if rec.ua_type is None else rec.ua_type.name,
        operator_id=rec.operator_id,
        lat_deg=None if where is None else where.lat_deg,
        lon_deg=None if where is None else where.lon_deg,
        alt_m=None if where is None else where.alt_amsl_m,
        location_t_s=rec.position_t_s,
        updated_t_s=rec.updated_t_s,
    )


class RidTracks:
    """See the module docstring. ``records``: the ingest's records by key (read at each call);
    ``operations``: the filed operations (their system ids)."""

    def __init__(
        self,
        records: Callable[[], Mapping[str, RidAircraft]],
        operations: Callable[[], Iterable[Operation]],
    ) -> None:
        self._records = records
        self._operations = operations

    def by_track(self) -> dict[str, RemoteIdentity]:
        """Remote identities by the id of the track they belong on (``sysid:<n>`` stands for
        every ``sysid:<n>@<address>`` track too)."""
        records = self._records()
        if not records:
            return {}
        op_of_sys: dict[int, str] = {
            op.sys_id: op.id for op in self._operations() if op.sys_id is not None
        }
        out: dict[str, RemoteIdentity] = {}
        for rec in list(records.values()):
            if rec.sys_id is None:
                out[rec.key] = remote_identity(rec)
            else:
                out[op_of_sys.get(rec.sys_id, rec.key)] = remote_identity(rec)
        return out

    def attach(self, tracks: dict[TrackId, Track]) -> dict[TrackId, Track]:
        """The snapshot with ``remote_id`` set on each track a record belongs on."""
        by_track = self.by_track()
        if not by_track:
            return tracks
        out = dict(tracks)
        for tid, track in tracks.items():
            ident = by_track.get(tid) or by_track.get(tid.split("@", 1)[0])
            if ident is not None:
                out[tid] = replace(track, remote_id=ident)
        return out

    def attach_list(self, tracks: Sequence[Track]) -> list[Track]:
        """:meth:`attach` for a batch of track samples (the store's track writes)."""
        by_track = self.by_track()
        if not by_track:
            return list(tracks)
        out: list[Track] = []
        for track in tracks:
            ident = by_track.get(track.id) or by_track.get(track.id.split("@", 1)[0])
            out.append(track if ident is None else replace(track, remote_id=ident))
        return out

    def track_sink(
        self,
        write_tracks: Callable[[list[Track]], None],
        write_identities: Callable[[list[tuple[TrackId, RemoteIdentity]]], None],
    ) -> Callable[[list[Track]], None]:
        """The tracking service's sink to the store: the tracks with their Remote ID, and the
        identities that changed since they were last written (:func:`changed_identities`)."""
        written: dict[str, float] = {}

        def sink(tracks: list[Track]) -> None:
            tracks = self.attach_list(tracks)
            write_tracks(tracks)
            rows = changed_identities(tracks, written)
            if rows:
                write_identities(rows)

        return sink


def changed_identities(
    tracks: Iterable[Track], written: dict[str, float]
) -> list[tuple[TrackId, RemoteIdentity]]:
    """(track id, identity) of each Remote ID on ``tracks`` that changed since it was last
    written (``written``: source -> its updated_t_s then; updated here)."""
    if len(written) > _WRITTEN_MAX:  # sources come and go (anybody in radio range): start again
        written.clear()
    out: list[tuple[TrackId, RemoteIdentity]] = []
    for track in tracks:
        ident = track.remote_id
        if ident is None or written.get(ident.source) == ident.updated_t_s:
            continue
        written[ident.source] = ident.updated_t_s
        out.append((track.id, ident))
    return out
