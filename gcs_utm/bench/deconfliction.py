"""Deconfliction latency: from a threat to the selected recommendation (EM + TD + Monitoring
verification), on three synthetic scenarios built in the local frame:

- ``deconfliction.los_2uas``: two UAS head-on at the same altitude (loss of separation);
- ``deconfliction.geofence_reroute_20``: one UAS whose plan crosses a row of geofences, 20
  geofences in the airspace (cylinders and polygons);
- ``deconfliction.chain_5uas``: five UAS, the paper's Figure 9 chain: A and B in conflict, and
  C, D, E stacked so that pushing one pushes the next.

Each run builds a fresh :class:`EmergencyManager` (so no state is reused) and times
``on_threat``; the scenario construction is outside the timing. The builders are public so
the tests exercise exactly what is benchmarked.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from gcs_utm.bench.timing import summary, time_runs
from gcs_utm.core.deconfliction import DeconflictionConfig, TacticalDeconfliction
from gcs_utm.core.emergency import EmergencyConfig, EmergencyManager
from gcs_utm.core.monitoring.config import MonitoringConfig
from gcs_utm.geo import LocalFrame
from gcs_utm.model import (
    AirspaceSnapshot,
    FlightPlan,
    Geofence,
    GeofenceId,
    GeofenceShape,
    LatLon,
    Operation,
    OperationId,
    OperationState,
    Position,
    Threat,
    ThreatId,
    ThreatKind,
    VehicleKind,
    Waypoint4D,
)

NAME = "deconfliction"
T0_S = 1_700_000_000.0
FRAME = LocalFrame(37.41, -6.0, 0.0)


def make_operation(
    op_id: str,
    points_enz: Sequence[tuple[float, float, float]],
    *,
    frame: LocalFrame = FRAME,
    t0_s: float = T0_S,
    speed_mps: float = 10.0,
    priority: int = 1,
    ov_m: float = 10.0,
    landing_sites: Sequence[tuple[float, float, float]] = (),
    endurance_s: float | None = None,
    home_enz: tuple[float, float, float] | None = None,
) -> Operation:
    """An active multirotor operation flying ``points_enz`` (local east/north m, AMSL m) at
    ``speed_mps`` from ``t0_s``."""
    pts = np.asarray(points_enz, dtype=np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1) if len(pts) > 1 else np.zeros(0)
    t = t0_s + np.concatenate([[0.0], np.cumsum(seg / speed_mps)])
    lat, lon = frame.to_wgs84(pts[:, 0], pts[:, 1])
    wps = tuple(
        Waypoint4D(
            lat_deg=float(lat[i]),
            lon_deg=float(lon[i]),
            alt_amsl_m=float(pts[i, 2]),
            t_s=float(t[i]),
        )
        for i in range(len(pts))
    )

    def pos(p: tuple[float, float, float]) -> Position:
        la, lo = frame.point_to_wgs84(p[0], p[1])
        return Position(lat_deg=la, lon_deg=lo, alt_amsl_m=p[2])

    oid = OperationId(op_id)
    return Operation(
        id=oid,
        icao24=None,
        sys_id=None,
        priority=priority,
        plan=FlightPlan(operation_id=oid, version=1, waypoints=wps),
        vehicle_kind=VehicleKind.MULTIROTOR,
        cruise_speed_mps=speed_mps,
        flight_geometry_m=ov_m / 2.0,
        operational_volume_m=ov_m,
        state=OperationState.ACTIVE,
        landing_sites=tuple(pos(s) for s in landing_sites),
        endurance_s=endurance_s,
        home=pos(home_enz) if home_enz is not None else None,
        max_climb_rate_mps=3.0,
    )


def cylinder(
    fid: str,
    e_m: float,
    n_m: float,
    radius_m: float,
    *,
    frame: LocalFrame = FRAME,
    min_alt_m: float = 0.0,
    max_alt_m: float = 500.0,
) -> Geofence:
    lat, lon = frame.point_to_wgs84(e_m, n_m)
    return Geofence(
        id=GeofenceId(fid),
        shape=GeofenceShape.CYLINDER,
        min_alt_amsl_m=min_alt_m,
        max_alt_amsl_m=max_alt_m,
        center=LatLon(lat_deg=lat, lon_deg=lon),
        radius_m=radius_m,
    )


def polygon(
    fid: str,
    vertices_en: Sequence[tuple[float, float]],
    *,
    frame: LocalFrame = FRAME,
    min_alt_m: float = 0.0,
    max_alt_m: float = 500.0,
) -> Geofence:
    verts = []
    for e, n in vertices_en:
        lat, lon = frame.point_to_wgs84(e, n)
        verts.append(LatLon(lat_deg=lat, lon_deg=lon))
    return Geofence(
        id=GeofenceId(fid),
        shape=GeofenceShape.POLYGON,
        min_alt_amsl_m=min_alt_m,
        max_alt_amsl_m=max_alt_m,
        vertices=tuple(verts),
    )


def snapshot(
    ops: Sequence[Operation], fences: Sequence[Geofence] = (), t_s: float = T0_S
) -> AirspaceSnapshot:
    return AirspaceSnapshot(
        t_s=t_s, operations={o.id: o for o in ops}, tracks={}, geofences=tuple(fences)
    )


def threat(
    kind: ThreatKind,
    uas: Sequence[str],
    *,
    tid: str = "t1",
    t_s: float = T0_S,
    event_in_s: float = 60.0,
    **extra: object,
) -> Threat:
    return Threat(
        id=ThreatId(tid),
        kind=kind,
        uas_ids=tuple(OperationId(u) for u in uas),
        detected_at_s=t_s,
        predicted_event_at_s=t_s + event_in_s,
        **extra,  # type: ignore[arg-type]
    )


def scenario_los_2uas() -> tuple[AirspaceSnapshot, Threat]:
    a = make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=1)
    b = make_operation("B", [(1000, 0, 100), (-1000, 0, 100)], priority=2)
    return snapshot([a, b]), threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=100)


def scenario_geofence_reroute(n_fences: int = 20) -> tuple[AirspaceSnapshot, Threat]:
    """A west-east plan through a 5 x 4 field of geofences (alternating cylinders and
    squares), the first one on the track."""
    op = make_operation("A", [(-1500, 0, 100), (1500, 0, 100)], ov_m=10.0)
    fences: list[Geofence] = []
    for k in range(n_fences):
        col, row = divmod(k, 4)
        e = -800.0 + col * 400.0
        n = (0.0, 450.0, -450.0, 900.0)[row]  # row 0 sits on the track
        if k % 2 == 0:
            fences.append(cylinder(f"g{k}", e, n, 80.0))
        else:
            fences.append(
                polygon(
                    f"g{k}",
                    [(e - 70, n - 70), (e + 70, n - 70), (e + 70, n + 70), (e - 70, n + 70)],
                )
            )
    # 30 s into the flight: 300 m from home, the first fence 400 m ahead.
    return snapshot([op], fences, t_s=T0_S + 30.0), threat(
        ThreatKind.GEOFENCE_CONFLICT,
        ["A"],
        geofence_id=GeofenceId("g0"),
        t_s=T0_S + 30.0,
        event_in_s=40,
    )


def scenario_chain_5uas() -> tuple[AirspaceSnapshot, Threat]:
    """A and B converge head-on at 100 m; C (125 m) and E (150 m) fly 30 and 60 m north of
    A's track, D (75 m) 30 m south: stacked just above the 20 m vertical minimum, so a
    vertical push on A or B runs into the next UAS (Figure 9)."""
    ops = [
        make_operation("A", [(-1000, 0, 100), (1000, 0, 100)], priority=1),
        make_operation("B", [(1000, 0, 100), (-1000, 0, 100)], priority=1),
        make_operation("C", [(-1000, 30, 125), (1000, 30, 125)], priority=2),
        make_operation("D", [(1000, -30, 75), (-1000, -30, 75)], priority=2),
        make_operation("E", [(-1000, 60, 150), (1000, 60, 150)], priority=3),
    ]
    return snapshot(ops), threat(ThreatKind.LOSS_OF_SEPARATION, ["A", "B"], event_in_s=100)


def build_manager(frame: LocalFrame = FRAME) -> EmergencyManager:
    mon = MonitoringConfig()
    td = TacticalDeconfliction(frame, DeconflictionConfig(), mon)
    return EmergencyManager(frame, EmergencyConfig(), td, mon)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--runs", type=int, default=30, help="timed repetitions per scenario")
    p.add_argument("--warmup", type=int, default=2, help="untimed repetitions first")


def run(args: argparse.Namespace) -> list[dict[str, object]]:
    runs = int(getattr(args, "runs", 30))
    warmup = int(getattr(args, "warmup", 2))
    out: list[dict[str, object]] = []
    cases = (
        ("deconfliction.los_2uas", 2, scenario_los_2uas, 20.0),
        ("deconfliction.geofence_reroute_20", 20, scenario_geofence_reroute, 50.0),
        ("deconfliction.chain_5uas", 5, scenario_chain_5uas, 200.0),
    )
    for name, n, build, target_ms in cases:
        snap, thr = build()
        # A fresh manager per call (a second on_threat for the same threat would be a no-op),
        # built before the timing starts: only on_threat is timed.
        managers = [build_manager() for _ in range(runs + warmup)]
        selected: list[int] = []

        def once(
            snap: AirspaceSnapshot = snap,
            thr: Threat = thr,
            sel: list[int] = selected,
            pool: list[EmergencyManager] = managers,
        ) -> None:
            d = pool.pop().on_threat(thr, snap)
            sel.append(len(d.recommendations))

        durations = time_runs(once, runs=runs, warmup=warmup)
        out.append(
            summary(name, n, durations, target_p99_ms=target_ms, recommendations=selected[-1])
        )
    return out
