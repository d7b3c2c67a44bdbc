"""The JSON-able report of a replay (documented in docs/formats.md), built from what its
:class:`~gcs_utm.app.replay_log.ReplayLog` saw and the runtime's parts."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from adapters.mavlink.vehicle import VehicleState
from adapters.tlog import TlogCounters
from gcs_utm.messages import VehicleStatus

from .replay import ReplayRuntime
from .replay_log import Point, ReplayLog


def replay_report(
    rt: ReplayRuntime,
    *,
    path: Path,
    records: int,
    span: tuple[float | None, float | None],
    counters: TlogCounters,
    wall_s: float,
    inputs: Sequence[dict[str, Any]] = (),
    adsb_feeds: dict[str, dict[str, int]] | None = None,
) -> dict[str, Any]:
    """The JSON-able report (docs/formats.md). Times are POSIX seconds; ``*_rel_s`` are
    seconds after the first record (``span``: the first and last record times)."""
    first_t_s, last_t_s = span
    t0 = first_t_s or 0.0

    def rel(t: float | None) -> float | None:
        return None if t is None else round(t - t0, 3)

    log = rt.log
    frame = rt.frame if rt.framed else None
    return {
        "file": str(path),
        "inputs": list(inputs) or [{"path": str(path), "kind": "tlog"}],
        "records": records,
        "vehicles": _vehicles(rt.hub.states(), log),
        "duration": {
            "first_t_s": first_t_s,
            "last_t_s": last_t_s,
            "duration_s": (
                round(last_t_s - first_t_s, 3)
                if first_t_s is not None and last_t_s is not None
                else 0.0
            ),
        },
        "frame": (
            None
            if frame is None
            else {
                "origin_lat_deg": frame.origin_lat_deg,
                "origin_lon_deg": frame.origin_lon_deg,
                "ground_elevation_amsl_m": frame.ground_elevation_amsl_m,
                "epsg": frame.epsg,
            }
        ),
        "tracks": {
            tid: {
                "cooperative": ts.cooperative,
                "updates": ts.updates,
                "first_t_s": ts.first_t_s,
                "last_t_s": ts.last_t_s,
                "first_rel_s": rel(ts.first_t_s),
                "last_rel_s": rel(ts.last_t_s),
                "last_position": _pos_json(ts.last_wgs84),
                "distance_m": round(ts.distance_m, 2),
                "max_ground_speed_mps": round(ts.max_speed_mps, 2),
            }
            for tid, ts in sorted(log.tracks.items())
        },
        "threats": [
            {
                "id": tid,
                "kind": th.kind,
                "uas": list(th.uas),
                "intruder": th.intruder,
                "first_t_s": th.first_t_s,
                "last_t_s": th.last_t_s,
                "first_rel_s": rel(th.first_t_s),
                "last_rel_s": rel(th.last_t_s),
                "closed_t_s": th.closed_t_s,
                "cycles": th.cycles,
                "min_closest_approach_m": th.min_closest_approach_m,
                "predicted_event_t_s": th.predicted_event_t_s,
                "message": th.message,
            }
            for tid, th in sorted(log.threats.items(), key=lambda kv: kv[1].first_t_s)
        ],
        "hazards": [
            {
                "kind": h.kind.value,
                "sys_id": h.sys_id,
                "t_s": h.t_s,
                "rel_s": rel(h.t_s),
                "message": h.message,
            }
            for h in log.hazards
        ],
        "remote_id": _remote_id_report(rt),
        "counters": _counters(rt, counters, adsb_feeds),
        "wall_s": round(wall_s, 3),
    }


def _counters(
    rt: ReplayRuntime, counters: TlogCounters, adsb_feeds: dict[str, dict[str, int]] | None
) -> dict[str, Any]:
    hc = rt.hub.counters
    tc = rt.tracking.tracker.counters
    reasons = ("out_of_order", "duplicate", "invalid", "gate", "unassociated")
    return {
        "corrupt_records": counters.corrupt_chunks + counters.truncated_tail,
        "tlog": counters.as_dict(),
        "adsb_relay": dataclasses.asdict(rt.hub.adsb_relay.counters),
        "adsb_feeds": adsb_feeds or {},
        "adsb_capture_measurements": rt.log.capture_measurements,
        "bad_frames": {
            "bad_crc": hc.bad_crc,
            "garbage": hc.garbage,
            "truncated": hc.truncated,
            "bad_signature": hc.bad_signature,
        },
        "frames": hc.frames,
        # valid frames of messages outside the adapter's common dialect (ArduPilot- or
        # PX4-specific): the tlog reader checked their CRC; telemetry ignores them
        "frames_not_in_common_dialect": hc.unknown_msg,
        "gcs_messages": hc.gcs_heartbeats,
        "handler_errors": hc.handler_errors,
        "measurements": rt.log.measurements,
        "accepted_measurements": tc.get("accepted", 0),
        "rejected_measurements": {r: tc.get(r, 0) for r in reasons},
        "monitoring_cycles": rt.monitoring.cycles,
    }


def _vehicles(states: list[VehicleState], log: ReplayLog) -> list[dict[str, Any]]:
    """One entry per sender that is a vehicle (an autopilot's heartbeat or a position). A
    system id's positions go to its component that reported them."""
    by_key = {(int(st.sys_id), st.key.comp_id): st for st in states}
    owner: dict[int, tuple[int, int]] = {}
    for key in sorted(by_key, key=lambda k: by_key[k].first_t_s):
        cur = owner.get(key[0])
        if cur is None or (
            by_key[cur].last_position is None and by_key[key].last_position is not None
        ):
            owner[key[0]] = key
    out = []
    for key in sorted(by_key):
        st = by_key[key]
        info = log.infos.get(key)
        pos = log.positions.get(key[0]) if owner.get(key[0]) == key else None
        if info is None and pos is None:
            continue  # not a vehicle: no autopilot heartbeat, no position
        status = log.statuses.get(key[0])
        last = pos.last if pos else None
        out.append(
            {
                "sys_id": key[0],
                "comp_id": key[1],
                "autopilot": info.autopilot.value if info else "unknown",
                "vehicle_kind": (info.vehicle_kind.value if info and info.vehicle_kind else None),
                "mav_type": info.mav_type if info else None,
                "messages": st.received,
                "positions": pos.count if pos else 0,
                "first_t_s": st.first_t_s,
                "last_t_s": st.last_heard_t_s,
                "first_position": _pos_json(pos.first if pos else None),
                "last_position": _pos_json(last),
                "home": _pos_json(_home(status)),
                "last_height_above_home_m": _above_home(status, last),
                "last_mode": status.mode.value if status else None,
                "armed": status.armed if status else None,
            }
        )
    return out


def _remote_id_report(rt: ReplayRuntime) -> dict[str, Any]:
    """The Remote ID heard: each source's identity on its track, and the counters."""
    return {
        "declared_sys_ids": sorted(rt.hub.remote_id.declared),
        "identities": [
            {"track_id": tid, **dataclasses.asdict(ident)}
            for tid, ident in sorted(rt.rid_tracks.by_track().items())
        ],
        "counters": {
            **dataclasses.asdict(rt.hub.remote_id.counters),
            **dataclasses.asdict(rt.rid_ingest.counters),
        },
    }


def _pos_json(p: Point | None) -> dict[str, float] | None:
    if p is None:
        return None
    return {"lat_deg": p[0], "lon_deg": p[1], "alt_amsl_m": p[2]}


def _home(status: VehicleStatus | None) -> Point | None:
    home = None if status is None else status.home
    return None if home is None else (home.lat_deg, home.lon_deg, home.alt_amsl_m)


def _above_home(status: VehicleStatus | None, last: Point | None) -> float | None:
    """The last position's height above the vehicle's home (AGL where home is on the
    ground), as the live service reads relative altitudes; None without a home."""
    home = _home(status)
    if home is None or last is None:
        return None
    return round(last[2] - home[2], 3)
