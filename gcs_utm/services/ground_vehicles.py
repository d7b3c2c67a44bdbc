"""MAVLink vehicles without an operation that say they are on the ground are not intruders.

Tracking names the track of a MAVLink vehicle that flies no operation ``sysid:<n>``, or
``sysid:<n>@<host:port>`` (``core/tracking/intake.py``), and Monitoring checks every
non-cooperative track against the UAS as an intruder. A disarmed vehicle standing beside a
take-off point (a second copter, a relay, one waiting for its mission) was an INTRUDER threat
of the UAS climbing above it: on the ground it is not traffic, as an operation's vehicle on
the ground is not (``AirspaceSnapshot.grounded``). Its own messages say so (flight_state.py).
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

from gcs_utm.model import SysId, Track, TrackId

_PREFIX = "sysid:"


def track_sys_id(track_id: str) -> SysId | None:
    """The system id in a ``sysid:<n>[@<host:port>]`` track id, else None."""
    if not track_id.startswith(_PREFIX):
        return None
    text = track_id[len(_PREFIX) :].split("@", 1)[0]
    return SysId(int(text)) if text.isdigit() else None


def grounded_tracks(
    tracks: Mapping[TrackId, Track], on_ground: Collection[SysId]
) -> frozenset[TrackId]:
    """The non-cooperative tracks of MAVLink vehicles whose system id is ``on_ground``."""
    if not on_ground:
        return frozenset()
    return frozenset(
        tid for tid, t in tracks.items() if not t.cooperative and track_sys_id(tid) in on_ground
    )
